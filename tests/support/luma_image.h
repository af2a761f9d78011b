#pragma once
/// @file
/// Grey frames from colour ones, as a grey camera of the same view gives
/// them: the BT.601 luma of each pixel (common::Luma).

#include <cstddef>
#include <cstdint>

#include "common/image.h"

namespace hg::testing {

/// Writes the luma of `rgb` into *grey, resized only when its size differs.
inline void LumaOf(const common::ImageRgb8& rgb, common::ImageU8* grey) {
  if (grey->width != rgb.width || grey->height != rgb.height) {
    *grey = common::ImageU8(rgb.width, rgb.height);
  }
  for (std::size_t p = 0; p < grey->pixels.size(); ++p) {
    grey->pixels[p] = static_cast<std::uint8_t>(common::Luma(rgb.pixels.data() + 3 * p));
  }
}

/// The same, returned.
inline common::ImageU8 LumaOf(const common::ImageRgb8& rgb) {
  common::ImageU8 grey;
  LumaOf(rgb, &grey);
  return grey;
}

}  // namespace hg::testing
