#include "silhouette/tile_dilation.h"

#include <algorithm>
#include <cstring>

#include <emmintrin.h>

#include "common/check.h"

namespace hg::silhouette {

namespace {

constexpr int kDilateTile = 8;  // The tiles of DilateSquare's `tiles`.

// Row `in` dilated along itself by r over columns [u0, u1): out[u] = 255 iff
// some in[u - r .. u + r] is non-zero (cut at the row's ends), 16 pixels at a
// time away from the ends.
void DilateRow(const std::uint8_t* __restrict in, int w, int r, int u0, int u1,
               std::uint8_t* __restrict out) {
  auto scalar = [&](int u) {
    std::uint8_t any = 0;
    for (int k = std::max(0, u - r); k <= std::min(w - 1, u + r); ++k) any |= in[k];
    out[u] = any != 0 ? 255 : 0;
  };
  int u = u0;
  for (; u < std::min(r, u1); ++u) scalar(u);
  const __m128i zero = _mm_setzero_si128();
  for (; u + 16 <= u1 && u + 16 + r <= w; u += 16) {
    __m128i any = _mm_loadu_si128(reinterpret_cast<const __m128i*>(in + u - r));
    for (int k = 1 - r; k <= r; ++k) {
      any = _mm_or_si128(any, _mm_loadu_si128(reinterpret_cast<const __m128i*>(in + u + k)));
    }
    // 0 where all were zero, 255 elsewhere.
    const __m128i result = _mm_andnot_si128(_mm_cmpeq_epi8(any, zero), _mm_set1_epi8(-1));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + u), result);
  }
  for (; u < u1; ++u) scalar(u);
}

}  // namespace

void DilateSquare(common::ImageU8* mask, int radius_px, DilateScratch* scratch,
                  const std::uint8_t* tiles) {
  const int w = mask->width, h = mask->height, r = radius_px;
  if (r <= 0 || w <= 0 || h <= 0) return;
  const int tx_n = (w + kDilateTile - 1) / kDilateTile;
  const int ty_n = (h + kDilateTile - 1) / kDilateTile;
  const auto tile_count = static_cast<std::size_t>(tx_n) * ty_n;
  // A ring of the 2 r + 1 horizontally dilated rows an output row needs: row
  // v is written once rows up to v + r are in the ring, and the input rows
  // still to be read all lie below v. The ring stays in the first-level cache.
  const int ring = 2 * r + 1;
  const auto ring_bytes = static_cast<std::size_t>(ring) * w;
  if (scratch->rows.size() < ring_bytes) scratch->rows.resize(ring_bytes);
  // Two tile maps: `across`, the tiles whose pixel rows may be non-zero after
  // the horizontal pass (a foreground tile within reach along the tile row),
  // and `near`, those that may be after both passes. Each tile row's runs of
  // set tiles, as pixel columns [u0, u1), are listed once per map.
  if (scratch->tiles.size() < 2 * tile_count) scratch->tiles.resize(2 * tile_count);
  const std::size_t max_runs = 2 * static_cast<std::size_t>(ty_n) * ((tx_n + 1) / 2);
  if (scratch->runs.size() < 2 * max_runs) scratch->runs.resize(2 * max_runs);
  const std::size_t row_starts = 2 * (static_cast<std::size_t>(ty_n) + 1);
  if (scratch->first.size() < row_starts) scratch->first.resize(row_starts);
  std::uint8_t* across = scratch->tiles.data();
  std::uint8_t* near = across + tile_count;
  const int reach = (r + kDilateTile - 1) / kDilateTile;  // r in tiles, rounded up.
  for (int ty = 0; ty < ty_n; ++ty) {
    for (int tx = 0; tx < tx_n; ++tx) {
      std::uint8_t any = tiles == nullptr ? 1 : 0;
      for (int k = std::max(0, tx - reach); k <= std::min(tx_n - 1, tx + reach) && any == 0; ++k) {
        any = tiles[static_cast<std::size_t>(ty) * tx_n + k] != 0 ? 1 : 0;
      }
      across[static_cast<std::size_t>(ty) * tx_n + tx] = any;
    }
  }
  for (int ty = 0; ty < ty_n; ++ty) {
    for (int tx = 0; tx < tx_n; ++tx) {
      std::uint8_t any = 0;
      for (int k = std::max(0, ty - reach); k <= std::min(ty_n - 1, ty + reach) && any == 0; ++k) {
        any = across[static_cast<std::size_t>(k) * tx_n + tx];
      }
      near[static_cast<std::size_t>(ty) * tx_n + tx] = any;
    }
  }
  std::uint32_t* runs = scratch->runs.data();
  std::uint32_t* first = scratch->first.data();
  std::size_t n = 0;
  for (int map = 0; map < 2; ++map) {
    for (int ty = 0; ty < ty_n; ++ty) {
      first[map * (ty_n + 1) + ty] = static_cast<std::uint32_t>(n);
      const std::uint8_t* flags = (map == 0 ? across : near) + static_cast<std::size_t>(ty) * tx_n;
      for (int t = 0; t < tx_n;) {
        if (flags[t] == 0) {
          ++t;
          continue;
        }
        const int start = t;
        while (t < tx_n && flags[t] != 0) ++t;
        runs[n++] = static_cast<std::uint32_t>(start * kDilateTile);
        runs[n++] = static_cast<std::uint32_t>(std::min(w, t * kDilateTile));
      }
    }
    first[map * (ty_n + 1) + ty_n] = static_cast<std::uint32_t>(n);
  }
  // Calls f(u0, u1) for the runs of map 0 (across) or 1 (near) of pixel row v.
  auto for_each_run = [&](int map, int v, auto&& f) {
    const std::uint32_t* row_first = first + map * (ty_n + 1) + v / kDilateTile;
    for (std::uint32_t i = row_first[0]; i < row_first[1]; i += 2) {
      f(static_cast<int>(runs[i]), static_cast<int>(runs[i + 1]));
    }
  };
  std::uint8_t* pixels = mask->pixels.data();
  auto ring_row = [&](int v) {
    return scratch->rows.data() + static_cast<std::size_t>(v % ring) * w;
  };
  // Row v's horizontal pass, zero outside the tiles it can reach.
  auto horizontal = [&](int v) {
    std::uint8_t* out = ring_row(v);
    std::memset(out, 0, static_cast<std::size_t>(w));
    const std::uint8_t* in = pixels + static_cast<std::size_t>(v) * w;
    for_each_run(0, v, [&](int u0, int u1) { DilateRow(in, w, r, u0, u1, out); });
  };
  for (int v = 0; v < std::min(r, h); ++v) horizontal(v);
  for (int v = 0; v < h; ++v) {
    if (v + r < h) horizontal(v + r);
    const int lo = std::max(0, v - r), hi = std::min(h - 1, v + r);
    std::uint8_t* __restrict out = pixels + static_cast<std::size_t>(v) * w;
    // Outside `near` the input is zero and so is the result: not written.
    for_each_run(1, v, [&](int u0, int u1) {
      std::memcpy(out + u0, ring_row(lo) + u0, static_cast<std::size_t>(u1 - u0));
      for (int k = lo + 1; k <= hi; ++k) {
        const std::uint8_t* __restrict row = ring_row(k);
        for (int u = u0; u < u1; ++u) out[u] |= row[u];
      }
    });
  }
}

}  // namespace hg::silhouette
