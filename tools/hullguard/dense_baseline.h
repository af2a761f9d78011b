#pragma once
/// @file
/// The baseline the paper compares with: a dense R^3 voxel grid, each voxel's
/// centre projected into every camera and kept when every camera that sees it
/// shows foreground there. No hierarchy, no footprints: it is not conservative
/// (a voxel whose centre projects onto background is carved even when part of
/// it is inside a person), which `hullguard bench` measures.

#include <cstdint>
#include <vector>

#include "common/box.h"
#include "common/image.h"
#include "common/worker_pool.h"
#include "geometry/camera.h"

namespace hg::tools {

class DenseCarver {
 public:
  /// `cameras` are pinhole; masks given to Carve() are theirs, 0/255.
  DenseCarver(const common::Box3& bounds, int resolution,
              const std::vector<geometry::CameraModel>& cameras);

  /// Carves the grid from the masks (foreground iff > 127), z slabs on `pool`.
  /// Returns the number of occupied voxels.
  std::int64_t Carve(const std::vector<const common::ImageU8*>& masks, common::WorkerPool& pool);

  /// Whether the voxel holding p_W is occupied (false outside the bounds).
  [[nodiscard]] bool Occupied(const Eigen::Vector3d& p_W) const;

 private:
  common::Box3 bounds_;
  int n_ = 0;
  // Per camera and axis: the projection's contribution of each grid coordinate
  // (P's column times the voxel centre coordinate), so a voxel costs three adds.
  struct AxisTerms {
    std::vector<Eigen::Vector3f> x, y, z;
  };
  std::vector<AxisTerms> terms_;
  std::vector<int> widths_, heights_;
  std::vector<std::uint8_t> occupied_;
};

}  // namespace hg::tools
