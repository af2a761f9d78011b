#include "silhouette/mask_io.h"

#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/config_error.h"
#include "common/input_file.h"

namespace hg::silhouette {

namespace {

// The image file at `path` decoded with `flags`; empty when it is cut short
// or no image. Missing, a folder or unreadable: ConfigError naming it.
cv::Mat Decode(const std::string& path, int flags) {
  std::string bytes = common::ReadInputFile(path, "image", std::ios::binary);
  if (bytes.empty() || !common::IsCompleteImage(bytes)) return {};
  if (!common::IsTrustedImageFormat(bytes)) {
    throw common::ConfigError(path + ": not an image format read reliably (use " +
                              common::kTrustedImageFormats + ")");
  }
  if (IndexesPastItsPalette(bytes)) return {};
  const cv::Mat encoded(1, static_cast<int>(bytes.size()), CV_8UC1, bytes.data());
  try {
    return cv::imdecode(encoded, flags);
  } catch (const cv::Exception&) {
    return {};
  }
}

}  // namespace

bool IndexesPastItsPalette(std::string_view encoded) {
  std::optional<std::string> white = common::WithPaletteFilled(encoded, 255);
  if (!white) return false;
  std::optional<std::string> black = common::WithPaletteFilled(encoded, 0);
  const auto decode = [](std::string& bytes) {
    try {
      return cv::imdecode(cv::Mat(1, static_cast<int>(bytes.size()), CV_8UC1, bytes.data()),
                          cv::IMREAD_UNCHANGED);
    } catch (const cv::Exception&) {
      return cv::Mat();
    }
  };
  const cv::Mat w = decode(*white), k = decode(*black);
  return w.empty() || w.size() != k.size() || w.type() != k.type() ||
         cv::norm(w, k, cv::NORM_INF) != 0.0;
}

common::ImageU8 ReadGreyImage(const std::string& path) {
  // ANYDEPTH keeps a 16-bit image 16-bit, refused below: a plain GRAYSCALE read
  // would scale it to 8 bits, so 255 would read as 0 (foreground as background).
  const cv::Mat m = Decode(path, cv::IMREAD_GRAYSCALE | cv::IMREAD_ANYDEPTH);
  if (m.empty() || m.type() != CV_8UC1) {
    throw common::ConfigError(path + ": not a readable 8-bit image");
  }
  common::ImageU8 out(m.cols, m.rows);
  for (int v = 0; v < m.rows; ++v) {
    std::memcpy(&out.At(0, v), m.ptr<std::uint8_t>(v), static_cast<std::size_t>(m.cols));
  }
  return out;
}

namespace {

void WriteMat(const std::string& path, const cv::Mat& m) {
  bool ok = false;
  try {
    // Fast PNG compression: synthetic sequences write hundreds of frames.
    ok = cv::imwrite(path, m, {cv::IMWRITE_PNG_COMPRESSION, 1});
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok) throw common::ConfigError(path + ": cannot write image");
}

}  // namespace

void WriteGreyImage(const std::string& path, const common::ImageU8& image) {
  const cv::Mat m(image.height, image.width, CV_8UC1,
                  const_cast<std::uint8_t*>(image.pixels.data()));
  WriteMat(path, m);
}

common::ImageRgb8 ReadRgbImage(const std::string& path) {
  const cv::Mat bgr = Decode(path, cv::IMREAD_COLOR | cv::IMREAD_ANYDEPTH);
  if (bgr.empty() || bgr.type() != CV_8UC3) {
    throw common::ConfigError(path + ": not a readable 8-bit image");
  }
  common::ImageRgb8 out(bgr.cols, bgr.rows);
  cv::Mat rgb(bgr.rows, bgr.cols, CV_8UC3, out.pixels.data());
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  return out;
}

void WriteRgbImage(const std::string& path, const common::ImageRgb8& image) {
  const cv::Mat rgb(image.height, image.width, CV_8UC3,
                    const_cast<std::uint8_t*>(image.pixels.data()));
  cv::Mat bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  WriteMat(path, bgr);
}

}  // namespace hg::silhouette
