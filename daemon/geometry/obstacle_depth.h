#pragma once
/// @file
/// Static obstacles as seen by one camera: per-pixel depth maps and pyramids
/// with exact rectangle predicates.

#include <limits>
#include <vector>

#include "geometry/camera.h"
#include "geometry/mesh.h"

namespace hg::geometry {

/// Depth (camera z, metres) of static obstacles per pixel of one pinhole camera.
/// Thread-compatible value type.
struct ObstacleDepthMap {
  static constexpr float kNone = std::numeric_limits<float>::infinity();
  int width = 0;
  int height = 0;
  /// Per pixel, a lower bound of the camera z of every obstacle point that
  /// projects anywhere inside the pixel square (conservative rasterisation);
  /// kNone where no obstacle touches the pixel. A point in front of this depth is
  /// in front of every obstacle seen through that pixel.
  std::vector<float> near_depth;
  /// Per pixel, the depth of the nearest obstacle surface along the ray through
  /// the pixel centre; kNone where that ray hits no obstacle. Used only to label
  /// space hidden behind obstacles (never to certify free space).
  std::vector<float> centre_depth;
  /// The camera is blocked: an obstacle reaches within the near plane (1 mm)
  /// in front of the camera centre, where it cannot be rendered, or the ray
  /// through every pixel centre meets an obstacle nearer than kEnclosedDepthM
  /// (the camera inside a mesh: its housing or mount modelled with the
  /// obstacles). near_depth is then 0 everywhere, so the camera certifies
  /// nothing free.
  bool blocked = false;
  static constexpr double kEnclosedDepthM = 0.1;
  /// What a blocked camera means to the user, after the camera's name.
  static constexpr const char* kBlockedText =
      "is blocked: an obstacle reaches within 1 mm in front of its centre or covers its whole "
      "view within 10 cm (the camera or its mount modelled into the obstacle meshes?); it sees "
      "nothing and is reported failed (blocked), the status degraded; leave the camera and its "
      "mount out of the obstacle meshes";
};

/// Renders the meshes into the depth maps of a pinhole camera (distortion is
/// ignored: the octree works on undistorted masks). Triangles are clipped at a
/// near plane 1 mm in front of the camera; one that reaches in front of the
/// camera within it blocks the whole view (ObstacleDepthMap::blocked), and so
/// do obstacles within 10 cm at every pixel.
[[nodiscard]] ObstacleDepthMap RenderObstacleDepth(const CameraModel& pinhole,
                                                   const std::vector<TriangleMesh>& meshes);

/// Min- or max-pyramid over a per-pixel float map, answering rectangle
/// predicates exactly (descending only where the answer is still open).
/// Immutable after construction; thread-safe for concurrent queries.
class DepthPyramid {
 public:
  enum class Kind { kMin, kMax };
  DepthPyramid() = default;
  DepthPyramid(const std::vector<float>& values, int width, int height, Kind kind);

  /// kMin pyramid: true iff every pixel of `rect` holds a value > z.
  /// Precondition: rect lies inside the image and is not empty.
  [[nodiscard]] bool AllGreater(const PixelRect& rect, double z) const;
  /// kMax pyramid: true iff every pixel of `rect` holds a value < z.
  /// Precondition: rect lies inside the image and is not empty.
  [[nodiscard]] bool AllLess(const PixelRect& rect, double z) const;
  /// Min (kMin) or max (kMax) over the whole image.
  [[nodiscard]] float Global() const;
  [[nodiscard]] bool empty() const { return levels_.empty(); }

 private:
  struct Level {
    int width = 0;
    int height = 0;
    std::vector<float> values;
  };
  Kind kind_ = Kind::kMin;
  std::vector<Level> levels_;  // levels_[0] is the pixel level.
};

}  // namespace hg::geometry
