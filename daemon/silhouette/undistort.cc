#include "silhouette/undistort.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>
#include <utility>

#include <Eigen/Core>
#include <Eigen/LU>

#include "common/check.h"

namespace hg::silhouette {
namespace {

// How the source region of an output pixel is bounded.
//
// The map f = K * Distort * K^-1 takes an ideal pinhole pixel position to the
// distorted (source) image. Where its Jacobian determinant is positive, f is a local
// diffeomorphism, so it maps the interior of the pixel square S to an open set and
// every extreme point of the compact set f(S) is the image of a point of the
// boundary of S: the bounding box of f(S) equals the bounding box of f(boundary S).
//
// The boundary is sampled with kSegments segments per edge. Between two samples
// h apart along an edge curve gamma with |gamma''| <= M, gamma stays within
// M h^2 / 8 of the chord, so the sampled polyline's box grown by M h^2 / 8 contains
// f(boundary S). M is estimated from the second differences of the samples
// (|gamma(s-h) - 2 gamma(s) + gamma(s+h)| ~= |gamma''| h^2). Lens distortion is a
// low-order polynomial in normalised coordinates, so in pixel units its second
// derivative is tiny (order |k| r / f, about 1e-2 px/px^2 or less) and varies
// slowly; the estimate is multiplied by kCurvatureSafety and a fixed kMarginFloor
// is added on top, which dominates in practice and also absorbs rounding.
constexpr int kSegments = 8;
constexpr double kCurvatureSafety = 4.0;
constexpr double kMarginFloor = 0.01;  // px

// Beyond the radius where the polynomial model folds over (Jacobian determinant
// <= 0) it no longer describes the lens; pixels there are treated as unseen. The
// determinant is only known at samples, so it must clear kMinJacobian by twice its
// spread over the pixel's samples, which bounds how far it can dip in between.
constexpr double kMinJacobian = 0.05;

/// f and its Jacobian determinant at one output (pinhole) position.
struct Sample {
  double x = 0;
  double y = 0;
  double det = 0;
};

class DistortionMap {
 public:
  explicit DistortionMap(const geometry::CameraModel& camera)
      : K_(camera.K), K_inv_(camera.K.inverse()), d_(camera.distortion) {}

  [[nodiscard]] Sample At(double u, double v) const {
    const double x = K_inv_(0, 0) * u + K_inv_(0, 1) * v + K_inv_(0, 2);
    const double y = K_inv_(1, 1) * v + K_inv_(1, 2);
    const double k1 = d_[0], k2 = d_[1], p1 = d_[2], p2 = d_[3], k3 = d_[4];
    const double r2 = x * x + y * y;
    const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    const double dx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
    const double dy = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
    // d(radial)/dx = 2 x g, d(radial)/dy = 2 y g.
    const double g = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);
    const double j00 = radial + 2.0 * x * x * g + 2.0 * p1 * y + 6.0 * p2 * x;
    const double j01 = 2.0 * x * y * g + 2.0 * p1 * x + 2.0 * p2 * y;
    const double j10 = 2.0 * x * y * g + 2.0 * p1 * x + 2.0 * p2 * y;
    const double j11 = radial + 2.0 * y * y * g + 6.0 * p1 * y + 2.0 * p2 * x;
    // K's 2x2 block and its inverse cancel in the determinant of K D K^-1.
    Sample s;
    s.x = K_(0, 0) * dx + K_(0, 1) * dy + K_(0, 2);
    s.y = K_(1, 1) * dy + K_(1, 2);
    s.det = j00 * j11 - j01 * j10;
    return s;
  }

 private:
  Eigen::Matrix3d K_;
  Eigen::Matrix3d K_inv_;
  std::array<double, 5> d_;
};

/// Accumulates one output pixel's boundary samples.
struct RegionBounds {
  double x_min = std::numeric_limits<double>::infinity();
  double x_max = -std::numeric_limits<double>::infinity();
  double y_min = std::numeric_limits<double>::infinity();
  double y_max = -std::numeric_limits<double>::infinity();
  double det_min = std::numeric_limits<double>::infinity();
  double det_max = -std::numeric_limits<double>::infinity();
  double max_second_difference = 0;  // px
  bool finite = true;

  void Add(const Sample& s) {
    if (!std::isfinite(s.x) || !std::isfinite(s.y) || !std::isfinite(s.det)) {
      finite = false;
    }
    x_min = std::min(x_min, s.x);
    x_max = std::max(x_max, s.x);
    y_min = std::min(y_min, s.y);
    y_max = std::max(y_max, s.y);
    AddDet(s.det);
  }
  void AddDet(double det) {
    det_min = std::min(det_min, det);
    det_max = std::max(det_max, det);
  }
  /// One edge, kSegments + 1 samples in order along it.
  void AddEdge(const Sample* const* edge) {
    for (int i = 0; i <= kSegments; ++i) {
      Add(*edge[i]);
    }
    for (int i = 1; i < kSegments; ++i) {
      const double ddx = edge[i - 1]->x - 2.0 * edge[i]->x + edge[i + 1]->x;
      const double ddy = edge[i - 1]->y - 2.0 * edge[i]->y + edge[i + 1]->y;
      max_second_difference = std::max(max_second_difference, std::sqrt(ddx * ddx + ddy * ddy));
    }
  }
};

}  // namespace

ConservativeUndistorter::ConservativeUndistorter(const geometry::CameraModel& camera)
    : width_(camera.width), height_(camera.height), source_(camera.width, camera.height) {
  HG_CHECK(width_ > 0 && height_ > 0);
  HG_CHECK(width_ < kOutside && height_ < kOutside);
  const int w = width_;
  const int h = height_;
  rects_.resize(static_cast<std::size_t>(w) * h);

  if (!camera.HasDistortion()) {
    // The map is the identity: each output pixel is exactly its source pixel.
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        const auto uu = static_cast<std::uint16_t>(u);
        const auto vv = static_cast<std::uint16_t>(v);
        rects_[static_cast<std::size_t>(v) * w + u] = {uu, vv, uu, vv};
      }
    }
    BuildTileRects();
    return;
  }

  const DistortionMap map(camera);
  constexpr double kStep = 1.0 / kSegments;
  // Samples on the horizontal pixel boundary lines above (top) and below (bottom)
  // the current output row, and on the vertical boundary lines between them
  // (interior samples only; their end points are in top and bottom). Neighbouring
  // pixels share these samples.
  const int line_samples = kSegments * w + 1;
  std::vector<Sample> top(line_samples);
  std::vector<Sample> bottom(line_samples);
  std::vector<Sample> vertical(static_cast<std::size_t>(w + 1) * (kSegments - 1));
  auto fill_line = [&](double y, std::vector<Sample>* line) {
    for (int k = 0; k < line_samples; ++k) {
      (*line)[k] = map.At(-0.5 + k * kStep, y);
    }
  };
  fill_line(-0.5, &top);

  const Sample* edge[kSegments + 1];
  for (int v = 0; v < h; ++v) {
    fill_line(v + 0.5, &bottom);
    for (int i = 0; i <= w; ++i) {
      for (int j = 1; j < kSegments; ++j) {
        vertical[static_cast<std::size_t>(i) * (kSegments - 1) + (j - 1)] =
            map.At(i - 0.5, v - 0.5 + j * kStep);
      }
    }
    for (int u = 0; u < w; ++u) {
      RegionBounds b;
      const int k0 = kSegments * u;
      for (int j = 0; j <= kSegments; ++j) {
        edge[j] = &top[k0 + j];
      }
      b.AddEdge(edge);
      for (int j = 0; j <= kSegments; ++j) {
        edge[j] = &bottom[k0 + j];
      }
      b.AddEdge(edge);
      for (int side = 0; side < 2; ++side) {
        const int i = u + side;
        edge[0] = &top[static_cast<std::size_t>(kSegments) * i];
        for (int j = 1; j < kSegments; ++j) {
          edge[j] = &vertical[static_cast<std::size_t>(i) * (kSegments - 1) + (j - 1)];
        }
        edge[kSegments] = &bottom[static_cast<std::size_t>(kSegments) * i];
        b.AddEdge(edge);
      }
      b.AddDet(map.At(u, v).det);

      const double margin = kMarginFloor + kCurvatureSafety * b.max_second_difference / 8.0;
      // Source pixel s covers [s - 0.5, s + 0.5), so the pixels touching the closed
      // box [lo, hi] are floor(lo + 0.5) .. floor(hi + 0.5).
      const double su0 = std::floor(b.x_min - margin + 0.5);
      const double su1 = std::floor(b.x_max + margin + 0.5);
      const double sv0 = std::floor(b.y_min - margin + 0.5);
      const double sv1 = std::floor(b.y_max + margin + 0.5);
      const bool folded = !(b.det_min - 2.0 * (b.det_max - b.det_min) >= kMinJacobian);
      // Written so that NaN lands on the outside branch.
      const bool inside = b.finite && su0 >= 0 && sv0 >= 0 && su1 <= w - 1 && sv1 <= h - 1;
      SourceRect& r = rects_[static_cast<std::size_t>(v) * w + u];
      if (folded || !inside) {
        r = {kOutside, kOutside, kOutside, kOutside};
      } else {
        r = {static_cast<std::uint16_t>(su0), static_cast<std::uint16_t>(sv0),
             static_cast<std::uint16_t>(su1), static_cast<std::uint16_t>(sv1)};
      }
    }
    std::swap(top, bottom);
  }
  BuildTileRects();
}

void ConservativeUndistorter::BuildTileRects() {
  tiles_w_ = (width_ + kTile - 1) / kTile;
  tiles_h_ = (height_ + kTile - 1) / kTile;
  tile_rects_.assign(static_cast<std::size_t>(tiles_w_) * tiles_h_, SourceRect{});
  for (int ty = 0; ty < tiles_h_; ++ty) {
    for (int tx = 0; tx < tiles_w_; ++tx) {
      SourceRect t{kOutside, kOutside, 0, 0};
      bool outside = false;
      for (int v = ty * kTile; v < std::min(height_, (ty + 1) * kTile); ++v) {
        for (int u = tx * kTile; u < std::min(width_, (tx + 1) * kTile); ++u) {
          const SourceRect& r = rects_[static_cast<std::size_t>(v) * width_ + u];
          if (r.u0 == kOutside) {
            outside = true;
            continue;
          }
          t.u0 = std::min(t.u0, r.u0);
          t.v0 = std::min(t.v0, r.v0);
          t.u1 = std::max(t.u1, r.u1);
          t.v1 = std::max(t.v1, r.v1);
        }
      }
      // A tile with a pixel whose region leaves the image is always read
      // pixel by pixel.
      tile_rects_[static_cast<std::size_t>(ty) * tiles_w_ + tx] =
          outside ? SourceRect{kOutside, kOutside, kOutside, kOutside} : t;
    }
  }
}

std::uint8_t ConservativeUndistorter::PixelValue(const common::ImageViewU8& in,
                                                 std::uint8_t threshold, const SourceRect& r) {
  if (r.u0 == kOutside) return 255;
  const int du = r.u1 - r.u0;
  const int dv = r.v1 - r.v0;
  const std::ptrdiff_t stride = in.stride;
  const std::uint8_t* p = in.Row(r.v0) + r.u0;
  std::uint8_t peak;
  // Almost every rectangle is 2x2 or smaller, nearly all the rest 3x3 or smaller.
  // Those read a fixed pattern whose middle row and column collapse onto the edges
  // for smaller sizes (reading a pixel twice is harmless), so the common paths have
  // no data-dependent inner loop.
  if ((du | dv) <= 1) {
    const std::uint8_t* q = p + dv * stride;
    peak = std::max(std::max(p[0], p[du]), std::max(q[0], q[du]));
  } else if (du <= 2 && dv <= 2) {
    const int mu = du >> 1;
    const std::uint8_t* q = p + (dv >> 1) * stride;
    const std::uint8_t* z = p + dv * stride;
    peak = std::max(std::max(std::max(p[0], p[mu]), std::max(p[du], q[0])),
                    std::max(std::max(q[mu], q[du]), std::max(std::max(z[0], z[mu]), z[du])));
  } else {
    peak = 0;
    for (int y = 0; y <= dv; ++y, p += stride) {
      for (int x = 0; x <= du; ++x) {
        peak = std::max(peak, p[x]);
      }
    }
  }
  return peak > threshold ? 255 : 0;
}

void ConservativeUndistorter::ApplyPerPixel(const common::ImageViewU8& in, std::uint8_t threshold,
                                            common::ImageU8* out) const {
  HG_CHECK(out != nullptr);
  HG_CHECK(in.data != nullptr && in.width == width_ && in.height == height_);
  if (out->width != width_ || out->height != height_) *out = common::ImageU8(width_, height_);
  const std::size_t n = static_cast<std::size_t>(width_) * height_;
  for (std::size_t i = 0; i < n; ++i) {
    out->pixels[i] = PixelValue(in, threshold, rects_[i]);
  }
}

void ConservativeUndistorter::Apply(const common::ImageViewU8& in, std::uint8_t threshold,
                                    common::ImageU8* out) {
  HG_CHECK(out != nullptr);
  HG_CHECK(in.data != nullptr && in.width == width_ && in.height == height_);
  if (out->width != width_ || out->height != height_) *out = common::ImageU8(width_, height_);
  // The source's silhouette quadtree tells, for the region an output tile's
  // pixels may come from, whether it is all background, all foreground or mixed.
  source_.Build(in, threshold);
  // 2. Per output tile: when every source tile its pixels may come from is
  // pure, so is the output tile; otherwise pixel by pixel.
  for (int ty = 0; ty < tiles_h_; ++ty) {
    const int v_end = std::min(height_, (ty + 1) * kTile);
    for (int tx = 0; tx < tiles_w_; ++tx) {
      const SourceRect& t = tile_rects_[static_cast<std::size_t>(ty) * tiles_w_ + tx];
      const Cover cover =
          t.u0 == kOutside ? Cover::kMixed : source_.Query({t.u0, t.v0, t.u1, t.v1});
      const int u0 = tx * kTile;
      const int u_end = std::min(width_, u0 + kTile);
      if (cover == Cover::kBackground || cover == Cover::kForeground) {
        const std::uint8_t value = cover == Cover::kForeground ? 255 : 0;
        for (int v = ty * kTile; v < v_end; ++v) {
          std::memset(out->pixels.data() + static_cast<std::size_t>(v) * width_ + u0, value,
                      static_cast<std::size_t>(u_end - u0));
        }
        continue;
      }
      for (int v = ty * kTile; v < v_end; ++v) {
        const std::size_t row = static_cast<std::size_t>(v) * width_;
        for (int u = u0; u < u_end; ++u) {
          out->pixels[row + u] = PixelValue(in, threshold, rects_[row + u]);
        }
      }
    }
  }
}

}  // namespace hg::silhouette
