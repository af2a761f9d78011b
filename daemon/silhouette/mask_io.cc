#include "silhouette/mask_io.h"

#include <cstring>
#include <filesystem>

#include <opencv2/imgcodecs.hpp>

#include "common/config_error.h"

namespace hg::silhouette {

common::ImageU8 ReadGreyImage(const std::string& path) {
  if (!std::filesystem::exists(path))
    throw common::ConfigError(path + ": cannot open: no such file");
  const cv::Mat m = cv::imread(path, cv::IMREAD_GRAYSCALE);
  if (m.empty() || m.type() != CV_8UC1) {
    throw common::ConfigError(path + ": not a readable 8-bit image");
  }
  common::ImageU8 out(m.cols, m.rows);
  for (int v = 0; v < m.rows; ++v) {
    std::memcpy(&out.At(0, v), m.ptr<std::uint8_t>(v), static_cast<std::size_t>(m.cols));
  }
  return out;
}

void WriteGreyImage(const std::string& path, const common::ImageU8& image) {
  const cv::Mat m(image.height, image.width, CV_8UC1,
                  const_cast<std::uint8_t*>(image.pixels.data()));
  bool ok = false;
  try {
    ok = cv::imwrite(path, m);
  } catch (const cv::Exception& e) {
    ok = false;
  }
  if (!ok) throw common::ConfigError(path + ": cannot write image");
}

}  // namespace hg::silhouette
