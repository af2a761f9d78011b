#pragma once
/// @file
/// The particle likelihood of Ober-Gecks et al.: every voxel inside a
/// particle's ellipsoid adds a score by its state, summed with the row prefix
/// counts of the VoxelMap (one lookup pair per (y, z) row the ellipsoid spans).

#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "tracking/voxel_map.h"

namespace hg::tracking {

/// Per-voxel scores of the likelihood (the paper's rho, sigma, tau, epsilon).
struct LikelihoodWeights {
  double unknown = 1.0;   ///< rho: occupied, not an obstacle: evidence of a person.
  double occluded = 0.1;  ///< sigma: nobody can see it: a person may hide there.
  double known = -5.0;    ///< tau: inside an obstacle: no person.
  double free = -0.1;     ///< epsilon: seen empty.
  /// Lattice positions below the floor (the grid's bottom, or the top of the
  /// obstacle the ellipsoid stands on): no person there, scored like free
  /// space. Were they not counted, an ellipsoid could reach through the floor
  /// for free and its centre would sink; scored like an obstacle, the
  /// ellipsoid's free margin would push it up instead (a person standing on a
  /// table was tracked 0.1 m too high when the table top counted as KNOWN).
  /// Set to 0 when the bounds start above the floor.
  double below_floor = -0.1;
};

/// Axis-aligned ellipsoid: centre and half-axes (k, l, m) along x, y, z.
struct Ellipsoid {
  Eigen::Vector3d centre_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d half_axes_m = Eigen::Vector3d::Ones();

  /// True iff p_W lies inside or on the ellipsoid. This is the membership test
  /// of every voxel centre in the stage (same arithmetic, same rounding; the
  /// reciprocals let the likelihood hoist them out of its loops).
  [[nodiscard]] bool Contains(const Eigen::Vector3d& p_W) const {
    const double dx = (p_W.x() - centre_W.x()) * (1.0 / half_axes_m.x());
    const double dy = (p_W.y() - centre_W.y()) * (1.0 / half_axes_m.y());
    const double dz = (p_W.z() - centre_W.z()) * (1.0 / half_axes_m.z());
    return dx * dx + (dy * dy + dz * dz) <= 1.0;
  }
  [[nodiscard]] double Volume() const;
};

/// Closed half-space normal . p <= offset (normal need not be unit).
struct HalfSpace {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitX();
  double offset = 0.0;

  /// Membership of a point; the arithmetic every voxel test of the stage uses.
  [[nodiscard]] bool Contains(const Eigen::Vector3d& p_W) const {
    return normal.x() * p_W.x() + (normal.y() * p_W.y() + normal.z() * p_W.z()) <= offset;
  }
  /// The points at least as near to `own` as to `other`: the Voronoi cell of
  /// `own` for the pair (bisector plane, ties on the plane belong to both).
  [[nodiscard]] static HalfSpace NearerTo(const Eigen::Vector3d& own, const Eigen::Vector3d& other);
};

/// Voxels whose centres lie inside an ellipsoid, by state. With an own
/// region, UNKNOWN voxels outside it are counted as foreign_unknown instead.
struct EllipsoidCounts {
  int unknown = 0;          ///< UNKNOWN inside the own region.
  int foreign_unknown = 0;  ///< UNKNOWN outside the own region (another track's evidence).
  int occluded = 0;
  int known = 0;
  int free = 0;
  /// Positions of the grid's lattice below the floor (any x, y).
  int below_floor = 0;
  /// Voxels of the grid inside the ellipsoid (below_floor not included).
  [[nodiscard]] int Total() const { return unknown + foreign_unknown + occluded + known + free; }
};

/// Counts the voxels of `map` whose centres lie inside `ellipsoid`, by state,
/// and the lattice positions below the floor inside it (below_floor); other
/// positions outside the grid are not counted (the space beyond the cell's
/// sides is neither evidence nor obstacle, so tracks can follow people out).
/// The floor is the grid's bottom, or the top of layer floor_layer - 1 when
/// floor_layer > 0 (the surface the ellipsoid stands on:
/// VoxelMap::SupportLayer): every lattice position inside the ellipsoid
/// below it counts as below_floor, at any x and y and whatever its state.
/// `own_region`: UNKNOWN voxels outside the intersection of these half-spaces
/// count as foreign_unknown (empty: every UNKNOWN voxel is own).
///
/// Which lines CountVoxels sums along: kAuto takes z columns when the
/// ellipsoid is taller than it is long in x (fewer columns than rows), else x
/// rows; kX and kZ force one (tests, benchmarks). kXScalar and kZScalar are
/// kX and kZ without the vector instructions they use where the processor has
/// AVX2 (tests). The result is the same.
enum class SumAxis { kAuto, kX, kZ, kXScalar, kZScalar };

/// Cost: O(lines spanned * (1 + own_region.size())): per (y, z) row, or per
/// (x, y) column, the extent of the ellipsoid (and of the region) along it is
/// solved in closed form and the counts come from two prefix entries, never
/// from a loop over the voxels. A standing person's ellipsoid at 4 cm voxels
/// spans about 420 rows but 140 columns. Exact: the result equals a loop over
/// all voxels with Ellipsoid::Contains and HalfSpace::Contains on
/// VoxelGrid::Centre (boundary voxels whose closed-form index is within
/// rounding of an integer are re-tested with those predicates). Thread-safe
/// for concurrent calls on a map that is not being updated.
[[nodiscard]] EllipsoidCounts CountVoxels(const VoxelMap& map, const Ellipsoid& ellipsoid,
                                          std::span<const HalfSpace> own_region = {},
                                          SumAxis axis = SumAxis::kAuto, int floor_layer = 0);

/// CountVoxels' floor_layer for `ellipsoid`: the obstacle top under its
/// centre (VoxelMap::SupportLayer) when that lies at most reach_m above the
/// ellipsoid's bottom (it stands on it), else 0 (the grid's bottom: a person
/// standing beside a low obstacle, the centre above it, keeps the evidence
/// of the legs beside it). reach_m <= 0: always 0.
[[nodiscard]] int FloorLayerOf(const VoxelMap& map, const Ellipsoid& ellipsoid, double reach_m);

/// Appends the indices of the voxels of `grid` whose centres lie inside the
/// ellipsoid (Ellipsoid::Contains), in index order: synthetic UNKNOWN blobs
/// for tests, tools and benchmarks. Cost: the voxels of its bounding box.
void AppendVoxelsInside(const VoxelGrid& grid, const Ellipsoid& ellipsoid,
                        std::vector<std::uint32_t>* out);

/// The paper's sum: rho * unknown + sigma * occluded + tau * known +
/// epsilon * (free + foreign_unknown), plus below_floor * its weight. Foreign UNKNOWN voxels count
/// as free space for this track: they are explained by another person, and scoring them as empty
/// pushes the two particle clouds apart instead of merging them.
[[nodiscard]] double Score(const EllipsoidCounts& counts, const LikelihoodWeights& weights);

}  // namespace hg::tracking
