#include "octree/camera_view.h"

#include "common/check.h"

namespace hg::octree {

CameraView::CameraView(const geometry::CameraModel& pinhole,
                       const std::vector<geometry::TriangleMesh>& obstacles)
    : projector_(pinhole.ProjectionMatrix()), width_(pinhole.width), height_(pinhole.height) {
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
  has_obstacles_ = near_min_.Global() != geometry::ObstacleDepthMap::kNone;
}

Verdict Classify(const CameraView& view, const silhouette::SilhouetteQuadtree* mask,
                 const geometry::Footprint& fp, bool* geometric) {
  using Side = geometry::Footprint::Side;
  *geometric = true;
  if (mask == nullptr || fp.side == Side::kBehind) return Verdict::kHidden;
  if (fp.side == Side::kStraddling) return Verdict::kMixed;
  const geometry::PixelRect clip = geometry::ClipToImage(fp.rect, view.width(), view.height());
  if (clip.Empty()) return Verdict::kHidden;
  const bool inside = geometry::InsideImage(fp.rect, view.width(), view.height());
  const silhouette::Cover cover = mask->Query(clip);
  if (view.has_obstacles()) {
    if (inside && cover == silhouette::Cover::kBackground &&
        view.near_min().AllGreater(clip, fp.z_far)) {
      return Verdict::kFree;
    }
    if (view.centre_max().AllLess(clip, fp.z_near)) return Verdict::kHidden;
  } else if (inside && cover == silhouette::Cover::kBackground) {
    return Verdict::kFree;
  }
  if (cover == silhouette::Cover::kForeground) return Verdict::kFull;
  *geometric = cover != silhouette::Cover::kMixed;
  return Verdict::kMixed;
}

}  // namespace hg::octree
