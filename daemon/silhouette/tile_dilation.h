#pragma once
/// @file
/// Conservative, cheap dilation of silhouette masks at 8x8-tile granularity.

#include <cstdint>
#include <span>
#include <vector>

#include "common/image.h"
#include "geometry/camera.h"

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

/// Grows the foreground of a mask by at least `radius_px` pixels in every
/// direction (Chebyshev distance, so it also covers the Euclidean disc), at
/// the granularity of 8x8 tiles: the result is foreground on every tile within
/// radius_px / 8 + 1 tiles of a tile holding any foreground pixel. It never
/// shrinks the foreground and overshoots by less than two tiles. Cost is one
/// pass over the mask plus a pass over the tile map, independent of the radius.
///
/// Thread-compatible; buffers are sized at construction, Apply() does not
/// allocate once the output has the mask's size.
class TileDilator {
 public:
  static constexpr int kTile = 8;

  TileDilator(int width, int height);

  /// Writes the dilated mask (255 foreground, 0 background; input foreground
  /// iff > 127) to *out. radius_px <= 0 copies the mask as it is. With
  /// radius_px > 0, what lies beyond the image's edges counts as foreground
  /// (nothing was seen there, and an object just outside may have moved in):
  /// pixels within the radius of an edge are foreground too.
  void Apply(const common::ImageViewU8& mask, int radius_px, common::ImageU8* out);

  /// The same dilation as a tile map, without writing pixels: one byte per
  /// tile, row-major, (width + 7) / 8 by (height + 7) / 8, non-zero where the
  /// dilated mask is foreground (SilhouetteQuadtree::BuildFromTiles() reads
  /// it). `seeds` (empty, or one byte per tile): tiles taken as foreground
  /// before dilating, such as those where an obstacle may hide someone.
  /// Precondition: radius_px > 0. Valid until the next call.
  [[nodiscard]] std::span<const std::uint8_t> DilateTiles(const common::ImageViewU8& mask,
                                                          int radius_px,
                                                          std::span<const std::uint8_t> seeds = {});

  /// Tiles (as DilateTiles' map) holding a pixel where `pixel_set` is true.
  template <class PixelSet>
  [[nodiscard]] std::vector<std::uint8_t> TilesWhere(PixelSet pixel_set) const {
    std::vector<std::uint8_t> tiles(tiles_.size(), 0);
    for (int v = 0; v < height_; ++v) {
      for (int u = 0; u < width_; ++u) {
        if (pixel_set(u, v)) tiles[static_cast<std::size_t>(v / kTile) * tiles_x_ + u / kTile] = 1;
      }
    }
    return tiles;
  }

 private:
  int width_, height_, tiles_x_, tiles_y_;
  std::vector<std::uint8_t> tiles_, scratch_;
  std::vector<int> prefix_;
};

/// Pixel radius that covers every point within `distance_m` of a foreground
/// point, for points at least `min_depth_m` from the camera centre, anywhere
/// in the image of the pinhole camera: f * delta * sec^2(theta_max + delta)
/// with delta = asin(distance_m / min_depth_m) the angle the distance can
/// subtend and theta_max the angle of the farthest image corner. Returns
/// a negative value when the distance subtends 90 degrees or more (no finite
/// dilation covers it: the camera must not certify anything).
[[nodiscard]] int CoveringRadiusPx(const geometry::CameraModel& pinhole, double distance_m,
                                   double min_depth_m);

}  // namespace hg::silhouette
