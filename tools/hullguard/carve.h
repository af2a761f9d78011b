#pragma once
/// @file
/// One-shot carving of a set of masks, shared by `hullguard carve` and `hullguard demo`.

#include <memory>
#include <string>
#include <vector>

#include "common/box.h"
#include "common/image.h"
#include "geometry/camera.h"
#include "geometry/mesh.h"
#include "octree/octree.h"
#include "silhouette/quadtree.h"

namespace hg::tools {

struct CarveJob {
  std::vector<geometry::CameraModel> cameras;  ///< As calibrated (may have distortion).
  std::vector<common::ImageU8> masks;          ///< One per camera, same order, camera-sized.
  common::Box3 bounds;
  int depth = 8;
  int threads = 1;
  /// See octree::OctreeConfig::boundary_coarsening; 0 resolves view and obstacle edges exactly.
  int boundary_coarsening = octree::OctreeConfig{}.boundary_coarsening;
  std::uint8_t threshold = 127;  ///< Foreground iff grey value > threshold.
  std::int64_t max_nodes = 0;    ///< octree::OctreeConfig::max_nodes (0: from the depth).
  std::vector<geometry::TriangleMesh> obstacles;
};

struct CarveResult {
  std::vector<silhouette::SilhouetteQuadtree> quadtrees;
  std::unique_ptr<octree::Octree> tree;
  octree::UpdateStats stats;
  double undistort_ms = 0.0;
  double quadtree_ms = 0.0;
  double setup_ms = 0.0;  ///< Camera views and obstacle depth maps.
};

/// Undistorts masks conservatively where needed, builds the quadtrees and the
/// octree from scratch. Preconditions (checked by the callers that read input):
/// masks match cameras in number and size, at most octree::Octree::kMaxCameras
/// cameras, bounds valid (finite, max > min), 3 <= depth <= 16.
[[nodiscard]] CarveResult Carve(const CarveJob& job);

/// Writes a PNG of the tree's non-free leaves (WriteSnapshotPicture).
void WriteSnapshot(const octree::Octree& tree, const std::vector<geometry::CameraModel>& cameras,
                   const std::vector<geometry::TriangleMesh>& obstacles, const std::string& path);

}  // namespace hg::tools
