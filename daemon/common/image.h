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

}  // namespace hg::common
