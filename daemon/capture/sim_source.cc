#include "capture/sim_source.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <thread>

#include "sim/colour_renderer.h"

namespace hg::capture {
namespace {

constexpr std::size_t kNoiseTable = std::size_t{1} << 16;  // A power of two.

// The empty cell with the mask's pixels taken from `painted` (the empty cell
// 100 grey levels off), plus noise read from `noise` (2 * kNoiseTable entries,
// so that a block of kNoiseTable bytes reads it contiguously) at an offset
// chosen per frame. Plain loops the compiler vectorises: about 2 ms per Full
// HD frame.
void ComposeColour(const common::ImageRgb8& empty, const common::ImageRgb8& painted,
                   const common::ImageU8& mask, const std::vector<std::int8_t>& noise,
                   std::uint64_t frame_index, common::ImageRgb8* out) {
  if (out->width != empty.width || out->height != empty.height) {
    *out = common::ImageRgb8(empty.width, empty.height);  // First frame only.
  }
  const std::size_t pixels = static_cast<std::size_t>(empty.width) * empty.height;
  std::uint8_t* o = out->pixels.data();
  std::copy(empty.pixels.begin(), empty.pixels.end(), o);
  // People: where the mask is set, 8 pixels at a time skipped while clear.
  const std::uint8_t* m = mask.pixels.data();
  const std::uint8_t* fg = painted.pixels.data();
  for (std::size_t start = 0; start < pixels; start += 8) {
    const std::size_t end = std::min(pixels, start + 8);
    std::uint64_t word = 0;
    std::memcpy(&word, m + start, end - start);
    if (word == 0) continue;
    for (std::size_t p = start; p < end; ++p) {
      if (m[p] != 0) std::memcpy(o + 3 * p, fg + 3 * p, 3);
    }
  }
  // A multiplicative hash of the index: the noise differs from frame to frame.
  const std::size_t offset =
      static_cast<std::size_t>(frame_index * 0x9E3779B97F4A7C15ULL >> 40) & (kNoiseTable - 1);
  const std::int8_t* n = noise.data() + offset;
  const std::size_t bytes = 3 * pixels;
  for (std::size_t start = 0; start < bytes; start += kNoiseTable) {
    const std::size_t end = std::min(bytes, start + kNoiseTable);
    std::uint8_t* block = o + start;
    for (std::size_t j = 0; j < end - start; ++j) {
      const int v = block[j] + n[j];
      block[j] = static_cast<std::uint8_t>(std::clamp(v, 0, 255));
    }
  }
}

}  // namespace

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

void SimSource::EnableColour(double empty_s) {
  colour_ = true;
  empty_s_ = empty_s;
  sim::ColourRenderer(*scene_, camera_index_).RenderEmpty(&empty_);
  painted_ = empty_;
  for (std::uint8_t& v : painted_.pixels)
    v = static_cast<std::uint8_t>(v < 128 ? v + 100 : v - 100);
  noise_.resize(2 * kNoiseTable);
  std::mt19937_64 rng(scene_->imaging.seed + static_cast<std::uint64_t>(camera_index_));
  std::normal_distribution<double> gauss(0.0, scene_->imaging.noise_sigma);
  for (std::size_t i = 0; i < kNoiseTable; ++i) {
    noise_[i] = static_cast<std::int8_t>(std::clamp(std::lround(gauss(rng)), -127L, 127L));
    noise_[i + kNoiseTable] = noise_[i];
  }
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
  people_.resize(scene_->people.size());
  for (std::size_t p = 0; p < people_.size(); ++p) {
    people_[p] = sim::EvaluatePerson(scene_->people[p], t);
  }
  if (!colour_) {
    frame->kind = FrameKind::kMask;
    renderer_.Render(people_, &frame->grey);
  } else {
    if (t < empty_s_) people_.clear();  // Resized again by the next frame's poses.
    renderer_.Render(people_, &mask_);
    frame->kind = FrameKind::kRgb;
    ComposeColour(empty_, painted_, mask_, noise_, index_, &frame->rgb);
  }
  frame->stamp_ns = clock_.epoch_ns + since_start.count();
  frame->index = index_++;
  return true;
}

}  // namespace hg::capture
