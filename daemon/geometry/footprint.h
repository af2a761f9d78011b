#pragma once
/// @file
/// The footprint of an axis-aligned box in a pinhole camera: the integer pixel
/// rectangle covering the projection of its 8 corners, and its depth range.

#include <algorithm>
#include <cmath>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include <Eigen/Core>
#include <Eigen/LU>

#include "geometry/camera.h"

namespace hg::geometry {

/// Smallest camera depth (m) at which a corner counts as in front of the camera.
inline constexpr double kMinFrontDepth = 1e-6;
/// Slack (pixels) added on each side before rounding to pixels, so that rounding
/// errors of the projection can only grow the rectangle.
inline constexpr double kFootprintSlackPx = 1e-6;
/// What the camera loaders accept, so that the projection's rounding error
/// stays far inside kFootprintSlackPx (it grows with how far off the optical
/// axis, in focal lengths, a point in view may lie):
/// the largest ratio of the two focal lengths, either way round (real lenses
/// have square pixels to a few per cent; at a ratio of 1e6 the error reached
/// 2e-5 px) ...
inline constexpr double kMaxFocalAspect = 10.0;
/// ... and the farthest the image may reach from the principal point, in focal
/// lengths along each axis: a view up to 179.4 degrees wide, beyond any lens a
/// pinhole model describes (1 px focal lengths on 65535 px images came within
/// a factor of a few of the slack).
inline constexpr double kMaxImageReach = 100.0;

/// The pixel holding image coordinate x (pixel u covers [u - 0.5, u + 0.5)),
/// clamped far outside any image.
inline int PixelOf(double x) {
  return static_cast<int>(std::floor(std::clamp(x + 0.5, -1e9, 1e9)));
}

/// Where a box lies relative to one camera. Value type.
struct Footprint {
  enum class Side { kInFront, kBehind, kStraddling };
  Side side = Side::kBehind;
  PixelRect rect;       ///< Valid only when side == kInFront; may exceed the image.
  double z_near = 0.0;  ///< Smallest camera depth of the 8 corners (m).
  double z_far = 0.0;   ///< Largest camera depth of the 8 corners (m).
};

/// Precomputed pinhole projection P = K [R | t] of one camera. K(2, 2) must be 1,
/// so that row 2 of P gives the camera depth. Value type.
///
/// Points are projected relative to the camera centre o:
/// P (x, 1) = M (x - o) + c, with M = P's left 3x3 and c = M o + P's last
/// column (nearly zero), computed once without rounding error. Every term is
/// then of the order of a row of K times the point's distance from the
/// camera, so the rounding error of u and v stays near 1e-16 times the
/// largest entry of K over the point's depth ratio, whatever the coordinates
/// (below 1e-8 px within the loaders' limits, kMaxFocalAspect and
/// kMaxImageReach).
/// Projected as M x + P's last column, terms
/// of the size of the focal length times the coordinates (site frames place
/// cells a million metres from the origin) cancel, and the error exceeded
/// kFootprintSlackPx: a corner on the wrong side of a pixel border, a box
/// freed by a pixel it touches.
struct BoxProjector {
  Eigen::Matrix<double, 3, 4> P;
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  ///< o: the camera centre (world, m).
  double offset[3] = {0.0, 0.0, 0.0};                ///< c = M o + P's last column.

  explicit BoxProjector(const Eigen::Matrix<double, 3, 4>& projection) : P(projection) {
    const Eigen::Vector3d o = -P.leftCols<3>().inverse() * P.col(3);
    if (o.allFinite()) origin = o;
    for (int r = 0; r < 3; ++r) offset[r] = ExactRowAt(r, origin);
  }

  /// The projection of the calibrated camera K [R | t] itself, not of its
  /// product rounded to doubles: P's last column K t, rounded, moves the
  /// camera centre by up to 1e-16 |t| cx / fx (10 nm a million metres out,
  /// far more than kFootprintSlackPx at close range). The offset c is
  /// K (R o + t), with R o + t summed without rounding, so only M = K R is
  /// rounded, an error relative to the point's distance from the camera.
  BoxProjector(const Eigen::Matrix3d& K, const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
    P.leftCols<3>() = K * R;
    P.col(3) = K * t;
    const Eigen::Vector3d o = -R.transpose() * t;
    if (o.allFinite()) origin = o;
    // w = R o + t as hi + lo (each a double-double sum of exact products).
    double w_hi[3], w_lo[3];
    for (int b = 0; b < 3; ++b) {
      double hi = t[b], lo = 0.0;
      for (int a = 0; a < 3; ++a) TwoSumAdd(R(b, a), origin[a], &hi, &lo);
      w_hi[b] = hi;
      w_lo[b] = lo;
    }
    for (int r = 0; r < 3; ++r) {
      double hi = 0.0, lo = 0.0;
      for (int b = 0; b < 3; ++b) {
        TwoSumAdd(K(r, b), w_hi[b], &hi, &lo);
        TwoSumAdd(K(r, b), w_lo[b], &hi, &lo);
      }
      offset[r] = hi + lo;
    }
  }

  /// (*hi, *lo) += a * b: the product split exactly (fma), both parts added
  /// with an error-free sum into hi and the rounding carried in lo.
  static void TwoSumAdd(double a, double b, double* hi, double* lo) {
    const double p = a * b;
    const double p_err = std::fma(a, b, -p);
    const double s = *hi + p;
    const double bb = s - *hi;
    *lo += (*hi - (s - bb)) + (p - bb) + p_err;
    *hi = s;
  }

  /// Row r of P at (x, 1), rounded once (double-double accumulation of exact
  /// products).
  [[nodiscard]] double ExactRowAt(int r, const Eigen::Vector3d& x) const {
    double hi = P(r, 3), lo = 0.0;
    for (int a = 0; a < 3; ++a) TwoSumAdd(P(r, a), x[a], &hi, &lo);
    return hi + lo;
  }

  /// Projects the grid of points (xs[i], ys[j], zs[k]), i, j, k < N, into
  /// image coordinates (pixels; meaningful where z > 0), u at uv[2 n] and v at
  /// uv[2 n + 1], and camera depth z[n] (m), for n = i + N (j + N k). Every
  /// footprint is computed from such a grid, so that a box gets bit-identical
  /// corners whether it is projected alone or as one of the eight children of
  /// a 3x3x3 grid.
  template <int N>
  void ProjectGrid(const double (&xs)[N], const double (&ys)[N], const double (&zs)[N], double* uv,
                   double* z) const {
    double dx[N], dy[N], dz[N];  // Relative to the camera centre.
    for (int i = 0; i < N; ++i) {
      dx[i] = xs[i] - origin.x();
      dy[i] = ys[i] - origin.y();
      dz[i] = zs[i] - origin.z();
    }
    double ax[3][N], ay[3][N], az[3][N];
    for (int r = 0; r < 3; ++r) {
      for (int i = 0; i < N; ++i) {
        ax[r][i] = P(r, 0) * dx[i];
        ay[r][i] = P(r, 1) * dy[i];
        az[r][i] = P(r, 2) * dz[i] + offset[r];
      }
    }
    for (int k = 0; k < N; ++k) {
      for (int j = 0; j < N; ++j) {
        for (int i = 0; i < N; ++i) {
          const int n = i + N * (j + N * k);
          z[n] = ax[2][i] + ay[2][j] + az[2][k];
          const double inv = 1.0 / z[n];
          uv[2 * n] = (ax[0][i] + ay[0][j] + az[0][k]) * inv;
          uv[2 * n + 1] = (ax[1][i] + ay[1][j] + az[1][k]) * inv;
        }
      }
    }
  }

  /// P (p_W, 1), the homogeneous image point, computed relative to the
  /// camera centre like ProjectGrid(): its error is of the order of 1e-16
  /// times P's rows times the distance of p_W from the camera, not times the
  /// coordinates. For P = [R | t] it is the camera-frame point.
  [[nodiscard]] Eigen::Vector3d Homogeneous(const Eigen::Vector3d& p_W) const {
    const Eigen::Vector3d d = p_W - origin;
    Eigen::Vector3d out;
    for (int r = 0; r < 3; ++r)
      out[r] = P(r, 0) * d.x() + P(r, 1) * d.y() + (P(r, 2) * d.z() + offset[r]);
    return out;
  }

  /// Image coordinates (u, v) of p_W (meaningful where it lies in front), by
  /// the same arithmetic as ProjectGrid().
  [[nodiscard]] Eigen::Vector2d ProjectPoint(const Eigen::Vector3d& p_W) const {
    const double xs[1] = {p_W.x()}, ys[1] = {p_W.y()}, zs[1] = {p_W.z()};
    double uv[2], z[1];
    ProjectGrid<1>(xs, ys, zs, uv, z);
    return {uv[0], uv[1]};
  }

  /// Footprint of the box [lo, hi]. Every point of the box projects inside
  /// `rect` when the box lies in front (the projection of a box is the convex
  /// hull of its projected corners).
  [[nodiscard]] Footprint Project(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) const {
    const double xs[2] = {lo.x(), hi.x()}, ys[2] = {lo.y(), hi.y()}, zs[2] = {lo.z(), hi.z()};
    alignas(16) double uv[16];
    double z[8];
    ProjectGrid<2>(xs, ys, zs, uv, z);
    return FromCorners<2>(uv, z, 0, 0, 0);
  }

  /// Footprint of the box whose lowest corner is grid point (i, j, k) of a grid
  /// projected by ProjectGrid<N>.
  template <int N>
  [[nodiscard]] static Footprint FromCorners(const double* uv, const double* z, int i, int j,
                                             int k) {
    const int base = i + N * (j + N * k);
    const int idx[8] = {base,         base + 1,         base + N,         base + N + 1,
                        base + N * N, base + N * N + 1, base + N * N + N, base + N * N + N + 1};
    double z_min = z[idx[0]], z_max = z[idx[0]];
    for (int c = 1; c < 8; ++c) {
      z_min = std::min(z_min, z[idx[c]]);
      z_max = std::max(z_max, z[idx[c]]);
    }
    Footprint f;
    f.z_near = z_min;
    f.z_far = z_max;
    if (z_max <= 0.0) {
      f.side = Footprint::Side::kBehind;
      return f;
    }
    if (z_min <= kMinFrontDepth) {
      f.side = Footprint::Side::kStraddling;
      return f;
    }
    f.side = Footprint::Side::kInFront;
#if defined(__SSE2__)
    // u and v side by side: the same operations as below, two at a time.
    __m128d lo = _mm_loadu_pd(uv + 2 * idx[0]);
    __m128d hi = lo;
    for (int c = 1; c < 8; ++c) {
      const __m128d p = _mm_loadu_pd(uv + 2 * idx[c]);
      lo = _mm_min_pd(p, lo);
      hi = _mm_max_pd(p, hi);
    }
    const __m128d slack = _mm_set1_pd(kFootprintSlackPx);
    int low[2], high[2];
    PixelsOf(_mm_sub_pd(lo, slack), low);
    PixelsOf(_mm_add_pd(hi, slack), high);
    f.rect.u0 = low[0];
    f.rect.v0 = low[1];
    f.rect.u1 = high[0];
    f.rect.v1 = high[1];
#else
    double u_min = uv[2 * idx[0]], u_max = u_min, v_min = uv[2 * idx[0] + 1], v_max = v_min;
    for (int c = 1; c < 8; ++c) {
      u_min = std::min(u_min, uv[2 * idx[c]]);
      u_max = std::max(u_max, uv[2 * idx[c]]);
      v_min = std::min(v_min, uv[2 * idx[c] + 1]);
      v_max = std::max(v_max, uv[2 * idx[c] + 1]);
    }
    f.rect.u0 = PixelOf(u_min - kFootprintSlackPx);
    f.rect.u1 = PixelOf(u_max + kFootprintSlackPx);
    f.rect.v0 = PixelOf(v_min - kFootprintSlackPx);
    f.rect.v1 = PixelOf(v_max + kFootprintSlackPx);
#endif
    return f;
  }

#if defined(__SSE2__)
  /// PixelOf() of both halves of x (finite), into out[0] and out[1].
  static void PixelsOf(__m128d x, int* out) {
    __m128d y = _mm_add_pd(x, _mm_set1_pd(0.5));
    y = _mm_min_pd(_mm_max_pd(y, _mm_set1_pd(-1e9)), _mm_set1_pd(1e9));
    // Truncation, then one less where it rounded up (negative non-integers).
    __m128i t = _mm_cvttpd_epi32(y);
    const __m128d above = _mm_cmpgt_pd(_mm_cvtepi32_pd(t), y);
    t = _mm_add_epi32(t, _mm_shuffle_epi32(_mm_castpd_si128(above), _MM_SHUFFLE(2, 0, 2, 0)));
    out[0] = _mm_cvtsi128_si32(t);
    out[1] = _mm_cvtsi128_si32(_mm_shuffle_epi32(t, _MM_SHUFFLE(1, 1, 1, 1)));
  }
#endif
};

/// Intersection of a rectangle with the image [0, width) x [0, height).
inline PixelRect ClipToImage(const PixelRect& r, int width, int height) {
  return {std::max(r.u0, 0), std::max(r.v0, 0), std::min(r.u1, width - 1),
          std::min(r.v1, height - 1)};
}

inline bool InsideImage(const PixelRect& r, int width, int height) {
  return r.u0 >= 0 && r.v0 >= 0 && r.u1 < width && r.v1 < height;
}

}  // namespace hg::geometry
