#include "capture/sim_source.h"

#include <thread>

namespace hg::capture {

SimSource::SimSource(std::shared_ptr<const sim::Scene> scene, int camera_index, double rate_hz,
                     std::chrono::steady_clock::time_point start)
    : scene_(std::move(scene)),
      camera_index_(camera_index),
      period_(std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 / rate_hz))),
      start_(start),
      next_(start),
      renderer_(scene_->cameras[camera_index].model, scene_->obstacles, scene_->foreground_objects,
                scene_->mask_occlusion),
      people_(scene_->people.size()) {}

bool SimSource::Next(MaskFrame* frame, std::chrono::milliseconds timeout) {
  using Clock = std::chrono::steady_clock;
  const Clock::time_point give_up = Clock::now() + timeout;
  for (;;) {
    if (stopped_.load()) return false;
    const Clock::time_point now = Clock::now();
    if (now >= next_ && !paused_.load()) break;
    if (now >= give_up) return false;
    // Sleep in short steps so Stop() and SetPaused() take effect soon.
    const Clock::time_point wake =
        std::min({paused_.load() ? now + std::chrono::milliseconds(5) : next_, give_up,
                  now + std::chrono::milliseconds(20)});
    std::this_thread::sleep_until(wake);
  }
  // Frames that fell due while paused or busy are skipped, as a camera would.
  const Clock::time_point now = Clock::now();
  while (next_ <= now) next_ += period_;
  const double t = std::chrono::duration<double>(now - start_).count() +
                   scene_->cameras[camera_index_].time_offset_s;
  for (std::size_t p = 0; p < people_.size(); ++p) {
    people_[p] = sim::EvaluatePerson(scene_->people[p], t);
  }
  renderer_.Render(people_, &frame->mask);
  frame->stamp_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                        std::chrono::system_clock::now().time_since_epoch())
                        .count();
  frame->index = index_++;
  return true;
}

}  // namespace hg::capture
