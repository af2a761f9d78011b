#include "silhouette/hole_fill.h"

#include <algorithm>
#include <cstring>

#include "common/check.h"

namespace hg::silhouette {
namespace {

constexpr std::uint64_t kOnes = 0x0101010101010101ULL;
constexpr std::uint64_t kHighs = 0x8080808080808080ULL;

/// Whether some byte of `word` is zero.
bool HasZeroByte(std::uint64_t word) { return ((word - kOnes) & ~word & kHighs) != 0; }

std::uint64_t Load8(const std::uint8_t* p) {
  std::uint64_t word;
  std::memcpy(&word, p, sizeof(word));
  return word;
}

std::uint32_t Find(std::uint32_t* parent, std::uint32_t i) {
  while (parent[i] != i) {
    parent[i] = parent[parent[i]];  // Path halving.
    i = parent[i];
  }
  return i;
}

}  // namespace

int FillEnclosedBackground(common::ImageU8* mask, HoleFillScratch* scratch) {
  HG_CHECK(mask != nullptr && scratch != nullptr);
  const int width = mask->width;
  const int height = mask->height;
  HG_CHECK(width <= 65535);
  HG_CHECK(mask->pixels.size() == static_cast<std::size_t>(width) * height);
  // Below 3 x 3 every pixel lies on the border.
  if (width < 3 || height < 3) return 0;
  HoleFillScratch& s = *scratch;
  const std::size_t capacity =
      std::max(HoleFillScratch::kMinRuns,
               static_cast<std::size_t>(static_cast<double>(width) * height * s.runs_per_pixel));
  if (s.begin.size() < capacity) {
    s.begin.resize(capacity);
    s.end.resize(capacity);
    s.parent.resize(capacity);
    s.outside.resize(capacity);
  }
  if (s.row_first.size() < static_cast<std::size_t>(height) + 1) s.row_first.resize(height + 1);
  std::uint32_t* parent = s.parent.data();
  auto unite = [&](std::uint32_t a, std::uint32_t b) {
    a = Find(parent, a);
    b = Find(parent, b);
    if (a == b) return;
    if (b < a) std::swap(a, b);
    parent[b] = a;
    s.outside[a] |= s.outside[b];
  };

  // The background runs, row by row, each joined with the runs of the row
  // above that it touches along an edge (4-connected).
  std::uint32_t n = 0;
  for (int v = 0; v < height; ++v) {
    s.row_first[v] = n;
    const std::uint8_t* row = mask->pixels.data() + static_cast<std::size_t>(v) * width;
    const bool border_row = v == 0 || v == height - 1;
    int u = 0;
    while (u < width) {
      while (u + 8 <= width && !HasZeroByte(Load8(row + u))) u += 8;
      while (u < width && row[u] != 0) ++u;
      if (u == width) break;
      const int start = u;
      while (u + 8 <= width && Load8(row + u) == 0) u += 8;
      while (u < width && row[u] == 0) ++u;
      if (n == capacity) return -1;
      s.begin[n] = static_cast<std::uint16_t>(start);
      s.end[n] = static_cast<std::uint16_t>(u);
      parent[n] = n;
      s.outside[n] = border_row || start == 0 || u == width ? 1 : 0;
      ++n;
    }
    if (v == 0) continue;
    std::uint32_t a = s.row_first[v - 1];
    const std::uint32_t a_end = s.row_first[v];
    std::uint32_t b = s.row_first[v];
    while (a < a_end && b < n) {
      if (s.begin[a] < s.end[b] && s.begin[b] < s.end[a]) unite(a, b);
      if (s.end[a] < s.end[b]) {
        ++a;
      } else {
        ++b;
      }
    }
  }
  s.row_first[height] = n;

  int filled = 0;
  for (int v = 1; v + 1 < height; ++v) {
    std::uint8_t* row = mask->pixels.data() + static_cast<std::size_t>(v) * width;
    for (std::uint32_t i = s.row_first[v]; i < s.row_first[v + 1]; ++i) {
      if (s.outside[Find(parent, i)] != 0) continue;
      std::memset(row + s.begin[i], 255, s.end[i] - s.begin[i]);
      filled += s.end[i] - s.begin[i];
    }
  }
  return filled;
}

}  // namespace hg::silhouette
