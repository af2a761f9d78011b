#include "capture/replay_source.h"

#include <algorithm>
#include <thread>

namespace hg::capture {

ReplaySource::ReplaySource(RecordingCamera recording, SimClock clock, ReplayPacing pacing)
    : recording_(std::move(recording)), clock_(clock), pacing_(pacing) {}

std::chrono::steady_clock::time_point ReplaySource::Due(int index) const {
  return clock_.start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::nanoseconds(recording_.frames[index].time_ns));
}

std::int64_t ReplaySource::StampOf(int index) const {
  return clock_.epoch_ns + recording_.frames[index].time_ns;
}

bool ReplaySource::ReadFrame(int index, Frame* frame) {
  if (index < 0 || index >= frames() ||
      !LoadRecordedFrame(recording_, static_cast<std::size_t>(index), frame, &file_bytes_,
                         &path_)) {
    return false;
  }
  frame->stamp_ns = StampOf(index);
  frame->index = recording_.frames[index].source_index;
  return true;
}

bool ReplaySource::Next(Frame* frame, std::chrono::milliseconds timeout) {
  using Clock = std::chrono::steady_clock;
  const Clock::time_point give_up = Clock::now() + timeout;
  const int count = frames();
  if (pacing_ == ReplayPacing::kFast) {
    if (stopped_.load()) return false;
    if (next_index_ >= count) {
      // The recording ended: the camera falls silent.
      std::this_thread::sleep_until(give_up);
      return false;
    }
    const int index = next_index_++;
    if (!LoadRecordedFrame(recording_, static_cast<std::size_t>(index), frame, &file_bytes_,
                           &path_)) {
      corrupt_.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    frame->stamp_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                          std::chrono::system_clock::now().time_since_epoch())
                          .count();
    frame->index = recording_.frames[index].source_index;
    return true;
  }
  for (;;) {
    if (stopped_.load()) return false;
    const Clock::time_point now = Clock::now();
    if (next_index_ >= count) {
      // The recording ended: the camera falls silent.
      std::this_thread::sleep_until(std::min(give_up, now + std::chrono::milliseconds(20)));
      if (Clock::now() >= give_up) return false;
      continue;
    }
    if (now >= Due(next_index_)) break;
    if (now >= give_up) return false;
    std::this_thread::sleep_until(
        std::min({Due(next_index_), give_up, now + std::chrono::milliseconds(20)}));
  }
  // The newest frame that is due; earlier ones are skipped, as a camera's
  // would be when its reader falls behind.
  const Clock::time_point now = Clock::now();
  while (next_index_ + 1 < count && Due(next_index_ + 1) <= now) ++next_index_;
  const int index = next_index_++;
  if (!LoadRecordedFrame(recording_, static_cast<std::size_t>(index), frame, &file_bytes_,
                         &path_)) {
    corrupt_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  frame->stamp_ns = StampOf(index);
  frame->index = recording_.frames[index].source_index;
  return true;
}

}  // namespace hg::capture
