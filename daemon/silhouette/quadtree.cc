#include "silhouette/quadtree.h"

#include <algorithm>
#include <atomic>
#include <cstring>

#include <emmintrin.h>

#include "common/check.h"
#include "common/limits.h"

namespace hg::silhouette {
namespace {

constexpr std::uint64_t kByteRepeat = 0x0101010101010101ULL;

// Bits of a tile covered by columns [c0, c1] and rows [r0, r1] (0..7, inclusive).
inline std::uint64_t TileMask(int c0, int c1, int r0, int r1) {
  const std::uint64_t cols = ((1ULL << (c1 - c0 + 1)) - 1) << c0;
  const int rows = r1 - r0 + 1;
  const std::uint64_t row_sel = (rows == 8 ? ~0ULL : ((1ULL << (8 * rows)) - 1)) << (8 * r0);
  return (cols * kByteRepeat) & row_sel;
}

// Bits of tile (tx, ty) that lie inside `rect` (which must overlap the tile).
inline std::uint64_t RectBitsInTile(const geometry::PixelRect& rect, int tx, int ty) {
  const int x0 = tx * 8, y0 = ty * 8;
  return TileMask(std::max(rect.u0, x0) - x0, std::min(rect.u1, x0 + 7) - x0,
                  std::max(rect.v0, y0) - y0, std::min(rect.v1, y0 + 7) - y0);
}

// Cover bits of the foreground word `w` restricted to the mask bits `m`.
inline std::uint8_t CoverOfBits(std::uint64_t w, std::uint64_t m) {
  return static_cast<std::uint8_t>(((w & m) != 0 ? 2 : 0) | ((~w & m) != 0 ? 1 : 0));
}

inline std::uint8_t CoverOf(std::uint64_t word, std::uint64_t valid) {
  const std::uint64_t fg = word & valid;
  return static_cast<std::uint8_t>((fg != 0 ? 2 : 0) | (fg != valid ? 1 : 0));
}

}  // namespace

namespace {

std::uint64_t NewQuadtreeId() {
  static std::atomic<std::uint64_t> next{1};
  return next.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace

SilhouetteQuadtree::SilhouetteQuadtree(const SilhouetteQuadtree& other)
    : width_(other.width_),
      height_(other.height_),
      tiles_w_(other.tiles_w_),
      tiles_h_(other.tiles_h_),
      version_(other.version_),
      id_(NewQuadtreeId()),
      words_(other.words_),
      changed_(other.changed_),
      valid_(other.valid_),
      levels_(other.levels_),
      sums_(other.sums_) {}

SilhouetteQuadtree& SilhouetteQuadtree::operator=(const SilhouetteQuadtree& other) {
  if (this != &other) {
    *this = SilhouetteQuadtree(other);  // A copy with a new id, moved in.
  }
  return *this;
}

SilhouetteQuadtree::SilhouetteQuadtree(int width, int height)
    : width_(width),
      height_(height),
      tiles_w_((width + 7) / 8),
      tiles_h_((height + 7) / 8),
      id_(NewQuadtreeId()) {
  HG_CHECK(width > 0 && height > 0);
  const std::size_t tiles = static_cast<std::size_t>(tiles_w_) * tiles_h_;
  // Two of sums_'s 21-bit counts are added before one is subtracted (TileSum):
  // up to 2^20 tiles, an image of about 8000 x 8000 pixels (the camera
  // loaders refuse larger ones).
  HG_CHECK(common::ImageFits(width, height));
  HG_CHECK(tiles <= static_cast<std::size_t>(common::kMaxImageTiles));
  words_.assign(tiles, 0);
  changed_.assign(tiles, 0);
  valid_.assign(tiles, 0);
  sums_.assign(static_cast<std::size_t>(tiles_w_ + 1) * (tiles_h_ + 1), 0);
  for (int ty = 0; ty < tiles_h_; ++ty) {
    for (int tx = 0; tx < tiles_w_; ++tx) {
      valid_[ty * tiles_w_ + tx] =
          TileMask(0, std::min(7, width_ - 1 - tx * 8), 0, std::min(7, height_ - 1 - ty * 8));
    }
  }
  int w = tiles_w_;
  int h = tiles_h_;
  int shift = 0;
  for (;;) {
    const std::size_t n = static_cast<std::size_t>(w) * h;
    levels_.push_back(
        Level{w, h, shift, std::vector<std::uint8_t>(n), std::vector<std::uint64_t>(n, 0)});
    if (w == 1 && h == 1) break;
    w = (w + 1) / 2;
    h = (h + 1) / 2;
    ++shift;
  }
  MarkAllChanged();
}

void SilhouetteQuadtree::Build(const common::ImageViewU8& mask, std::uint8_t threshold) {
  HG_CHECK(mask.width == width_ && mask.height == height_);
  const bool first = version_ == 0;
  ++version_;
  // x > threshold for unsigned bytes, as a signed compare after flipping the top bit.
  const __m128i bias = _mm_set1_epi8(static_cast<char>(0x80));
  const __m128i thr = _mm_set1_epi8(static_cast<char>(threshold ^ 0x80));
  const int full_chunks = width_ / 16;
  for (int ty = 0; ty < tiles_h_; ++ty) {
    std::uint64_t* row_changed = changed_.data() + static_cast<std::size_t>(ty) * tiles_w_;
    // The new words are assembled into changed_ first, then swapped with the old.
    std::memset(row_changed, 0, sizeof(std::uint64_t) * tiles_w_);
    const int rows = std::min(8, height_ - ty * 8);
    for (int r = 0; r < rows; ++r) {
      const std::uint8_t* px = mask.Row(ty * 8 + r);
      const int shift = 8 * r;
      int chunk = 0;
      for (; chunk < full_chunks; ++chunk) {
        const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(px + chunk * 16));
        const int bits = _mm_movemask_epi8(_mm_cmpgt_epi8(_mm_xor_si128(v, bias), thr));
        row_changed[2 * chunk] |= static_cast<std::uint64_t>(bits & 0xFF) << shift;
        row_changed[2 * chunk + 1] |= static_cast<std::uint64_t>((bits >> 8) & 0xFF) << shift;
      }
      for (int u = chunk * 16; u < width_; ++u) {
        if (px[u] > threshold) row_changed[u >> 3] |= 1ULL << (shift + (u & 7));
      }
    }
    CommitTileRow(ty, first);
  }
  BuildCoarseLevels();
}

void SilhouetteQuadtree::CommitTileRow(int ty, bool first) {
  const std::size_t row = static_cast<std::size_t>(ty) * tiles_w_;
  std::uint64_t* row_words = words_.data() + row;
  std::uint64_t* row_changed = changed_.data() + row;
  const std::uint64_t* row_valid = valid_.data() + row;
  std::uint8_t* cells = levels_[0].cells.data() + row;
  std::uint64_t* changed_at = levels_[0].changed_at.data() + row;
  for (int tx = 0; tx < tiles_w_; ++tx) {
    const std::uint64_t fresh = row_changed[tx];
    const std::uint64_t diff = first ? row_valid[tx] : (fresh ^ row_words[tx]);
    row_words[tx] = fresh;
    row_changed[tx] = diff;
    if (diff != 0) changed_at[tx] = version_;
    cells[tx] =
        static_cast<std::uint8_t>(CoverOf(fresh, row_valid[tx]) | (diff != 0 ? kChangedBit : 0));
  }
}

void SilhouetteQuadtree::MarkAllChanged() {
  for (std::size_t t = 0; t < words_.size(); ++t) {
    changed_[t] = valid_[t];
    levels_[0].cells[t] = static_cast<std::uint8_t>(CoverOf(words_[t], valid_[t]) | kChangedBit);
    levels_[0].changed_at[t] = version_;
  }
  BuildCoarseLevels();
}

void SilhouetteQuadtree::BuildCoarseLevels() {
  BuildSums();
  for (std::size_t k = 1; k < levels_.size(); ++k) {
    const Level& fine = levels_[k - 1];
    Level& coarse = levels_[k];
    for (int y = 0; y < coarse.height; ++y) {
      const int fy0 = 2 * y;
      const bool has_fy1 = fy0 + 1 < fine.height;
      const std::uint8_t* r0 = fine.cells.data() + static_cast<std::size_t>(fy0) * fine.width;
      const std::uint8_t* r1 = has_fy1 ? r0 + fine.width : nullptr;
      std::uint8_t* out = coarse.cells.data() + static_cast<std::size_t>(y) * coarse.width;
      const std::uint64_t* a0 = fine.changed_at.data() + static_cast<std::size_t>(fy0) * fine.width;
      const std::uint64_t* a1 = has_fy1 ? a0 + fine.width : nullptr;
      std::uint64_t* out_at = coarse.changed_at.data() + static_cast<std::size_t>(y) * coarse.width;
      for (int x = 0; x < coarse.width; ++x) {
        const int fx0 = 2 * x;
        const bool has_fx1 = fx0 + 1 < fine.width;
        std::uint8_t c = r0[fx0];
        std::uint64_t at = a0[fx0];
        if (has_fx1) c |= r0[fx0 + 1], at = std::max(at, a0[fx0 + 1]);
        if (r1 != nullptr) {
          c |= r1[fx0];
          at = std::max(at, a1[fx0]);
          if (has_fx1) c |= r1[fx0 + 1], at = std::max(at, a1[fx0 + 1]);
        }
        out[x] = c;
        out_at[x] = at;
      }
    }
  }
}

namespace {
constexpr int kSumBits = 21;
constexpr std::uint64_t kSumField = (std::uint64_t{1} << kSumBits) - 1;
}  // namespace

void SilhouetteQuadtree::BuildSums() {
  const std::size_t stride = static_cast<std::size_t>(tiles_w_) + 1;
  const std::vector<std::uint8_t>& cells = levels_[0].cells;
  for (int ty = 0; ty < tiles_h_; ++ty) {
    const std::uint64_t* above = sums_.data() + static_cast<std::size_t>(ty) * stride;
    std::uint64_t* row = sums_.data() + static_cast<std::size_t>(ty + 1) * stride;
    const std::uint8_t* c = cells.data() + static_cast<std::size_t>(ty) * tiles_w_;
    std::uint64_t run = 0;  // This row's tiles so far; no field exceeds the tile count.
    for (int tx = 0; tx < tiles_w_; ++tx) {
      run += static_cast<std::uint64_t>(c[tx] & 1) |
             (static_cast<std::uint64_t>((c[tx] >> 1) & 1) << kSumBits) |
             (static_cast<std::uint64_t>((c[tx] & kChangedBit) != 0) << (2 * kSumBits));
      row[tx + 1] = above[tx + 1] + run;
    }
  }
}

std::uint64_t SilhouetteQuadtree::TileSum(int tx0, int ty0, int tx1, int ty1) const {
  const std::size_t stride = static_cast<std::size_t>(tiles_w_) + 1;
  const std::uint64_t* top = sums_.data() + static_cast<std::size_t>(ty0) * stride;
  const std::uint64_t* bottom = sums_.data() + static_cast<std::size_t>(ty1 + 1) * stride;
  // Inclusion-exclusion field by field: the additions first, so that no
  // field goes negative on the way.
  return (bottom[tx1 + 1] + top[tx0]) - (top[tx1 + 1] + bottom[tx0]);
}

template <bool kChanged>
std::uint8_t SilhouetteQuadtree::LargeRect(const geometry::PixelRect& rect) const {
  const int tu0 = rect.u0 >> 3, tu1 = rect.u1 >> 3, tv0 = rect.v0 >> 3, tv1 = rect.v1 >> 3;
  // Every tile the rect touches: pure there is pure in the rect.
  const std::uint64_t all = TileSum(tu0, tv0, tu1, tv1);
  if constexpr (kChanged) {
    if (((all >> (2 * kSumBits)) & kSumField) == 0) return 0;
  } else {
    if (((all >> kSumBits) & kSumField) == 0) return 1;  // No tile holds foreground.
    if ((all & kSumField) == 0) return 2;                // No tile holds background.
  }
  // Tiles wholly inside the rect (a tile's pixels beyond the image count as
  // inside): their counts are the rect's own.
  const int ix0 = (rect.u0 & 7) == 0 ? tu0 : tu0 + 1;
  const int ix1 = ((rect.u1 & 7) == 7 || rect.u1 == width_ - 1) ? tu1 : tu1 - 1;
  const int iy0 = (rect.v0 & 7) == 0 ? tv0 : tv0 + 1;
  const int iy1 = ((rect.v1 & 7) == 7 || rect.v1 == height_ - 1) ? tv1 : tv1 - 1;
  const bool interior = ix0 <= ix1 && iy0 <= iy1;
  std::uint8_t acc = 0;
  if (interior) {
    const std::uint64_t in = TileSum(ix0, iy0, ix1, iy1);
    if constexpr (kChanged) {
      if (((in >> (2 * kSumBits)) & kSumField) != 0) return 1;
    } else {
      acc = static_cast<std::uint8_t>(((in & kSumField) != 0 ? 1 : 0) |
                                      (((in >> kSumBits) & kSumField) != 0 ? 2 : 0));
      if (acc == 3) return acc;
    }
  }
  // The border tiles, pixel-exact.
  auto tile = [&](int tx, int ty) {
    const std::size_t t = static_cast<std::size_t>(ty) * tiles_w_ + tx;
    if constexpr (kChanged) {
      return static_cast<std::uint8_t>((changed_[t] & RectBitsInTile(rect, tx, ty)) != 0);
    } else {
      const std::uint8_t cover = levels_[0].cells[t] & 3;
      acc |= cover != 3 ? cover : CoverOfBits(words_[t], RectBitsInTile(rect, tx, ty));
      return static_cast<std::uint8_t>(acc == 3);
    }
  };
  for (int ty = tv0; ty <= tv1; ++ty) {
    const bool middle = interior && ty >= iy0 && ty <= iy1;
    for (int tx = tu0; tx <= tu1; ++tx) {
      if (middle && tx == ix0) tx = ix1 + 1;  // Skip the interior.
      if (tx > tu1) break;
      if (tile(tx, ty) != 0) return kChanged ? 1 : 3;
    }
  }
  return acc;
}

int SilhouetteQuadtree::PushCover(const geometry::PixelRect& rect, Item* stack) const {
  // Start at the finest level where the rect spans at most 2x2 elements
  // instead of descending from the root.
  const int tu0 = rect.u0 >> 3, tu1 = rect.u1 >> 3, tv0 = rect.v0 >> 3, tv1 = rect.v1 >> 3;
  int start = 0;
  const int top = static_cast<int>(levels_.size()) - 1;
  while (start < top &&
         (((tu1 >> start) - (tu0 >> start)) > 1 || ((tv1 >> start) - (tv0 >> start)) > 1)) {
    ++start;
  }
  int sp = 0;
  for (int y = tv1 >> start; y >= (tv0 >> start); --y) {
    for (int x = tu1 >> start; x >= (tu0 >> start); --x) stack[sp++] = {start, x, y};
  }
  return sp;
}

Cover SilhouetteQuadtree::Query(const geometry::PixelRect& rect) const {
  // Footprints of fine octree cells span a few pixels: up to 2x2 tiles are read
  // directly, without the descent.
  const int tu0 = rect.u0 >> 3, tu1 = rect.u1 >> 3, tv0 = rect.v0 >> 3, tv1 = rect.v1 >> 3;
  if (tu1 - tu0 > 1 || tv1 - tv0 > 1) return static_cast<Cover>(LargeRect<false>(rect));
  std::uint8_t acc = 0;
  for (int ty = tv0; ty <= tv1; ++ty) {
    for (int tx = tu0; tx <= tu1; ++tx) {
      const std::size_t t = static_cast<std::size_t>(ty) * tiles_w_ + tx;
      const std::uint8_t cover = levels_[0].cells[t] & 3;
      // A pure tile's part of the rect is pure too; a mixed one is read bit by bit.
      acc |= cover != 3 ? cover : CoverOfBits(words_[t], RectBitsInTile(rect, tx, ty));
      if (acc == 3) return Cover::kMixed;
    }
  }
  return static_cast<Cover>(acc);
}

bool SilhouetteQuadtree::AnyChanged(const geometry::PixelRect& rect) const {
  const int tu0 = rect.u0 >> 3, tu1 = rect.u1 >> 3, tv0 = rect.v0 >> 3, tv1 = rect.v1 >> 3;
  if (tu1 - tu0 > 1 || tv1 - tv0 > 1) return LargeRect<true>(rect) != 0;
  for (int ty = tv0; ty <= tv1; ++ty) {
    for (int tx = tu0; tx <= tu1; ++tx) {
      const std::size_t t = static_cast<std::size_t>(ty) * tiles_w_ + tx;
      if ((changed_[t] & RectBitsInTile(rect, tx, ty)) != 0) return true;
    }
  }
  return false;
}

bool SilhouetteQuadtree::ChangedSince(const geometry::PixelRect& rect,
                                      std::uint64_t version) const {
  Item stack[kStackSize];
  int sp = PushCover(rect, stack);
  const int tu0 = rect.u0 >> 3, tu1 = rect.u1 >> 3, tv0 = rect.v0 >> 3, tv1 = rect.v1 >> 3;
  while (sp > 0) {
    const Item it = stack[--sp];
    const Level& lv = levels_[it.level];
    if (lv.changed_at[static_cast<std::size_t>(it.y) * lv.width + it.x] <= version) continue;
    // Tiles count whole; a coarser element only when the rect holds it.
    if (it.level == 0) return true;
    const int side = 8 << lv.shift;
    const int ex0 = it.x * side;
    const int ey0 = it.y * side;
    if (ex0 >= rect.u0 && ey0 >= rect.v0 && ex0 + side - 1 <= rect.u1 &&
        ey0 + side - 1 <= rect.v1) {
      return true;
    }
    // Children whose tiles overlap the rect's tiles.
    const int fl = it.level - 1;
    const Level& fine = levels_[fl];
    for (int fy = std::max(2 * it.y, tv0 >> fl); fy <= std::min(2 * it.y + 1, tv1 >> fl); ++fy) {
      for (int fx = std::max(2 * it.x, tu0 >> fl); fx <= std::min(2 * it.x + 1, tu1 >> fl); ++fx) {
        if (fx < fine.width && fy < fine.height) stack[sp++] = {fl, fx, fy};
      }
    }
  }
  return false;
}

bool SilhouetteQuadtree::IsForeground(int u, int v) const {
  const std::size_t t = static_cast<std::size_t>(v >> 3) * tiles_w_ + (u >> 3);
  return ((words_[t] >> ((v & 7) * 8 + (u & 7))) & 1) != 0;
}

}  // namespace hg::silhouette
