#include "tracking/collision.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <type_traits>
#include <utility>

namespace hg::tracking {
namespace {

using Eigen::Vector3d;

/// Squared segment lengths below this (1e-12 m) make a segment a point.
constexpr double kPointSquaredM2 = 1e-24;

/// Golden-section bracket width (segment parameter) of SegmentNearCylinder.
constexpr double kBracket = 1e-7;

/// Squared distance from p (box frame) to the centred box of half extents h.
double PointBoxDistanceSquared(const Vector3d& p, const Vector3d& h) {
  double d2 = 0.0;
  for (int i = 0; i < 3; ++i) {
    const double e = std::abs(p[i]) - h[i];
    if (e > 0.0) d2 += e * e;
  }
  return d2;
}

Vector3d AbsHalfExtents(const sim::BoxSolid& b) {
  return b.R_WB.cwiseAbs() * b.half_extents_m.cwiseAbs();
}

}  // namespace

double SegmentSegmentDistanceSquared(const Vector3d& p0, const Vector3d& p1, const Vector3d& q0,
                                     const Vector3d& q1) {
  // Closest points s in [0, 1] on p, t in [0, 1] on q: minimise the convex
  // quadratic |p0 + s d1 - q0 - t d2|^2 over the unit square, clamping one
  // parameter and re-solving the other on the border.
  const Vector3d d1 = p1 - p0;
  const Vector3d d2 = q1 - q0;
  const Vector3d r = p0 - q0;
  const double a = d1.squaredNorm();
  const double e = d2.squaredNorm();
  const double f = d2.dot(r);
  double s = 0.0;
  double t = 0.0;
  if (a <= kPointSquaredM2 && e <= kPointSquaredM2) {
    return r.squaredNorm();
  }
  if (a <= kPointSquaredM2) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= kPointSquaredM2) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2);
      const double denom = a * e - b * b;  // >= 0; 0 when parallel.
      // Parallel: every s gives the same distance after re-solving t; take 0.
      s = denom > 0.0 ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0.0) {
        t = 0.0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1.0) {
        t = 1.0;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  return (p0 + s * d1 - (q0 + t * d2)).squaredNorm();
}

double SegmentBoxDistanceSquared(const Vector3d& p0, const Vector3d& p1, const sim::BoxSolid& box) {
  const Vector3d p = box.R_WB.transpose() * (p0 - box.centre_W);
  const Vector3d d = box.R_WB.transpose() * (p1 - p0);
  const Vector3d h = box.half_extents_m.cwiseAbs();
  // Breakpoints: parameters where the point crosses a face plane x_i = +-h_i.
  std::array<double, 8> ts{};
  int n = 0;
  ts[n++] = 0.0;
  ts[n++] = 1.0;
  for (int i = 0; i < 3; ++i) {
    if (d[i] == 0.0) continue;
    for (const double side : {-h[i], h[i]}) {
      const double t = (side - p[i]) / d[i];
      if (t > 0.0 && t < 1.0) ts[n++] = t;
    }
  }
  for (int i = 1; i < n; ++i) {  // Insertion sort of at most 8 values.
    for (int j = i; j > 0 && ts[j] < ts[j - 1]; --j) std::swap(ts[j], ts[j - 1]);
  }
  double best = PointBoxDistanceSquared(p, h);
  for (int k = 0; k + 1 < n; ++k) {
    const double t0 = ts[k];
    const double t1 = ts[k + 1];
    const double tm = 0.5 * (t0 + t1);
    // On (t0, t1) every axis stays above, inside or below its slab: the squared
    // distance is sum over outside axes of (p_i + t d_i - side_i)^2.
    double qa = 0.0;
    double qb = 0.0;
    for (int i = 0; i < 3; ++i) {
      const double x = p[i] + tm * d[i];
      double side = 0.0;
      if (x > h[i]) {
        side = h[i];
      } else if (x < -h[i]) {
        side = -h[i];
      } else {
        continue;
      }
      qa += d[i] * d[i];
      qb += 2.0 * d[i] * (p[i] - side);
    }
    double t = t0;
    if (qa > 0.0) t = std::clamp(-qb / (2.0 * qa), t0, t1);
    best = std::min(
        {best, PointBoxDistanceSquared(p + t * d, h), PointBoxDistanceSquared(p + t1 * d, h)});
  }
  return best;
}

double PointCylinderDistance(const Vector3d& p, const sim::CylinderSolid& cyl) {
  const Vector3d axis = cyl.b_W - cyl.a_W;
  const double len = axis.norm();
  const Vector3d w = p - cyl.a_W;
  if (len < 1e-12) return std::max(w.norm() - cyl.radius_m, 0.0);
  const Vector3d u = axis / len;
  const double s = w.dot(u);
  const double radial = (w - s * u).norm();
  const double dr = std::max(radial - cyl.radius_m, 0.0);
  const double ds = std::max({-s, s - len, 0.0});
  return std::sqrt(dr * dr + ds * ds);
}

bool SegmentNearCylinder(const Vector3d& p0, const Vector3d& p1, const sim::CylinderSolid& cyl,
                         double radius) {
  // The cylinder lies inside the capsule of its axis: missing that misses it.
  const double reach = radius + cyl.radius_m;
  if (SegmentSegmentDistanceSquared(p0, p1, cyl.a_W, cyl.b_W) > reach * reach) return false;
  const Vector3d d = p1 - p0;
  auto f = [&](double t) { return PointCylinderDistance(p0 + t * d, cyl); };
  double best = std::min(f(0.0), f(1.0));
  if (best <= radius) return true;
  const double len = d.norm();
  // Golden-section search on the convex distance: a minimiser stays in [lo, hi].
  constexpr double kInvPhi = 0.6180339887498949;
  double lo = 0.0;
  double hi = 1.0;
  double x1 = hi - kInvPhi * (hi - lo);
  double x2 = lo + kInvPhi * (hi - lo);
  double f1 = f(x1);
  double f2 = f(x2);
  while (hi - lo > kBracket) {
    if (f1 <= f2) {
      hi = x2;
      x2 = x1;
      f2 = f1;
      x1 = hi - kInvPhi * (hi - lo);
      f1 = f(x1);
    } else {
      lo = x1;
      x1 = x2;
      f1 = f2;
      x2 = lo + kInvPhi * (hi - lo);
      f2 = f(x2);
    }
    best = std::min({best, f1, f2});
    if (best <= radius) return true;
  }
  // f(x) - f(t*) <= len * |x - t*| for the minimiser t* in [lo, hi].
  return std::min(f1, f2) - len * (hi - lo) <= radius;
}

bool CapsuleHits(const Vector3d& p0, const Vector3d& p1, double radius,
                 const CollisionShape& shape) {
  return std::visit(
      [&](const auto& s) {
        using T = std::decay_t<decltype(s)>;
        if constexpr (std::is_same_v<T, sim::BoxSolid>) {
          return SegmentBoxDistanceSquared(p0, p1, s) <= radius * radius;
        } else if constexpr (std::is_same_v<T, sim::CylinderSolid>) {
          return SegmentNearCylinder(p0, p1, s, radius);
        } else {
          const double reach = radius + s.radius_m;
          return SegmentSegmentDistanceSquared(p0, p1, s.a_W, s.b_W) <= reach * reach;
        }
      },
      shape);
}

common::Box3 ShapeBounds(const CollisionShape& shape) {
  return std::visit(
      [](const auto& s) {
        using T = std::decay_t<decltype(s)>;
        if constexpr (std::is_same_v<T, sim::BoxSolid>) {
          const Vector3d e = AbsHalfExtents(s);
          return common::Box3{s.centre_W - e, s.centre_W + e};
        } else {
          const Vector3d r = Vector3d::Constant(std::abs(s.radius_m));
          return common::Box3{s.a_W.cwiseMin(s.b_W) - r, s.a_W.cwiseMax(s.b_W) + r};
        }
      },
      shape);
}

CollisionWorld::CollisionWorld(std::vector<CollisionShape> shapes, double cell_m)
    : shapes_(std::move(shapes)) {
  if (shapes_.empty()) return;
  bounds_.reserve(shapes_.size());
  extent_ = ShapeBounds(shapes_.front());
  for (const CollisionShape& s : shapes_) {
    bounds_.push_back(ShapeBounds(s));
    extent_.min = extent_.min.cwiseMin(bounds_.back().min);
    extent_.max = extent_.max.cwiseMax(bounds_.back().max);
  }
  constexpr int kMaxCellsPerAxis = 64;
  cell_m_ = std::max({cell_m, extent_.Size().maxCoeff() / kMaxCellsPerAxis, 1e-3});
  for (int a = 0; a < 3; ++a) {
    dims_[a] = std::max(1, static_cast<int>(std::ceil(extent_.Size()[a] / cell_m_)));
  }
  const int cells = dims_.prod();
  auto cell_range = [&](const common::Box3& b, Eigen::Vector3i* lo, Eigen::Vector3i* hi) {
    for (int a = 0; a < 3; ++a) {
      (*lo)[a] = std::clamp(static_cast<int>(std::floor((b.min[a] - extent_.min[a]) / cell_m_)), 0,
                            dims_[a] - 1);
      (*hi)[a] = std::clamp(static_cast<int>(std::floor((b.max[a] - extent_.min[a]) / cell_m_)), 0,
                            dims_[a] - 1);
    }
  };
  std::vector<int> count(cells + 1, 0);
  for (int pass = 0; pass < 2; ++pass) {
    for (int s = 0; s < static_cast<int>(shapes_.size()); ++s) {
      Eigen::Vector3i lo, hi;
      cell_range(bounds_[s], &lo, &hi);
      for (int z = lo.z(); z <= hi.z(); ++z) {
        for (int y = lo.y(); y <= hi.y(); ++y) {
          for (int x = lo.x(); x <= hi.x(); ++x) {
            const int c = (z * dims_.y() + y) * dims_.x() + x;
            if (pass == 0) {
              ++count[c + 1];
            } else {
              items_[count[c]++] = s;
            }
          }
        }
      }
    }
    if (pass == 0) {
      for (int c = 0; c < cells; ++c) count[c + 1] += count[c];
      cell_start_ = count;
      items_.resize(count[cells]);
    }
  }
}

bool CollisionWorld::CapsuleHits(const Vector3d& p0, const Vector3d& p1, double radius) const {
  if (shapes_.empty()) return false;
  const Vector3d r = Vector3d::Constant(radius);
  const Vector3d qmin = p0.cwiseMin(p1) - r;
  const Vector3d qmax = p0.cwiseMax(p1) + r;
  if ((qmax.array() < extent_.min.array()).any() || (qmin.array() > extent_.max.array()).any()) {
    return false;
  }
  auto cell_of = [&](double v, int a) {
    return std::clamp(static_cast<int>(std::floor((v - extent_.min[a]) / cell_m_)), 0,
                      dims_[a] - 1);
  };
  Eigen::Vector3i lo, hi;
  for (int a = 0; a < 3; ++a) {
    lo[a] = cell_of(std::max(qmin[a], extent_.min[a]), a);
    hi[a] = cell_of(std::min(qmax[a], extent_.max[a]), a);
  }
  for (int z = lo.z(); z <= hi.z(); ++z) {
    for (int y = lo.y(); y <= hi.y(); ++y) {
      for (int x = lo.x(); x <= hi.x(); ++x) {
        const int c = (z * dims_.y() + y) * dims_.x() + x;
        for (int k = cell_start_[c]; k < cell_start_[c + 1]; ++k) {
          const int s = items_[k];
          const common::Box3& b = bounds_[s];
          if ((b.min.array() > qmax.array()).any() || (b.max.array() < qmin.array()).any()) {
            continue;
          }
          // Test each shape once: in the cell of the overlap's low corner.
          const Vector3d corner = b.min.cwiseMax(qmin);
          if (cell_of(corner.x(), 0) != x || cell_of(corner.y(), 1) != y ||
              cell_of(corner.z(), 2) != z) {
            continue;
          }
          if (tracking::CapsuleHits(p0, p1, radius, shapes_[s])) return true;
        }
      }
    }
  }
  return false;
}

}  // namespace hg::tracking
