#include "capture/sim_source.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <thread>

#include <emmintrin.h>

#include "sim/colour_renderer.h"

namespace hg::capture {
namespace {

constexpr std::size_t kNoiseTable = std::size_t{1} << 16;  // A power of two.
constexpr std::size_t kChunk = 16;                         // Pixels composed together.

// The empty cell with the mask's pixels taken from `painted` (the empty cell
// 100 grey levels off), plus noise, into `out`; images of `channels` bytes per
// pixel (1: a Bayer mosaic, 3: RGB). `up` and `down` (kNoiseTable + 3 *
// kChunk entries past any offset) hold the noise's positive and negative
// parts, read at an offset chosen per frame. One pass, 16 pixels at a time:
// saturating byte arithmetic (SSE2) where the mask is clear, pixel by pixel
// where it is not. About 1 ms per Full HD RGB frame, most of it memory traffic.
void ComposeColour(const std::uint8_t* empty, const std::uint8_t* painted,
                   const common::ImageU8& mask, int channels, const std::vector<std::uint8_t>& up,
                   const std::vector<std::uint8_t>& down, std::uint64_t frame_index,
                   std::uint8_t* out) {
  const std::size_t pixels = mask.pixels.size();
  const auto c = static_cast<std::size_t>(channels);
  // A multiplicative hash of the index: the noise differs from frame to frame.
  const std::size_t offset =
      static_cast<std::size_t>(frame_index * 0x9E3779B97F4A7C15ULL >> 40) & (kNoiseTable - 1);
  const std::uint8_t* m = mask.pixels.data();
  // Bytes of pixels [first_pixel, first_pixel + n), noise from the tables at j on.
  auto pixel_by_pixel = [&](std::size_t first_pixel, std::size_t n, std::size_t j) {
    for (std::size_t k = 0; k < c * n; ++k) {
      const std::size_t i = c * first_pixel + k;
      const std::uint8_t value = m[first_pixel + k / c] != 0 ? painted[i] : empty[i];
      const int v = std::min(255, value + up[j + k]) - down[j + k];
      out[i] = static_cast<std::uint8_t>(std::max(0, v));
    }
  };
  const __m128i zero = _mm_setzero_si128();
  std::size_t p = 0;
  for (; p + kChunk <= pixels; p += kChunk) {
    const std::size_t i = c * p;
    const std::size_t j = offset + (i & (kNoiseTable - 1));
    const __m128i people = _mm_loadu_si128(reinterpret_cast<const __m128i*>(m + p));
    if (_mm_movemask_epi8(_mm_cmpeq_epi8(people, zero)) != 0xFFFF) {
      pixel_by_pixel(p, kChunk, j);
      continue;
    }
    for (std::size_t b = 0; b < c * kChunk; b += 16) {
      const __m128i x = _mm_loadu_si128(reinterpret_cast<const __m128i*>(empty + i + b));
      const __m128i a = _mm_loadu_si128(reinterpret_cast<const __m128i*>(up.data() + j + b));
      const __m128i d = _mm_loadu_si128(reinterpret_cast<const __m128i*>(down.data() + j + b));
      _mm_storeu_si128(reinterpret_cast<__m128i*>(out + i + b),
                       _mm_subs_epu8(_mm_adds_epu8(x, a), d));
    }
  }
  if (p < pixels) pixel_by_pixel(p, pixels - p, offset + ((c * p) & (kNoiseTable - 1)));
}

// The Bayer mosaic of an RGB image, pattern RG (GenICam BayerRG8: red at even
// columns of even rows, blue at odd columns of odd rows, green elsewhere).
std::vector<std::uint8_t> BayerRgMosaic(const common::ImageRgb8& rgb) {
  std::vector<std::uint8_t> mosaic(static_cast<std::size_t>(rgb.width) * rgb.height);
  for (int v = 0; v < rgb.height; ++v) {
    for (int u = 0; u < rgb.width; ++u) {
      const int channel = (u & 1) + (v & 1);  // 0 red, 1 green, 2 blue.
      mosaic[static_cast<std::size_t>(v) * rgb.width + u] = rgb.Pixel(u, v)[channel];
    }
  }
  return mosaic;
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

void SimSource::EnableColour(double empty_s, bool bayer) {
  colour_ = true;
  bayer_ = bayer;
  empty_s_ = empty_s;
  common::ImageRgb8 empty;
  sim::ColourRenderer(*scene_, camera_index_).RenderEmpty(&empty);
  empty_ = bayer ? BayerRgMosaic(empty) : empty.pixels;
  painted_ = empty_;
  for (std::uint8_t& v : painted_) v = static_cast<std::uint8_t>(v < 128 ? v + 100 : v - 100);
  // Any offset below kNoiseTable may be followed by kNoiseTable + 3 * kChunk reads.
  const std::size_t table = 2 * kNoiseTable + 3 * kChunk;
  noise_up_.assign(table, 0);
  noise_down_.assign(table, 0);
  std::mt19937_64 rng(scene_->imaging.seed + static_cast<std::uint64_t>(camera_index_));
  std::normal_distribution<double> gauss(0.0, scene_->imaging.noise_sigma);
  for (std::size_t i = 0; i < table; ++i) {
    const long n = std::clamp(std::lround(gauss(rng)), -127L, 127L);
    noise_up_[i] = static_cast<std::uint8_t>(std::max(0L, n));
    noise_down_[i] = static_cast<std::uint8_t>(std::max(0L, -n));
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
    if (t < empty_s_ || (gate_ && !gate_->open())) {
      people_.clear();  // Resized again by the next frame's poses.
    } else if (people_from_ns_.load(std::memory_order_relaxed) == 0) {
      people_from_ns_.store(clock_.epoch_ns + since_start.count());
    }
    renderer_.Render(people_, &mask_);
    const int width = mask_.width, height = mask_.height;
    std::uint8_t* out = nullptr;
    if (bayer_) {
      frame->kind = FrameKind::kMono;  // The raw mosaic, as a Bayer camera's.
      if (frame->grey.width != width || frame->grey.height != height) {
        frame->grey = common::ImageU8(width, height);  // First frame only.
      }
      out = frame->grey.pixels.data();
    } else {
      frame->kind = FrameKind::kRgb;
      if (frame->rgb.width != width || frame->rgb.height != height) {
        frame->rgb = common::ImageRgb8(width, height);  // First frame only.
      }
      out = frame->rgb.pixels.data();
    }
    ComposeColour(empty_.data(), painted_.data(), mask_, bayer_ ? 1 : 3, noise_up_, noise_down_,
                  index_, out);
  }
  frame->stamp_ns = clock_.epoch_ns + since_start.count();
  frame->index = index_++;
  return true;
}

}  // namespace hg::capture
