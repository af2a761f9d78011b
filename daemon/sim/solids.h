#pragma once
/// @file
/// Solid primitives of simulated cells: boxes, cylinders, capsules and triangle
/// meshes, with bounds, point containment and circumscribing tessellation.

#include <string>
#include <variant>

#include <Eigen/Core>

#include "common/box.h"
#include "geometry/mesh.h"

namespace hg::sim {

/// Oriented box: centre, half extents along its own axes, R_WB (box -> world).
struct BoxSolid {
  Eigen::Vector3d centre_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d half_extents_m = Eigen::Vector3d::Constant(0.1);
  Eigen::Matrix3d R_WB = Eigen::Matrix3d::Identity();
};

/// Cylinder with flat caps: axis from a_W to b_W, radius_m.
struct CylinderSolid {
  Eigen::Vector3d a_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_W = Eigen::Vector3d::UnitZ();
  double radius_m = 0.1;
};

/// Segment a_W-b_W swept by a sphere of radius_m (a == b gives a sphere).
struct CapsuleSolid {
  Eigen::Vector3d a_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_W = Eigen::Vector3d::UnitZ();
  double radius_m = 0.1;
};

/// Triangle mesh in world coordinates (already placed).
struct MeshSolid {
  geometry::TriangleMesh mesh;
  /// The mesh file as the scene file names it (a relative path is relative to
  /// the scene file's folder); empty for meshes built in code.
  std::string file = {};
  /// The path `file` resolved to, which the mesh was loaded from.
  std::string loaded_from = {};
};

using SolidGeometry = std::variant<BoxSolid, CylinderSolid, CapsuleSolid, MeshSolid>;

/// RGB colour, components in [0, 1].
using Rgb = Eigen::Vector3f;

/// A named, coloured solid of the cell.
struct Solid {
  std::string name;
  SolidGeometry geometry;
  Rgb colour = Rgb(0.6F, 0.6F, 0.6F);
};

/// Axis-aligned bounding box of the solid.
[[nodiscard]] common::Box3 Bounds(const SolidGeometry& solid);

/// True iff p_W lies inside or on the solid. For meshes: inside the closed
/// surface by ray parity (meshes that are not closed give unspecified results).
[[nodiscard]] bool Contains(const SolidGeometry& solid, const Eigen::Vector3d& p_W);

/// A triangle mesh that contains the solid (circumscribing: every point of the
/// solid is inside or on the mesh, so an obstacle drawn from it never hides
/// less than the solid does). Curved surfaces use `segments` facets around
/// (at least 8). Meshes are returned as they are.
[[nodiscard]] geometry::TriangleMesh Tessellate(const SolidGeometry& solid, int segments = 24);

}  // namespace hg::sim
