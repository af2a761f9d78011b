#pragma once
/// @file
/// Fast conservative ground-truth silhouettes of simulated people and static
/// foreground objects for one camera, lens distortion included.

#include <cstdint>
#include <memory>
#include <vector>

#include "common/image.h"
#include "geometry/camera.h"
#include "sim/body.h"
#include "sim/solids.h"

namespace hg::sim {

/// Renders masks of one camera: a pixel is foreground (255) when some point of
/// some body capsule or static foreground solid lies in the pixel's viewing
/// pyramid (the rays through the closed pixel square of the distorted image), in
/// front of the camera, and is not certainly hidden by an obstacle; otherwise 0.
///
/// Every relaxation only adds foreground: the pyramid is replaced by a cone that
/// contains it, cylinders by their capsules, meshes by their bounding boxes, and
/// a pixel counts as hidden only where an obstacle covers the whole pixel
/// nearer than the nearest point of the capsule. Fast enough for 8 Full HD
/// cameras at 30 Hz on two cores (BM_SimMasks in tests/bench).
///
/// Construction does the per-camera work (ray tables for distorted lenses,
/// the obstacle occlusion map, the static foreground mask). Render() is const,
/// allocation-free once `out` has the camera's size, and may run concurrently
/// on different renderers.
class MaskRenderer {
 public:
  /// `obstacles` hide what is behind them when `occlusion` is true.
  /// `static_foreground` solids (crates) are drawn in every mask.
  MaskRenderer(const geometry::CameraModel& camera, const std::vector<Solid>& obstacles,
               const std::vector<Solid>& static_foreground, bool occlusion);
  ~MaskRenderer();
  MaskRenderer(MaskRenderer&&) noexcept;
  MaskRenderer& operator=(MaskRenderer&&) noexcept;

  /// Renders the mask of `people` into *out (resized to the camera on first use).
  void Render(const std::vector<BodyState>& people, common::ImageU8* out) const;

  [[nodiscard]] const geometry::CameraModel& camera() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace hg::sim
