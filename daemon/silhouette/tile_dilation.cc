#include "silhouette/tile_dilation.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>

#include <emmintrin.h>

#include "common/check.h"

namespace hg::silhouette {

namespace {

// Row `in` dilated along itself by r: out[u] = 255 iff some in[u - r .. u + r]
// is non-zero (cut at the ends), 16 pixels at a time inside the row.
void DilateRow(const std::uint8_t* __restrict in, int w, int r, std::uint8_t* __restrict out) {
  auto scalar = [&](int u) {
    std::uint8_t any = 0;
    for (int k = std::max(0, u - r); k <= std::min(w - 1, u + r); ++k) any |= in[k];
    out[u] = any != 0 ? 255 : 0;
  };
  int u = 0;
  for (; u < std::min(r, w); ++u) scalar(u);
  const __m128i zero = _mm_setzero_si128();
  for (; u + 16 + r <= w; u += 16) {
    __m128i any = _mm_loadu_si128(reinterpret_cast<const __m128i*>(in + u - r));
    for (int k = 1 - r; k <= r; ++k) {
      any = _mm_or_si128(any, _mm_loadu_si128(reinterpret_cast<const __m128i*>(in + u + k)));
    }
    // 0 where all were zero, 255 elsewhere.
    const __m128i result = _mm_andnot_si128(_mm_cmpeq_epi8(any, zero), _mm_set1_epi8(-1));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + u), result);
  }
  for (; u < w; ++u) scalar(u);
}

}  // namespace

void DilateSquare(common::ImageU8* mask, int radius_px, std::vector<std::uint8_t>* scratch) {
  const int w = mask->width, h = mask->height, r = radius_px;
  if (r <= 0 || w <= 0 || h <= 0) return;
  // A ring of the 2 r + 1 horizontally dilated rows an output row needs: row
  // v is written once rows up to v + r are in the ring, and the input rows
  // still to be read all lie below v. The ring stays in the first-level cache.
  const int ring = 2 * r + 1;
  const auto ring_bytes = static_cast<std::size_t>(ring) * w;
  if (scratch->size() < ring_bytes) scratch->resize(ring_bytes);
  std::uint8_t* pixels = mask->pixels.data();
  auto ring_row = [&](int v) { return scratch->data() + static_cast<std::size_t>(v % ring) * w; };
  for (int v = 0; v < std::min(r, h); ++v)
    DilateRow(pixels + std::size_t{1} * v * w, w, r, ring_row(v));
  for (int v = 0; v < h; ++v) {
    if (v + r < h) DilateRow(pixels + static_cast<std::size_t>(v + r) * w, w, r, ring_row(v + r));
    const int lo = std::max(0, v - r), hi = std::min(h - 1, v + r);
    std::uint8_t* __restrict out = pixels + static_cast<std::size_t>(v) * w;
    // Row by row: each pass over a cached row, no index arithmetic inside.
    std::memcpy(out, ring_row(lo), static_cast<std::size_t>(w));
    for (int k = lo + 1; k <= hi; ++k) {
      const std::uint8_t* __restrict row = ring_row(k);
      for (int u = 0; u < w; ++u) out[u] |= row[u];
    }
  }
}

TileDilator::TileDilator(int width, int height)
    : width_(width),
      height_(height),
      tiles_x_((width + kTile - 1) / kTile),
      tiles_y_((height + kTile - 1) / kTile),
      tiles_(static_cast<std::size_t>(tiles_x_) * tiles_y_, 0),
      scratch_(tiles_.size(), 0),
      prefix_(static_cast<std::size_t>(std::max(tiles_x_, tiles_y_)) + 1, 0) {}

void TileDilator::Apply(const common::ImageViewU8& mask, int radius_px, common::ImageU8* out) {
  if (out->width != width_ || out->height != height_) *out = common::ImageU8(width_, height_);
  if (radius_px <= 0) {
    for (int v = 0; v < height_; ++v) {
      const std::uint8_t* in = mask.Row(v);
      std::uint8_t* o = out->pixels.data() + static_cast<std::size_t>(v) * width_;
      for (int u = 0; u < width_; ++u) o[u] = in[u] > 127 ? 255 : 0;
    }
    return;
  }
  const std::span<const std::uint8_t> tiles = DilateTiles(mask, radius_px);
  for (int v = 0; v < height_; ++v) {
    const std::uint8_t* tile_row = tiles.data() + static_cast<std::size_t>(v / kTile) * tiles_x_;
    std::uint8_t* o = out->pixels.data() + static_cast<std::size_t>(v) * width_;
    for (int tx = 0; tx < tiles_x_; ++tx) {
      const int u0 = tx * kTile;
      std::memset(o + u0, tile_row[tx] != 0 ? 255 : 0,
                  static_cast<std::size_t>(std::min(kTile, width_ - u0)));
    }
  }
}

std::span<const std::uint8_t> TileDilator::DilateTiles(const common::ImageViewU8& mask,
                                                       int radius_px) {
  HG_CHECK(radius_px > 0 && mask.width == width_ && mask.height == height_);
  // Tile map: a tile is foreground when any of its pixels is (> 127, i.e. its
  // top bit is set: eight pixels are tested with one word).
  std::fill(tiles_.begin(), tiles_.end(), 0);
  const int full_words = width_ / kTile;
  for (int v = 0; v < height_; ++v) {
    const std::uint8_t* in = mask.Row(v);
    std::uint8_t* tile_row = tiles_.data() + static_cast<std::size_t>(v / kTile) * tiles_x_;
    for (int w = 0; w < full_words; ++w) {
      std::uint64_t word;
      std::memcpy(&word, in + w * kTile, sizeof(word));
      tile_row[w] |= static_cast<std::uint8_t>((word & 0x8080808080808080ULL) != 0);
    }
    for (int u = full_words * kTile; u < width_; ++u) {
      tile_row[u / kTile] |= static_cast<std::uint8_t>(in[u] > 127);
    }
  }
  // Pixels within radius_px of each other lie in tiles at most
  // radius_px / 8 + 1 apart. Separable box dilation by prefix counts.
  const int r = radius_px / kTile + 1;
  for (int ty = 0; ty < tiles_y_; ++ty) {
    const std::uint8_t* row = tiles_.data() + static_cast<std::size_t>(ty) * tiles_x_;
    std::uint8_t* dst = scratch_.data() + static_cast<std::size_t>(ty) * tiles_x_;
    prefix_[0] = 0;
    for (int tx = 0; tx < tiles_x_; ++tx) prefix_[tx + 1] = prefix_[tx] + row[tx];
    for (int tx = 0; tx < tiles_x_; ++tx) {
      const int lo = std::max(0, tx - r);
      const int hi = std::min(tiles_x_, tx + r + 1);
      dst[tx] = static_cast<std::uint8_t>(prefix_[hi] - prefix_[lo] > 0);
    }
  }
  for (int tx = 0; tx < tiles_x_; ++tx) {
    prefix_[0] = 0;
    for (int ty = 0; ty < tiles_y_; ++ty) {
      prefix_[ty + 1] = prefix_[ty] + scratch_[static_cast<std::size_t>(ty) * tiles_x_ + tx];
    }
    for (int ty = 0; ty < tiles_y_; ++ty) {
      const int lo = std::max(0, ty - r);
      const int hi = std::min(tiles_y_, ty + r + 1);
      tiles_[static_cast<std::size_t>(ty) * tiles_x_ + tx] =
          static_cast<std::uint8_t>(prefix_[hi] - prefix_[lo] > 0);
    }
  }
  return tiles_;
}

int CoveringRadiusPx(const geometry::CameraModel& pinhole, double distance_m, double min_depth_m) {
  if (distance_m <= 0.0) return 0;
  if (distance_m >= min_depth_m) return -1;
  const double fx = pinhole.K(0, 0);
  const double fy = pinhole.K(1, 1);
  const double cx = pinhole.K(0, 2);
  const double cy = pinhole.K(1, 2);
  double tan_max = 0.0;
  for (const double u : {0.0, static_cast<double>(pinhole.width)}) {
    for (const double v : {0.0, static_cast<double>(pinhole.height)}) {
      tan_max = std::max(tan_max, std::hypot((u - cx) / fx, (v - cy) / fy));
    }
  }
  const double delta = std::asin(distance_m / min_depth_m);
  const double theta = std::atan(tan_max) + delta;
  if (theta >= std::numbers::pi / 2 - 1e-3) return -1;
  const double sec = 1.0 / std::cos(theta);
  return static_cast<int>(std::ceil(std::max(fx, fy) * delta * sec * sec)) + 1;
}

}  // namespace hg::silhouette
