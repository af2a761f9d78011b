#pragma once
/// @file
/// What the octree knows of one camera, and the per-camera verdict on a box.

#include <cstdint>
#include <vector>

#include "geometry/camera.h"
#include "geometry/footprint.h"
#include "geometry/mesh.h"
#include "geometry/obstacle_depth.h"
#include "silhouette/quadtree.h"

namespace hg::octree {

/// Static data of one camera for the octree: pinhole projection and the
/// obstacle depth pyramids. Immutable after construction; thread-safe.
class CameraView {
 public:
  /// `pinhole` must have no distortion (masks are undistorted before the octree).
  CameraView(const geometry::CameraModel& pinhole,
             const std::vector<geometry::TriangleMesh>& obstacles);

  [[nodiscard]] const geometry::BoxProjector& projector() const { return projector_; }
  [[nodiscard]] int width() const { return width_; }
  [[nodiscard]] int height() const { return height_; }
  [[nodiscard]] bool has_obstacles() const { return !obstacle_rect_.Empty(); }
  /// Bounding rectangle of the pixels that see an obstacle (empty without).
  [[nodiscard]] const geometry::PixelRect& obstacle_rect() const { return obstacle_rect_; }
  [[nodiscard]] const geometry::DepthPyramid& near_min() const { return near_min_; }
  [[nodiscard]] const geometry::DepthPyramid& centre_max() const { return centre_max_; }
  [[nodiscard]] const geometry::ObstacleDepthMap& depth_map() const { return depth_map_; }

 private:
  geometry::BoxProjector projector_;
  int width_;
  int height_;
  geometry::PixelRect obstacle_rect_;
  geometry::ObstacleDepthMap depth_map_;
  geometry::DepthPyramid near_min_;
  geometry::DepthPyramid centre_max_;
};

/// One camera's verdict on a box (ARCHITECTURE.md, reconstruction rules).
enum class Verdict : std::uint8_t {
  kFree = 0,    ///< Footprint inside the image, all background, box in front of obstacles.
  kHidden = 1,  ///< The camera sees no part of the box (behind it, outside, behind obstacles).
  /// Every footprint pixel is foreground or outside the image (in the octree,
  /// with a margin, also: every sub-box's grown footprint holds foreground).
  kFull = 2,
  kMixed = 3,  ///< Anything else: a smaller box may get another verdict.
};

/// Where a box lies relative to the static obstacles in one camera's view:
/// the part of a verdict that never changes, so the octree can keep it.
enum class ObstacleRelation : std::uint8_t {
  kUnknown = 0,  ///< Not computed: Classify() looks the obstacle depths up itself.
  kClear = 1,    ///< In front of every obstacle surface in its footprint (or none there).
  kBehind = 2,   ///< Behind obstacles at every footprint pixel: the camera cannot see it.
  kPartial = 3,  ///< Neither (or not entirely in front of the camera).
};

/// The relation of the box with footprint `fp`. kClear is monotone: it holds
/// for every box inside a box for which it holds, since a sub-box has a
/// sub-footprint and a nearer farthest depth (likewise kBehind).
[[nodiscard]] ObstacleRelation RelateToObstacles(const CameraView& view,
                                                 const geometry::Footprint& fp);

/// Classifies the box with footprint `fp` in one camera. `mask == nullptr`
/// means the camera delivers nothing (lost or stale): it sees nothing.
/// `relation` is RelateToObstacles(view, fp) when known (from a cache or an
/// enclosing box); kUnknown makes Classify look up what it needs. The verdict
/// is the same either way.
/// For kMixed, `*geometric` tells whether the mixture comes only from geometry
/// (the box straddles the camera plane, the image border or an obstacle's
/// depth while every footprint pixel in the image is background), not from
/// the silhouette.
[[nodiscard]] Verdict Classify(const CameraView& view, const silhouette::SilhouetteQuadtree* mask,
                               const geometry::Footprint& fp, ObstacleRelation relation,
                               bool* geometric);

/// Whether Classify() would return kFree: the same test without the look-ups
/// that only tell the other verdicts apart.
[[nodiscard]] bool CertifiesFree(const CameraView& view, const silhouette::SilhouetteQuadtree* mask,
                                 const geometry::Footprint& fp, ObstacleRelation relation);

}  // namespace hg::octree
