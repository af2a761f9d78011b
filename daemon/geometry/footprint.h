#pragma once
/// @file
/// The footprint of an axis-aligned box in a pinhole camera: the integer pixel
/// rectangle covering the projection of its 8 corners, and its depth range.

#include <algorithm>
#include <cmath>

#include <Eigen/Core>

#include "geometry/camera.h"

namespace hg::geometry {

/// Smallest camera depth (m) at which a corner counts as in front of the camera.
inline constexpr double kMinFrontDepth = 1e-6;
/// Slack (pixels) added on each side before rounding to pixels, so that rounding
/// errors of the projection can only grow the rectangle.
inline constexpr double kFootprintSlackPx = 1e-6;

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
struct BoxProjector {
  Eigen::Matrix<double, 3, 4> P;

  explicit BoxProjector(const Eigen::Matrix<double, 3, 4>& projection) : P(projection) {}

  /// Footprint of the box [lo, hi]. Every point of the box projects inside
  /// `rect` when the box lies in front (the projection of a box is the convex
  /// hull of its projected corners).
  [[nodiscard]] Footprint Project(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) const {
    double u_min = 1e300, u_max = -1e300, v_min = 1e300, v_max = -1e300;
    double z_min = 1e300, z_max = -1e300;
    // Row terms for the low and high value of each axis.
    double ax[3][2], ay[3][2], az[3][2];
    for (int r = 0; r < 3; ++r) {
      ax[r][0] = P(r, 0) * lo.x();
      ax[r][1] = P(r, 0) * hi.x();
      ay[r][0] = P(r, 1) * lo.y();
      ay[r][1] = P(r, 1) * hi.y();
      az[r][0] = P(r, 2) * lo.z() + P(r, 3);
      az[r][1] = P(r, 2) * hi.z() + P(r, 3);
    }
    double us[8], vs[8], zs[8];
    for (int i = 0; i < 8; ++i) {
      const int bx = i & 1, by = (i >> 1) & 1, bz = (i >> 2) & 1;
      zs[i] = ax[2][bx] + ay[2][by] + az[2][bz];
      us[i] = ax[0][bx] + ay[0][by] + az[0][bz];
      vs[i] = ax[1][bx] + ay[1][by] + az[1][bz];
    }
    for (int i = 0; i < 8; ++i) {
      z_min = std::min(z_min, zs[i]);
      z_max = std::max(z_max, zs[i]);
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
    for (int i = 0; i < 8; ++i) {
      const double inv = 1.0 / zs[i];
      const double u = us[i] * inv;
      const double v = vs[i] * inv;
      u_min = std::min(u_min, u);
      u_max = std::max(u_max, u);
      v_min = std::min(v_min, v);
      v_max = std::max(v_max, v);
    }
    // Pixel u covers [u - 0.5, u + 0.5): a coordinate x lies in pixel floor(x + 0.5).
    auto to_pixel = [](double x) {
      return static_cast<int>(std::floor(std::clamp(x + 0.5, -1e9, 1e9)));
    };
    f.side = Footprint::Side::kInFront;
    f.rect.u0 = to_pixel(u_min - kFootprintSlackPx);
    f.rect.u1 = to_pixel(u_max + kFootprintSlackPx);
    f.rect.v0 = to_pixel(v_min - kFootprintSlackPx);
    f.rect.v1 = to_pixel(v_max + kFootprintSlackPx);
    return f;
  }
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
