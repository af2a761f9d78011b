#include "silhouette/tile_dilation.h"

#include <gtest/gtest.h>

#include <random>

#include <opencv2/imgproc.hpp>

#include "support/random_scene.h"

namespace hg::silhouette {
namespace {

// Pixel-exact against OpenCV's dilation (the 3x3 square applied r times) on
// random sparse masks of odd sizes, foreground at the borders included.
TEST(DilateSquare, EqualsOpenCvsIteratedSquareDilation) {
  std::mt19937 rng(17);
  DilateScratch scratch;
  for (int trial = 0; trial < testing::SoakSeeds(80); ++trial) {
    const int w = 1 + static_cast<int>(rng() % 233), h = 1 + static_cast<int>(rng() % 61);
    const int r = static_cast<int>(rng() % 13);  // Beyond one tile too.
    // Dense, and sparse enough that most tiles hold no foreground.
    const unsigned density = trial % 2 == 0 ? 23 : 900;
    common::ImageU8 mask(w, h, 0);
    for (std::uint8_t& p : mask.pixels)
      p = rng() % density == 0 ? static_cast<std::uint8_t>(1 + rng() % 255) : 0;
    cv::Mat expected(h, w, CV_8UC1);
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) expected.at<std::uint8_t>(v, u) = mask.At(u, v) != 0 ? 255 : 0;
    }
    if (r > 0) cv::dilate(expected, expected, cv::Mat(), cv::Point(-1, -1), r);
    // Three ways: the whole image, the tiles holding foreground, and those
    // plus random others (a superset is allowed).
    const int tx_n = (w + 7) / 8, ty_n = (h + 7) / 8;
    std::vector<std::uint8_t> exact(static_cast<std::size_t>(tx_n) * ty_n, 0);
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        if (mask.At(u, v) != 0) exact[static_cast<std::size_t>(v / 8) * tx_n + u / 8] = 1;
      }
    }
    std::vector<std::uint8_t> superset = exact;
    for (std::uint8_t& t : superset) t = t != 0 || rng() % 5 == 0 ? 1 : 0;
    const std::uint8_t* maps[] = {nullptr, exact.data(), superset.data()};
    const common::ImageU8 input = mask;
    for (const std::uint8_t* tiles : maps) {
      common::ImageU8 got_mask = input;
      DilateSquare(&got_mask, r, &scratch, tiles);
      for (int v = 0; v < h; ++v) {
        for (int u = 0; u < w; ++u) {
          // r = 0 leaves the mask as it was (non-zero, not 255).
          const int got = r == 0 ? (got_mask.At(u, v) != 0 ? 255 : 0) : got_mask.At(u, v);
          ASSERT_EQ(got, expected.at<std::uint8_t>(v, u))
              << "trial " << trial << " (" << u << ", " << v << ") r " << r << " tiles "
              << (tiles == nullptr        ? "none"
                  : tiles == exact.data() ? "exact"
                                          : "superset");
        }
      }
    }
  }
}

}  // namespace
}  // namespace hg::silhouette
