#pragma once
/// @file
/// Conservative undistortion of silhouette masks.

#include <cstdint>
#include <vector>

#include "common/image.h"
#include "geometry/camera.h"
#include "silhouette/quadtree.h"

namespace hg::silhouette {

/// Maps a mask taken through a distorting lens to the ideal pinhole image of the
/// same camera (same K and size), conservatively: an output pixel is foreground
/// when any source pixel that any point of the output pixel may come from is
/// foreground, and also when part of that region lies outside the source image
/// (the camera cannot certify what it does not see).
///
/// Built once per camera (not cheap); Apply() does not allocate when `out` already
/// has the right size. Thread-compatible: Apply() uses scratch of its own, so
/// one undistorter serves one thread at a time (the pipeline has one per camera).
class ConservativeUndistorter {
 public:
  explicit ConservativeUndistorter(const geometry::CameraModel& camera);

  /// `in` is the distorted grey mask (foreground iff value > threshold); `out`
  /// receives 255 for foreground and 0 for background.
  /// Whole 8x8 output tiles whose possible source pixels (the bounding
  /// rectangle of their regions) are all background or all foreground, as the
  /// source's quadtree tells, are written at once; the rest pixel by pixel.
  /// The result equals ApplyPerPixel() bit for bit.
  void Apply(const common::ImageViewU8& in, std::uint8_t threshold, common::ImageU8* out);

  /// The same map, every output pixel on its own: the reference Apply() must
  /// reproduce (tests). Thread-safe.
  void ApplyPerPixel(const common::ImageViewU8& in, std::uint8_t threshold,
                     common::ImageU8* out) const;

  [[nodiscard]] int width() const { return width_; }
  [[nodiscard]] int height() const { return height_; }

 private:
  struct SourceRect {
    std::uint16_t u0, v0, u1, v1;  // Inclusive source pixel rectangle.
  };
  static constexpr std::uint16_t kOutside = 0xFFFF;  // u0 == kOutside: region leaves the image.
  int width_ = 0;
  int height_ = 0;
  static constexpr int kTile = 8;
  void BuildTileRects();
  // 255 when some source pixel of r is foreground (> threshold) or r leaves the image.
  static std::uint8_t PixelValue(const common::ImageViewU8& in, std::uint8_t threshold,
                                 const SourceRect& r);

  std::vector<SourceRect> rects_;  // One per output pixel.
  int tiles_w_ = 0;
  int tiles_h_ = 0;
  // Per 8x8 output tile: the bounding rectangle of its pixels' source
  // regions, or kOutside when one of them leaves the image.
  std::vector<SourceRect> tile_rects_;
  SilhouetteQuadtree source_;  // Apply() scratch: the source mask's quadtree.
};

}  // namespace hg::silhouette
