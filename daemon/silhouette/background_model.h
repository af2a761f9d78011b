#pragma once
/// @file
/// Per-camera background model: colour (or grey) frame -> conservative
/// foreground mask. Learns the empty cell at start-up, follows global light
/// changes with one gain per frame, adapts slowly to local light changes only
/// far from foreground, and never learns a person it has seen as foreground
/// who stands still (what it cannot tell from the empty cell: docs/cameras.md,
/// "The background model: what it cannot see").

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "common/image.h"

namespace hg::silhouette {

/// Settings of one camera's background model. Grey levels are 8-bit units.
struct BackgroundModelOptions {
  /// Frames of the empty cell averaged at start-up (and after Reset()).
  int learn_frames = 30;
  /// A pixel is foreground when some channel differs from the expected
  /// background by at least max(min_threshold, noise_sigmas * sigma), sigma
  /// being the pixel's noise learned at start-up (largest over its channels).
  int min_threshold = 18;
  double noise_sigmas = 4.0;
  /// A pixel is also foreground when its texture differs from the
  /// background's, that is when the difference of its two neighbours along
  /// the row, or along the column, differs from the background's (in some
  /// channel, for colour frames) by at least texture_threshold after the
  /// inverse gain (as brightness differences are scaled in dim light), and
  /// by at least noise_sigmas * sqrt(2) * sigma, sigma being the largest
  /// noise of those neighbours, not scaled: a camera's noise does not dim
  /// with the light. Brightness alone misses a person whose colour or grey
  /// matches the background behind them; where the background is textured,
  /// the person hides its texture. 0: off. The pipeline leaves it off for
  /// raw Bayer mosaics (PipelineCamera), whose neighbours are of other
  /// colours. The default leaves room above the noise for the lag of slow
  /// adaptation: at 12, a background of sigma 2 that brightened locally by
  /// 40 levels in 20 s behind a sharp light edge turned foreground tile by
  /// tile, the tiles near foreground, which may not adapt, falling behind
  /// their neighbours.
  int texture_threshold = 14;
  /// Pixels whose threshold would exceed this (flicker, a monitor in view) are
  /// unreliable: always foreground, since nothing can be certified there.
  int max_threshold = 64;
  /// Per-frame blend of the background towards the frame, on background pixels
  /// far from any foreground only (0 disables adaptation); at most 0.25. Each
  /// row is updated every 8th frame at the equivalent rate.
  double adapt_rate = 0.02;
  /// No adaptation within this distance (pixels) of any foreground pixel. The
  /// guard is applied on 8x8 tiles and so reaches at least this far.
  int guard_px = 8;
  /// When false, a pixel darker than the background by a ratio in
  /// [shadow_min_ratio, shadow_max_ratio] with the background's chromaticity
  /// (its brightness ratio alone for grey frames) counts as background.
  bool shadows_are_foreground = true;
  double shadow_min_ratio = 0.45;
  double shadow_max_ratio = 0.95;
  /// Follow global light changes: per frame, one gain (median ratio of frame to
  /// the background learned at start-up, over a sparse sample of pixels that
  /// were far from foreground in the previous frame) scales the background
  /// before comparing. Ratios within 6 % of the last gain outvote the others
  /// whenever at least 1/64 of the sample has one: a change of the light as a
  /// whole moves every ratio, a person entering only theirs. When too few
  /// sample pixels qualify the gain is kept.
  bool compensate_gain = true;
};

/// Throws common::ConfigError ("background: <key>: <problem>") on bad options.
void ValidateBackgroundModelOptions(const BackgroundModelOptions& options);

/// Background subtraction for one camera.
///
/// State per pixel and channel: the background at the reference illumination
/// (the first learning frame) in 8.8 fixed point, and per pixel a threshold.
/// A frame is compared with gain * background, the gain being estimated from
/// the frame; where the light is dimmer than at learning the difference is
/// divided by the gain before the threshold (a person's contrast dims with the
/// light). Foreground pixels and their guard band never adapt, so a person who
/// stays still stays foreground for ever; only background far from any
/// foreground follows slow local light changes.
///
/// Every buffer is allocated at construction; Apply() does not allocate. The
/// first frame after construction or Reset() fixes the format (RGB or grey); a
/// frame of the other format restarts learning.
///
/// Cost (tests/bench/background_bench.cc): about 3 ms per Full HD RGB frame and
/// 1.5 ms per Mono8 frame on one core with AVX2, the texture test included
/// (brightness alone: about 2 and 1 ms); shadows as background add a scalar
/// pass over foreground pixels.
///
/// Thread-compatible (one camera's silhouette worker owns it).
class BackgroundModel {
 public:
  /// Throws common::ConfigError on bad options or a non-positive size.
  BackgroundModel(int width, int height, const BackgroundModelOptions& options);

  /// Feeds one RGB frame and writes the mask (255 foreground, 0 background;
  /// resized to the model's size if needed, which only allocates when it was
  /// not). While learning (the first learn_frames frames) the mask is all
  /// foreground: nothing is certified free before the empty cell is known.
  /// Precondition: the frame has the model's size.
  void Apply(const common::ImageRgb8& frame, common::ImageU8* mask);

  /// Same for Mono8 frames (grey cameras).
  void Apply(const common::ImageU8& frame, common::ImageU8* mask);

  /// True until learn_frames frames were fed since construction or Reset().
  [[nodiscard]] bool learning() const { return frames_learned_ < options_.learn_frames; }
  /// Light gain of the last frame relative to the first learning frame (1
  /// always when compensate_gain is false).
  [[nodiscard]] double gain() const { return gain_; }
  /// Share of foreground pixels in the last mask, [0, 1].
  [[nodiscard]] double foreground_fraction() const { return foreground_fraction_; }

  /// Forgets the background and learns again (after a camera was bumped or
  /// reconnected). Does not allocate.
  void Reset();

  /// Writes the learned background (per pixel and channel its mean, per
  /// pixel its noise) to `path`, through a temporary file renamed over it,
  /// so that a restart can take it up instead of learning a cell that may no
  /// longer be empty. Call it right after learning ended: the means saved are
  /// the empty cell's. `camera_id` names the camera and its calibration
  /// (the pipeline hashes its name, size, intrinsics, distortion and pose);
  /// Load() takes the file up for that camera only.
  /// Returns false with *error set when it cannot. Precondition: !learning().
  bool Save(const std::string& path, std::string* error, std::uint64_t camera_id = 0) const;

  /// Takes up a background written by Save() for a camera of this size: the
  /// model is then learned, with thresholds from its own options (which may
  /// differ from the saver's), and the format (RGB or grey) of the saver's
  /// frames. Returns false with *error set, the model unchanged, when the
  /// file cannot be read, is of another size or is damaged (checksum), or
  /// holds another format than `channels` (3 RGB, 1 grey; 0: either): a
  /// frame of the other format would make the model forget it and learn
  /// afresh, with whoever is in view; or was saved for another `camera_id`
  /// (another camera, or this one calibrated anew: its view has moved).
  bool Load(const std::string& path, std::string* error, int channels = 0,
            std::uint64_t camera_id = 0);

  /// The background of pixel (u, v), channel c (0 for grey), in grey levels at
  /// the reference illumination. For tests and diagnostics.
  [[nodiscard]] double MeanAt(int u, int v, int c) const;
  /// The foreground threshold of pixel (u, v) in grey levels; -1 for an
  /// unreliable pixel (always foreground). Meaningful once learning ended.
  [[nodiscard]] int ThresholdAt(int u, int v) const;
  /// The texture threshold of pixel (u, v) at the reference light, the
  /// larger of BackgroundModelOptions::texture_threshold and its noise bound;
  /// 0 where the texture is not tested (off, the image's outer pixels,
  /// unreliable pixels, a threshold beyond max_threshold). Meaningful once
  /// learning ended.
  [[nodiscard]] int TextureThresholdAt(int u, int v) const;

  /// The 8x8-pixel tiles (ceil(width / 8) per row, row-major) that hold
  /// foreground in the last mask Apply() wrote: every foreground pixel lies in
  /// a non-zero tile (shadows reported as background may leave more tiles
  /// set). Null while learning, when the mask is all foreground.
  [[nodiscard]] const std::uint8_t* foreground_tiles() const {
    return tiles_valid_ ? tile_foreground_.data() : nullptr;
  }

  [[nodiscard]] int width() const { return width_; }
  [[nodiscard]] int height() const { return height_; }
  [[nodiscard]] const BackgroundModelOptions& options() const { return options_; }

 private:
  void ApplyFrame(const std::uint8_t* frame, int channels, common::ImageU8* mask);
  void Learn(const std::uint8_t* frame);
  void FinishLearning();
  /// texture_threshold_ from the thresholds and the learned noise.
  void FinishTextureThresholds(double sigma_per_unit);
  /// Classifies the frame row by row; each 8-row band of tiles adapts as soon
  /// as the bands within its guard are classified, while its rows are still
  /// in cache.
  void Process(const std::uint8_t* frame, std::uint8_t* mask);
  /// Mask row v, this row's tile flags; returns its foreground count.
  int ClassifyRow(int v, const std::uint8_t* frame, std::uint8_t* mask);
  /// With the texture test: row v of frame - gain * mean (signed, per sample),
  /// computed once per frame (rows are classified in order; three are kept).
  const std::int16_t* DiffRow(int v, const std::uint8_t* frame);
  /// The free tiles of tile row ty (foreground of tile rows ty +- guard known)
  /// and the adaptation of its rows.
  void FinishTileRow(int ty, const std::uint8_t* frame);
  /// Median ratio of frame to `reference` (8.8, one entry per sample pixel and
  /// channel) in 1/256 over the gain sample; `all`: every sample pixel, else
  /// only those whose tile was free to adapt last frame. With `near_q8` > 0,
  /// the median of the ratios within kGainWindow of it when enough of them
  /// are (a person covering most of the view, darker or brighter than the
  /// background by more than the window, is then outvoted by the background
  /// still seen instead of setting the gain), else of all of them. Returns 0
  /// when too few sample pixels qualify.
  [[nodiscard]] int EstimateGainQ8(const std::uint8_t* frame, const std::uint16_t* reference,
                                   bool all, int near_q8 = 0);
  /// Copies the background at the sample pixels into `out`.
  void GatherSample(std::vector<std::uint16_t>* out) const;
  /// The background of sample i (pixel * channels + channel), 8.8.
  [[nodiscard]] std::uint16_t Mean(std::size_t i) const {
    return static_cast<std::uint16_t>(mean_high_[i] << 8 | mean_low_[i]);
  }

  int width_ = 0;
  int height_ = 0;
  BackgroundModelOptions options_;
  int channels_ = 0;  ///< 0 until the first frame fixes the format.

  int frames_learned_ = 0;
  int deviation_frames_ = 0;  ///< Learning frames that fed deviation_.
  std::uint64_t frames_applied_ = 0;
  bool tiles_valid_ = false;  ///< tile_foreground_ covers the last mask written.
  double gain_ = 1.0;
  int gain_q8_ = 256;
  // Per-frame constants of Process().
  int dim_gain_q8_ = 256;      ///< min(gain, 1) in 1/256.
  int inverse_gain_q8_ = 256;  ///< 1 / min(gain, 1) in 1/256.
  int rate_q17_ = 0;           ///< Adaptation step: rate / gain in 1/2^17.
  int guard_tiles_ = 1;        ///< guard_px in tiles, rounded up.
  double foreground_fraction_ = 1.0;

  // Per pixel and channel (width * height * 3, interleaved like the frame).
  // The background in 8.8 fixed point, split into its integer and fraction
  // bytes: classifying a frame reads the integer bytes only (half the memory
  // traffic), adaptation both.
  std::vector<std::uint8_t> mean_high_;
  std::vector<std::uint8_t> mean_low_;
  std::vector<std::uint16_t> deviation_;  ///< Learning: sum of |x - mean|, 1/4 grey levels.
  /// Learning: the largest single |x - mean|, grey levels (capped at 255).
  std::vector<std::uint8_t> peak_;
  // Per pixel.
  std::vector<std::uint8_t> threshold_;  ///< Foreground iff max |d| >= this; 0 = always.
  /// With texture_threshold: the noise bound of the texture test, at least
  /// 1 (0: not tested). Empty when off.
  std::vector<std::uint8_t> texture_threshold_;
  // Per 8x8 tile.
  int tiles_x_ = 0;
  int tiles_y_ = 0;
  std::vector<std::uint8_t> tile_foreground_;  ///< Some pixel differs (shadows included).
  std::vector<std::uint8_t> tile_scratch_;     ///< Foreground within the guard along the row.
  std::vector<std::uint8_t> tile_free_;        ///< No foreground within the guard: may adapt.
  // Scratch.
  std::vector<std::uint8_t> row_diff_;          ///< |frame - expected| of one row, per channel.
  std::vector<std::uint8_t> row_texture_;       ///< Colour texture differences of one row.
  std::vector<std::int16_t> diff_rows_;         ///< DiffRow(): three rows, row v in slot v % 3.
  std::array<int, 3> diff_row_of_{-1, -1, -1};  ///< The row each slot holds (-1: none).
  // The gain sample: a sparse, staggered grid of pixels. The gain is measured
  // against the background learned at start-up there, not against the adapted
  // background: measured against itself, gain and background could drift
  // together without bound (any split of a brightness change between them
  // explains the frame), and the pixels that never adapt (under a person)
  // would fall out of step.
  std::vector<std::uint32_t> sample_pixels_;
  std::vector<std::uint16_t> sample_reference_;  ///< Learned background there, 8.8.
  std::vector<std::uint16_t> sample_current_;    ///< Scratch while learning.
  std::vector<std::uint32_t> gain_histogram_;
};

}  // namespace hg::silhouette
