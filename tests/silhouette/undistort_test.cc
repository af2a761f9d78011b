#include "silhouette/undistort.h"
#include "support/random_scene.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/LU>

namespace hg::silhouette {
namespace {

using common::ImageU8;
using geometry::CameraModel;

CameraModel MakeCamera(int w, int h, double fx, double fy, double cx, double cy,
                       const std::array<double, 5>& distortion) {
  CameraModel c;
  c.name = "cam";
  c.width = w;
  c.height = h;
  c.K << fx, 0, cx, 0, fy, cy, 0, 0, 1;
  c.distortion = distortion;
  return c;
}

/// The pixel containing coordinate x: pixel u covers [u - 0.5, u + 0.5).
int PixelOf(double x) { return static_cast<int>(std::floor(x + 0.5)); }

/// Where the lens puts the ideal pinhole position q.
Eigen::Vector2d DistortPixel(const CameraModel& c, const Eigen::Vector2d& q) {
  const Eigen::Vector3d n = c.K.inverse() * Eigen::Vector3d(q.x(), q.y(), 1.0);
  const Eigen::Vector2d d = c.DistortNormalized(n.head<2>());
  const Eigen::Vector3d s = c.K * Eigen::Vector3d(d.x(), d.y(), 1.0);
  return s.head<2>();
}

long long CountForeground(const ImageU8& img) {
  return std::count_if(img.pixels.begin(), img.pixels.end(), [](std::uint8_t p) { return p != 0; });
}

TEST(ConservativeUndistorterTest, ZeroDistortionIsExactIdentity) {
  const int w = 97;
  const int h = 61;
  ConservativeUndistorter undistorter(MakeCamera(w, h, 80, 80, 48, 30, {0, 0, 0, 0, 0}));
  EXPECT_EQ(undistorter.width(), w);
  EXPECT_EQ(undistorter.height(), h);
  // A padded source (stride > width) with random grey values.
  const int stride = w + 13;
  std::vector<std::uint8_t> buffer(static_cast<std::size_t>(stride) * h);
  std::mt19937_64 rng(11);
  std::uniform_int_distribution<int> grey(0, 255);
  for (std::uint8_t& b : buffer) {
    b = static_cast<std::uint8_t>(grey(rng));
  }
  const common::ImageViewU8 in{buffer.data(), w, h, stride};
  ImageU8 out;
  undistorter.Apply(in, 100, &out);
  ASSERT_EQ(out.width, w);
  ASSERT_EQ(out.height, h);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      // Foreground means strictly above the threshold.
      ASSERT_EQ(out.At(u, v), in.At(u, v) > 100 ? 255 : 0) << u << "," << v;
    }
  }
}

// Object points are pushed forward through the lens into a distorted mask; every
// object point must then land on a foreground pixel of the undistorted mask. Points
// whose distorted image leaves the frame must land on foreground too, because
// there the camera cannot certify anything.
TEST(ConservativeUndistorterTest, EveryObjectPointStaysForeground) {
  std::mt19937_64 rng(0x5eed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  auto uniform = [&](double lo, double hi) { return lo + (hi - lo) * unit(rng); };
  const int w = 320;
  const int h = 240;
  long long checked = 0;
  long long checked_inside = 0;
  for (int trial = 0; trial < testing::SoakSeeds(10); ++trial) {
    const double fx = uniform(250, 400);
    const CameraModel cam = MakeCamera(
        w, h, fx, fx * uniform(0.95, 1.05), w / 2.0 + uniform(-10, 10), h / 2.0 + uniform(-10, 10),
        {uniform(-0.3, 0.1), uniform(-0.05, 0.05), uniform(-0.002, 0.002), uniform(-0.002, 0.002),
         uniform(-0.01, 0.01)});
    ConservativeUndistorter undistorter(cam);

    // Object points in ideal pinhole pixel coordinates, grouped into small blobs,
    // some of them exactly on or just beside pixel boundaries.
    std::vector<Eigen::Vector2d> points;
    for (int blob = 0; blob < 25; ++blob) {
      const Eigen::Vector2d centre(uniform(-15, w + 15), uniform(-15, h + 15));
      const double radius = uniform(0.3, 6.0);
      for (int i = 0; i < 300; ++i) {
        const double r = radius * std::sqrt(unit(rng));
        const double a = uniform(0, 2 * std::numbers::pi);
        Eigen::Vector2d q = centre + r * Eigen::Vector2d(std::cos(a), std::sin(a));
        if (i % 5 == 0) {
          q.x() = std::round(q.x()) + 0.5;
        }
        if (i % 7 == 0) {
          q.y() = std::nextafter(std::round(q.y()) + 0.5, -1e9);
        }
        points.push_back(q);
      }
    }

    ImageU8 distorted(w, h, 0);
    for (const Eigen::Vector2d& q : points) {
      const Eigen::Vector2d s = DistortPixel(cam, q);
      const int su = PixelOf(s.x());
      const int sv = PixelOf(s.y());
      if (su >= 0 && su < w && sv >= 0 && sv < h) {
        distorted.At(su, sv) = 200;
      }
    }
    ImageU8 out;
    undistorter.Apply(distorted.View(), 127, &out);

    for (const Eigen::Vector2d& q : points) {
      const int u = PixelOf(q.x());
      const int v = PixelOf(q.y());
      if (u < 0 || u >= w || v < 0 || v >= h) {
        continue;
      }
      ++checked;
      const Eigen::Vector2d s = DistortPixel(cam, q);
      if (PixelOf(s.x()) >= 0 && PixelOf(s.x()) < w && PixelOf(s.y()) >= 0 && PixelOf(s.y()) < h) {
        ++checked_inside;
      }
      ASSERT_EQ(out.At(u, v), 255) << "trial " << trial << " point (" << q.x() << ", " << q.y()
                                   << ") pixel " << u << "," << v;
    }
    // Not vacuous: the blobs cover only a small part of the image.
    EXPECT_LT(CountForeground(out), static_cast<long long>(w) * h / 4) << "trial " << trial;
  }
  EXPECT_GT(checked_inside, 20000);
  EXPECT_GT(checked, checked_inside);  // Some points leave the source image.
}

// Dilation stays modest. Reference: the usual point-sampled undistortion (output
// pixel takes the source pixel under the image of its centre). With k1 = -0.1 on a
// 640x480, f = 500 camera and disks of radius 8..30 px, the conservative mask
// contains the reference, lies within 2 pixels (Chebyshev) of it, and adds less
// than 10 % to its foreground (about 5 % measured; a full 1 px ring around the
// disks would add roughly 12 %).
TEST(ConservativeUndistorterTest, BarrelDistortionDilatesLittle) {
  const int w = 640;
  const int h = 480;
  const CameraModel cam = MakeCamera(w, h, 500, 500, 319.5, 239.5, {-0.1, 0, 0, 0, 0});
  ConservativeUndistorter undistorter(cam);

  // Barrel distortion pulls everything inwards: no pixel leaves the source.
  ImageU8 out;
  undistorter.Apply(ImageU8(w, h, 0).View(), 0, &out);
  EXPECT_EQ(CountForeground(out), 0);

  std::mt19937_64 rng(99);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  ImageU8 source(w, h, 0);
  for (int blob = 0; blob < 40; ++blob) {
    const double cu = w * unit(rng);
    const double cv = h * unit(rng);
    const double r = 8 + 22 * unit(rng);
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        if ((u - cu) * (u - cu) + (v - cv) * (v - cv) <= r * r) {
          source.At(u, v) = 255;
        }
      }
    }
  }
  undistorter.Apply(source.View(), 0, &out);

  ImageU8 reference(w, h, 0);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const Eigen::Vector2d s = DistortPixel(cam, Eigen::Vector2d(u, v));
      reference.At(u, v) = source.At(PixelOf(s.x()), PixelOf(s.y()));
    }
  }
  const long long ref_fg = CountForeground(reference);
  const long long out_fg = CountForeground(out);
  ASSERT_GT(ref_fg, 10000);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      if (reference.At(u, v) != 0) {
        ASSERT_EQ(out.At(u, v), 255) << u << "," << v;
      }
      if (out.At(u, v) == 0) {
        continue;
      }
      bool near = false;
      for (int dv = -2; dv <= 2 && !near; ++dv) {
        for (int du = -2; du <= 2 && !near; ++du) {
          const int uu = u + du;
          const int vv = v + dv;
          near = uu >= 0 && uu < w && vv >= 0 && vv < h && reference.At(uu, vv) != 0;
        }
      }
      ASSERT_TRUE(near) << u << "," << v;
    }
  }
  const double extra = static_cast<double>(out_fg - ref_fg) / static_cast<double>(ref_fg);
  EXPECT_LT(extra, 0.10) << "reference " << ref_fg << " conservative " << out_fg;
  RecordProperty("extra_foreground_fraction", std::to_string(extra));
}

TEST(ConservativeUndistorterTest, PixelsThatLeaveTheSourceAreForeground) {
  // Pincushion distortion pushes the corners out of the source image.
  const int w = 320;
  const int h = 240;
  ConservativeUndistorter undistorter(MakeCamera(w, h, 250, 250, 159.5, 119.5, {0.1, 0, 0, 0, 0}));
  ImageU8 out;
  undistorter.Apply(ImageU8(w, h, 0).View(), 0, &out);
  EXPECT_EQ(out.At(0, 0), 255);
  EXPECT_EQ(out.At(w - 1, h - 1), 255);
  EXPECT_EQ(out.At(w / 2, h / 2), 0);
  EXPECT_EQ(out.At(w / 2, 0), 255);  // The edge midpoint moves out by ~0.1 * 0.48^2 * 120 px.
  EXPECT_EQ(out.At(w / 2, 5), 0);
}

TEST(ConservativeUndistorterTest, FoldedModelIsForeground) {
  // With k1 = -1 the radial map r (1 - r^2) folds at r = 1/sqrt(3), 115 px from the
  // centre at f = 200; beyond it the model maps back inside the image but describes
  // no real lens, so those pixels must not be certified.
  const int w = 320;
  const int h = 240;
  ConservativeUndistorter undistorter(MakeCamera(w, h, 200, 200, 159.5, 119.5, {-1.0, 0, 0, 0, 0}));
  ImageU8 out;
  undistorter.Apply(ImageU8(w, h, 0).View(), 0, &out);
  EXPECT_EQ(out.At(0, 0), 255);
  EXPECT_EQ(out.At(w - 1, 0), 255);
  EXPECT_EQ(out.At(w / 2 + 125, h / 2), 255);
  EXPECT_EQ(out.At(w / 2 + 90, h / 2), 0);
  EXPECT_EQ(out.At(w / 2, h / 2), 0);
}

// A fold too narrow for samples of the pixel's edges: with these
// coefficients the determinant of the model's Jacobian is -0.27 at pinhole
// point (1.734375, 1.902344), inside the middle pixel of a 5 x 5 image, while
// it is positive at every point of a 9 x 9 grid on the pixel's edges and at
// its centre. A lower bound over the whole pixel sees it.
TEST(ConservativeUndistorterTest, AFoldInsideOnePixelIsForeground) {
  const CameraModel cam =
      MakeCamera(5, 5, 1.54450322, 1.54450322, 2, 2, {-22.6299903, 90.2068094, 0, 0, -119.254981});
  // The fold is there (the determinant from the same formulas as the library's
  // point form).
  const Eigen::Vector3d n = cam.K.inverse() * Eigen::Vector3d(1.734375, 1.902344, 1.0);
  const double x = n.x(), y = n.y(), r2 = x * x + y * y;
  const auto& d = cam.distortion;
  const double radial = 1 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
  const double g = d[0] + r2 * (2 * d[1] + 3 * d[4] * r2);
  const double det =
      (radial + 2 * x * x * g) * (radial + 2 * y * y * g) - 4 * x * x * y * y * g * g;
  ASSERT_LT(det, -0.2);
  ConservativeUndistorter undistorter(cam);
  ImageU8 out;
  undistorter.Apply(ImageU8(5, 5, 0).View(), 0, &out);
  EXPECT_EQ(out.At(2, 2), 255);
}

// Images up to the loader's 65535 pixels a side: the largest source index,
// 65534, is a region's, not the "outside" mark.
TEST(ConservativeUndistorterTest, TheWidestImage) {
  const int w = 65535;
  const CameraModel cam = MakeCamera(w, 3, 30000, 30000, 32767, 1, {-0.01, 0, 0, 0, 0});
  ConservativeUndistorter undistorter(cam);
  ImageU8 source(w, 3, 0);
  source.At(w - 1, 1) = 255;
  ImageU8 out;
  undistorter.Apply(source.View(), 0, &out);
  EXPECT_EQ(out.At(w / 2, 1), 0);
  // Barrel distortion pulls the last column inwards (from about column
  // 65150): background.
  EXPECT_EQ(out.At(w - 1, 1), 0);
  const int from = PixelOf(DistortPixel(cam, Eigen::Vector2d(w - 1, 1)).x());
  ASSERT_LT(from, w - 300);
  source.At(from, 1) = 255;
  undistorter.Apply(source.View(), 0, &out);
  EXPECT_EQ(out.At(w - 1, 1), 255);
}

TEST(ConservativeUndistorterTest, ReusesOutputOfTheRightSize) {
  const int w = 64;
  const int h = 48;
  ConservativeUndistorter undistorter(MakeCamera(w, h, 60, 60, 32, 24, {-0.2, 0, 0, 0, 0}));
  ImageU8 out(w, h, 77);
  const std::uint8_t* before = out.pixels.data();
  undistorter.Apply(ImageU8(w, h, 0).View(), 0, &out);
  EXPECT_EQ(out.pixels.data(), before);
  EXPECT_EQ(CountForeground(out), 0);

  ImageU8 wrong(3, 2, 0);
  undistorter.Apply(ImageU8(w, h, 255).View(), 0, &wrong);
  EXPECT_EQ(wrong.width, w);
  EXPECT_EQ(wrong.height, h);
  EXPECT_EQ(CountForeground(wrong), static_cast<long long>(w) * h);
}

// Apply() writes pure tiles at once; it must equal the per-pixel map bit for
// bit: random lenses (strong barrel ones whose corners leave the source image
// or fold), sizes that are not multiples of the tile, blobs and grey levels
// around the threshold, and a stride wider than the image.
TEST(ConservativeUndistorterTest, TilesEqualThePerPixelMap) {
  std::mt19937_64 rng(0x711e5);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  auto uniform = [&](double lo, double hi) { return lo + (hi - lo) * unit(rng); };
  long long pure_tiles = 0;
  for (int trial = 0; trial < testing::SoakSeeds(12); ++trial) {
    const int w = 150 + trial * 7, h = 101 + trial * 3;
    const double fx = uniform(90, 200);
    ConservativeUndistorter undistorter(MakeCamera(
        w, h, fx, fx * uniform(0.95, 1.05), w / 2.0 + uniform(-8, 8), h / 2.0 + uniform(-8, 8),
        {uniform(-0.45, 0.15), uniform(-0.05, 0.05), uniform(-0.003, 0.003), uniform(-0.003, 0.003),
         uniform(-0.02, 0.02)}));
    const int stride = w + 13;
    std::vector<std::uint8_t> pixels(static_cast<std::size_t>(stride) * h, 0);
    for (int blob = 0; blob < 6; ++blob) {
      const double cu = uniform(0, w), cv = uniform(0, h), r = uniform(2, 25);
      for (int v = 0; v < h; ++v) {
        for (int u = 0; u < w; ++u) {
          if (std::hypot(u - cu, v - cv) < r)
            pixels[static_cast<std::size_t>(v) * stride + u] = 200;
        }
      }
    }
    for (int k = 0; k < 300; ++k) {  // Scattered grey pixels on both sides of the threshold.
      pixels[static_cast<std::size_t>(rng() % h) * stride + rng() % w] =
          static_cast<std::uint8_t>(120 + rng() % 16);
    }
    const common::ImageViewU8 in{pixels.data(), w, h, stride};
    ImageU8 tiled, reference;
    for (const std::uint8_t threshold : {std::uint8_t{0}, std::uint8_t{254}, std::uint8_t{127}}) {
      undistorter.Apply(in, threshold, &tiled);
      undistorter.ApplyPerPixel(in, threshold, &reference);
      ASSERT_EQ(tiled.pixels, reference.pixels)
          << "trial " << trial << " threshold " << static_cast<int>(threshold);
    }
    // Not vacuous (threshold 127): most tiles take the fast path, some do not.
    long long mixed = 0, tiles = 0;
    for (int ty = 0; ty < (h + 7) / 8; ++ty) {
      for (int tx = 0; tx < (w + 7) / 8; ++tx, ++tiles) {
        bool fg = false, bg = false;
        for (int v = 8 * ty; v < std::min(h, 8 * ty + 8); ++v) {
          for (int u = 8 * tx; u < std::min(w, 8 * tx + 8); ++u) {
            (reference.At(u, v) != 0 ? fg : bg) = true;
          }
        }
        mixed += fg && bg;
      }
    }
    EXPECT_GT(mixed, 0) << "trial " << trial;
    pure_tiles += tiles - mixed;
  }
  EXPECT_GT(pure_tiles, 0);
}

}  // namespace
}  // namespace hg::silhouette
