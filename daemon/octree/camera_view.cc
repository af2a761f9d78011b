#include "octree/camera_view.h"

#include <algorithm>

#include "common/check.h"

namespace hg::octree {

CameraView::CameraView(const geometry::CameraModel& pinhole,
                       const std::vector<geometry::TriangleMesh>& obstacles)
    : projector_(pinhole.K, pinhole.R_CW, pinhole.t_CW),
      width_(pinhole.width),
      height_(pinhole.height) {
  HG_CHECK(!pinhole.HasDistortion());
  HG_CHECK(pinhole.K(2, 2) == 1.0 && pinhole.K(2, 0) == 0.0 && pinhole.K(2, 1) == 0.0);
  bool any_triangle = false;
  for (const auto& m : obstacles) any_triangle = any_triangle || !m.triangles.empty();
  if (!any_triangle) return;
  depth_map_ = geometry::RenderObstacleDepth(pinhole, obstacles);
  near_min_ = geometry::DepthPyramid(depth_map_.near_depth, width_, height_,
                                     geometry::DepthPyramid::Kind::kMin);
  centre_max_ = geometry::DepthPyramid(depth_map_.centre_depth, width_, height_,
                                       geometry::DepthPyramid::Kind::kMax);
  obstacle_rect_ = {width_, height_, -1, -1};
  for (int v = 0; v < height_; ++v) {
    for (int u = 0; u < width_; ++u) {
      if (depth_map_.near_depth[static_cast<std::size_t>(v) * width_ + u] !=
          geometry::ObstacleDepthMap::kNone) {
        obstacle_rect_ = {std::min(obstacle_rect_.u0, u), std::min(obstacle_rect_.v0, v),
                          std::max(obstacle_rect_.u1, u), std::max(obstacle_rect_.v1, v)};
      }
    }
  }
}

namespace {

// Outside the obstacles' rectangle (empty without obstacles) no pixel sees one.
bool NearObstacle(const CameraView& view, const geometry::PixelRect& clip) {
  const geometry::PixelRect& o = view.obstacle_rect();
  return clip.u0 <= o.u1 && clip.u1 >= o.u0 && clip.v0 <= o.v1 && clip.v1 >= o.v0;
}

}  // namespace

ObstacleRelation RelateToObstacles(const CameraView& view, const geometry::Footprint& fp) {
  if (fp.side != geometry::Footprint::Side::kInFront) return ObstacleRelation::kPartial;
  const geometry::PixelRect clip = geometry::ClipToImage(fp.rect, view.width(), view.height());
  if (clip.Empty() || !NearObstacle(view, clip)) return ObstacleRelation::kClear;
  if (view.near_min().AllGreater(clip, fp.z_far)) return ObstacleRelation::kClear;
  if (view.centre_max().AllLess(clip, fp.z_near)) return ObstacleRelation::kBehind;
  return ObstacleRelation::kPartial;
}

bool CertifiesFree(const CameraView& view, const silhouette::SilhouetteQuadtree* mask,
                   const geometry::Footprint& fp, ObstacleRelation relation) {
  if (mask == nullptr || fp.side != geometry::Footprint::Side::kInFront) return false;
  if (relation == ObstacleRelation::kBehind || relation == ObstacleRelation::kPartial) return false;
  if (!geometry::InsideImage(fp.rect, view.width(), view.height())) return false;
  const geometry::PixelRect clip = geometry::ClipToImage(fp.rect, view.width(), view.height());
  if (mask->Query(clip) != silhouette::Cover::kBackground) return false;
  return relation == ObstacleRelation::kClear || !NearObstacle(view, clip) ||
         view.near_min().AllGreater(clip, fp.z_far);
}

Verdict Classify(const CameraView& view, const silhouette::SilhouetteQuadtree* mask,
                 const geometry::Footprint& fp, ObstacleRelation relation, bool* geometric) {
  using Side = geometry::Footprint::Side;
  *geometric = true;
  if (mask == nullptr || fp.side == Side::kBehind) return Verdict::kHidden;
  if (fp.side == Side::kStraddling) return Verdict::kMixed;
  const geometry::PixelRect clip = geometry::ClipToImage(fp.rect, view.width(), view.height());
  if (clip.Empty() || relation == ObstacleRelation::kBehind) return Verdict::kHidden;
  const bool inside = geometry::InsideImage(fp.rect, view.width(), view.height());
  const silhouette::Cover cover = mask->Query(clip);
  // A box in front of every obstacle in its footprint is classified as if
  // there were none: free needs the same background, and it cannot be hidden.
  if (relation == ObstacleRelation::kUnknown && NearObstacle(view, clip)) {
    if (inside && cover == silhouette::Cover::kBackground &&
        view.near_min().AllGreater(clip, fp.z_far)) {
      return Verdict::kFree;
    }
    if (view.centre_max().AllLess(clip, fp.z_near)) return Verdict::kHidden;
  } else if (relation != ObstacleRelation::kPartial && inside &&
             cover == silhouette::Cover::kBackground) {
    return Verdict::kFree;
  }
  if (cover == silhouette::Cover::kForeground) return Verdict::kFull;
  *geometric = cover != silhouette::Cover::kMixed;
  return Verdict::kMixed;
}

}  // namespace hg::octree
