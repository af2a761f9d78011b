#include "octree/camera_view.h"

#include <algorithm>

#include "common/check.h"

namespace hg::octree {

namespace {

// Sliding minimum over [i - radius, i + radius] of `n` values `stride` apart
// starting at `data`, in place (a deque of candidate indices).
void SlidingMin(float* data, int n, std::ptrdiff_t stride, int radius, std::vector<float>* in,
                std::vector<int>* queue) {
  in->resize(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) (*in)[i] = data[i * stride];
  queue->resize(static_cast<std::size_t>(n));
  int head = 0, tail = 0;
  int next = 0;  // Next index to enter the window.
  for (int i = 0; i < n; ++i) {
    for (; next < n && next <= i + radius; ++next) {
      while (tail > head && (*in)[(*queue)[tail - 1]] >= (*in)[next]) --tail;
      (*queue)[tail++] = next;
    }
    while ((*queue)[head] < i - radius) ++head;
    data[i * stride] = (*in)[(*queue)[head]];
  }
}

}  // namespace

CameraView::CameraView(const geometry::CameraModel& pinhole,
                       const std::vector<geometry::TriangleMesh>& obstacles, LagMargin lag)
    : projector_(pinhole.ProjectionMatrix()),
      width_(pinhole.width),
      height_(pinhole.height),
      lag_(lag) {
  HG_CHECK(!pinhole.HasDistortion());
  HG_CHECK(pinhole.K(2, 2) == 1.0 && pinhole.K(2, 0) == 0.0 && pinhole.K(2, 1) == 0.0);
  HG_CHECK(lag.radius_px >= 0 && lag.depth_m >= 0.0);
  bool any_triangle = false;
  for (const auto& m : obstacles) any_triangle = any_triangle || !m.triangles.empty();
  if (!any_triangle) return;
  depth_map_ = geometry::RenderObstacleDepth(pinhole, obstacles);
  // The depths below which this camera may certify space free: the obstacles'
  // near depths, and with a lag margin the depth of each emergence edge less
  // the margin, over the pixels within its radius.
  std::vector<float> certify = depth_map_.near_depth;
  if (lag.radius_px > 0) {
    std::vector<float> edges(certify.size(), geometry::ObstacleDepthMap::kNone);
    for (int v = 0; v < height_; ++v) {
      for (int u = 0; u < width_; ++u) {
        if (geometry::EmergenceEdge(depth_map_, u, v)) {
          const std::size_t i = static_cast<std::size_t>(v) * width_ + u;
          edges[i] = std::max(0.0F, static_cast<float>(depth_map_.near_depth[i] - lag.depth_m));
        }
      }
    }
    std::vector<float> scratch;
    std::vector<int> queue;
    for (int v = 0; v < height_; ++v) {
      SlidingMin(edges.data() + static_cast<std::size_t>(v) * width_, width_, 1, lag.radius_px,
                 &scratch, &queue);
    }
    for (int u = 0; u < width_; ++u) {
      SlidingMin(edges.data() + u, height_, width_, lag.radius_px, &scratch, &queue);
    }
    for (std::size_t i = 0; i < certify.size(); ++i) certify[i] = std::min(certify[i], edges[i]);
  }
  near_min_ = geometry::DepthPyramid(certify, width_, height_, geometry::DepthPyramid::Kind::kMin);
  centre_max_ = geometry::DepthPyramid(depth_map_.centre_depth, width_, height_,
                                       geometry::DepthPyramid::Kind::kMax);
  obstacle_rect_ = {width_, height_, -1, -1};
  for (int v = 0; v < height_; ++v) {
    for (int u = 0; u < width_; ++u) {
      if (certify[static_cast<std::size_t>(v) * width_ + u] != geometry::ObstacleDepthMap::kNone) {
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
