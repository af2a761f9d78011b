#pragma once
/// @file
/// The simulator: a scene, its people over time, and renderers for every camera.

#include <cstdint>
#include <memory>
#include <vector>

#include "common/image.h"
#include "common/worker_pool.h"
#include "sim/colour_renderer.h"
#include "sim/ground_truth.h"
#include "sim/mask_renderer.h"
#include "sim/scene.h"

namespace hg::sim {

/// Renders all cameras of a scene at a scene time, cameras in parallel on its
/// own worker pool. Each camera sees the people at t + its capture offset.
/// Thread-compatible: one caller at a time.
class Simulator {
 public:
  /// `num_threads` >= 1 renders cameras in parallel. Colour renderers are built
  /// on first use (they cost a full static render per camera).
  Simulator(Scene scene, int num_threads);
  ~Simulator();

  [[nodiscard]] const Scene& scene() const { return scene_; }
  [[nodiscard]] int num_cameras() const { return static_cast<int>(scene_.cameras.size()); }

  /// Poses of every person at scene time t_s.
  [[nodiscard]] std::vector<BodyState> PeopleAt(double t_s) const;

  /// Ground truth of frame `frame` at scene time t_s.
  [[nodiscard]] FrameTruth Truth(int frame, double t_s) const;

  /// Ground-truth masks of every camera at scene time t_s. No allocation once
  /// *masks holds camera-sized images.
  void RenderMasks(double t_s, std::vector<common::ImageU8>* masks);

  /// Colour frames of every camera at scene time t_s; `frame` seeds the noise.
  void RenderColour(double t_s, std::uint64_t frame, std::vector<common::ImageRgb8>* frames);

 private:
  Scene scene_;
  common::WorkerPool pool_;
  std::vector<MaskRenderer> mask_renderers_;
  std::vector<std::unique_ptr<ColourRenderer>> colour_renderers_;  ///< Built on first use.
  std::vector<std::vector<BodyState>> per_camera_people_;
};

}  // namespace hg::sim
