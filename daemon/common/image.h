#pragma once
/// @file
/// Minimal owning and non-owning 8-bit single-channel image types.

#include <cstddef>
#include <cstdint>
#include <vector>

namespace hg::common {

/// Non-owning view of an 8-bit grey image, row-major with a stride in bytes.
/// Thread-compatible; the viewed memory must outlive the view.
struct ImageViewU8 {
  const std::uint8_t* data = nullptr;
  int width = 0;
  int height = 0;
  std::ptrdiff_t stride = 0;  ///< Bytes from one row to the next.

  [[nodiscard]] const std::uint8_t* Row(int v) const { return data + v * stride; }
  [[nodiscard]] std::uint8_t At(int u, int v) const { return Row(v)[u]; }
};

/// Owning 8-bit grey image, tightly packed (stride == width). Thread-compatible.
struct ImageU8 {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> pixels;

  ImageU8() = default;
  ImageU8(int w, int h, std::uint8_t fill = 0)
      : width(w), height(h), pixels(static_cast<std::size_t>(w) * h, fill) {}

  [[nodiscard]] std::uint8_t& At(int u, int v) {
    return pixels[static_cast<std::size_t>(v) * width + u];
  }
  [[nodiscard]] std::uint8_t At(int u, int v) const {
    return pixels[static_cast<std::size_t>(v) * width + u];
  }
  [[nodiscard]] ImageViewU8 View() const { return {pixels.data(), width, height, width}; }
};

/// Grey level (BT.601 luma, 8-bit fixed point) of an R G B pixel.
[[nodiscard]] inline int Luma(const std::uint8_t* rgb) {
  return (77 * rgb[0] + 150 * rgb[1] + 29 * rgb[2]) >> 8;
}

/// Owning 8-bit RGB image, tightly packed, R G B per pixel. Thread-compatible.
struct ImageRgb8 {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> pixels;  ///< 3 * width * height bytes.

  ImageRgb8() = default;
  ImageRgb8(int w, int h) : width(w), height(h), pixels(static_cast<std::size_t>(w) * h * 3, 0) {}

  [[nodiscard]] std::uint8_t* Pixel(int u, int v) {
    return pixels.data() + (static_cast<std::size_t>(v) * width + u) * 3;
  }
  [[nodiscard]] const std::uint8_t* Pixel(int u, int v) const {
    return pixels.data() + (static_cast<std::size_t>(v) * width + u) * 3;
  }
};

}  // namespace hg::common
