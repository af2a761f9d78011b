#include "capture/sim_source.h"

#include <cmath>
#include <thread>

namespace hg::capture {

SimClock SimClock::Now() {
  SimClock clock;
  clock.start = std::chrono::steady_clock::now();
  clock.epoch_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                       std::chrono::system_clock::now().time_since_epoch())
                       .count();
  return clock;
}

SimSource::SimSource(std::shared_ptr<const sim::Scene> scene, int camera_index, double rate_hz,
                     SimClock clock)
    : scene_(std::move(scene)),
      camera_index_(camera_index),
      period_(std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 / rate_hz))),
      clock_(clock),
      renderer_(scene_->cameras[camera_index].model, scene_->obstacles, scene_->foreground_objects,
                scene_->mask_occlusion),
      people_(scene_->people.size()) {
  const double period_s = 1.0 / rate_hz;
  double offset_s = std::fmod(scene_->cameras[camera_index].time_offset_s, period_s);
  if (offset_s < 0.0) offset_s += period_s;
  next_ = clock_.start + std::chrono::nanoseconds(static_cast<std::int64_t>(offset_s * 1e9));
}

bool SimSource::Next(Frame* frame, std::chrono::milliseconds timeout) {
  using Clock = std::chrono::steady_clock;
  const Clock::time_point give_up = Clock::now() + timeout;
  for (;;) {
    if (stopped_.load()) return false;
    const Clock::time_point now = Clock::now();
    const bool paused = paused_.load() || next_ - clock_.start >= stop_after_;
    if (now >= next_ && !paused) break;
    if (now >= give_up) return false;
    // Sleep in short steps so Stop() and SetPaused() take effect soon.
    const Clock::time_point wake = std::min({paused ? now + std::chrono::milliseconds(5) : next_,
                                             give_up, now + std::chrono::milliseconds(20)});
    std::this_thread::sleep_until(wake);
  }
  // The newest capture instant that has passed; earlier ones are skipped.
  const Clock::time_point now = Clock::now();
  while (next_ + period_ <= now) next_ += period_;
  const Clock::time_point capture = next_;
  next_ += period_;
  const std::chrono::nanoseconds since_start = capture - clock_.start;
  const double t = std::chrono::duration<double>(since_start).count();
  for (std::size_t p = 0; p < people_.size(); ++p) {
    people_[p] = sim::EvaluatePerson(scene_->people[p], t);
  }
  frame->kind = FrameKind::kMask;
  renderer_.Render(people_, &frame->grey);
  frame->stamp_ns = clock_.epoch_ns + since_start.count();
  frame->index = index_++;
  return true;
}

}  // namespace hg::capture
