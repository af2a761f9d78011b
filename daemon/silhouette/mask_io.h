#pragma once
/// @file
/// Reading and writing grey images (masks) and RGB frames as PNG files.

#include <string>

#include "common/image.h"

namespace hg::silhouette {

/// Reads an 8-bit grey image (colour images are converted to grey).
/// @throws common::ConfigError naming the file when it is missing or not an image.
[[nodiscard]] common::ImageU8 ReadGreyImage(const std::string& path);

/// Writes an 8-bit grey image; the format follows the extension (.png, .pgm).
/// @throws common::ConfigError naming the file when it cannot be written.
void WriteGreyImage(const std::string& path, const common::ImageU8& image);

/// Reads an 8-bit colour image as RGB (grey images are expanded).
/// @throws common::ConfigError naming the file when it is missing or not an image.
[[nodiscard]] common::ImageRgb8 ReadRgbImage(const std::string& path);

/// Writes an RGB image; the format follows the extension (.png, .ppm).
/// @throws common::ConfigError naming the file when it cannot be written.
void WriteRgbImage(const std::string& path, const common::ImageRgb8& image);

}  // namespace hg::silhouette
