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
// distorted (source) image. For an output pixel square S with centre c, the
// mean value theorem gives, for every p in S and each coordinate i,
// f_i(p) = f_i(c) + grad f_i(xi) . (p - c) with xi on the segment from c to p,
// inside S. So f_i(S) lies within f_i(c) +- 0.5 (|J_i0| + |J_i1|), where J is
// an interval enclosure of f's Jacobian over S (interval arithmetic over the
// normalised coordinates of S, a box around K^-1 S). This holds for any
// polynomial distortion, folded or not; it is tight to second order (the
// Jacobian varies by about |k| r / f per pixel), so the region is the
// pixel's image, rounded out. Rounding of the double arithmetic is covered by
// kMarginFloor plus a relative margin.
constexpr double kMarginFloor = 0.01;  // px
constexpr double kRelativeMargin = 1e-9;

// Where the polynomial model folds over (Jacobian determinant <= 0) it no
// longer describes a lens; pixels there are treated as unseen. A pixel counts
// as unfolded when a lower bound of the determinant over its square (the same
// interval arithmetic) is at least kMinJacobian.
constexpr double kMinJacobian = 0.05;

/// A closed interval of reals; arithmetic encloses every result of its
/// operands' members (up to the rounding covered by the margins above).
struct Interval {
  double lo = 0;
  double hi = 0;

  static Interval Of(double a, double b) { return {std::min(a, b), std::max(a, b)}; }
  [[nodiscard]] double Magnitude() const { return std::max(std::abs(lo), std::abs(hi)); }
  friend Interval operator+(Interval a, Interval b) { return {a.lo + b.lo, a.hi + b.hi}; }
  friend Interval operator-(Interval a, Interval b) { return {a.lo - b.hi, a.hi - b.lo}; }
  friend Interval operator+(double a, Interval b) { return {a + b.lo, a + b.hi}; }
  friend Interval operator*(double a, Interval b) { return Of(a * b.lo, a * b.hi); }
  friend Interval operator*(Interval a, Interval b) {
    const double p0 = a.lo * b.lo, p1 = a.lo * b.hi, p2 = a.hi * b.lo, p3 = a.hi * b.hi;
    return {std::min({p0, p1, p2, p3}), std::max({p0, p1, p2, p3})};
  }
  /// {x^2 : x in a}: tighter than a * a when a holds 0.
  [[nodiscard]] Interval Square() const {
    const double l = lo * lo, h = hi * hi;
    if (lo <= 0 && hi >= 0) return {0.0, std::max(l, h)};
    return Of(l, h);
  }
};

/// Where one output pixel's points may come from in the source image.
struct Region {
  double x_min = 0, x_max = 0, y_min = 0, y_max = 0;  // Source pixel coordinates.
  double det_lo = 0;  ///< Lower bound of the Jacobian determinant over the pixel.
  bool finite = true;
};

class DistortionMap {
 public:
  explicit DistortionMap(const geometry::CameraModel& camera)
      : K_(camera.K), K_inv_(camera.K.inverse()), d_(camera.distortion) {}

  /// The source region of output pixel (u, v), the square [u - 0.5, u + 0.5] x
  /// [v - 0.5, v + 0.5].
  [[nodiscard]] Region PixelRegion(int u, int v) const {
    const double k1 = d_[0], k2 = d_[1], p1 = d_[2], p2 = d_[3], k3 = d_[4];
    // f at the centre.
    const double xc = K_inv_(0, 0) * u + K_inv_(0, 1) * v + K_inv_(0, 2);
    const double yc = K_inv_(1, 1) * v + K_inv_(1, 2);
    const double r2c = xc * xc + yc * yc;
    const double radial_c = 1.0 + r2c * (k1 + r2c * (k2 + r2c * k3));
    const double dxc = xc * radial_c + 2.0 * p1 * xc * yc + p2 * (r2c + 2.0 * xc * xc);
    const double dyc = yc * radial_c + p1 * (r2c + 2.0 * yc * yc) + 2.0 * p2 * xc * yc;
    const double fu = K_(0, 0) * dxc + K_(0, 1) * dyc + K_(0, 2);
    const double fv = K_(1, 1) * dyc + K_(1, 2);

    // The normalised coordinates of the square: affine in (u, v), so their
    // ranges are those over its corners.
    const double hx = 0.5 * (std::abs(K_inv_(0, 0)) + std::abs(K_inv_(0, 1)));
    const double hy = 0.5 * std::abs(K_inv_(1, 1));
    const Interval x{xc - hx, xc + hx};
    const Interval y{yc - hy, yc + hy};
    // The distortion's Jacobian over them (as in the point form: d(radial)/dx
    // = 2 x g, d(radial)/dy = 2 y g).
    const Interval x2 = x.Square(), y2 = y.Square(), xy = x * y, r2 = x2 + y2;
    const Interval radial = 1.0 + r2 * (k1 + r2 * (k2 + k3 * r2));
    const Interval g = k1 + r2 * (2.0 * k2 + (3.0 * k3) * r2);
    const Interval j00 = radial + 2.0 * (x2 * g) + (2.0 * p1) * y + (6.0 * p2) * x;
    const Interval j01 = 2.0 * (xy * g) + (2.0 * p1) * x + (2.0 * p2) * y;  // == j10
    const Interval j11 = radial + 2.0 * (y2 * g) + (6.0 * p1) * y + (2.0 * p2) * x;
    // In pixels: J = K2 * Jd * K2^-1, K2 the upper-left 2x2 block of K.
    const double a = K_inv_(0, 0), b = K_inv_(0, 1), c = K_inv_(1, 1);
    const Interval m00 = a * j00, m01 = b * j00 + c * j01;
    const Interval m10 = a * j01, m11 = b * j01 + c * j11;
    const Interval J00 = K_(0, 0) * m00 + K_(0, 1) * m10;
    const Interval J01 = K_(0, 0) * m01 + K_(0, 1) * m11;
    const Interval J10 = K_(1, 1) * m10;
    const Interval J11 = K_(1, 1) * m11;
    const double half_u = 0.5 * (J00.Magnitude() + J01.Magnitude());
    const double half_v = 0.5 * (J10.Magnitude() + J11.Magnitude());
    const double margin_u = kMarginFloor + kRelativeMargin * (std::abs(fu) + half_u);
    const double margin_v = kMarginFloor + kRelativeMargin * (std::abs(fv) + half_v);

    Region r;
    r.x_min = fu - half_u - margin_u;
    r.x_max = fu + half_u + margin_u;
    r.y_min = fv - half_v - margin_v;
    r.y_max = fv + half_v + margin_v;
    // K's 2x2 block and its inverse cancel in the determinant.
    r.det_lo = (j00 * j11 - j01.Square()).lo;
    r.finite = std::isfinite(r.x_min) && std::isfinite(r.x_max) && std::isfinite(r.y_min) &&
               std::isfinite(r.y_max) && std::isfinite(r.det_lo);
    return r;
  }

 private:
  Eigen::Matrix3d K_;
  Eigen::Matrix3d K_inv_;
  std::array<double, 5> d_;
};

}  // namespace

ConservativeUndistorter::ConservativeUndistorter(const geometry::CameraModel& camera)
    : width_(camera.width), height_(camera.height), source_(camera.width, camera.height) {
  HG_CHECK(width_ > 0 && height_ > 0);
  // The largest source pixel index, 65534, stays below kOutside.
  HG_CHECK(width_ <= kOutside && height_ <= kOutside);
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
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const Region b = map.PixelRegion(u, v);
      // Source pixel s covers [s - 0.5, s + 0.5), so the pixels touching the closed
      // box [lo, hi] are floor(lo + 0.5) .. floor(hi + 0.5).
      const double su0 = std::floor(b.x_min + 0.5);
      const double su1 = std::floor(b.x_max + 0.5);
      const double sv0 = std::floor(b.y_min + 0.5);
      const double sv1 = std::floor(b.y_max + 0.5);
      const bool folded = !(b.det_lo >= kMinJacobian);
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
