#pragma once
/// @file
/// Reading and writing grey images (masks) and RGB frames as PNG files.

#include <string>
#include <string_view>

#include "common/image.h"

namespace hg::silhouette {

/// Whether an encoded palette image (PNG, BMP) has pixels that index colours
/// past its palette. Decoders read them as black without a word (in a mask:
/// background, a person there free), so the image is damaged. False for an
/// image without a palette or with a full one. The image is decoded twice,
/// with the missing colours filled white and black (common::WithPaletteFilled).
[[nodiscard]] bool IndexesPastItsPalette(std::string_view encoded);

/// Reads an 8-bit grey image (colour images are converted to grey).
/// @throws common::ConfigError naming the file when it is missing, not an
/// image or damaged (IndexesPastItsPalette).
[[nodiscard]] common::ImageU8 ReadGreyImage(const std::string& path);

/// Writes an 8-bit grey image; the format follows the extension (.png, .pgm).
/// @throws common::ConfigError naming the file when it cannot be written.
void WriteGreyImage(const std::string& path, const common::ImageU8& image);

/// Reads an 8-bit colour image as RGB (grey images are expanded).
/// @throws common::ConfigError naming the file when it is missing, not an
/// image or damaged (IndexesPastItsPalette).
[[nodiscard]] common::ImageRgb8 ReadRgbImage(const std::string& path);

/// Writes an RGB image; the format follows the extension (.png, .ppm).
/// @throws common::ConfigError naming the file when it cannot be written.
void WriteRgbImage(const std::string& path, const common::ImageRgb8& image);

}  // namespace hg::silhouette
