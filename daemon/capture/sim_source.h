#pragma once
/// @file
/// The `sim` camera source: one camera of a simulated scene, rendered live.

#include <atomic>
#include <chrono>
#include <memory>
#include <vector>

#include "capture/camera_source.h"
#include "sim/mask_renderer.h"
#include "sim/scene.h"

namespace hg::capture {

/// Renders ground-truth masks of camera `camera_index` of a scene in real time:
/// a frame every 1 / rate_hz seconds of steady time since `start`, showing the
/// scene at that time plus the camera's capture offset, stamped with the
/// system clock. Paced by sleeping in Next() (capture thread only).
class SimSource : public CameraSource {
 public:
  SimSource(std::shared_ptr<const sim::Scene> scene, int camera_index, double rate_hz,
            std::chrono::steady_clock::time_point start);

  bool Next(MaskFrame* frame, std::chrono::milliseconds timeout) override;
  void Stop() override { stopped_.store(true); }

  /// While paused the camera delivers nothing, as a camera whose cable was
  /// pulled (tests and demos of a lost camera).
  void SetPaused(bool paused) { paused_.store(paused); }

 private:
  std::shared_ptr<const sim::Scene> scene_;
  int camera_index_;
  std::chrono::nanoseconds period_;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point next_;
  sim::MaskRenderer renderer_;
  std::vector<sim::BodyState> people_;
  std::uint64_t index_ = 0;
  std::atomic<bool> stopped_{false};
  std::atomic<bool> paused_{false};
};

}  // namespace hg::capture
