#pragma once
/// @file
/// Colour frames of a simulated cell for one camera: textured floor and walls,
/// shaded obstacles and crates, clothed people, soft shadows, global light
/// changes, sensor noise and lens distortion.

#include <cstdint>
#include <memory>
#include <vector>

#include "common/image.h"
#include "sim/body.h"
#include "sim/scene.h"

namespace hg::sim {

/// Renders RGB frames as the camera `camera_index` of `scene` would capture
/// them. The static part (walls, floor, obstacles, crates, their shading and
/// shadows) is drawn once at construction; Render() draws the people over it
/// with a depth test, their soft shadows, the light gain of time t and noise.
/// Deterministic: the same (people, t, frame_index) give the same image.
/// Render() is const and may run concurrently on different renderers.
class ColourRenderer {
 public:
  ColourRenderer(const Scene& scene, int camera_index);
  ~ColourRenderer();
  ColourRenderer(ColourRenderer&&) noexcept;
  ColourRenderer& operator=(ColourRenderer&&) noexcept;

  /// `people` are the poses of scene.people, in order, at this camera's capture time.
  /// `frame_index` seeds the sensor noise (with the scene's imaging seed).
  void Render(const std::vector<BodyState>& people, double t_s, std::uint64_t frame_index,
              common::ImageRgb8* out) const;

  /// The empty cell without noise or light change (what a background model learns).
  void RenderEmpty(common::ImageRgb8* out) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace hg::sim
