#pragma once
/// @file
/// The static part of a camera placement problem: the cell as a voxel grid
/// with the voxels that touch obstacles marked, the obstacle meshes, the
/// sample people and the mounting surfaces. Built once per run.

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/box.h"
#include "geometry/mesh.h"
#include "placement/mounting.h"
#include "sim/scene.h"
#include "sim/solids.h"

namespace hg::placement {

/// Settings of the placement model. Plain struct.
struct ModelOptions {
  /// Requested voxel edge (m); each axis uses the largest edge <= this that
  /// divides the cell into whole voxels.
  double voxel_m = 0.10;
  /// Width of the reduced image on which visibility is decided (pixels); the
  /// height follows the aspect ratio. Coarser pixels only make the test more
  /// conservative.
  int render_width_px = 192;
  /// A sample person is the vertical capsule of this radius and total height,
  /// standing on the floor (bounds.min.z).
  double person_radius_m = 0.25;
  double person_height_m = 1.8;
  /// Spacing of the grid of sample floor positions (m).
  double person_spacing_m = 1.0;
};

/// Regular grid of nx * ny * nz voxels filling `bounds`. Voxel (i, j, k) has
/// index (k * ny + j) * nx + i; its corner (i, j, k) is bounds.min + (i, j, k)
/// * cell_m, corner index (k * (ny + 1) + j) * (nx + 1) + i. Value type.
struct VoxelGrid {
  common::Box3 bounds;
  int nx = 0;
  int ny = 0;
  int nz = 0;
  Eigen::Vector3d cell_m = Eigen::Vector3d::Zero();

  [[nodiscard]] int Count() const { return nx * ny * nz; }
  [[nodiscard]] int CornerCount() const { return (nx + 1) * (ny + 1) * (nz + 1); }
  [[nodiscard]] int Index(int i, int j, int k) const { return (k * ny + j) * nx + i; }
  [[nodiscard]] double VoxelVolume() const { return cell_m.prod(); }
  [[nodiscard]] common::Box3 VoxelBox(int i, int j, int k) const {
    common::Box3 box;
    box.min = bounds.min + Eigen::Vector3d(i, j, k).cwiseProduct(cell_m);
    box.max = box.min + cell_m;
    return box;
  }
};

/// One sample person: the capsule a_W-b_W of radius radius_m.
struct PersonSample {
  Eigen::Vector3d feet_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d a_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_W = Eigen::Vector3d::Zero();
  double radius_m = 0.0;
};

/// One obstacle as a triangle mesh for visibility. A closed mesh is turned
/// to outward normals, so that a camera outside it needs only the faces that
/// face it (the nearest point of a closed surface along any ray lies on such
/// a face).
struct Occluder {
  geometry::TriangleMesh mesh;
  bool closed = false;
  common::Box3 bounds;
  sim::SolidGeometry solid;  ///< The mesh as a solid, for "is the camera inside".
};

/// Everything about the cell that does not depend on the cameras. Immutable
/// after BuildPlacementScene; thread-safe for concurrent reads.
struct PlacementScene {
  std::string name;
  std::string source_file;
  VoxelGrid grid;
  /// Per voxel: 1 when the voxel touches an obstacle (it is then not part of
  /// the surveillance volume whose coverage is measured), else 0.
  std::vector<std::uint8_t> obstacle;
  int target_voxels = 0;  ///< Voxels with obstacle == 0.
  /// The obstacles as circumscribing triangle meshes (sim::Tessellate with
  /// kObstacleSegments facets around curved surfaces).
  std::vector<geometry::TriangleMesh> obstacle_meshes;
  std::vector<Occluder> occluders;  ///< The same meshes, prepared for visibility.
  std::vector<PersonSample> samples;
  std::vector<sim::MountingSurface> surfaces;
  PlacementIntrinsics intrinsics;
  ModelOptions options;

  [[nodiscard]] double TargetVolume() const { return target_voxels * grid.VoxelVolume(); }
};

/// Facets around the curved obstacles (cylinders, capsules). Fewer facets
/// than the simulator's meshes make visibility cheaper; the meshes still
/// contain the solids, so they only ever hide more.
inline constexpr int kObstacleSegments = 8;

/// Builds the placement model of `scene`: the voxel grid, the obstacle voxels
/// (a voxel is marked when some obstacle triangle overlaps it or it lies
/// inside an obstacle), one sample person per cell of a person_spacing_m grid
/// over the floor (moved within its grid cell, or left out, where the capsule
/// would touch an obstacle voxel) and the mounting surfaces (MountingSurfacesOf).
/// @throws common::ConfigError for bad options, a scene without mounting
/// surface, or a cell where no sample person fits.
[[nodiscard]] PlacementScene BuildPlacementScene(const sim::Scene& scene,
                                                 const PlacementIntrinsics& intrinsics,
                                                 const ModelOptions& options);

}  // namespace hg::placement
