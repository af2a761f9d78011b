#include "sim/mask_renderer.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <numeric>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/LU>

#include "common/check.h"

namespace hg::sim {
namespace {

using Eigen::Matrix2d;
using Eigen::Matrix3d;
using Eigen::Vector2d;
using Eigen::Vector3d;

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr float kInfF = std::numeric_limits<float>::infinity();

/// Side of the square tiles (in pixels) that bound the rays of distorted cameras.
constexpr int kTile = 16;

/// Growth of the per-pixel cone of a distorted lens over the angle to the
/// farthest undistorted pixel corner. The undistorted pixel square is a curved
/// quadrilateral; its edges bulge away from the corner chords by a second-order
/// amount (a tiny fraction of a pixel for any real lens), far below 50 %.
constexpr double kDistortedConeSafety = 1.5;

/// Extra radius of every cone test (metres, times D + 1 m) that absorbs the
/// float rounding of the camera-frame coordinates (relative error ~1e-7, so
/// ~1e-6 m at the scale of a work cell): an order of magnitude of headroom,
/// and still far below a pixel's footprint.
constexpr double kRadiusMarginRel = 1e-5;

/// A capsule whose inflated surface comes closer than this to the camera plane
/// (camera z, metres) has no bounded projection: every pixel is examined.
constexpr double kMinFrontZ = 1e-3;

/// Added to the depth beyond which a pixel hides capsules (metres): the
/// occlusion rule only drops capsules clearly behind an obstacle.
constexpr double kHiddenMarginM = 0.01;

/// Bounds of a set of rays in normalised image coordinates (x/z, y/z).
struct NormBox {
  double x0 = -kInf;
  double x1 = kInf;
  double y0 = -kInf;
  double y1 = kInf;

  void Extend(double x, double y) {
    x0 = std::min(x0, x);
    x1 = std::max(x1, x);
    y0 = std::min(y0, y);
    y1 = std::max(y1, y);
  }
  static NormBox Empty() { return {kInf, -kInf, kInf, -kInf}; }
};

/// Angle between the rays (a, 1) and (b, 1).
double RayAngle(const Vector2d& a, const Vector2d& b) {
  const Vector3d ra(a.x(), a.y(), 1.0);
  const Vector3d rb(b.x(), b.y(), 1.0);
  return std::atan2(ra.cross(rb).norm(), ra.dot(rb));
}

/// Rounds a non-negative double up to a float that is not smaller.
float FloatUp(double d) {
  float f = static_cast<float>(d);
  if (static_cast<double>(f) < d) f = std::nextafter(f, kInfF);
  return f;
}
float FloatDown(double d) {
  float f = static_cast<float>(d);
  if (static_cast<double>(f) > d) f = std::nextafter(f, -kInfF);
  return f;
}

double SegmentDistanceToOrigin(const Vector3d& a, const Vector3d& b) {
  const Vector3d e = b - a;
  const double len2 = e.squaredNorm();
  const double s = len2 > 0.0 ? std::clamp(-a.dot(e) / len2, 0.0, 1.0) : 0.0;
  return (a + s * e).norm();
}

/// Normalised-coordinate interval [t0, t1] of the tangent planes x = t z
/// (resp. y = t z) to the ball (c_h, c_z, radius), which lies in front with
/// c_z > radius: |c_h - t c_z| = radius sqrt(1 + t^2).
void BallInterval(double c_h, double c_z, double radius, double* t0, double* t1) {
  const double denom = c_z * c_z - radius * radius;
  const double root = radius * std::sqrt(std::max(0.0, c_h * c_h + denom));
  *t0 = (c_h * c_z - root) / denom;
  *t1 = (c_h * c_z + root) / denom;
}

/// Normalised bounds of the rays that meet the capsule (a, b, radius) given
/// in the camera frame; unbounded when it reaches near the camera plane.
NormBox CapsuleNormBox(const Vector3d& a, const Vector3d& b, double radius) {
  if (std::min(a.z(), b.z()) - radius < kMinFrontZ) {
    return NormBox{};
  }
  // The capsule is the convex hull of its end balls, and x/z is extreme over a
  // convex set in front of the camera where it is extreme over the generators.
  NormBox box = NormBox::Empty();
  for (const Vector3d* c : {&a, &b}) {
    double t0;
    double t1;
    double s0;
    double s1;
    BallInterval(c->x(), c->z(), radius, &t0, &t1);
    BallInterval(c->y(), c->z(), radius, &s0, &s1);
    box.Extend(t0, s0);
    box.Extend(t1, s1);
  }
  return box;
}

/// Normalised bounds of points in the camera frame (their convex hull's rays).
NormBox PointsNormBox(const Vector3d* points, int n) {
  NormBox box = NormBox::Empty();
  for (int i = 0; i < n; ++i) {
    if (points[i].z() < kMinFrontZ) {
      return NormBox{};
    }
    box.Extend(points[i].x() / points[i].z(), points[i].y() / points[i].z());
  }
  return box;
}

// -----------------------------------------------------------------------------
// Pixel rays of one camera.

/// Bounds of the rays of one tile of a distorted camera.
struct Tile {
  float x0 = kInfF;
  float x1 = -kInfF;
  float y0 = kInfF;
  float y1 = -kInfF;
  float tan_alpha = 0.0F;  ///< Largest cone tangent of the tile's image pixels.
};

/// Rays through the pixel centres of one camera as unnormalised directions
/// (x, y, 1) in the camera frame, for pixels -1..width and -1..height (a
/// one-pixel border for the occlusion neighbourhoods), and the half-angle of a
/// cone about each that contains the rays through the closed pixel square.
/// Pinhole rays are analytic; distorted ones come from a table.
class CameraRays {
 public:
  explicit CameraRays(const geometry::CameraModel& camera)
      : width_(camera.width),
        height_(camera.height),
        grid_w_(camera.width + 2),
        grid_h_(camera.height + 2),
        fx_(camera.K(0, 0)),
        fy_(camera.K(1, 1)),
        skew_(camera.K(0, 1)),
        cx_(camera.K(0, 2)),
        cy_(camera.K(1, 2)),
        pinhole_(!camera.HasDistortion()) {
    HG_CHECK(fx_ > 0.0 && fy_ > 0.0);
    if (pinhole_) {
      InitPinhole();
    } else {
      InitDistorted(camera);
    }
  }

  [[nodiscard]] bool pinhole() const { return pinhole_; }
  [[nodiscard]] double max_tan_alpha() const { return max_tan_alpha_; }

  /// Normalised ray of pixel (u, v), -1 <= u <= width, -1 <= v <= height; NaN
  /// where the lens model cannot be inverted.
  [[nodiscard]] Vector2d Ray(int u, int v) const {
    if (pinhole_) {
      const double y = (v - cy_) / fy_;
      return {(u - cx_ - skew_ * y) / fx_, y};
    }
    const std::size_t i = GridIndex(u, v);
    return {xs_[i], ys_[i]};
  }
  [[nodiscard]] bool Valid(int u, int v) const {
    return pinhole_ || !std::isnan(xs_[GridIndex(u, v)]);
  }
  /// Cone tangent for pixel (u, v) of the image.
  [[nodiscard]] double TanAlpha(int u, int v) const {
    if (pinhole_) {
      return max_tan_alpha_;
    }
    return tiles_[TileIndex(u, v)].tan_alpha;
  }

  [[nodiscard]] const float* XRow(int u, int v) const { return xs_.data() + GridIndex(u, v); }
  [[nodiscard]] const float* YRow(int u, int v) const { return ys_.data() + GridIndex(u, v); }
  [[nodiscard]] double fx() const { return fx_; }
  [[nodiscard]] double fy() const { return fy_; }
  [[nodiscard]] double skew() const { return skew_; }
  [[nodiscard]] double cx() const { return cx_; }
  [[nodiscard]] double cy() const { return cy_; }

  /// Calls f(v, u0, u1, tan_alpha) for row spans of pixels inside
  /// [u_min, u_max] x [v_min, v_max] that hold every pixel whose centre ray
  /// lies in `box`; tan_alpha bounds the cone of every pixel of the span.
  template <class F>
  void ForEachSpan(const NormBox& box, int u_min, int u_max, int v_min, int v_max, F&& f) const {
    if (!(box.x0 <= box.x1) || !(box.y0 <= box.y1)) {
      return;
    }
    if (pinhole_) {
      PinholeSpans(box, u_min, u_max, v_min, v_max, f);
    } else {
      TileSpans(box, u_min, u_max, v_min, v_max, f);
    }
  }

 private:
  [[nodiscard]] std::size_t GridIndex(int u, int v) const {
    return static_cast<std::size_t>(v + 1) * grid_w_ + (u + 1);
  }
  [[nodiscard]] std::size_t TileIndex(int u, int v) const {
    return static_cast<std::size_t>((v + 1) / kTile) * tiles_x_ + (u + 1) / kTile;
  }

  void InitPinhole() {
    // The closed pixel square lies within distance d of its centre on the
    // plane z = 1 (d: the largest corner offset, K^-1 of (+-0.5, +-0.5)).
    // Radial projection onto the unit sphere is 1-Lipschitz outside the unit
    // ball, so the chord between the unit rays is at most d and the angle at
    // most 2 asin(d / 2). Constant over the image.
    double d = 0.0;
    for (const double du : {-0.5, 0.5}) {
      for (const double dv : {-0.5, 0.5}) {
        const double dy = dv / fy_;
        const double dx = (du - skew_ * dy) / fx_;
        d = std::max(d, std::hypot(dx, dy));
      }
    }
    const double alpha = 2.0 * std::asin(std::min(1.0, 0.5 * d));
    max_tan_alpha_ = std::tan(alpha) * (1.0 + 1e-9);
  }

  /// Whether the lens model keeps a positive Jacobian determinant all along
  /// the straight path from the optical axis to the normalised point `x`
  /// (sampled): a root of the inversion past a fold is no ray of the lens,
  /// even where the polynomial rises again.
  static bool OnPrimaryBranch(const std::array<double, 5>& k, const Vector2d& x) {
    constexpr int kSamples = 1024;
    for (int i = 1; i <= kSamples; ++i) {
      Matrix2d jacobian;
      (void)geometry::ApplyDistortion(k, x * (static_cast<double>(i) / kSamples), &jacobian);
      if (!(jacobian.determinant() > 0.0)) return false;
    }
    return true;
  }

  /// Lens-free rays of the image points (u0 + i, v0 + j), i < nu, j < nv
  /// (NaN where there is none), on the lens model's primary branch: solved
  /// outward from the point nearest the principal point, whose root is
  /// checked along its path from the axis, each further point from its inner
  /// neighbour's solution (continuation). A point whose inner neighbour has
  /// no ray gets none: started afresh (from its distorted position, or from
  /// a neighbour across a fold) the solver may settle on a root of another
  /// branch, whose ray the lens never sees through this pixel.
  std::vector<Vector2d> InvertGrid(const geometry::CameraModel& camera, double u0, double v0,
                                   int nu, int nv) const {
    const Matrix3d K_inv = camera.K.inverse();
    auto normalised = [&K_inv](double u, double v) {
      return Vector2d(K_inv(0, 0) * u + K_inv(0, 1) * v + K_inv(0, 2),
                      K_inv(1, 1) * v + K_inv(1, 2));
    };
    std::vector<Vector2d> out(static_cast<std::size_t>(nu) * nv, Vector2d::Constant(std::nan("")));
    auto at = [&](int i, int j) -> Vector2d& { return out[static_cast<std::size_t>(j) * nu + i]; };
    auto solve = [&](int i, int j, const Vector2d& start) {
      if (!start.allFinite()) return;
      Vector2d x = start;
      if (geometry::InvertDistortion(camera.distortion, normalised(u0 + i, v0 + j), &x)) {
        at(i, j) = x;
      }
    };
    const auto nearest = [](double c, int n) {
      return static_cast<int>(std::clamp(std::round(c), 0.0, static_cast<double>(n - 1)));
    };
    const int i0 = nearest(cx_ - u0, nu);
    const int j0 = nearest(cy_ - v0, nv);
    solve(i0, j0, normalised(u0 + i0, v0 + j0));
    if (at(i0, j0).allFinite() && !OnPrimaryBranch(camera.distortion, at(i0, j0))) {
      at(i0, j0) = Vector2d::Constant(std::nan(""));
    }
    for (const int step : {-1, 1}) {
      for (int j = j0 + step; j >= 0 && j < nv; j += step) solve(i0, j, at(i0, j - step));
    }
    for (int j = 0; j < nv; ++j) {
      for (const int step : {-1, 1}) {
        for (int i = i0 + step; i >= 0 && i < nu; i += step) solve(i, j, at(i - step, j));
      }
    }
    return out;
  }

  void InitDistorted(const geometry::CameraModel& camera) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    // Pixel centres, u = -1..width, v = -1..height.
    const std::vector<Vector2d> centres = InvertGrid(camera, -1.0, -1.0, grid_w_, grid_h_);
    xs_.assign(static_cast<std::size_t>(grid_w_) * grid_h_, nan);
    ys_.assign(xs_.size(), nan);
    for (std::size_t i = 0; i < centres.size(); ++i) {
      if (!centres[i].allFinite()) continue;
      xs_[i] = static_cast<float>(centres[i].x());
      ys_[i] = static_cast<float>(centres[i].y());
    }
    // Pixel corners (u - 0.5, v - 0.5), u = 0..width, v = 0..height.
    const int cw = width_ + 1;
    const std::vector<Vector2d> corners = InvertGrid(camera, -0.5, -0.5, cw, height_ + 1);
    // Per pixel: the cone reaches kDistortedConeSafety times past the farthest
    // corner ray; tiles keep the largest. Pixels without a valid cone lose their
    // centre ray (they are drawn as foreground by the renderer).
    tiles_x_ = (grid_w_ + kTile - 1) / kTile;
    tiles_y_ = (grid_h_ + kTile - 1) / kTile;
    tiles_.assign(static_cast<std::size_t>(tiles_x_) * tiles_y_, Tile{});
    constexpr double kMaxAlpha = 1.3;  // rad; wider cones mean a broken model.
    for (int v = 0; v < height_; ++v) {
      for (int u = 0; u < width_; ++u) {
        const std::size_t gi = GridIndex(u, v);
        const Vector2d centre(xs_[gi], ys_[gi]);
        double alpha = 0.0;
        for (int k = 0; k < 4; ++k) {
          const Vector2d& c = corners[static_cast<std::size_t>(v + (k >> 1)) * cw + u + (k & 1)];
          const double angle = RayAngle(centre, c);
          alpha = std::isfinite(angle) ? std::max(alpha, angle) : kInf;
        }
        alpha *= kDistortedConeSafety;
        if (!std::isfinite(centre.x()) || !(alpha < kMaxAlpha)) {
          xs_[gi] = nan;
          ys_[gi] = nan;
          continue;
        }
        Tile& tile = tiles_[TileIndex(u, v)];
        tile.tan_alpha = std::max(tile.tan_alpha, FloatUp(std::tan(alpha)));
      }
    }
    for (int gv = 0; gv < grid_h_; ++gv) {
      for (int gu = 0; gu < grid_w_; ++gu) {
        const std::size_t gi = static_cast<std::size_t>(gv) * grid_w_ + gu;
        if (std::isnan(xs_[gi])) {
          continue;
        }
        Tile& tile = tiles_[static_cast<std::size_t>(gv / kTile) * tiles_x_ + gu / kTile];
        tile.x0 = std::min(tile.x0, xs_[gi]);
        tile.x1 = std::max(tile.x1, xs_[gi]);
        tile.y0 = std::min(tile.y0, ys_[gi]);
        tile.y1 = std::max(tile.y1, ys_[gi]);
      }
    }
    row_y0_.assign(tiles_y_, kInfF);
    row_y1_.assign(tiles_y_, -kInfF);
    max_tan_alpha_ = 0.0;
    for (int ty = 0; ty < tiles_y_; ++ty) {
      for (int tx = 0; tx < tiles_x_; ++tx) {
        const Tile& tile = tiles_[static_cast<std::size_t>(ty) * tiles_x_ + tx];
        row_y0_[ty] = std::min(row_y0_[ty], tile.y0);
        row_y1_[ty] = std::max(row_y1_[ty], tile.y1);
        max_tan_alpha_ = std::max(max_tan_alpha_, static_cast<double>(tile.tan_alpha));
      }
    }
  }

  template <class F>
  void PinholeSpans(const NormBox& box, int u_min, int u_max, int v_min, int v_max, F& f) const {
    // Pixel coordinates: v = fy y + cy, u = fx x + skew y + cx. A one-pixel
    // slack absorbs the rounding of these bounds.
    auto clamp_to_int = [](double value, int lo, int hi) {
      if (!(value > lo)) return lo;  // Also NaN.
      if (!(value < hi)) return hi;
      return static_cast<int>(value);
    };
    const double v_lo = fy_ * box.y0 + cy_;
    const double v_hi = fy_ * box.y1 + cy_;
    double u_lo = fx_ * box.x0 + cx_;
    double u_hi = fx_ * box.x1 + cx_;
    if (skew_ != 0.0) {
      const double s0 = skew_ * box.y0;
      const double s1 = skew_ * box.y1;
      u_lo += std::min(s0, s1);
      u_hi += std::max(s0, s1);
    }
    const int v0 = clamp_to_int(std::floor(v_lo) - 1.0, v_min, v_max + 1);
    const int v1 = clamp_to_int(std::ceil(v_hi) + 1.0, v_min - 1, v_max);
    const int u0 = clamp_to_int(std::floor(u_lo) - 1.0, u_min, u_max + 1);
    const int u1 = clamp_to_int(std::ceil(u_hi) + 1.0, u_min - 1, u_max);
    if (u1 < u0) {
      return;
    }
    for (int v = v0; v <= v1; ++v) {
      f(v, u0, u1, max_tan_alpha_);
    }
  }

  template <class F>
  void TileSpans(const NormBox& box, int u_min, int u_max, int v_min, int v_max, F& f) const {
    for (int ty = 0; ty < tiles_y_; ++ty) {
      if (!(row_y0_[ty] <= box.y1 && row_y1_[ty] >= box.y0)) {
        continue;
      }
      int c0 = tiles_x_;
      int c1 = -1;
      float tan_alpha = 0.0F;
      for (int tx = 0; tx < tiles_x_; ++tx) {
        const Tile& t = tiles_[static_cast<std::size_t>(ty) * tiles_x_ + tx];
        if (t.x0 <= box.x1 && t.x1 >= box.x0 && t.y0 <= box.y1 && t.y1 >= box.y0) {
          c0 = std::min(c0, tx);
          c1 = tx;
        }
      }
      if (c1 < c0) {
        continue;
      }
      for (int tx = c0; tx <= c1; ++tx) {
        tan_alpha =
            std::max(tan_alpha, tiles_[static_cast<std::size_t>(ty) * tiles_x_ + tx].tan_alpha);
      }
      // Grid coordinates are pixel coordinates + 1.
      const int u0 = std::max(u_min, c0 * kTile - 1);
      const int u1 = std::min(u_max, (c1 + 1) * kTile - 2);
      const int v0 = std::max(v_min, ty * kTile - 1);
      const int v1 = std::min(v_max, (ty + 1) * kTile - 2);
      if (u1 < u0) {
        continue;
      }
      for (int v = v0; v <= v1; ++v) {
        f(v, u0, u1, static_cast<double>(tan_alpha));
      }
    }
  }

  int width_;
  int height_;
  int grid_w_;
  int grid_h_;
  double fx_;
  double fy_;
  double skew_;
  double cx_;
  double cy_;
  bool pinhole_;
  double max_tan_alpha_ = 0.0;
  // Distorted only: grid rays (NaN where invalid) and tiles over the grid.
  std::vector<float> xs_;
  std::vector<float> ys_;
  int tiles_x_ = 0;
  int tiles_y_ = 0;
  std::vector<Tile> tiles_;
  std::vector<float> row_y0_;
  std::vector<float> row_y1_;
};

// -----------------------------------------------------------------------------
// The per-pixel capsule test.
//
// For the pixel ray u = (x, y, 1) and the segment a-b (camera frame), with
// P = a x u, Q = b x u and E = Q - P = (b - a) x u, the squared distance from
// the segment point a + s (b - a) to the line of u, times |u|^2, is
// |P + s E|^2 = C + 2 B s + A s^2 (C = |P|^2, B = P . E, A = |E|^2). Its minimum
// over s in [0, 1] is at an end (|P|^2 or |Q|^2) or, when 0 < -B < A, inside,
// where it equals (A C - B^2) / A. The pixel is hit when that minimum is at
// most R^2 |u|^2.
//
// Rounding (float): each component of P and Q comes from camera-frame
// coordinates of a few metres, so it is off by ~1e-7 of that scale, i.e. the
// distances tested are off by ~1e-6 m; the radius margin of 1e-5 (D + 1 m)
// covers that tenfold. The interior minimum is tested as |A P - B E|^2 <=
// R^2 |u|^2 A^2 (A P - B E = A (P + s E) at s = -B / A), whose components
// carry a rounding of ~1e-7 A |P| (|B| <= |P| |E|, |E|^2 = A), the same
// distance error as P's; not as A C - B^2 <= R^2 |u|^2 A: that difference
// of two products of the ends' distances cancels with an error of ~1e-7 A C,
// which for a long, thin part (ends metres off the ray, a radius of a
// millimetre) exceeds R^2 A. Within the loader's coordinates (1e6 m) the
// products stay far below float's range. Where B or A are rounded across a
// case boundary, the interior minimum and the end value agree to the same
// order. Where E vanishes in rounding (the ray along the segment), the
// interior test can only pass spuriously, which adds pixels.

struct SegmentF {
  float ax, ay, az, bx, by, bz;
};

/// Tests the pixels i = 0..n-1 of one row span and ORs 255 into out[i] where
/// hit. Rays: from xs/ys when kTable, else x = x0 + i dx at height y.
template <bool kTable, bool kOcclusion>
void MarkSpan(const SegmentF& s, float r2, float near, const float* __restrict xs,
              const float* __restrict ys, float x0, float dx, float y, const float* __restrict thr,
              int n, std::uint8_t* __restrict out) {
  for (int i = 0; i < n; ++i) {
    float x;
    float yy;
    if constexpr (kTable) {
      x = xs[i];
      yy = ys[i];
    } else {
      x = x0 + dx * static_cast<float>(i);
      yy = y;
    }
    const float p0 = s.ay - s.az * yy;
    const float p1 = s.az * x - s.ax;
    const float p2 = s.ax * yy - s.ay * x;
    const float q0 = s.by - s.bz * yy;
    const float q1 = s.bz * x - s.bx;
    const float q2 = s.bx * yy - s.by * x;
    const float e0 = q0 - p0;
    const float e1 = q1 - p1;
    const float e2 = q2 - p2;
    const float t = r2 * (x * x + yy * yy + 1.0F);
    const float ca = p0 * p0 + p1 * p1 + p2 * p2;
    const float cb = q0 * q0 + q1 * q1 + q2 * q2;
    const float aa = e0 * e0 + e1 * e1 + e2 * e2;
    const float bb = p0 * e0 + p1 * e1 + p2 * e2;
    // The interior minimum |P + s E|^2 at s = -B / A, times A^2: the squared
    // length of the vector A P - B E (not (A C - B^2) A, whose cancellation
    // loses the squared distance of the ends, not of the closest point: a
    // thin cable 10 m long had holes). No division: the loop stays vectorised.
    const float v0 = aa * p0 - bb * e0;
    const float v1 = aa * p1 - bb * e1;
    const float v2 = aa * p2 - bb * e2;
    bool hit = (ca <= t) | (cb <= t) |
               ((bb < 0.0F) & (-bb < aa) & (v0 * v0 + v1 * v1 + v2 * v2 <= t * aa * aa));
    if constexpr (kOcclusion) {
      hit = hit & (near <= thr[i]);
    }
    out[i] = static_cast<std::uint8_t>(out[i] | (hit ? 0xFF : 0x00));
  }
}

// -----------------------------------------------------------------------------
// Obstacle depth along pixel-centre rays (construction only).

/// A convex piece of an obstacle in the camera frame with the id of the convex
/// set it belongs to (equal ids: the same convex solid, or the same triangle).
struct BoxPiece {
  Matrix3d R_BC;  // camera -> box
  Vector3d o_B;   // camera centre in the box frame
  Vector3d half;
};
struct CylinderPiece {
  Vector3d a;
  Vector3d b;
  double radius;
};
struct CapsulePiece {
  Vector3d a;
  Vector3d b;
  double radius;
};
struct TrianglePiece {
  Vector3d p0;
  Vector3d p1;
  Vector3d p2;
};
using Piece = std::variant<BoxPiece, CylinderPiece, CapsulePiece, TrianglePiece>;

/// Intersects [*t0, *t1] with the ray parameters where the slab
/// lo <= o + t d <= hi holds; false when empty.
bool ClipSlab(double o, double d, double lo, double hi, double* t0, double* t1) {
  if (d == 0.0) {
    return o >= lo && o <= hi;
  }
  double ta = (lo - o) / d;
  double tb = (hi - o) / d;
  if (ta > tb) std::swap(ta, tb);
  *t0 = std::max(*t0, ta);
  *t1 = std::min(*t1, tb);
  return *t0 <= *t1;
}

/// Ray (origin, direction u) against a sphere; entry t >= 0 or +inf.
double SphereEntry(const Vector3d& u, const Vector3d& c, double radius) {
  const double a = u.squaredNorm();
  const double b = -u.dot(c);
  const double cc = c.squaredNorm() - radius * radius;
  const double disc = b * b - a * cc;
  if (disc < 0.0) {
    return kInf;
  }
  const double root = std::sqrt(disc);
  const double t1 = (-b + root) / a;
  if (t1 < 0.0) {
    return kInf;
  }
  return std::max(0.0, (-b - root) / a);
}

/// Ray from the origin along u against the finite cylinder a-b; entry t >= 0 or +inf.
double CylinderEntry(const Vector3d& u, const Vector3d& a, const Vector3d& b, double radius) {
  const Vector3d axis = b - a;
  const double length = axis.norm();
  if (!(length > 0.0)) {
    return kInf;
  }
  const Vector3d w = axis / length;
  double t0 = 0.0;
  double t1 = kInf;
  // Between the caps: 0 <= (t u - a) . w <= length.
  if (!ClipSlab(-a.dot(w), u.dot(w), 0.0, length, &t0, &t1)) {
    return kInf;
  }
  // Inside the infinite cylinder: |o + t m| <= radius, radial parts o, m.
  const Vector3d o = -a + a.dot(w) * w;
  const Vector3d m = u - u.dot(w) * w;
  const double qa = m.squaredNorm();
  const double qb = o.dot(m);
  const double qc = o.squaredNorm() - radius * radius;
  if (qa == 0.0) {
    if (qc > 0.0) return kInf;
  } else {
    const double disc = qb * qb - qa * qc;
    if (disc < 0.0) return kInf;
    const double root = std::sqrt(disc);
    t0 = std::max(t0, (-qb - root) / qa);
    t1 = std::min(t1, (-qb + root) / qa);
  }
  return t0 <= t1 ? t0 : kInf;
}

double TriangleEntry(const Vector3d& u, const TrianglePiece& tri) {
  const Vector3d e1 = tri.p1 - tri.p0;
  const Vector3d e2 = tri.p2 - tri.p0;
  const Vector3d pv = u.cross(e2);
  const double det = e1.dot(pv);
  if (det == 0.0) return kInf;
  const double inv = 1.0 / det;
  const Vector3d tv = -tri.p0;
  const double bu = tv.dot(pv) * inv;
  if (bu < 0.0 || bu > 1.0) return kInf;
  const Vector3d qv = tv.cross(e1);
  const double bv = u.dot(qv) * inv;
  if (bv < 0.0 || bu + bv > 1.0) return kInf;
  const double t = e2.dot(qv) * inv;
  return t >= 0.0 ? t : kInf;
}

/// Ray parameter t (the hit's camera z, u = (x, y, 1)) where the ray from the
/// camera centre enters the piece; +inf when it misses.
double PieceEntry(const Piece& piece, const Vector3d& u) {
  return std::visit(
      [&u](const auto& p) -> double {
        using T = std::decay_t<decltype(p)>;
        if constexpr (std::is_same_v<T, BoxPiece>) {
          const Vector3d d = p.R_BC * u;
          double t0 = 0.0;
          double t1 = kInf;
          for (int i = 0; i < 3; ++i) {
            if (!ClipSlab(p.o_B[i], d[i], -p.half[i], p.half[i], &t0, &t1)) return kInf;
          }
          return t0;
        } else if constexpr (std::is_same_v<T, CylinderPiece>) {
          return CylinderEntry(u, p.a, p.b, p.radius);
        } else if constexpr (std::is_same_v<T, CapsulePiece>) {
          return std::min({SphereEntry(u, p.a, p.radius), SphereEntry(u, p.b, p.radius),
                           CylinderEntry(u, p.a, p.b, p.radius)});
        } else {
          return TriangleEntry(u, p);
        }
      },
      piece);
}

/// Normalised bounds of a piece's rays.
NormBox PieceNormBox(const Piece& piece) {
  return std::visit(
      [](const auto& p) -> NormBox {
        using T = std::decay_t<decltype(p)>;
        if constexpr (std::is_same_v<T, BoxPiece>) {
          std::array<Vector3d, 8> corners;
          const Matrix3d R_CB = p.R_BC.transpose();
          const Vector3d centre_C = -R_CB * p.o_B;
          for (int i = 0; i < 8; ++i) {
            const Vector3d local((i & 1) ? p.half.x() : -p.half.x(),
                                 (i & 2) ? p.half.y() : -p.half.y(),
                                 (i & 4) ? p.half.z() : -p.half.z());
            corners[i] = centre_C + R_CB * local;
          }
          return PointsNormBox(corners.data(), 8);
        } else if constexpr (std::is_same_v<T, TrianglePiece>) {
          const std::array<Vector3d, 3> corners = {p.p0, p.p1, p.p2};
          return PointsNormBox(corners.data(), 3);
        } else {
          return CapsuleNormBox(p.a, p.b, p.radius);
        }
      },
      piece);
}

/// Groups the triangles of a mesh into convex pieces: a connected component
/// that is a closed surface with every vertex on one side of every face plane
/// bounds a convex solid and gets one id; any other triangle gets its own.
std::vector<int> ConvexGroups(const geometry::TriangleMesh& mesh, int* next_id) {
  const int nv = static_cast<int>(mesh.vertices.size());
  std::vector<int> parent(nv);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&parent](int i) {
    while (parent[i] != i) {
      parent[i] = parent[parent[i]];
      i = parent[i];
    }
    return i;
  };
  for (const auto& t : mesh.triangles) {
    parent[find(t[1])] = find(t[0]);
    parent[find(t[2])] = find(t[0]);
  }
  // Triangles and vertices per component.
  std::vector<std::vector<int>> comp_tris(nv);
  std::vector<std::vector<int>> comp_verts(nv);
  for (int i = 0; i < static_cast<int>(mesh.triangles.size()); ++i) {
    comp_tris[find(mesh.triangles[i][0])].push_back(i);
  }
  for (int v = 0; v < nv; ++v) {
    comp_verts[find(v)].push_back(v);
  }
  std::vector<int> ids(mesh.triangles.size(), -1);
  for (int c = 0; c < nv; ++c) {
    const std::vector<int>& tris = comp_tris[c];
    if (tris.empty()) {
      continue;
    }
    bool convex = static_cast<double>(tris.size()) * comp_verts[c].size() <= 2e7;
    // Closed: every edge appears exactly twice.
    if (convex) {
      std::vector<std::pair<int, int>> edges;
      for (const int ti : tris) {
        const auto& t = mesh.triangles[ti];
        for (int k = 0; k < 3; ++k) {
          edges.emplace_back(std::min(t[k], t[(k + 1) % 3]), std::max(t[k], t[(k + 1) % 3]));
        }
      }
      std::sort(edges.begin(), edges.end());
      for (std::size_t i = 0; i < edges.size() && convex;) {
        std::size_t j = i;
        while (j < edges.size() && edges[j] == edges[i]) ++j;
        convex = (j - i) == 2;
        i = j;
      }
    }
    for (std::size_t i = 0; i < tris.size() && convex; ++i) {
      const auto& t = mesh.triangles[tris[i]];
      const Vector3d& p0 = mesh.vertices[t[0]];
      const Vector3d n = (mesh.vertices[t[1]] - p0).cross(mesh.vertices[t[2]] - p0);
      const double scale = n.norm();
      if (!(scale > 0.0)) {
        continue;  // A degenerate triangle adds no face.
      }
      bool below = false;
      bool above = false;
      double extent = 0.0;
      for (const int v : comp_verts[c]) {
        extent = std::max(extent, (mesh.vertices[v] - p0).norm());
      }
      const double tol = 1e-9 * scale * std::max(1.0, extent);
      for (const int v : comp_verts[c]) {
        const double side = n.dot(mesh.vertices[v] - p0);
        below = below || side < -tol;
        above = above || side > tol;
      }
      convex = !(below && above);
    }
    if (convex) {
      const int id = (*next_id)++;
      for (const int ti : tris) ids[ti] = id;
    } else {
      for (const int ti : tris) ids[ti] = (*next_id)++;
    }
  }
  return ids;
}

/// Oriented box in the camera frame.
struct BoxC {
  Vector3d centre;
  Matrix3d R_CB;
  Vector3d half;
};

BoxC ToCameraBox(const geometry::CameraModel& camera, const BoxSolid& box) {
  return {camera.ToCamera(box.centre_W), camera.R_CW * box.R_WB, box.half_extents_m};
}

BoxSolid BoundsBox(const SolidGeometry& solid) {
  const common::Box3 b = Bounds(solid);
  BoxSolid box;
  box.centre_W = 0.5 * (b.min + b.max);
  box.half_extents_m = 0.5 * (b.max - b.min);
  return box;
}

}  // namespace

struct MaskRenderer::Impl {
  geometry::CameraModel camera;
  CameraRays rays;
  int width;
  int height;
  /// Static foreground (crates) and pixels without a valid lens model.
  std::vector<std::uint8_t> static_mask;
  /// Per pixel: a capsule whose nearest point is farther than this (metres
  /// from the camera centre) is hidden there; +inf where nothing is certain.
  std::vector<float> hidden_beyond;
  float min_hidden_beyond = kInfF;
  bool occlusion = false;

  Impl(const geometry::CameraModel& cam, const std::vector<Solid>& obstacles,
       const std::vector<Solid>& static_foreground, bool use_occlusion)
      : camera(cam), rays(cam), width(cam.width), height(cam.height) {
    HG_CHECK(width > 0 && height > 0);
    static_mask.assign(static_cast<std::size_t>(width) * height, 0);
    if (!rays.pinhole()) {
      for (int v = 0; v < height; ++v) {
        for (int u = 0; u < width; ++u) {
          if (!rays.Valid(u, v)) static_mask[static_cast<std::size_t>(v) * width + u] = 255;
        }
      }
    }
    if (use_occlusion && !obstacles.empty()) {
      BuildOcclusion(obstacles);
    }
    for (const Solid& solid : static_foreground) {
      DrawStatic(solid.geometry);
    }
  }

  // Occlusion, and why it is conservative.
  //
  // Depths are the distances from the camera centre to where the rays through
  // the pixel centres enter the nearest obstacle piece. Pieces are convex:
  // boxes, cylinders and capsules are, a closed mesh component counts as one
  // piece only when it is convex (checked), and otherwise each triangle is its
  // own piece. A pixel's bound is the largest of the nine depths of the 3x3
  // neighbourhood of centres, and exists only when all nine rays enter the
  // same piece O (+inf otherwise).
  //
  // Claim: every ray r through the closed pixel square meets O at a distance
  // no larger than that bound H. The square lies in the convex hull of the
  // nine neighbouring centres, so r lies in the convex cone of their rays.
  // Central projection maps the convex hull of the nine entry points h_i
  // (inside O, which is convex) onto that cone, so some point h of hull(h_i)
  // lies on r, and |h| <= max |h_i| = H because the norm is convex. A capsule
  // point q on r with |q| > H lies beyond h, and h (a point of an opaque
  // obstacle) hides it. So a capsule whose nearest point is farther than H is
  // hidden in every ray of the pixel, and dropping it there loses nothing.
  //
  // Assumptions: obstacles are opaque solids (a mesh is the closed surface of
  // one); for distorted lenses the undistorted pixel square lies within the
  // hull of the undistorted neighbouring centres, i.e. the lens is smooth at
  // the scale of a pixel (any real lens is). Neighbourhoods that straddle two
  // pieces (gaps between obstacles, edges) are never hidden: extra foreground.
  void BuildOcclusion(const std::vector<Solid>& obstacles) {
    std::vector<Piece> pieces;
    std::vector<int> piece_ids;
    int next_id = 0;
    for (const Solid& solid : obstacles) {
      std::visit(
          [&](const auto& s) {
            using T = std::decay_t<decltype(s)>;
            if constexpr (std::is_same_v<T, BoxSolid>) {
              const BoxC box = ToCameraBox(camera, s);
              const Matrix3d R_BC = box.R_CB.transpose();
              pieces.push_back(BoxPiece{R_BC, -(R_BC * box.centre), box.half});
              piece_ids.push_back(next_id++);
            } else if constexpr (std::is_same_v<T, CylinderSolid>) {
              if ((s.b_W - s.a_W).norm() > 0.0) {
                pieces.push_back(
                    CylinderPiece{camera.ToCamera(s.a_W), camera.ToCamera(s.b_W), s.radius_m});
                piece_ids.push_back(next_id++);
              }
            } else if constexpr (std::is_same_v<T, CapsuleSolid>) {
              pieces.push_back(
                  CapsulePiece{camera.ToCamera(s.a_W), camera.ToCamera(s.b_W), s.radius_m});
              piece_ids.push_back(next_id++);
            } else {
              const std::vector<int> ids = ConvexGroups(s.mesh, &next_id);
              for (std::size_t i = 0; i < s.mesh.triangles.size(); ++i) {
                const auto& t = s.mesh.triangles[i];
                pieces.push_back(TrianglePiece{camera.ToCamera(s.mesh.vertices[t[0]]),
                                               camera.ToCamera(s.mesh.vertices[t[1]]),
                                               camera.ToCamera(s.mesh.vertices[t[2]])});
                piece_ids.push_back(ids[i]);
              }
            }
          },
          solid.geometry);
    }

    // Nearest entry per pixel centre of the bordered grid.
    const int gw = width + 2;
    const int gh = height + 2;
    std::vector<double> depth(static_cast<std::size_t>(gw) * gh, kInf);
    std::vector<int> id(depth.size(), -1);
    for (std::size_t k = 0; k < pieces.size(); ++k) {
      rays.ForEachSpan(PieceNormBox(pieces[k]), -1, width, -1, height,
                       [&](int v, int u0, int u1, double /*tan_alpha*/) {
                         for (int u = u0; u <= u1; ++u) {
                           if (!rays.Valid(u, v)) continue;
                           const Vector2d xy = rays.Ray(u, v);
                           const Vector3d ray(xy.x(), xy.y(), 1.0);
                           const double t = PieceEntry(pieces[k], ray);
                           if (!(t < kInf)) continue;
                           const double dist = t * ray.norm();
                           const std::size_t gi = static_cast<std::size_t>(v + 1) * gw + (u + 1);
                           if (dist < depth[gi]) {
                             depth[gi] = dist;
                             id[gi] = piece_ids[k];
                           }
                         }
                       });
    }

    hidden_beyond.assign(static_cast<std::size_t>(width) * height, kInfF);
    min_hidden_beyond = kInfF;
    for (int v = 0; v < height; ++v) {
      for (int u = 0; u < width; ++u) {
        // Grid (u + 1, v + 1) is the pixel; its neighbours are u..u+2, v..v+2.
        const int id0 = id[static_cast<std::size_t>(v) * gw + u];
        double bound = 0.0;
        bool certain = id0 >= 0;
        for (int dv = 0; dv < 3 && certain; ++dv) {
          for (int du = 0; du < 3; ++du) {
            const std::size_t gi = static_cast<std::size_t>(v + dv) * gw + (u + du);
            if (id[gi] != id0) {
              certain = false;
              break;
            }
            bound = std::max(bound, depth[gi]);
          }
        }
        if (certain) {
          const float h = FloatUp(bound + kHiddenMarginM);
          hidden_beyond[static_cast<std::size_t>(v) * width + u] = h;
          min_hidden_beyond = std::min(min_hidden_beyond, h);
        }
      }
    }
    occlusion = min_hidden_beyond < kInfF;
    if (!occlusion) {
      hidden_beyond.clear();
    }
  }

  void DrawStatic(const SolidGeometry& geometry) {
    std::visit(
        [&](const auto& s) {
          using T = std::decay_t<decltype(s)>;
          if constexpr (std::is_same_v<T, BoxSolid>) {
            DrawStaticBox(s);
          } else if constexpr (std::is_same_v<T, CylinderSolid>) {
            // The capsule of a cylinder contains it.
            DrawCapsule(s.a_W, s.b_W, s.radius_m, static_mask.data());
          } else if constexpr (std::is_same_v<T, CapsuleSolid>) {
            DrawCapsule(s.a_W, s.b_W, s.radius_m, static_mask.data());
          } else {
            if (!s.mesh.vertices.empty()) DrawStaticBox(BoundsBox(geometry));
          }
        },
        geometry);
  }

  /// A pixel's cone meets the box when its centre ray (the half-line, as the
  /// cone's half-angle is below 90 degrees) passes within D tan(alpha) of the
  /// box, D bounding the distance of every box point (farthest corner): the
  /// slab test against the box grown by that much along each of its axes.
  void DrawStaticBox(const BoxSolid& solid) {
    const BoxC box = ToCameraBox(camera, solid);
    double far = 0.0;
    for (int i = 0; i < 8; ++i) {
      const Vector3d local((i & 1) ? box.half.x() : -box.half.x(),
                           (i & 2) ? box.half.y() : -box.half.y(),
                           (i & 4) ? box.half.z() : -box.half.z());
      far = std::max(far, (box.centre + box.R_CB * local).norm());
    }
    const Matrix3d R_BC = box.R_CB.transpose();
    const Vector3d o_B = -(R_BC * box.centre);
    // Distance from the camera centre to the box (0 inside).
    const double near = (o_B.cwiseAbs() - box.half).cwiseMax(0.0).norm();
    const double margin = kRadiusMarginRel * (far + 1.0);
    const double grow_max = far * rays.max_tan_alpha() + margin;
    std::array<Vector3d, 8> corners;
    for (int i = 0; i < 8; ++i) {
      const Vector3d g = box.half + Vector3d::Constant(grow_max);
      const Vector3d local((i & 1) ? g.x() : -g.x(), (i & 2) ? g.y() : -g.y(),
                           (i & 4) ? g.z() : -g.z());
      corners[i] = box.centre + box.R_CB * local;
    }
    rays.ForEachSpan(PointsNormBox(corners.data(), 8), 0, width - 1, 0, height - 1,
                     [&](int v, int u0, int u1, double tan_alpha) {
                       const Vector3d grown =
                           box.half + Vector3d::Constant(far * tan_alpha + margin);
                       for (int u = u0; u <= u1; ++u) {
                         if (!rays.Valid(u, v)) continue;
                         const std::size_t pi = static_cast<std::size_t>(v) * width + u;
                         if (occlusion && near > hidden_beyond[pi]) continue;
                         const Vector2d xy = rays.Ray(u, v);
                         const Vector3d d = R_BC * Vector3d(xy.x(), xy.y(), 1.0);
                         double t0 = 0.0;
                         double t1 = kInf;
                         bool hit = true;
                         for (int i = 0; i < 3 && hit; ++i) {
                           hit = ClipSlab(o_B[i], d[i], -grown[i], grown[i], &t0, &t1);
                         }
                         if (hit) static_mask[pi] = 255;
                       }
                     });
  }

  /// ORs the capsule's pixels into `out` (width x height).
  ///
  /// Why conservative: a capsule point q in the cone of half-angle alpha about
  /// the pixel's centre ray is within |q| sin(alpha) <= D tan(alpha) of that
  /// ray's line, D = max(|a|, |b|) + r bounding |q|; its segment point is
  /// within r more. So every pixel whose cone (which holds the pixel's
  /// viewing pyramid) meets the capsule passes the test with
  /// R = r + D tan(alpha) (plus the rounding margin). Only the part of the
  /// segment with z >= -r can carry capsule points in front of the camera
  /// (z > 0), so the segment is clipped there; points behind the camera never
  /// hit a pixel in reality and, as the test measures distance to the whole
  /// line, the clipped rest can only add pixels.
  void DrawCapsule(const Vector3d& a_W, const Vector3d& b_W, double radius,
                   std::uint8_t* out) const {
    Vector3d a = camera.ToCamera(a_W);
    Vector3d b = camera.ToCamera(b_W);
    const double z_clip = -radius;
    if (a.z() < z_clip && b.z() < z_clip) {
      return;
    }
    if (a.z() < z_clip) {
      a = a + (b - a) * ((z_clip - a.z()) / (b.z() - a.z()));
    } else if (b.z() < z_clip) {
      b = b + (a - b) * ((z_clip - b.z()) / (a.z() - b.z()));
    }
    const double far = std::max(a.norm(), b.norm()) + radius;
    const double margin = kRadiusMarginRel * (far + 1.0);
    const double near = SegmentDistanceToOrigin(a, b) - radius;
    const double rect_radius = (radius + far * rays.max_tan_alpha() + margin) * 1.001 + 1e-4;
    const NormBox box = CapsuleNormBox(a, b, rect_radius);

    const SegmentF seg{static_cast<float>(a.x()), static_cast<float>(a.y()),
                       static_cast<float>(a.z()), static_cast<float>(b.x()),
                       static_cast<float>(b.y()), static_cast<float>(b.z())};
    const float near_f = FloatDown(near);
    const bool occluded_somewhere = occlusion && near_f > min_hidden_beyond;
    const bool table = !rays.pinhole();
    rays.ForEachSpan(
        box, 0, width - 1, 0, height - 1, [&](int v, int u0, int u1, double tan_alpha) {
          const double r = radius + far * tan_alpha + margin;
          const float r2 = FloatUp(r * r);
          const int n = u1 - u0 + 1;
          const std::size_t pi = static_cast<std::size_t>(v) * width + u0;
          std::uint8_t* row = out + pi;
          const float* thr = occluded_somewhere ? hidden_beyond.data() + pi : nullptr;
          if (table) {
            const float* xs = rays.XRow(u0, v);
            const float* ys = rays.YRow(u0, v);
            if (occluded_somewhere) {
              MarkSpan<true, true>(seg, r2, near_f, xs, ys, 0, 0, 0, thr, n, row);
            } else {
              MarkSpan<true, false>(seg, r2, near_f, xs, ys, 0, 0, 0, thr, n, row);
            }
          } else {
            const double y = (v - rays.cy()) / rays.fy();
            const auto x0 = static_cast<float>((u0 - rays.cx() - rays.skew() * y) / rays.fx());
            const auto dx = static_cast<float>(1.0 / rays.fx());
            const auto yf = static_cast<float>(y);
            if (occluded_somewhere) {
              MarkSpan<false, true>(seg, r2, near_f, nullptr, nullptr, x0, dx, yf, thr, n, row);
            } else {
              MarkSpan<false, false>(seg, r2, near_f, nullptr, nullptr, x0, dx, yf, thr, n, row);
            }
          }
        });
  }
};

MaskRenderer::MaskRenderer(const geometry::CameraModel& camera, const std::vector<Solid>& obstacles,
                           const std::vector<Solid>& static_foreground, bool occlusion)
    : impl_(std::make_unique<Impl>(camera, obstacles, static_foreground, occlusion)) {}

MaskRenderer::~MaskRenderer() = default;
MaskRenderer::MaskRenderer(MaskRenderer&&) noexcept = default;
MaskRenderer& MaskRenderer::operator=(MaskRenderer&&) noexcept = default;

void MaskRenderer::Render(const std::vector<BodyState>& people, common::ImageU8* out) const {
  const Impl& impl = *impl_;
  if (out->width != impl.width || out->height != impl.height ||
      out->pixels.size() != impl.static_mask.size()) {
    *out = common::ImageU8(impl.width, impl.height);
  }
  std::copy(impl.static_mask.begin(), impl.static_mask.end(), out->pixels.begin());
  for (const BodyState& person : people) {
    for (const BodyCapsule& part : person.parts) {
      impl.DrawCapsule(part.a_W, part.b_W, part.radius_m, out->pixels.data());
    }
  }
}

const geometry::CameraModel& MaskRenderer::camera() const { return impl_->camera; }

}  // namespace hg::sim
