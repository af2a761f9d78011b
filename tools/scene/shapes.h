#pragma once
/// @file
/// Analytic solid shapes for generated scenes: spheres, oriented boxes, capsules.

#include <type_traits>
#include <variant>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "common/box.h"

namespace hg::scene {

struct Sphere {
  Eigen::Vector3d centre_W = Eigen::Vector3d::Zero();
  double radius_m = 0.1;
};

/// Oriented box: centre, half extents along its own axes, rotation R_WB (box -> world).
struct OrientedBox {
  Eigen::Vector3d centre_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d half_extents_m = Eigen::Vector3d::Constant(0.1);
  Eigen::Matrix3d R_WB = Eigen::Matrix3d::Identity();
};

/// Segment a-b swept by a sphere of radius_m.
struct Capsule {
  Eigen::Vector3d a_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_W = Eigen::Vector3d::UnitZ();
  double radius_m = 0.1;
};

using Shape = std::variant<Sphere, OrientedBox, Capsule>;

/// True iff p_W lies inside or on the shape.
[[nodiscard]] bool Contains(const Shape& shape, const Eigen::Vector3d& p_W);
/// Support point: the point of the shape farthest along direction d (need not be unit).
[[nodiscard]] Eigen::Vector3d Support(const Shape& shape, const Eigen::Vector3d& d);
/// Axis-aligned bounding box of the shape.
[[nodiscard]] common::Box3 Bounds(const Shape& shape);
/// Volume of the shape in m^3.
[[nodiscard]] double Volume(const Shape& shape);

/// The shape moved by offset_m.
[[nodiscard]] inline Shape Translated(Shape shape, const Eigen::Vector3d& offset_m) {
  std::visit(
      [&](auto& s) {
        if constexpr (std::is_same_v<std::decay_t<decltype(s)>, Capsule>) {
          s.a_W += offset_m;
          s.b_W += offset_m;
        } else {
          s.centre_W += offset_m;
        }
      },
      shape);
  return shape;
}

/// Uniform random point inside the shape from two uniforms generator `u01`
/// (called as many times as needed, each returning a double in [0, 1)).
template <class Uniform01>
Eigen::Vector3d SampleInside(const Shape& shape, Uniform01&& u01) {
  const common::Box3 b = Bounds(shape);
  for (;;) {
    Eigen::Vector3d p(b.min.x() + u01() * (b.max.x() - b.min.x()),
                      b.min.y() + u01() * (b.max.y() - b.min.y()),
                      b.min.z() + u01() * (b.max.z() - b.min.z()));
    if (Contains(shape, p)) return p;
  }
}

}  // namespace hg::scene
