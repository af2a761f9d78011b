#pragma once
/// @file
/// Collision test of particle propagation: the capsule swept between a
/// particle's previous and predicted centre must not touch a static obstacle.
/// Obstacles are oriented boxes, cylinders and capsules (sim's solid types).

#include <variant>
#include <vector>

#include <Eigen/Core>

#include "common/box.h"
#include "sim/solids.h"

namespace hg::tracking {

/// An obstacle of the collision world.
using CollisionShape = std::variant<sim::BoxSolid, sim::CylinderSolid, sim::CapsuleSolid>;

/// Squared distance between segments p0-p1 and q0-q1 (either may be a point).
/// Exact up to rounding, also for parallel segments.
[[nodiscard]] double SegmentSegmentDistanceSquared(const Eigen::Vector3d& p0,
                                                   const Eigen::Vector3d& p1,
                                                   const Eigen::Vector3d& q0,
                                                   const Eigen::Vector3d& q1);

/// Squared distance between segment p0-p1 and the solid oriented box (0 when
/// they intersect). Exact up to rounding: the squared distance along the
/// segment is a convex piecewise quadratic whose pieces break where the point
/// crosses a face plane; each piece is minimised in closed form.
[[nodiscard]] double SegmentBoxDistanceSquared(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1,
                                               const sim::BoxSolid& box);

/// Distance from a point to the solid cylinder (0 inside). A cylinder whose
/// axis is shorter than 1e-12 m is treated as the ball of its radius around
/// a_W, which contains it (the distance never comes out too large).
[[nodiscard]] double PointCylinderDistance(const Eigen::Vector3d& p,
                                           const sim::CylinderSolid& cylinder);

/// Conservative: true whenever the segment p0-p1 comes within `radius` of the
/// solid cylinder; may also answer true when it misses by at most
/// 1e-7 * |p1 - p0| m. The distance along the segment is convex (the cylinder
/// is convex): a golden-section search brackets its minimum, and the answer
/// uses a lower bound of the minimum (the distance is |p1 - p0|-Lipschitz in
/// the segment parameter). A capsule around the cylinder's axis rejects most
/// misses first.
[[nodiscard]] bool SegmentNearCylinder(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1,
                                       const sim::CylinderSolid& cylinder, double radius);

/// True when the capsule p0-p1 of `radius` touches or overlaps the shape
/// (distance <= radius; touching counts as a hit).
[[nodiscard]] bool CapsuleHits(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, double radius,
                               const CollisionShape& shape);

/// Axis-aligned bounds of a shape (for a cylinder, of the capsule around it).
[[nodiscard]] common::Box3 ShapeBounds(const CollisionShape& shape);

/// The static obstacles of the cell with a uniform-grid broad phase: each
/// shape is listed in the grid cells its bounds overlap; a query tests each
/// shape once (in the cell holding the low corner of the overlap of the
/// shape's and the query's bounds), so queries need no scratch state.
/// Immutable after construction; thread-safe for concurrent queries.
class CollisionWorld {
 public:
  /// An empty world: nothing collides.
  CollisionWorld() = default;
  /// @param cell_m broad-phase cell edge (metres); the grid is coarsened so it
  ///        has at most 64 cells per axis.
  explicit CollisionWorld(std::vector<CollisionShape> shapes, double cell_m = 0.5);

  /// True when the capsule p0-p1 of `radius` touches any shape.
  [[nodiscard]] bool CapsuleHits(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1,
                                 double radius) const;

  [[nodiscard]] const std::vector<CollisionShape>& shapes() const { return shapes_; }

 private:
  std::vector<CollisionShape> shapes_;
  std::vector<common::Box3> bounds_;  // Per shape.
  common::Box3 extent_;               // Union of the shape bounds.
  double cell_m_ = 1.0;
  Eigen::Vector3i dims_ = Eigen::Vector3i::Zero();
  std::vector<int> cell_start_;  // CSR: shapes of cell c are items_[start[c], start[c+1]).
  std::vector<int> items_;
};

}  // namespace hg::tracking
