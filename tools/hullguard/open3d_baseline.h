#pragma once
/// @file
/// Optional baseline (CMake option HG_WITH_OPEN3D): Open3D's voxel carving,
/// VoxelGrid::CarveSilhouette, on a dense grid rebuilt every frame. A voxel
/// survives a camera when one of its eight corners projects onto foreground
/// (bilinear mask value > 0) or, as configured here, outside the image.

#include <cstdint>
#include <memory>
#include <vector>

#include "common/box.h"
#include "common/image.h"
#include "geometry/camera.h"

namespace hg::tools {

class Open3dCarver {
 public:
  /// `cameras` are pinhole; masks given to Carve() are theirs, 0/255.
  Open3dCarver(const common::Box3& bounds, int resolution,
               const std::vector<geometry::CameraModel>& cameras);
  ~Open3dCarver();

  /// Builds the dense grid and carves it with every mask. Returns the voxels left.
  std::int64_t Carve(const std::vector<const common::ImageU8*>& masks);

  /// Whether the voxel holding p_W survived the last Carve().
  [[nodiscard]] bool Occupied(const Eigen::Vector3d& p_W) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace hg::tools
