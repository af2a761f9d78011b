#include "silhouette/hole_fill.h"

#include <gtest/gtest.h>

#include <random>

#include <opencv2/imgproc.hpp>

#include "support/random_scene.h"

namespace hg::silhouette {
namespace {

// The oracle: OpenCV's flood fill (4-connected) of the background from
// outside a one-pixel background frame around the mask; background it does
// not reach is enclosed.
common::ImageU8 Expected(const common::ImageU8& mask) {
  const int w = mask.width, h = mask.height;
  cv::Mat padded(h + 2, w + 2, CV_8UC1, cv::Scalar(0));
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) padded.at<std::uint8_t>(v + 1, u + 1) = mask.At(u, v) != 0 ? 1 : 0;
  }
  cv::floodFill(padded, cv::Point(0, 0), cv::Scalar(2), nullptr, cv::Scalar(0), cv::Scalar(0), 4);
  common::ImageU8 out = mask;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      if (padded.at<std::uint8_t>(v + 1, u + 1) == 0)
        out.pixels[static_cast<std::size_t>(v) * w + u] = 255;
    }
  }
  return out;
}

int Differences(const common::ImageU8& a, const common::ImageU8& b) {
  int n = 0;
  for (std::size_t i = 0; i < a.pixels.size(); ++i) n += a.pixels[i] != b.pixels[i] ? 1 : 0;
  return n;
}

// Pixel-exact against the flood fill on random masks of odd sizes: noise of
// several densities (many small enclosed pockets, and diagonal gaps, which do
// not connect), and rings of random rectangles and discs, open or closed.
TEST(FillEnclosedBackground, EqualsAFloodFillFromTheBorder) {
  std::mt19937 rng(23);
  HoleFillScratch scratch;
  scratch.runs_per_pixel = 1.0;  // Room for the runs of noise.
  int filled_total = 0;
  for (int trial = 0; trial < testing::SoakSeeds(120); ++trial) {
    const int w = 1 + static_cast<int>(rng() % 301), h = 1 + static_cast<int>(rng() % 97);
    common::ImageU8 mask(w, h, 0);
    if (trial % 2 == 0) {
      const unsigned percent = 20 + static_cast<unsigned>(rng() % 60);
      for (std::uint8_t& p : mask.pixels) {
        p = rng() % 100 < percent ? static_cast<std::uint8_t>(1 + rng() % 255) : 0;
      }
    } else {
      cv::Mat m(h, w, CV_8UC1, cv::Scalar(0));
      for (int k = 0; k < 6; ++k) {
        const cv::Point c(static_cast<int>(rng() % w), static_cast<int>(rng() % h));
        const int r = 2 + static_cast<int>(rng() % 30);
        const int thickness = 1 + static_cast<int>(rng() % 3);
        if (rng() % 2 == 0) {
          cv::circle(m, c, r, cv::Scalar(255), thickness, cv::LINE_8);
        } else {
          cv::rectangle(m, cv::Rect(c.x - r, c.y - r / 2, 2 * r, r), cv::Scalar(255), thickness);
        }
        if (rng() % 3 == 0) {  // A gap: the ring is open.
          cv::line(m, c, c + cv::Point(r + 3, 0), cv::Scalar(0), 1);
        }
      }
      for (int v = 0; v < h; ++v) {
        for (int u = 0; u < w; ++u)
          mask.pixels[static_cast<std::size_t>(v) * w + u] = m.at<std::uint8_t>(v, u);
      }
    }
    const common::ImageU8 expected = Expected(mask);
    common::ImageU8 got = mask;
    const int filled = FillEnclosedBackground(&got, &scratch);
    ASSERT_EQ(Differences(got, expected), 0) << "trial " << trial << ", " << w << " x " << h;
    ASSERT_EQ(filled, Differences(mask, expected)) << "trial " << trial;
    filled_total += filled;
  }
  EXPECT_GT(filled_total, 1000) << "the masks held few holes: the test shows little";
}

TEST(FillEnclosedBackground, ARingIsFilledAndAnOpenOneIsNot) {
  HoleFillScratch scratch;
  cv::Mat m(60, 80, CV_8UC1, cv::Scalar(0));
  cv::circle(m, cv::Point(20, 30), 12, cv::Scalar(255), 2);
  cv::rectangle(m, cv::Rect(45, 10, 25, 30), cv::Scalar(255), 1);
  cv::line(m, cv::Point(57, 10), cv::Point(58, 10), cv::Scalar(0), 1);  // Opened at the top.
  // A ring cut by the image border encloses nothing.
  cv::circle(m, cv::Point(0, 55), 8, cv::Scalar(255), 2);
  common::ImageU8 mask(80, 60, 0);
  for (int v = 0; v < 60; ++v) {
    for (int u = 0; u < 80; ++u)
      mask.pixels[static_cast<std::size_t>(v) * 80 + u] = m.at<std::uint8_t>(v, u);
  }
  const int filled = FillEnclosedBackground(&mask, &scratch);
  EXPECT_EQ(mask.At(20, 30), 255);  // Inside the closed ring.
  EXPECT_EQ(mask.At(57, 25), 0);    // Inside the open rectangle.
  EXPECT_EQ(mask.At(2, 57), 0);     // Inside the ring at the border.
  EXPECT_EQ(mask.At(40, 5), 0);
  EXPECT_GT(filled, 300);
}

// A mask of more background runs than the scratch holds is left unchanged
// (-1), never half filled.
TEST(FillEnclosedBackground, TooManyRunsLeaveTheMaskAsItWas) {
  HoleFillScratch scratch;
  const int w = 640, h = 480;  // 19 200 runs reserved, 153 600 needed.
  common::ImageU8 mask(w, h, 0);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u)
      mask.pixels[static_cast<std::size_t>(v) * w + u] = (u + v) % 2 == 0 ? 255 : 0;
  }
  const common::ImageU8 before = mask;
  EXPECT_EQ(FillEnclosedBackground(&mask, &scratch), -1);
  EXPECT_EQ(Differences(mask, before), 0);
  // A checkerboard's background touches only diagonally: every pixel of it
  // inside the border is enclosed, and a small one is filled so.
  common::ImageU8 small(9, 7, 0);
  for (int v = 0; v < 7; ++v) {
    for (int u = 0; u < 9; ++u)
      small.pixels[static_cast<std::size_t>(v) * 9 + u] = (u + v) % 2 == 0 ? 255 : 0;
  }
  const common::ImageU8 expected = Expected(small);
  const common::ImageU8 small_before = small;
  EXPECT_EQ(FillEnclosedBackground(&small, &scratch), Differences(small_before, expected));
  EXPECT_EQ(Differences(small, expected), 0);
  EXPECT_EQ(small.At(4, 1), 255);  // Background inside the border: filled.
  EXPECT_EQ(small.At(1, 0), 0);    // On the border: kept.
}

}  // namespace
}  // namespace hg::silhouette
