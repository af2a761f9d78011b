#pragma once
/// @file
/// Phase lock of the fixed-rate fusion cycle to the cameras' frames.

#include <chrono>
#include <cstdint>
#include <span>

namespace hg::pipeline {

/// Settings of CyclePhase.
struct CyclePhaseOptions {
  /// The cycle aims to start this long after the last frame of a capture
  /// instant is usually ready, plus `spread` times the jitter of that instant.
  std::chrono::nanoseconds margin = std::chrono::milliseconds(2);
  double spread = 2.0;
  /// Share of the remaining phase error corrected per cycle.
  double gain = 0.25;
  /// Largest shift of one cycle start, either way.
  std::chrono::nanoseconds max_step = std::chrono::milliseconds(2);
  /// Smoothing of the error's mean and jitter (share of the newest cycle).
  double smoothing = 0.1;
  /// The lock holds while the jitter (mean absolute deviation of the error)
  /// stays below this share of the period; otherwise nothing is corrected.
  double max_jitter = 0.125;
};

/// Where in its period the fusion cycle should start: a phase lock.
///
/// Free-running cameras at the cycle's rate deliver their frames at fixed
/// phases of the cycle, and the phase the cycle happens to have depends on
/// when the daemon started. A cycle that starts just before a camera's frame
/// is ready uses that camera's previous frame, up to a period older: the
/// snapshot is stamped up to a period earlier than it could be (latency), and
/// the older frame certifies less free, by the motion meanwhile (a looser hull).
///
/// Each cycle, the instants at which the cameras' newest frames became ready,
/// taken modulo the period, lie around the cycle's circle. The widest gap
/// between two of them separates the frames of one capture instant from
/// those of the next (cameras triggered together, or at small offsets, are
/// ready close together), so the frame before that gap completes a set. The
/// phase error is how far after the cycle's start that frame was ready, plus
/// `margin`. Its mean and its jitter are smoothed over the cycles, and the
/// next start moves by `gain` of (error + spread * jitter), at most
/// `max_step`: it settles where the set is complete even when that frame is
/// late by the usual jitter. The period itself never changes; when the error
/// does not settle (cameras at another rate than the cycle, or arriving at
/// random), the jitter exceeds `max_jitter` of the period and the lock lets
/// go instead of dragging the cycle along.
///
/// Not thread-safe: one instance per fusion loop.
class CyclePhase {
 public:
  using Duration = std::chrono::nanoseconds;

  CyclePhase(Duration period, const CyclePhaseOptions& options);

  /// `ready_before_start`: for each camera that delivers, how long before the
  /// cycle's start its newest frame became ready (negative: after the start).
  /// Returns how far to move the next cycle's start (positive: later); zero
  /// without cameras or without a lock. No allocation (at most kMaxCameras
  /// are considered).
  Duration Update(std::span<const Duration> ready_before_start);

  /// The phase error of one cycle alone: how far after its start (in
  /// [-period / 2, period / 2)) the cycle should have started; zero without cameras.
  [[nodiscard]] Duration Error(std::span<const Duration> ready_before_start) const;

  /// Whether the last Update() found the error settled enough to correct.
  [[nodiscard]] bool locked() const { return locked_; }
  /// Smoothed jitter of the error (mean absolute deviation).
  [[nodiscard]] Duration jitter() const { return Duration(static_cast<std::int64_t>(jitter_)); }

  static constexpr int kMaxCameras = 16;

 private:
  Duration period_;
  CyclePhaseOptions options_;
  bool started_ = false;
  bool locked_ = false;
  double mean_ = 0.0;    // ns.
  double jitter_ = 0.0;  // ns.
};

}  // namespace hg::pipeline
