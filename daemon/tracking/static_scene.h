#pragma once
/// @file
/// The static part of the tracking voxel states, computed once at start-up:
/// KNOWN (voxelised obstacles) and OCCLUDED (space no camera can see past the
/// obstacles), plus the collision shapes of the obstacles.

#include <cstdint>
#include <vector>

#include "common/box.h"
#include "geometry/camera.h"
#include "geometry/mesh.h"
#include "sim/solids.h"
#include "tracking/collision.h"
#include "tracking/voxel_grid.h"

namespace hg::tracking {

/// Cameras and obstacles of the cell. Obstacles come as triangle meshes
/// (daemon config) and as analytic solids (simulated scenes; a sim::MeshSolid
/// is treated as a mesh).
struct StaticScene {
  std::vector<geometry::CameraModel> cameras;  ///< Distortion is ignored (pinhole part).
  std::vector<geometry::TriangleMesh> meshes;
  std::vector<sim::SolidGeometry> solids;
};

/// Cameras whose views BuildStaticVoxels records per voxel (the octree's limit too).
inline constexpr int kMaxViewCameras = 16;

/// Static labels of every voxel and the boxes that cover the mesh obstacles.
struct StaticVoxels {
  std::vector<VoxelState> states;        ///< Per voxel: kFree, kOccluded or kKnown.
  std::vector<common::Box3> mesh_boxes;  ///< Cover the KNOWN voxels of the meshes.
  /// Per voxel: bit c set when camera c (c < kMaxViewCameras) sees its centre,
  /// as MarkOccluded decides it. Empty when there are no cameras.
  std::vector<std::uint16_t> views;
  /// Per voxel: 1 when no camera has it in view with a margin (OutOfView).
  /// Empty when there are no cameras.
  std::vector<std::uint8_t> out_of_view;
};

/// Sets mask[i] = 1 for every voxel of the mesh obstacle: voxels whose closed
/// box a triangle touches (separating-axis test with a tolerance that only
/// adds voxels) and voxels the surface encloses. Enclosed = not reachable from
/// outside the mesh's bounds through untouched voxels (6-connected), so a mesh
/// that is not closed marks its surface only. The search runs on a local grid
/// over the mesh's bounds, clipped two voxels beyond this grid; where the
/// clipping cuts the mesh, the cut is taken as closed.
/// Precondition: mask->size() == grid.size().
void VoxelizeMesh(const VoxelGrid& grid, const geometry::TriangleMesh& mesh,
                  std::vector<std::uint8_t>* mask);

/// Sets mask[i] = 1 for every voxel the solid overlaps: exact for boxes
/// (separating axes) and capsules (segment-to-box distance); for cylinders,
/// every voxel whose centre lies within half a voxel diagonal of the cylinder
/// (a superset of the overlapping voxels). A MeshSolid goes to VoxelizeMesh.
void VoxelizeSolid(const VoxelGrid& grid, const sim::SolidGeometry& solid,
                   std::vector<std::uint8_t>* mask);

/// Greedy merge of the marked voxels into axis-aligned boxes (runs along x,
/// then grown along y, then z). The boxes cover exactly the marked voxels.
[[nodiscard]] std::vector<common::Box3> MergeIntoBoxes(const VoxelGrid& grid,
                                                       const std::vector<std::uint8_t>& mask);

/// Relabels as kOccluded every voxel in `states` that is not kKnown and that
/// the obstacles hide from every camera: its centre lies in some camera's view
/// (in front of it, projecting into the image), and for every camera it is
/// out of view or behind the obstacle surface seen through the pixel it
/// projects to (geometry::RenderObstacleDepth, centre_depth), or the camera
/// is blocked (an obstacle inside its lens: it sees nothing). Space out of
/// every camera's view (above the cameras, say) stays kFree: the rig does not
/// cover it, and a person's ellipsoid gains nothing by reaching into it.
/// Without cameras every voxel that is not kKnown is kOccluded.
void MarkOccluded(const VoxelGrid& grid, const std::vector<geometry::CameraModel>& cameras,
                  const std::vector<geometry::TriangleMesh>& occluders,
                  std::vector<VoxelState>* states);

/// Per voxel: 1 unless some camera has the ball of one voxel diagonal around
/// its centre wholly in view (in front of it, projecting inside the image).
/// The octree cannot carve a cell that reaches out of a camera's image with
/// that camera, so near the edge of the views (under the top of every
/// camera's image, say) the occupancy holds a layer of cells no camera could
/// carve; their voxels, and those wholly out of view, are no evidence of a
/// person (VoxelMap keeps them kFree).
[[nodiscard]] std::vector<std::uint8_t> OutOfView(
    const VoxelGrid& grid, const std::vector<geometry::CameraModel>& cameras);

/// Per voxel, bit c set when camera c (c < kMaxViewCameras; later cameras are
/// left out) sees the voxel's centre, by MarkOccluded's rule. With `in_view`,
/// also 1 per voxel whose centre lies in the view of one of those cameras.
[[nodiscard]] std::vector<std::uint16_t> CameraViews(
    const VoxelGrid& grid, const std::vector<geometry::CameraModel>& cameras,
    const std::vector<geometry::TriangleMesh>& occluders,
    std::vector<std::uint8_t>* in_view = nullptr);

/// KNOWN from every obstacle, OCCLUDED from the cameras (MarkOccluded's rule; analytic solids hide
/// what their circumscribing tessellation hides), the cameras' views, and the
/// mesh boxes.
/// Cost: one depth map per camera plus one projection per voxel and camera.
[[nodiscard]] StaticVoxels BuildStaticVoxels(const VoxelGrid& grid, const StaticScene& scene);

/// Collision shapes of the obstacles: analytic boxes, cylinders and capsules as
/// they are; mesh obstacles as the boxes of `voxels.mesh_boxes` (they cover
/// the voxelised meshes, so a mesh never blocks less than itself and, unlike
/// one box around a whole mesh, leaves free the space under a table top).
[[nodiscard]] std::vector<CollisionShape> CollisionShapes(const StaticScene& scene,
                                                          const StaticVoxels& voxels);

}  // namespace hg::tracking
