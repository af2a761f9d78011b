#include "silhouette/background_model.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include "common/check.h"
#include "common/config_error.h"

// The per-row kernels are plain loops for the auto-vectoriser. x86-64's
// baseline (SSE2) cannot gather every third byte, which the RGB threshold
// needs, so on x86-64 they are also built for AVX2 and picked at load time.
// Not under ThreadSanitizer: the clones' resolver runs while the program is
// being loaded, before the sanitizer's runtime is up, and crashes there.
#if defined(__x86_64__) && defined(__has_attribute) && !defined(__SANITIZE_THREAD__)
#if __has_attribute(target_clones) && !defined(__clang__)
#define HG_VECTOR_CLONES __attribute__((target_clones("avx2", "default")))
#endif
#endif
#ifndef HG_VECTOR_CLONES
#define HG_VECTOR_CLONES
#endif

namespace hg::silhouette {
namespace {

constexpr int kTile = 8;
/// Adaptation visits every kAdaptInterleave-th row per frame (each row once in
/// kAdaptInterleave frames, at the equivalent rate): an eighth of the work of
/// updating every row every frame, for the same time constant (50 frames at
/// the default rate; a row is revisited every 0.27 s at 30 Hz).
constexpr int kAdaptInterleave = 8;
/// Gain histogram: ratios in 1/256, up to 4.
constexpr int kGainBins = 1024;
constexpr int kMinGainQ8 = 16;
/// Ratios within this share of the last gain outvote the others (EstimateGainQ8).
constexpr int kGainWindowDivisor = 16;  // 1/16: about 6 %.
/// About this many pixels are sampled for the gain.
constexpr int kGainSampleTarget = 8192;
/// Learning measures the noise over at most this many frames (uint16 sums).
constexpr int kMaxDeviationFrames = 64;
/// A deviation term is at most 255 grey levels in 1/4 levels.
constexpr int kMaxDeviationTerm = 1020;
/// Background darker than this (mean grey level per channel) is too noisy for
/// ratios: no gain sample there, and no shadow there.
constexpr int kMinRatioLevel = 24;
/// Gain sample pixels must not be (nearly) saturated.
constexpr int kMaxRatioLevel = 250;

// The kernels below keep to 8- and 16-bit lanes: (a * b) >> 16 of two uint16
// narrowed to uint16 becomes one multiply-high instruction per 16 samples.
// Minima and maxima are written as conditionals on values: std::min's
// references to temporaries keep GCC from vectorising some of these loops.

/// The high 16 bits of a * b.
inline std::uint16_t MulHigh(std::uint16_t a, std::uint16_t b) {
  return static_cast<std::uint16_t>((static_cast<std::uint32_t>(a) * b) >> 16);
}

/// Expected value of a background sample under the gain: mean * gain with the
/// mean in 8.8 and the gain in 1/256, clipped like the camera clips.
inline std::uint16_t Expected(std::uint16_t mean, std::uint16_t gain_q8) {
  const std::uint16_t e = MulHigh(mean, gain_q8);
  return e < 255 ? e : 255;
}

/// The same from the integer byte of the mean alone (the fraction taken as
/// 1/2): at most half a grey level off.
inline std::uint16_t ExpectedHigh(std::uint8_t mean_high, std::uint16_t gain_q8) {
  return Expected(static_cast<std::uint16_t>(mean_high << 8 | 0x80), gain_q8);
}

/// A frame value at least this high may be clipped: what is there may be
/// anything brighter, a white vest before a bright wall as well as the wall.
constexpr std::uint8_t kClipped = 254;

/// |frame - expected| * inverse_gain (in 1/256), saturated to 255.
inline std::uint8_t ScaledDifference(std::uint8_t frame, std::uint16_t expected,
                                     std::uint16_t inverse_gain_q8) {
  const std::uint16_t f = frame;
  const std::uint16_t hi = f > expected ? f : expected;
  const std::uint16_t lo = f > expected ? expected : f;
  const std::uint16_t scaled = MulHigh(static_cast<std::uint16_t>((hi - lo) << 8), inverse_gain_q8);
  return static_cast<std::uint8_t>(scaled < 255 ? scaled : 255);
}

/// out[i] = |frame[i] - gain * mean[i]| * inverse_gain for n samples.
HG_VECTOR_CLONES void AbsDiffRow(const std::uint8_t* __restrict frame,
                                 const std::uint8_t* __restrict mean_high, int n,
                                 std::uint16_t gain_q8, std::uint16_t inverse_gain_q8,
                                 std::uint8_t* __restrict out) {
  for (int i = 0; i < n; ++i) {
    const std::uint8_t d =
        ScaledDifference(frame[i], ExpectedHigh(mean_high[i], gain_q8), inverse_gain_q8);
    // A clipped value can certify nothing.
    out[i] = frame[i] >= kClipped ? 255 : d;
  }
}

/// mask[u] = 255 iff the largest channel difference of pixel u reaches its
/// threshold. Returns the number of foreground pixels.
HG_VECTOR_CLONES int ThresholdRgbRow(const std::uint8_t* __restrict diff,
                                     const std::uint8_t* __restrict threshold, int width,
                                     std::uint8_t* __restrict mask) {
  int count = 0;
  for (int u = 0; u < width; ++u) {
    const std::uint8_t a = diff[3 * u];
    const std::uint8_t b = diff[3 * u + 1];
    const std::uint8_t c = diff[3 * u + 2];
    const std::uint8_t ab = a > b ? a : b;
    const std::uint8_t m = ab > c ? ab : c;
    const bool foreground = m >= threshold[u];
    mask[u] = foreground ? 255 : 0;
    count += foreground ? 1 : 0;
  }
  return count;
}

/// The grey version: difference and threshold in one pass.
HG_VECTOR_CLONES int ThresholdMonoRow(const std::uint8_t* __restrict frame,
                                      const std::uint8_t* __restrict mean_high,
                                      const std::uint8_t* __restrict threshold, int width,
                                      std::uint16_t gain_q8, std::uint16_t inverse_gain_q8,
                                      std::uint8_t* __restrict mask) {
  int count = 0;
  for (int u = 0; u < width; ++u) {
    const bool foreground = (ScaledDifference(frame[u], ExpectedHigh(mean_high[u], gain_q8),
                                              inverse_gain_q8) >= threshold[u]) |
                            (frame[u] >= kClipped);  // A clipped value can certify nothing.
    mask[u] = foreground ? 255 : 0;
    count += foreground ? 1 : 0;
  }
  return count;
}

/// Grey frames: diff[u] = frame[u] - gain * mean[u] (signed) for one row.
HG_VECTOR_CLONES void SignedDiffRow(const std::uint8_t* __restrict frame,
                                    const std::uint8_t* __restrict mean_high, int width,
                                    std::uint16_t gain_q8, std::int16_t* __restrict diff) {
  for (int u = 0; u < width; ++u) {
    diff[u] = static_cast<std::int16_t>(frame[u] - ExpectedHigh(mean_high[u], gain_q8));
  }
}

/// |d| saturated to 255 (thresholds are at most 255).
inline std::uint8_t Magnitude(std::int16_t d) {
  const auto a = static_cast<std::uint16_t>(d < 0 ? -d : d);
  return static_cast<std::uint8_t>(a < 255 ? a : 255);
}

/// Grey frames with the texture test, rows with a row above and below:
/// ThresholdMonoRow from the row's SignedDiffRow() `diff`, and besides the
/// pixels u in 1 .. width - 2 whose texture differs from the background's:
/// the difference of the neighbours along the row (frame[u + 1] - frame[u -
/// 1]), or along the column (below minus above), differs from the same of
/// the expected background by at least texture[u] (the pixel's noise
/// bound; 0: not tested), and after the inverse gain by at least `floor`
/// (the configured texture threshold). That is a difference of
/// SignedDiffRow()s: (f[u + 1] - e[u + 1]) - (f[u - 1] - e[u - 1]). The
/// noise bound is not divided by the gain, as the floor is: a camera's noise
/// does not dim with the light, and a bound near the noise, scaled up in dim
/// light, would speckle the whole view. Returns the number of foreground
/// pixels. Precondition: width >= 3.
HG_VECTOR_CLONES int ThresholdMonoTextureRow(
    const std::uint8_t* __restrict frame, const std::int16_t* __restrict above,
    const std::int16_t* __restrict diff, const std::int16_t* __restrict below,
    const std::uint8_t* __restrict threshold, const std::uint8_t* __restrict texture, int width,
    std::uint16_t inverse_gain_q8, std::uint16_t floor, std::uint8_t* __restrict mask) {
  auto scale = [inverse_gain_q8](std::int16_t d) {
    // Thresholds are at most 255, so a difference beyond it needs no scaling.
    return MulHigh(static_cast<std::uint16_t>(Magnitude(d) << 8), inverse_gain_q8);
  };
  int count = 0;
  for (const int u : {0, width - 1}) {  // Brightness only: a neighbour is missing.
    const bool foreground = (scale(diff[u]) >= threshold[u]) | (frame[u] >= kClipped);
    mask[u] = foreground ? 255 : 0;
    count += foreground ? 1 : 0;
  }
  for (int u = 1; u + 1 < width; ++u) {
    // Each difference in [-255, 255], theirs in [-510, 510]: int16.
    const std::uint8_t tx = Magnitude(static_cast<std::int16_t>(diff[u + 1] - diff[u - 1]));
    const std::uint8_t ty = Magnitude(static_cast<std::int16_t>(below[u] - above[u]));
    const std::uint8_t t = tx > ty ? tx : ty;
    const std::uint16_t scaled = MulHigh(static_cast<std::uint16_t>(t << 8), inverse_gain_q8);
    const bool foreground = (scale(diff[u]) >= threshold[u]) | (frame[u] >= kClipped) |
                            ((texture[u] != 0) & (t >= texture[u]) & (scaled >= floor));
    mask[u] = foreground ? 255 : 0;
    count += foreground ? 1 : 0;
  }
  return count;
}

/// Colour frames with the texture test, first pass over the n = 3 * width
/// samples of a row (channels interleaved like the frame), from its
/// SignedDiffRow() `diff` and those of the rows above and below:
/// bright[i] = the sample's brightness difference after the inverse gain
/// (255 where the frame is clipped), texture[i] = the larger of its texture
/// differences along the row and the column, not divided by the gain
/// (ThresholdMonoTextureRow; 0 for the first and the last pixel, whose row
/// neighbour is missing), both saturated to 255.
/// Precondition: n >= 9.
HG_VECTOR_CLONES void RgbTextureDiffRow(const std::uint8_t* __restrict frame,
                                        const std::int16_t* __restrict above,
                                        const std::int16_t* __restrict diff,
                                        const std::int16_t* __restrict below, int n,
                                        std::uint16_t inverse_gain_q8,
                                        std::uint8_t* __restrict bright,
                                        std::uint8_t* __restrict texture) {
  auto scale = [inverse_gain_q8](std::int16_t d) {
    const std::uint16_t s = MulHigh(static_cast<std::uint16_t>(Magnitude(d) << 8), inverse_gain_q8);
    return static_cast<std::uint8_t>(s < 255 ? s : 255);
  };
  for (int i = 0; i < n; ++i) {
    const std::uint8_t clipped = frame[i] >= kClipped ? 255 : 0;
    bright[i] = static_cast<std::uint8_t>(scale(diff[i]) | clipped);
  }
  for (int i = 0; i < 3; ++i) texture[i] = texture[n - 3 + i] = 0;
  for (int i = 3; i + 3 < n; ++i) {
    // Each difference in [-255, 255], theirs in [-510, 510]: int16.
    const std::uint8_t tx = Magnitude(static_cast<std::int16_t>(diff[i + 3] - diff[i - 3]));
    const std::uint8_t ty = Magnitude(static_cast<std::int16_t>(below[i] - above[i]));
    texture[i] = tx > ty ? tx : ty;
  }
}

/// Second pass: mask[u] = 255 iff some channel's brightness difference
/// reaches threshold[u], or some channel's texture difference reaches
/// texture_threshold[u] (0: not tested) and, after the inverse gain, `floor`
/// (ThresholdMonoTextureRow). Returns the number of foreground pixels.
HG_VECTOR_CLONES int ThresholdRgbTextureRow(const std::uint8_t* __restrict bright,
                                            const std::uint8_t* __restrict texture,
                                            const std::uint8_t* __restrict threshold,
                                            const std::uint8_t* __restrict texture_threshold,
                                            int width, std::uint16_t inverse_gain_q8,
                                            std::uint16_t floor, std::uint8_t* __restrict mask) {
  int count = 0;
  for (int u = 0; u < width; ++u) {
    const std::uint8_t b01 = bright[3 * u] > bright[3 * u + 1] ? bright[3 * u] : bright[3 * u + 1];
    const std::uint8_t b = b01 > bright[3 * u + 2] ? b01 : bright[3 * u + 2];
    const std::uint8_t t01 =
        texture[3 * u] > texture[3 * u + 1] ? texture[3 * u] : texture[3 * u + 1];
    const std::uint8_t t = t01 > texture[3 * u + 2] ? t01 : texture[3 * u + 2];
    const std::uint16_t scaled = MulHigh(static_cast<std::uint16_t>(t << 8), inverse_gain_q8);
    const bool foreground = (b >= threshold[u]) | ((texture_threshold[u] != 0) &
                                                   (t >= texture_threshold[u]) & (scaled >= floor));
    mask[u] = foreground ? 255 : 0;
    count += foreground ? 1 : 0;
  }
  return count;
}

/// One learning frame over n samples: each mean (8.8, split into high and low
/// bytes) moves to the running average with the frame brought back to the
/// reference gain, x = frame * inverse_gain >> 8; `inverse_count` is
/// 2^16 / (frames averaged + 1), 0 for the first frame (the mean becomes x).
/// With `unbias_q12` > 0 the deviation of x from the new mean, in quarter
/// levels, has its largest value kept in `peak` (levels), and with
/// `add_deviation` it is also added up (the noise).
/// 32-bit lanes suffice: |x - m| < 2^16 and
/// inverse_count <= 2^15 after the first frame, and (p + 2^15) >> 16 is
/// computed as ((p >> 1) + 2^14) >> 15, which is the same for every p.
HG_VECTOR_CLONES void LearnSpan(const std::uint8_t* __restrict frame, std::size_t n,
                                std::uint32_t inverse_gain, std::int32_t inverse_count,
                                std::int32_t unbias_q12, bool add_deviation,
                                std::uint8_t* __restrict mean_high,
                                std::uint8_t* __restrict mean_low,
                                std::uint16_t* __restrict deviation,
                                std::uint8_t* __restrict peak) {
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t scaled = (frame[i] * inverse_gain) >> 8;
    const auto x = static_cast<std::int32_t>(scaled < 65535u ? scaled : 65535u);
    const std::int32_t m = (mean_high[i] << 8) | mean_low[i];
    std::int32_t updated = x;
    if (inverse_count != 0) updated = m + (((((x - m) * inverse_count) >> 1) + (1 << 14)) >> 15);
    updated = updated < 0 ? 0 : updated > 65535 ? 65535 : updated;
    mean_high[i] = static_cast<std::uint8_t>(updated >> 8);
    mean_low[i] = static_cast<std::uint8_t>(updated);
    if (unbias_q12 != 0) {
      const std::int32_t d = x > updated ? x - updated : updated - x;
      // 8.8 -> quarter levels: >> 6; Q12: >> 12.
      const std::int32_t term = (d * unbias_q12) >> 18;
      const std::int32_t capped = term < kMaxDeviationTerm ? term : kMaxDeviationTerm;
      if (add_deviation) deviation[i] = static_cast<std::uint16_t>(deviation[i] + capped);
      const auto level = static_cast<std::uint8_t>(capped >> 2);
      peak[i] = level > peak[i] ? level : peak[i];
    }
  }
}

/// mean += rate / gain * (frame - gain * mean), in 8.8: the background follows
/// the frame brought back to the reference illumination. `rate_q17` is
/// rate / gain in 1/2^17, so that the product of (d * 128) and it, high 16 bits
/// kept, is the step in 1/256 grey levels (one 16-bit multiply-high per sample).
HG_VECTOR_CLONES void AdaptSpan(const std::uint8_t* __restrict frame,
                                std::uint8_t* __restrict mean_high,
                                std::uint8_t* __restrict mean_low, int n, std::uint16_t gain_q8,
                                std::int16_t rate_q17) {
  for (int i = 0; i < n; ++i) {
    const auto mean = static_cast<std::uint16_t>(mean_high[i] << 8 | mean_low[i]);
    // (frame - expected) * 128 lies in [-32640, 32640].
    const auto d7 = static_cast<std::int16_t>(
        static_cast<std::uint16_t>(frame[i] - Expected(mean, gain_q8)) << 7);
    const auto step = static_cast<std::int16_t>((static_cast<std::int32_t>(d7) * rate_q17) >> 16);
    // mean + step, saturated to [0, 65535].
    const std::uint16_t up = step > 0 ? static_cast<std::uint16_t>(step) : 0;
    const std::uint16_t down = step < 0 ? static_cast<std::uint16_t>(-step) : 0;
    const auto room = static_cast<std::uint16_t>(65535 - mean);
    const auto next =
        static_cast<std::uint16_t>(mean + (up < room ? up : room) - (down < mean ? down : mean));
    mean_high[i] = static_cast<std::uint8_t>(next >> 8);
    mean_low[i] = static_cast<std::uint8_t>(next);
  }
}

std::string Bad(const std::string& key, const std::string& problem) {
  return "background: " + key + ": " + problem;
}

}  // namespace

void ValidateBackgroundModelOptions(const BackgroundModelOptions& o) {
  using common::ConfigError;
  if (o.learn_frames < 1 || o.learn_frames > 100000) {
    throw ConfigError(Bad("learn_frames", "must be in [1, 100000]"));
  }
  if (o.min_threshold < 1 || o.min_threshold > 255) {
    throw ConfigError(Bad("min_threshold", "must be in [1, 255] grey levels"));
  }
  if (o.max_threshold < o.min_threshold || o.max_threshold > 255) {
    throw ConfigError(Bad("max_threshold", "must be in [min_threshold, 255] grey levels"));
  }
  if (!(o.noise_sigmas >= 0.0 && o.noise_sigmas <= 100.0)) {
    throw ConfigError(Bad("noise_sigmas", "must be in [0, 100]"));
  }
  if (!(o.adapt_rate >= 0.0 && o.adapt_rate <= 0.25)) {
    throw ConfigError(Bad("adapt_rate", "must be in [0, 0.25] per frame"));
  }
  if (o.guard_px < 0 || o.guard_px > 1024) {
    throw ConfigError(Bad("guard_px", "must be in [0, 1024] pixels"));
  }
  if (o.texture_threshold < 0 || o.texture_threshold > 255) {
    throw ConfigError(Bad("texture_threshold", "must be in [0, 255] grey levels (0: off)"));
  }
  if (!(o.shadow_min_ratio > 0.0 && o.shadow_min_ratio < 1.0)) {
    throw ConfigError(Bad("shadow_min_ratio", "must be in (0, 1)"));
  }
  if (!(o.shadow_max_ratio >= o.shadow_min_ratio && o.shadow_max_ratio < 1.0)) {
    throw ConfigError(Bad("shadow_max_ratio", "must be in [shadow_min_ratio, 1)"));
  }
}

BackgroundModel::BackgroundModel(int width, int height, const BackgroundModelOptions& options)
    : width_(width), height_(height), options_(options) {
  ValidateBackgroundModelOptions(options_);
  if (width < 1 || height < 1 || width > 32768 || height > 32768) {
    throw common::ConfigError(Bad("size", "width and height must be in [1, 32768] pixels"));
  }
  const auto pixels = static_cast<std::size_t>(width) * height;
  mean_high_.assign(3 * pixels, 0);
  mean_low_.assign(3 * pixels, 0);
  deviation_.assign(3 * pixels, 0);
  peak_.assign(3 * pixels, 0);
  threshold_.assign(pixels, 0);
  if (options_.texture_threshold > 0) {
    texture_threshold_.assign(pixels, 0);
    diff_rows_.assign(9 * static_cast<std::size_t>(width), 0);  // Three rows of RGB.
    row_texture_.assign(3 * static_cast<std::size_t>(width), 0);
  }
  tiles_x_ = (width + kTile - 1) / kTile;
  tiles_y_ = (height + kTile - 1) / kTile;
  const auto tiles = static_cast<std::size_t>(tiles_x_) * tiles_y_;
  tile_foreground_.assign(tiles, 0);
  tile_scratch_.assign(tiles, 0);
  tile_free_.assign(tiles, 1);
  row_diff_.assign(3 * static_cast<std::size_t>(width), 0);
  gain_histogram_.assign(kGainBins, 0);
  const int step =
      std::max(1, static_cast<int>(std::sqrt(static_cast<double>(pixels) / kGainSampleTarget)));
  int row = 0;
  for (int v = step / 2; v < height_; v += step, ++row) {
    // Staggered columns, so that the sample does not line up with textures.
    for (int u = (row * 5 + step / 2) % step; u < width_; u += step) {
      sample_pixels_.push_back(static_cast<std::uint32_t>(v) * width_ + u);
    }
  }
  sample_reference_.assign(3 * sample_pixels_.size(), 0);
  sample_current_.assign(3 * sample_pixels_.size(), 0);
}

void BackgroundModel::Reset() {
  channels_ = 0;
  frames_learned_ = 0;
  deviation_frames_ = 0;
  gain_ = 1.0;
  gain_q8_ = 256;
  foreground_fraction_ = 1.0;
  tiles_valid_ = false;
  std::fill(mean_high_.begin(), mean_high_.end(), 0);
  std::fill(mean_low_.begin(), mean_low_.end(), 0);
  std::fill(deviation_.begin(), deviation_.end(), 0);
  std::fill(peak_.begin(), peak_.end(), 0);
  std::fill(threshold_.begin(), threshold_.end(), 0);
  std::fill(texture_threshold_.begin(), texture_threshold_.end(), 0);
  std::fill(tile_free_.begin(), tile_free_.end(), 1);
}

namespace {

// A saved background: this header, then the mean's integer bytes and fraction
// bytes (width * height * channels each), then per pixel the largest learning
// deviation over its channels (uint16), all in host byte order; the checksum
// (FNV-1a, 64 bit) covers everything after the header.
struct SavedHeader {
  // Format 2: the checksum covers the size and frame count too (format 1's
  // did not: a flipped bit of deviation_frames was taken up).
  char magic[8] = {'H', 'G', 'B', 'G', 'M', 'O', 'D', '2'};
  std::int32_t width = 0;
  std::int32_t height = 0;
  std::int32_t channels = 0;
  std::int32_t deviation_frames = 0;
  std::uint64_t camera_id = 0;  // The camera and its calibration (Save()).
  std::uint64_t checksum = 0;
};

class Fnv1a {
 public:
  void Add(const void* data, std::size_t size) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < size; ++i) hash_ = (hash_ ^ p[i]) * 0x100000001b3ULL;
  }
  [[nodiscard]] std::uint64_t value() const { return hash_; }

 private:
  std::uint64_t hash_ = 0xcbf29ce484222325ULL;
};

/// The header's fields into the checksum (all but the checksum itself).
void AddHeader(const SavedHeader& header, Fnv1a* sum) {
  sum->Add(header.magic, sizeof(header.magic));
  for (const std::int32_t v :
       {header.width, header.height, header.channels, header.deviation_frames}) {
    sum->Add(&v, sizeof(v));
  }
  sum->Add(&header.camera_id, sizeof(header.camera_id));
}

}  // namespace

bool BackgroundModel::Save(const std::string& path, std::string* error,
                           std::uint64_t camera_id) const {
  HG_CHECK(!learning() && channels_ > 0);
  const auto pixels = static_cast<std::size_t>(width_) * height_;
  const std::size_t values = pixels * static_cast<std::size_t>(channels_);
  std::vector<std::uint16_t> noise(pixels, 0);
  for (std::size_t p = 0; p < pixels; ++p) {
    for (int k = 0; k < channels_; ++k) {
      noise[p] = std::max(noise[p], deviation_[p * channels_ + k]);
    }
  }
  SavedHeader header;
  header.width = width_;
  header.height = height_;
  header.channels = channels_;
  header.deviation_frames = deviation_frames_;
  header.camera_id = camera_id;
  Fnv1a sum;
  AddHeader(header, &sum);
  sum.Add(mean_high_.data(), values);
  sum.Add(mean_low_.data(), values);
  sum.Add(noise.data(), noise.size() * sizeof(std::uint16_t));
  header.checksum = sum.value();
  const std::string temporary = path + ".new";
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(&header), sizeof(header));
    out.write(reinterpret_cast<const char*>(mean_high_.data()),
              static_cast<std::streamsize>(values));
    out.write(reinterpret_cast<const char*>(mean_low_.data()),
              static_cast<std::streamsize>(values));
    out.write(reinterpret_cast<const char*>(noise.data()),
              static_cast<std::streamsize>(noise.size() * sizeof(std::uint16_t)));
    out.flush();
    if (!out) {
      *error = temporary + ": cannot write";
      std::error_code ec;
      std::filesystem::remove(temporary, ec);
      return false;
    }
  }
  std::error_code ec;
  std::filesystem::rename(temporary, path, ec);
  if (ec) {
    *error = path + ": cannot rename the new file over it: " + ec.message();
    std::filesystem::remove(temporary, ec);
    return false;
  }
  return true;
}

bool BackgroundModel::Load(const std::string& path, std::string* error, int channels,
                           std::uint64_t camera_id) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    *error = path + ": cannot open";
    return false;
  }
  SavedHeader header;
  const SavedHeader expected;
  in.read(reinterpret_cast<char*>(&header), sizeof(header));
  if (!in || std::memcmp(header.magic, expected.magic, sizeof(header.magic) - 1) != 0) {
    *error = path + ": not a saved background";
    return false;
  }
  if (header.magic[7] != expected.magic[7]) {
    *error = path +
             ": a background saved in another format (an older hullguard's?); teach it "
             "again";
    return false;
  }
  if (header.deviation_frames < 0 || header.deviation_frames > kMaxDeviationFrames) {
    *error = path + ": damaged (a noise of " + std::to_string(header.deviation_frames) +
             " frames, at most " + std::to_string(kMaxDeviationFrames) + " are learned)";
    return false;
  }
  if (header.width != width_ || header.height != height_ ||
      (header.channels != 1 && header.channels != 3)) {
    *error = path + ": a background of " + std::to_string(header.width) + "x" +
             std::to_string(header.height) + " pixels, " + std::to_string(header.channels) +
             " channels; the camera is " + std::to_string(width_) + "x" + std::to_string(height_);
    return false;
  }
  if (channels != 0 && header.channels != channels) {
    auto kind = [](int c) { return c == 3 ? "colour" : "grey"; };
    *error = path + " holds a background of " + kind(header.channels) +
             " frames, the camera now delivers " + kind(channels) +
             " ones (its pixel format changed?)";
    return false;
  }
  const auto pixels = static_cast<std::size_t>(width_) * height_;
  const std::size_t values = pixels * static_cast<std::size_t>(header.channels);
  std::vector<std::uint8_t> high(values), low(values);
  std::vector<std::uint16_t> noise(pixels);
  in.read(reinterpret_cast<char*>(high.data()), static_cast<std::streamsize>(values));
  in.read(reinterpret_cast<char*>(low.data()), static_cast<std::streamsize>(values));
  in.read(reinterpret_cast<char*>(noise.data()),
          static_cast<std::streamsize>(pixels * sizeof(std::uint16_t)));
  Fnv1a sum;
  AddHeader(header, &sum);
  sum.Add(high.data(), values);
  sum.Add(low.data(), values);
  sum.Add(noise.data(), noise.size() * sizeof(std::uint16_t));
  if (!in || in.peek() != std::char_traits<char>::eof() || sum.value() != header.checksum) {
    *error = path + ": damaged (truncated, too long or checksum mismatch)";
    return false;
  }
  if (header.camera_id != camera_id) {
    *error = path +
             ": taught for another camera, or before this one was calibrated anew (its "
             "view may have moved); teach the background again";
    return false;
  }
  Reset();
  channels_ = header.channels;
  std::copy(high.begin(), high.end(), mean_high_.begin());
  std::copy(low.begin(), low.end(), mean_low_.begin());
  for (std::size_t p = 0; p < pixels; ++p) deviation_[p * channels_] = noise[p];
  deviation_frames_ = header.deviation_frames;
  frames_learned_ = options_.learn_frames;
  FinishLearning();
  return true;
}

void BackgroundModel::Apply(const common::ImageRgb8& frame, common::ImageU8* mask) {
  HG_CHECK(frame.width == width_ && frame.height == height_);
  HG_CHECK(frame.pixels.size() == 3 * static_cast<std::size_t>(width_) * height_);
  ApplyFrame(frame.pixels.data(), 3, mask);
}

void BackgroundModel::Apply(const common::ImageU8& frame, common::ImageU8* mask) {
  HG_CHECK(frame.width == width_ && frame.height == height_);
  HG_CHECK(frame.pixels.size() == static_cast<std::size_t>(width_) * height_);
  ApplyFrame(frame.pixels.data(), 1, mask);
}

double BackgroundModel::MeanAt(int u, int v, int c) const {
  HG_CHECK(u >= 0 && u < width_ && v >= 0 && v < height_ && c >= 0 && c < std::max(1, channels_));
  const std::size_t i = (static_cast<std::size_t>(v) * width_ + u) * std::max(1, channels_) + c;
  return Mean(i) / 256.0;
}

int BackgroundModel::ThresholdAt(int u, int v) const {
  HG_CHECK(u >= 0 && u < width_ && v >= 0 && v < height_);
  const std::uint8_t t = threshold_[static_cast<std::size_t>(v) * width_ + u];
  return t == 0 ? -1 : t;
}

int BackgroundModel::TextureThresholdAt(int u, int v) const {
  HG_CHECK(u >= 0 && u < width_ && v >= 0 && v < height_);
  if (texture_threshold_.empty()) return 0;
  const std::uint8_t bound = texture_threshold_[static_cast<std::size_t>(v) * width_ + u];
  return bound == 0 ? 0 : std::max<int>(bound, options_.texture_threshold);
}

void BackgroundModel::ApplyFrame(const std::uint8_t* frame, int channels, common::ImageU8* mask) {
  HG_CHECK(mask != nullptr);
  const auto pixels = static_cast<std::size_t>(width_) * height_;
  if (mask->width != width_ || mask->height != height_ || mask->pixels.size() != pixels) {
    *mask = common::ImageU8(width_, height_);
  }
  if (channels_ != channels) {
    // A camera that changed its pixel format is a camera we do not know.
    if (channels_ != 0) Reset();
    channels_ = channels;
  }
  tiles_valid_ = false;
  if (learning()) {
    Learn(frame);
    ++frames_learned_;
    ++frames_applied_;
    if (!learning()) FinishLearning();
    std::fill(mask->pixels.begin(), mask->pixels.end(), 255);
    foreground_fraction_ = 1.0;
    return;
  }
  if (options_.compensate_gain) {
    const int q = EstimateGainQ8(frame, sample_reference_.data(), /*all=*/false, gain_q8_);
    // Too few pixels far from foreground to measure: keep the last gain.
    if (q > 0) gain_q8_ = q;
    gain_ = gain_q8_ / 256.0;
  }
  Process(frame, mask->pixels.data());
  tiles_valid_ = true;
  ++frames_applied_;
}

void BackgroundModel::GatherSample(std::vector<std::uint16_t>* out) const {
  const int c = channels_;
  for (std::size_t s = 0; s < sample_pixels_.size(); ++s) {
    for (int k = 0; k < c; ++k) (*out)[s * c + k] = Mean(sample_pixels_[s] * c + k);
  }
}

int BackgroundModel::EstimateGainQ8(const std::uint8_t* frame, const std::uint16_t* reference,
                                    bool all, int near_q8) {
  std::fill(gain_histogram_.begin(), gain_histogram_.end(), 0);
  const int c = channels_;
  const auto min_sum = static_cast<std::uint32_t>(c * kMinRatioLevel * 256);
  int count = 0;
  for (std::size_t s = 0; s < sample_pixels_.size(); ++s) {
    const std::uint32_t p = sample_pixels_[s];
    if (!all) {
      const std::uint32_t v = p / width_;
      const std::uint32_t u = p - v * width_;
      if (tile_free_[(v / kTile) * tiles_x_ + u / kTile] == 0) continue;
    }
    const std::uint8_t* f = frame + static_cast<std::size_t>(p) * c;
    const std::uint16_t* m = reference + s * c;
    std::uint32_t f_sum = 0;
    std::uint32_t m_sum = 0;
    bool usable = true;
    for (int k = 0; k < c; ++k) {
      usable = usable && f[k] < kMaxRatioLevel && m[k] < kMaxRatioLevel * 256;
      f_sum += f[k];
      m_sum += m[k];
    }
    if (!usable || m_sum < min_sum) continue;
    const std::uint32_t ratio = ((f_sum << 16) + m_sum / 2) / m_sum;
    ++gain_histogram_[std::min<std::uint32_t>(ratio, kGainBins - 1)];
    ++count;
  }
  const int enough = std::max<int>(16, static_cast<int>(sample_pixels_.size() / 64));
  if (count < enough) return 0;
  // The median of the bins [lo, hi] holding `n` samples.
  auto median = [&](int lo, int hi, int n) {
    const int half = (n + 1) / 2;
    int cumulative = 0;
    for (int bin = lo; bin <= hi; ++bin) {
      cumulative += static_cast<int>(gain_histogram_[bin]);
      if (cumulative >= half) return std::max(bin, kMinGainQ8);
    }
    return std::max(hi, kMinGainQ8);
  };
  if (near_q8 > 0) {
    const int reach = std::max(1, near_q8 / kGainWindowDivisor);
    const int lo = std::max(0, near_q8 - reach);
    const int hi = std::min(kGainBins - 1, near_q8 + reach);
    int near = 0;
    for (int bin = lo; bin <= hi; ++bin) near += static_cast<int>(gain_histogram_[bin]);
    if (near >= enough) return median(lo, hi, near);
  }
  return median(0, kGainBins - 1, count);
}

void BackgroundModel::Learn(const std::uint8_t* frame) {
  const int k = frames_learned_;  // Frames already averaged.
  int gain_q8 = 256;
  if (k > 0 && options_.compensate_gain) {
    // The first frame is the reference illumination; later frames are brought
    // back to it so that light changing while learning is not taken for noise.
    GatherSample(&sample_current_);
    const int q = EstimateGainQ8(frame, sample_current_.data(), /*all=*/true);
    if (q > 0) gain_q8 = q;
  }
  gain_q8_ = gain_q8;
  gain_ = gain_q8 / 256.0;
  // x = frame / gain in 8.8: frame * (2^24 / gain_q8) >> 8.
  const auto inverse_gain = static_cast<std::uint32_t>((1u << 24) / gain_q8);
  const std::int64_t inverse_count = (std::int64_t{1} << 16) / (k + 1);
  // The noise is measured over the last frames (at most kMaxDeviationFrames:
  // the sums are 16-bit); what passed is looked for in every frame after the
  // first: something in view over the first of many learning frames (a
  // person leaving) shows as the frame that differs from the mean of those
  // before it.
  const bool measure_noise = k >= 1 && k >= options_.learn_frames - kMaxDeviationFrames;
  // |x - mean after this frame| has deviation sigma * sqrt(k / (k + 1)) for a
  // mean of k + 1 samples; scaling by sqrt((k + 1) / k) makes it unbiased.
  const auto unbias_q12 =
      k >= 1 ? static_cast<std::int64_t>(std::lround(4096.0 * std::sqrt((k + 1.0) / k))) : 0;
  const std::size_t n = static_cast<std::size_t>(width_) * height_ * channels_;
  LearnSpan(frame, n, inverse_gain, k == 0 ? 0 : static_cast<std::int32_t>(inverse_count),
            static_cast<std::int32_t>(unbias_q12), measure_noise, mean_high_.data(),
            mean_low_.data(), deviation_.data(), peak_.data());
  if (measure_noise) ++deviation_frames_;
}

void BackgroundModel::FinishLearning() {
  // Adaptation's row phase counts from here, so that a background taken up
  // by Load() adapts exactly as the model that saved it.
  frames_applied_ = 0;
  // Mean absolute deviation of a Gaussian is sigma * sqrt(2 / pi).
  const double sigma_per_unit =
      deviation_frames_ > 0 ? std::sqrt(M_PI / 2.0) / (4.0 * deviation_frames_) : 0.0;
  const std::size_t pixels = static_cast<std::size_t>(width_) * height_;
  const int c = channels_;
  for (std::size_t p = 0; p < pixels; ++p) {
    int largest = 0;
    for (int k = 0; k < c; ++k) largest = std::max<int>(largest, deviation_[p * c + k]);
    const double sigma = largest * sigma_per_unit;
    const double t = std::max<double>(options_.min_threshold, options_.noise_sigmas * sigma);
    const auto rounded = static_cast<int>(std::ceil(t - 1e-9));
    // A learning frame that differed from the background by a threshold or
    // more showed something passing (a robot arm moving while the cell was
    // learned): it biased the mean and the noise there, which could hide a
    // person of the contrast the threshold promises. Such a pixel is
    // unreliable, always foreground, and saved so (its noise saturated).
    // A saturated noise (0xFFFF, more than learning can add up) is such a
    // pixel taken up from a saved background, whatever the thresholds.
    int peak = 0;
    for (int k = 0; k < c; ++k) peak = std::max<int>(peak, peak_[p * c + k]);
    const bool passed = peak >= rounded || largest == 0xFFFF;
    if (passed) {
      for (int k = 0; k < c; ++k) deviation_[p * c + k] = 0xFFFF;
    }
    threshold_[p] =
        passed || rounded > options_.max_threshold ? 0 : static_cast<std::uint8_t>(rounded);
  }
  if (!texture_threshold_.empty()) FinishTextureThresholds(sigma_per_unit);
  std::fill(tile_free_.begin(), tile_free_.end(), 1);
  GatherSample(&sample_reference_);
}

void BackgroundModel::FinishTextureThresholds(double sigma_per_unit) {
  std::fill(texture_threshold_.begin(), texture_threshold_.end(), 0);
  if (width_ < 3 || height_ < 3) return;
  // The texture compares differences of two pixels: their noise adds up. A
  // neighbour that is unreliable (its deviation saturated) makes the pixel's
  // texture untested; its brightness still is.
  const double scale = options_.noise_sigmas * std::sqrt(2.0) * sigma_per_unit;
  const std::size_t w = static_cast<std::size_t>(width_);
  const std::size_t c = static_cast<std::size_t>(channels_);
  for (int v = 1; v + 1 < height_; ++v) {
    for (int u = 1; u + 1 < width_; ++u) {
      const std::size_t p = static_cast<std::size_t>(v) * width_ + u;
      std::uint16_t noisiest = 0;
      for (const std::size_t q : {p - 1, p + 1, p - w, p + w}) {
        for (std::size_t k = 0; k < c; ++k) noisiest = std::max(noisiest, deviation_[q * c + k]);
      }
      if (threshold_[p] == 0 || noisiest == 0xFFFF) continue;
      // The noise bound alone (at least 1: 0 marks untested pixels); the
      // configured threshold is the floor it is tested beside, after the
      // gain (ThresholdMonoTextureRow).
      const auto bound = std::max(1, static_cast<int>(std::ceil(scale * noisiest - 1e-9)));
      texture_threshold_[p] = std::max(bound, options_.texture_threshold) > options_.max_threshold
                                  ? 0
                                  : static_cast<std::uint8_t>(bound);
    }
  }
}

void BackgroundModel::Process(const std::uint8_t* frame, std::uint8_t* mask) {
  // Where the light is dimmer than at learning, a person's contrast shrinks with
  // it: differences are divided by the gain, so the person stays as visible.
  // Brighter light is not given the reverse (which would only remove
  // foreground); the noise does not grow with it.
  dim_gain_q8_ = std::min(gain_q8_, 256);
  inverse_gain_q8_ = std::min(65535, (65536 + dim_gain_q8_ / 2) / dim_gain_q8_);
  rate_q17_ = 0;
  if (options_.adapt_rate > 0.0) {
    const double rate = 1.0 - std::pow(1.0 - options_.adapt_rate, kAdaptInterleave);
    rate_q17_ = static_cast<int>(std::clamp<long>(std::lround(rate / gain_ * 131072.0), 0, 32767));
  }
  guard_tiles_ = (options_.guard_px + kTile - 1) / kTile;
  diff_row_of_.fill(-1);  // A new frame (and gain).
  const int r = guard_tiles_;
  std::int64_t count = 0;
  for (int ty = 0; ty < tiles_y_; ++ty) {
    std::uint8_t* fg = tile_foreground_.data() + static_cast<std::size_t>(ty) * tiles_x_;
    std::fill(fg, fg + tiles_x_, 0);
    for (int v = ty * kTile; v < std::min(height_, (ty + 1) * kTile); ++v) {
      count += ClassifyRow(v, frame, mask);
    }
    // Horizontal half of the (separable, Chebyshev) dilation by r tiles.
    std::uint8_t* near = tile_scratch_.data() + static_cast<std::size_t>(ty) * tiles_x_;
    for (int tx = 0; tx < tiles_x_; ++tx) {
      std::uint8_t any = 0;
      for (int x = std::max(0, tx - r); x <= std::min(tiles_x_ - 1, tx + r); ++x) any |= fg[x];
      near[tx] = any;
    }
    if (ty >= r) FinishTileRow(ty - r, frame);
  }
  for (int ty = std::max(0, tiles_y_ - r); ty < tiles_y_; ++ty) FinishTileRow(ty, frame);
  foreground_fraction_ = static_cast<double>(count) / (static_cast<double>(width_) * height_);
}

const std::int16_t* BackgroundModel::DiffRow(int v, const std::uint8_t* frame) {
  const int slot = v % 3;
  const int n = width_ * channels_;
  std::int16_t* row = diff_rows_.data() + static_cast<std::size_t>(slot) * n;
  if (diff_row_of_[slot] != v) {
    const std::size_t start = static_cast<std::size_t>(v) * n;
    SignedDiffRow(frame + start, mean_high_.data() + start, n, static_cast<std::uint16_t>(gain_q8_),
                  row);
    diff_row_of_[slot] = v;
  }
  return row;
}

int BackgroundModel::ClassifyRow(int v, const std::uint8_t* frame, std::uint8_t* mask) {
  const int c = channels_;
  const auto gain_q8 = static_cast<std::uint16_t>(gain_q8_);
  const auto inverse_gain_q8 = static_cast<std::uint16_t>(inverse_gain_q8_);
  const std::size_t row = static_cast<std::size_t>(v) * width_;
  const std::uint8_t* f = frame + row * c;
  const std::uint8_t* m = mean_high_.data() + row * c;
  const std::uint8_t* t = threshold_.data() + row;
  std::uint8_t* out = mask + row;
  int count;
  const bool texture = !texture_threshold_.empty() && v > 0 && v + 1 < height_ && width_ >= 3;
  if (c == 3) {
    if (texture) {
      RgbTextureDiffRow(f, DiffRow(v - 1, frame), DiffRow(v, frame), DiffRow(v + 1, frame),
                        3 * width_, inverse_gain_q8, row_diff_.data(), row_texture_.data());
      count = ThresholdRgbTextureRow(row_diff_.data(), row_texture_.data(), t,
                                     texture_threshold_.data() + row, width_, inverse_gain_q8,
                                     static_cast<std::uint16_t>(options_.texture_threshold), out);
    } else {
      AbsDiffRow(f, m, 3 * width_, gain_q8, inverse_gain_q8, row_diff_.data());
      count = ThresholdRgbRow(row_diff_.data(), t, width_, out);
    }
  } else {
    if (texture) {
      count = ThresholdMonoTextureRow(f, DiffRow(v - 1, frame), DiffRow(v, frame),
                                      DiffRow(v + 1, frame), t, texture_threshold_.data() + row,
                                      width_, inverse_gain_q8,
                                      static_cast<std::uint16_t>(options_.texture_threshold), out);
    } else {
      count = ThresholdMonoRow(f, m, t, width_, gain_q8, inverse_gain_q8, out);
    }
  }
  if (count == 0) return 0;
  // Tiles with any differing pixel, shadows included: the guard keeps the
  // background from learning a shadow that is reported as background.
  std::uint8_t* tiles = tile_foreground_.data() + static_cast<std::size_t>(v / kTile) * tiles_x_;
  const int full_tiles = width_ / kTile;
  for (int tx = 0; tx < full_tiles; ++tx) {
    std::uint64_t word;
    std::memcpy(&word, out + tx * kTile, sizeof(word));
    tiles[tx] |= word != 0 ? 1 : 0;
  }
  for (int u = full_tiles * kTile; u < width_; ++u) tiles[u / kTile] |= out[u] != 0 ? 1 : 0;
  if (options_.shadows_are_foreground) return count;
  const auto lo_q8 = static_cast<int>(std::lround(options_.shadow_min_ratio * 256.0));
  const auto hi_q8 = static_cast<int>(std::lround(options_.shadow_max_ratio * 256.0));
  for (int u0 = 0; u0 < width_; u0 += kTile) {
    const int u1 = std::min(width_, u0 + kTile);
    if (u1 - u0 == kTile) {
      std::uint64_t word;
      std::memcpy(&word, out + u0, sizeof(word));
      if (word == 0) continue;
    }
    for (int u = u0; u < u1; ++u) {
      if (out[u] == 0) continue;
      const std::uint8_t* fp = f + static_cast<std::size_t>(u) * c;
      const std::uint8_t* mp = m + static_cast<std::size_t>(u) * c;
      // Sums stay below 2^10 and products below 2^31: int is enough.
      int e[3] = {0, 0, 0};
      int e_sum = 0;
      int f_sum = 0;
      for (int k = 0; k < c; ++k) {
        e[k] = ExpectedHigh(mp[k], gain_q8);
        e_sum += e[k];
        f_sum += fp[k];
      }
      // Darker by a ratio in [lo, hi] (never where the threshold is 0: an
      // unreliable pixel stays foreground) ...
      bool shadow = (t[u] != 0) & (e_sum >= c * kMinRatioLevel) & (f_sum * 256 >= lo_q8 * e_sum) &
                    (f_sum * 256 <= hi_q8 * e_sum);
      // ... and, in colour, every channel within the threshold (scaled as in
      // Process()) of the background scaled by that ratio:
      // |f_k - (F / E) e_k| < t * min(gain, 1).
      if (c == 3) {
        const int tolerance = t[u] * dim_gain_q8_ * e_sum;
        for (int k = 0; k < 3; ++k) {
          const int d = fp[k] * e_sum - f_sum * e[k];
          shadow &= (d < 0 ? -d : d) * 256 < tolerance;
        }
      }
      out[u] = shadow ? 0 : out[u];
      count -= shadow ? 1 : 0;
    }
  }
  return count;
}

void BackgroundModel::FinishTileRow(int ty, const std::uint8_t* frame) {
  const int r = guard_tiles_;
  std::uint8_t* free_row = tile_free_.data() + static_cast<std::size_t>(ty) * tiles_x_;
  std::fill(free_row, free_row + tiles_x_, 1);
  for (int y = std::max(0, ty - r); y <= std::min(tiles_y_ - 1, ty + r); ++y) {
    const std::uint8_t* near = tile_scratch_.data() + static_cast<std::size_t>(y) * tiles_x_;
    for (int tx = 0; tx < tiles_x_; ++tx) free_row[tx] &= near[tx] ^ 1;
  }
  if (rate_q17_ == 0) return;
  const int c = channels_;
  const auto gain_q8 = static_cast<std::uint16_t>(gain_q8_);
  const auto rate_q17 = static_cast<std::int16_t>(rate_q17_);
  // Each row adapts in one frame out of kAdaptInterleave.
  const int phase = static_cast<int>(frames_applied_ % kAdaptInterleave);
  const int v0 = ty * kTile;
  const int v1 = std::min(height_, v0 + kTile);
  for (int v = v0 + (phase - v0 % kAdaptInterleave + kAdaptInterleave) % kAdaptInterleave; v < v1;
       v += kAdaptInterleave) {
    const std::size_t row = static_cast<std::size_t>(v) * width_ * c;
    int tx = 0;
    while (tx < tiles_x_) {
      if (free_row[tx] == 0) {
        ++tx;
        continue;
      }
      const int start = tx;
      while (tx < tiles_x_ && free_row[tx] != 0) ++tx;
      const int u0 = start * kTile;
      const int u1 = std::min(tx * kTile, width_);
      const std::size_t i = row + static_cast<std::size_t>(u0) * c;
      AdaptSpan(frame + i, mean_high_.data() + i, mean_low_.data() + i, (u1 - u0) * c, gain_q8,
                rate_q17);
    }
  }
}

}  // namespace hg::silhouette
