#include "scene/shapes.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace hg::scene {
namespace {

// Unit vector along d, or zero for a zero direction (every surface point is
// then a valid support point; returning the centre keeps callers finite).
Eigen::Vector3d UnitOrZero(const Eigen::Vector3d& d) {
  const double n = d.norm();
  return n > 0.0 ? Eigen::Vector3d(d / n) : Eigen::Vector3d::Zero();
}

// Squared distance from p to the segment a-b (a point when a == b).
double SquaredDistanceToSegment(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                const Eigen::Vector3d& b) {
  const Eigen::Vector3d ab = b - a;
  const double len2 = ab.squaredNorm();
  double t = 0.0;
  if (len2 > 0.0) t = std::clamp((p - a).dot(ab) / len2, 0.0, 1.0);
  return (p - (a + t * ab)).squaredNorm();
}

struct ContainsVisitor {
  const Eigen::Vector3d& p_W;
  bool operator()(const Sphere& s) const {
    return (p_W - s.centre_W).squaredNorm() <= s.radius_m * s.radius_m;
  }
  bool operator()(const OrientedBox& b) const {
    const Eigen::Vector3d q_B = b.R_WB.transpose() * (p_W - b.centre_W);
    return (q_B.array().abs() <= b.half_extents_m.array()).all();
  }
  bool operator()(const Capsule& c) const {
    return SquaredDistanceToSegment(p_W, c.a_W, c.b_W) <= c.radius_m * c.radius_m;
  }
};

struct SupportVisitor {
  const Eigen::Vector3d& d;
  Eigen::Vector3d operator()(const Sphere& s) const {
    return s.centre_W + s.radius_m * UnitOrZero(d);
  }
  Eigen::Vector3d operator()(const OrientedBox& b) const {
    const Eigen::Vector3d d_B = b.R_WB.transpose() * d;
    Eigen::Vector3d corner_B;
    for (int i = 0; i < 3; ++i) {
      corner_B[i] = d_B[i] >= 0.0 ? b.half_extents_m[i] : -b.half_extents_m[i];
    }
    return b.centre_W + b.R_WB * corner_B;
  }
  Eigen::Vector3d operator()(const Capsule& c) const {
    const Eigen::Vector3d& end = d.dot(c.b_W - c.a_W) > 0.0 ? c.b_W : c.a_W;
    return end + c.radius_m * UnitOrZero(d);
  }
};

struct BoundsVisitor {
  common::Box3 operator()(const Sphere& s) const {
    const Eigen::Vector3d r = Eigen::Vector3d::Constant(s.radius_m);
    return {s.centre_W - r, s.centre_W + r};
  }
  common::Box3 operator()(const OrientedBox& b) const {
    // Half extent of the rotated box along world axis i: sum_j |R_ij| h_j.
    const Eigen::Vector3d half = b.R_WB.cwiseAbs() * b.half_extents_m;
    return {b.centre_W - half, b.centre_W + half};
  }
  common::Box3 operator()(const Capsule& c) const {
    const Eigen::Vector3d r = Eigen::Vector3d::Constant(c.radius_m);
    return {c.a_W.cwiseMin(c.b_W) - r, c.a_W.cwiseMax(c.b_W) + r};
  }
};

struct VolumeVisitor {
  static constexpr double kPi = std::numbers::pi;
  double operator()(const Sphere& s) const {
    return 4.0 / 3.0 * kPi * s.radius_m * s.radius_m * s.radius_m;
  }
  double operator()(const OrientedBox& b) const { return 8.0 * b.half_extents_m.prod(); }
  double operator()(const Capsule& c) const {
    const double r = c.radius_m;
    return kPi * r * r * (c.b_W - c.a_W).norm() + 4.0 / 3.0 * kPi * r * r * r;
  }
};

}  // namespace

bool Contains(const Shape& shape, const Eigen::Vector3d& p_W) {
  return std::visit(ContainsVisitor{p_W}, shape);
}

Eigen::Vector3d Support(const Shape& shape, const Eigen::Vector3d& d) {
  return std::visit(SupportVisitor{d}, shape);
}

common::Box3 Bounds(const Shape& shape) { return std::visit(BoundsVisitor{}, shape); }

double Volume(const Shape& shape) { return std::visit(VolumeVisitor{}, shape); }

}  // namespace hg::scene
