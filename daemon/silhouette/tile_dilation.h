#pragma once
/// @file
/// Pixel-exact square dilation of silhouette masks (the background model's
/// foreground growth), with work limited to the tiles near foreground.

#include <cstdint>
#include <vector>

#include "common/image.h"

namespace hg::silhouette {

/// Grows the foreground of `mask` (non-zero) in place to every pixel within
/// Chebyshev distance `radius_px` of it, pixel-exact: a (2 r + 1)^2 square,
/// cut at the image border, as cv::dilate with its default 3x3 kernel
/// applied r times. Foreground becomes 255. Separable, in one pass over the
/// mask; `scratch` holds 2 r + 1 rows and maps of tiles and allocates only
/// when it is too small for them, so a per-frame call with a kept scratch
/// does not allocate.
///
/// `tiles`, when given, flags the 8x8-pixel tiles of the mask (ceil(width /
/// 8) per row, ceil(height / 8) rows, row-major) that may hold foreground:
/// every non-zero pixel must lie in a flagged tile (more may be flagged). Only
/// pixels within reach of a flagged tile are then read or written, the cost
/// following the foreground instead of the image.
struct DilateScratch {
  std::vector<std::uint8_t> rows;    ///< The ring of horizontally dilated rows.
  std::vector<std::uint8_t> tiles;   ///< Tile maps.
  std::vector<std::uint32_t> runs;   ///< Runs of tiles, as pixel columns.
  std::vector<std::uint32_t> first;  ///< Per tile map and tile row: its first run.
};
void DilateSquare(common::ImageU8* mask, int radius_px, DilateScratch* scratch,
                  const std::uint8_t* tiles = nullptr);

}  // namespace hg::silhouette
