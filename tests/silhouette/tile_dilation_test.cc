#include "silhouette/tile_dilation.h"

#include "silhouette/quadtree.h"
#include "support/random_scene.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

namespace hg::silhouette {
namespace {

common::ImageU8 RandomBlobs(int w, int h, int blobs, std::mt19937_64& rng) {
  common::ImageU8 mask(w, h, 0);
  std::uniform_int_distribution<int> u(0, w - 1), v(0, h - 1), size(0, 6);
  for (int b = 0; b < blobs; ++b) {
    const int u0 = u(rng), v0 = v(rng), s = size(rng);
    for (int y = std::max(0, v0 - s); y <= std::min(h - 1, v0 + s); ++y) {
      for (int x = std::max(0, u0 - s); x <= std::min(w - 1, u0 + s); ++x) mask.At(x, y) = 200;
    }
  }
  return mask;
}

// Chebyshev distance from every pixel to the nearest foreground pixel (brute force).
std::vector<int> DistanceToForeground(const common::ImageU8& mask) {
  std::vector<int> d(mask.pixels.size(), 1 << 20);
  for (int y = 0; y < mask.height; ++y) {
    for (int x = 0; x < mask.width; ++x) {
      if (mask.At(x, y) <= 127) continue;
      for (int v = 0; v < mask.height; ++v) {
        for (int u = 0; u < mask.width; ++u) {
          int& e = d[static_cast<std::size_t>(v) * mask.width + u];
          e = std::min(e, std::max(std::abs(u - x), std::abs(v - y)));
        }
      }
    }
  }
  return d;
}

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

// With a radius, what lies beyond the image's edges counts as foreground
// (an object just outside the view may have moved in), so the distance is
// to the nearest foreground pixel or the nearest pixel outside the image.
TEST(TileDilator, CoversTheRadiusAndOvershootsByLessThanTwoTiles) {
  std::mt19937_64 rng(7);
  for (int trial = 0; trial < testing::SoakSeeds(12); ++trial) {
    const int w = 61 + trial * 3, h = 45 + trial;  // Not multiples of the tile size.
    const common::ImageU8 mask = RandomBlobs(w, h, 1 + trial % 4, rng);
    const std::vector<int> dist = DistanceToForeground(mask);
    TileDilator dilator(w, h);
    common::ImageU8 out;
    for (const int radius : {0, 1, 5, 8, 13, 30}) {
      dilator.Apply(mask.View(), radius, &out);
      for (int v = 0; v < h; ++v) {
        for (int u = 0; u < w; ++u) {
          const int outside = std::min({u + 1, v + 1, w - u, h - v});
          const int d =
              std::min(dist[static_cast<std::size_t>(v) * w + u], radius == 0 ? 1 << 20 : outside);
          const bool fg = out.At(u, v) == 255;
          if (d <= radius) {
            ASSERT_TRUE(fg) << "trial " << trial << " radius " << radius << " at " << u << "," << v
                            << " distance " << d;
          }
          if (d > radius + 2 * TileDilator::kTile) {
            ASSERT_FALSE(fg) << "trial " << trial << " radius " << radius;
          }
          if (radius == 0) {
            ASSERT_EQ(fg, d == 0);
          }
        }
      }
    }
  }
}

// Seed tiles (where an obstacle may hide someone) grow like foreground: the
// map with seeds equals the map of the mask with the seed tiles filled in.
TEST(TileDilator, SeedTilesGrowLikeForeground) {
  std::mt19937_64 rng(5);
  const int w = 203, h = 117;
  TileDilator dilator(w, h);
  const common::ImageU8 mask = RandomBlobs(w, h, 2, rng);
  common::ImageU8 filled = mask;
  for (int v = 60; v < 80; ++v) {
    for (int u = 100; u < 130; ++u) filled.At(u, v) = 255;
  }
  const std::vector<std::uint8_t> seeds =
      dilator.TilesWhere([](int u, int v) { return u >= 100 && u < 130 && v >= 60 && v < 80; });
  for (const int radius : {1, 9, 20}) {
    const auto with_fill = dilator.DilateTiles(filled.View(), radius);
    const std::vector<std::uint8_t> expected(with_fill.begin(), with_fill.end());
    const auto with_seeds = dilator.DilateTiles(mask.View(), radius, seeds);
    EXPECT_EQ(std::vector<std::uint8_t>(with_seeds.begin(), with_seeds.end()), expected) << radius;
    const auto without = dilator.DilateTiles(mask.View(), radius);
    EXPECT_NE(std::vector<std::uint8_t>(without.begin(), without.end()), expected) << radius;
  }
}

// The pipeline builds the quadtree of a dilated mask from the tile map; it
// must answer every query as the quadtree built from the dilated pixels,
// changed flags included, frame after frame.
TEST(TileDilator, TileMapBuildsTheSameQuadtreeAsThePixels) {
  std::mt19937_64 rng(11);
  const int w = 203, h = 117;  // Partial tiles on the right and at the bottom.
  TileDilator dilator(w, h);
  SilhouetteQuadtree from_pixels(w, h), from_tiles(w, h);
  common::ImageU8 dilated;
  std::uniform_int_distribution<int> u(0, w - 1), v(0, h - 1);
  for (int frame = 0; frame < 8; ++frame) {
    const common::ImageU8 mask = RandomBlobs(w, h, 1 + frame % 3, rng);
    const int radius = 1 + 7 * frame;
    dilator.Apply(mask.View(), radius, &dilated);
    from_pixels.Build(dilated.View(), 127);
    from_tiles.BuildFromTiles(dilator.DilateTiles(mask.View(), radius));
    for (int q = 0; q < 3000; ++q) {
      int u0 = u(rng), u1 = u(rng), v0 = v(rng), v1 = v(rng);
      if (u0 > u1) std::swap(u0, u1);
      if (v0 > v1) std::swap(v0, v1);
      const geometry::PixelRect rect{u0, v0, u1, v1};
      ASSERT_EQ(from_tiles.Query(rect), from_pixels.Query(rect)) << "frame " << frame;
      ASSERT_EQ(from_tiles.AnyChanged(rect), from_pixels.AnyChanged(rect)) << "frame " << frame;
    }
  }
}

TEST(CoveringRadiusPx, BoundsTheImageDisplacementOfNearbyPoints) {
  geometry::CameraModel cam;
  cam.width = 640;
  cam.height = 480;
  cam.K << 400, 0, 320, 0, 400, 240, 0, 0, 1;
  const double rho = 0.05, min_depth = 1.0;
  const int r = CoveringRadiusPx(cam, rho, min_depth);
  ASSERT_GT(r, 0);
  EXPECT_LT(r, 60);
  // Random point pairs at depth >= min_depth within rho of each other, both in
  // the image: their pixel distance never exceeds r.
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> uu(0, cam.width), vv(0, cam.height), depth(1.0, 6.0),
      dir(-1.0, 1.0);
  int tested = 0;
  double worst = 0.0;
  while (tested < 20000) {
    const Eigen::Vector3d ray((uu(rng) - 320) / 400, (vv(rng) - 240) / 400, 1.0);
    const Eigen::Vector3d p = ray.normalized() * depth(rng);
    Eigen::Vector3d offset(dir(rng), dir(rng), dir(rng));
    if (offset.norm() < 1e-6) continue;
    const Eigen::Vector3d q = p + offset.normalized() * rho;
    if (q.z() <= 0) continue;
    const Eigen::Vector2d a(400 * p.x() / p.z() + 320, 400 * p.y() / p.z() + 240);
    const Eigen::Vector2d b(400 * q.x() / q.z() + 320, 400 * q.y() / q.z() + 240);
    if (b.x() < 0 || b.x() > cam.width || b.y() < 0 || b.y() > cam.height) continue;
    worst = std::max(worst, (a - b).norm());
    ++tested;
  }
  EXPECT_LE(worst, r);
  EXPECT_EQ(CoveringRadiusPx(cam, 0.0, 1.0), 0);
  EXPECT_LT(CoveringRadiusPx(cam, 1.5, 1.0), 0);
}

}  // namespace
}  // namespace hg::silhouette
