#include "pipeline/cycle_phase.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

#include "common/check.h"

namespace hg::pipeline {

CyclePhase::CyclePhase(Duration period, const CyclePhaseOptions& options)
    : period_(period), options_(options) {
  HG_CHECK(period_.count() > 0);
  HG_CHECK(options_.gain > 0.0 && options_.gain <= 1.0);
  HG_CHECK(options_.max_step.count() >= 0);
  HG_CHECK(options_.spread >= 0.0);
  HG_CHECK(options_.smoothing > 0.0 && options_.smoothing <= 1.0);
}

CyclePhase::Duration CyclePhase::Error(std::span<const Duration> ready_before_start) const {
  const std::int64_t period = period_.count();
  std::array<std::int64_t, kMaxCameras> phases{};
  const std::size_t n = std::min<std::size_t>(ready_before_start.size(), kMaxCameras);
  if (n == 0) return Duration::zero();
  for (std::size_t i = 0; i < n; ++i) {
    // The instant the frame was ready, as a phase after the cycle's start.
    std::int64_t phase = (-ready_before_start[i].count()) % period;
    if (phase < 0) phase += period;
    phases[i] = phase;
  }
  std::sort(phases.begin(), phases.begin() + static_cast<std::ptrdiff_t>(n));
  // The frame followed by the widest gap (around the circle) completes a set.
  std::size_t last = n - 1;
  std::int64_t widest = phases[0] + period - phases[n - 1];
  for (std::size_t i = 0; i + 1 < n; ++i) {
    const std::int64_t gap = phases[i + 1] - phases[i];
    if (gap > widest) {
      widest = gap;
      last = i;
    }
  }
  std::int64_t error = (phases[last] + options_.margin.count()) % period;
  if (error >= period / 2) error -= period;
  return Duration(error);
}

CyclePhase::Duration CyclePhase::Update(std::span<const Duration> ready_before_start) {
  if (ready_before_start.empty()) return Duration::zero();
  const auto error = static_cast<double>(Error(ready_before_start).count());
  if (!started_) {
    started_ = true;
    mean_ = error;
  }
  const double a = options_.smoothing;
  jitter_ += a * (std::abs(error - mean_) - jitter_);
  mean_ += a * (error - mean_);
  locked_ = jitter_ < options_.max_jitter * static_cast<double>(period_.count());
  if (!locked_) return Duration::zero();
  const double step = options_.gain * (error + options_.spread * jitter_);
  const double limit = static_cast<double>(options_.max_step.count());
  return Duration(static_cast<std::int64_t>(std::llround(std::clamp(step, -limit, limit))));
}

}  // namespace hg::pipeline
