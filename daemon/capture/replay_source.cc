#include "capture/replay_source.h"

#include <algorithm>
#include <cmath>
#include <thread>

#include "common/config_error.h"

namespace hg::capture {

namespace {

int FirstLoopFrame(const RecordingCamera& recording, double loop_start_s) {
  const auto& f = recording.frames;
  const auto start_ns = static_cast<std::int64_t>(std::llround(loop_start_s * 1e9));
  return static_cast<int>(
      std::find_if(f.begin(), f.end(),
                   [&](const RecordedFrame& r) { return r.time_ns >= start_ns; }) -
      f.begin());
}

}  // namespace

std::int64_t LoopLengthNs(const RecordingCamera& recording, double loop_start_s) {
  const auto& f = recording.frames;
  const int count = static_cast<int>(f.size());
  const int first = FirstLoopFrame(recording, loop_start_s);
  const std::string what =
      "replay of '" + recording.directory + "', camera '" + recording.camera + "': ";
  if (first >= count - 1) {
    throw common::ConfigError(
        what + "loop_start_s " + std::to_string(loop_start_s) +
        " leaves fewer than two frames to loop" +
        (count > 0 ? " (the last frame is at " +
                         std::to_string(static_cast<double>(f.back().time_ns) * 1e-9) + " s)"
                   : std::string()));
  }
  const std::int64_t span = f[count - 1].time_ns - f[first].time_ns;
  if (span <= 0) {
    throw common::ConfigError(what + "the frames to loop (from loop_start_s " +
                              std::to_string(loop_start_s) +
                              ") end no later than they start: the recording's capture times "
                              "stepped back, so it has no loop length");
  }
  // One frame interval after the last frame, the loop's first frame again.
  return span + span / (count - 1 - first);
}

ReplaySource::ReplaySource(RecordingCamera recording, SimClock clock, const ReplayOptions& options)
    : recording_(std::move(recording)), clock_(clock), pacing_(options.pacing) {
  const int count = frames();
  if (options.loop && count > 0) {
    const auto& f = recording_.frames;
    loop_first_ = FirstLoopFrame(recording_, options.loop_start_s);
    loop_period_ns_ =
        std::max(LoopLengthNs(recording_, options.loop_start_s), options.loop_period_ns);
    std::uint64_t last_index = 0;
    for (const RecordedFrame& r : f) last_index = std::max(last_index, r.source_index);
    index_stride_ = last_index + 1;
    loop_ = true;
  }
  if (options.preload) {
    preloaded_.resize(static_cast<std::size_t>(count));
    for (int i = 0; i < count; ++i) {
      Frame& frame = preloaded_[static_cast<std::size_t>(i)];
      if (!LoadRecordedFrame(recording_, static_cast<std::size_t>(i), &frame, &file_bytes_,
                             &path_)) {
        frame = Frame{};  // No pixels: counted when it comes round.
        continue;
      }
      preloaded_bytes_ += frame.grey.pixels.size() + frame.rgb.pixels.size();
    }
    file_bytes_ = {};
  }
}

int ReplaySource::FrameAt(std::int64_t n) const {
  const int count = frames();
  if (!loop_ || n < count) return static_cast<int>(n);
  return loop_first_ + static_cast<int>((n - count) % (count - loop_first_));
}

std::int64_t ReplaySource::OffsetNs(std::int64_t n) const {
  const int count = frames();
  if (!loop_ || n < count) return 0;
  return (1 + (n - count) / (count - loop_first_)) * loop_period_ns_;
}

std::chrono::steady_clock::time_point ReplaySource::Due(std::int64_t n) const {
  return clock_.start +
         std::chrono::duration_cast<std::chrono::steady_clock::duration>(
             std::chrono::nanoseconds(recording_.frames[FrameAt(n)].time_ns + OffsetNs(n)));
}

std::int64_t ReplaySource::StampOf(std::int64_t n) const {
  return clock_.epoch_ns + recording_.frames[FrameAt(n)].time_ns + OffsetNs(n);
}

bool ReplaySource::Load(std::int64_t n, Frame* frame) {
  const int i = FrameAt(n);
  bool ok;
  if (!preloaded_.empty()) {
    const Frame& stored = preloaded_[static_cast<std::size_t>(i)];
    ok = !stored.grey.pixels.empty() || !stored.rgb.pixels.empty();
    if (ok) {
      // Copy-assignment keeps the destination's buffers: no allocation once
      // they have the size.
      frame->kind = stored.kind;
      frame->grey = stored.grey;
      frame->rgb = stored.rgb;
      frame->device_stamp_ns = stored.device_stamp_ns;
    }
  } else {
    ok = LoadRecordedFrame(recording_, static_cast<std::size_t>(i), frame, &file_bytes_, &path_);
  }
  if (!ok) {
    corrupt_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  const std::uint64_t repetition =
      loop_ && n >= frames()
          ? 1 + static_cast<std::uint64_t>((n - frames()) / (frames() - loop_first_))
          : 0;
  frame->index = recording_.frames[i].source_index + repetition * index_stride_;
  return true;
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
  if (frames() == 0) {
    std::this_thread::sleep_until(give_up);
    return false;
  }
  if (pacing_ == ReplayPacing::kFast) {
    if (stopped_.load()) return false;
    if (Ended(next_)) {
      // The recording ended: the camera falls silent.
      std::this_thread::sleep_until(give_up);
      return false;
    }
    const std::int64_t n = next_++;
    if (!Load(n, frame)) return false;
    frame->stamp_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                          std::chrono::system_clock::now().time_since_epoch())
                          .count();
    return true;
  }
  for (;;) {
    if (stopped_.load()) return false;
    const Clock::time_point now = Clock::now();
    if (Ended(next_)) {
      // The recording ended: the camera falls silent.
      std::this_thread::sleep_until(std::min(give_up, now + std::chrono::milliseconds(20)));
      if (Clock::now() >= give_up) return false;
      continue;
    }
    if (now >= Due(next_)) break;
    if (now >= give_up) return false;
    std::this_thread::sleep_until(
        std::min({Due(next_), give_up, now + std::chrono::milliseconds(20)}));
  }
  // The newest frame that is due; earlier ones are skipped, as a camera's
  // would be when its reader falls behind.
  const Clock::time_point now = Clock::now();
  while (!Ended(next_ + 1) && Due(next_ + 1) <= now) ++next_;
  const std::int64_t n = next_++;
  if (!Load(n, frame)) return false;
  frame->stamp_ns = StampOf(n);
  return true;
}

}  // namespace hg::capture
