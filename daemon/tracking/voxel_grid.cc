#include "tracking/voxel_grid.h"

#include <cmath>
#include <string>

#include "common/config_error.h"

namespace hg::tracking {

VoxelGrid::VoxelGrid(const common::Box3& bounds, double voxel_m) : origin_(bounds.min) {
  if (!bounds.min.allFinite() || !bounds.max.allFinite() || !bounds.IsValid()) {
    throw common::ConfigError("tracking: bounds: must be finite with max > min on every axis");
  }
  if (!(voxel_m > 0.0) || !std::isfinite(voxel_m)) {
    throw common::ConfigError("tracking: voxel_m: must be > 0");
  }
  voxel_m_ = voxel_m;
  const Eigen::Vector3d cells = (bounds.Size() / voxel_m).array().ceil();
  if (cells.x() > kMaxRowLength || cells.y() > kMaxRowLength || cells.z() > kMaxRowLength ||
      cells.prod() >= 2147483648.0) {
    throw common::ConfigError("tracking: voxel_m: " + std::to_string(voxel_m) +
                              " m gives too many voxels for the bounds");
  }
  nx_ = static_cast<int>(cells.x());
  ny_ = static_cast<int>(cells.y());
  nz_ = static_cast<int>(cells.z());
}

common::Box3 VoxelGrid::covered() const {
  return {origin_, origin_ + voxel_m_ * Eigen::Vector3d(nx_, ny_, nz_)};
}

Eigen::Vector3i VoxelGrid::VoxelOf(const Eigen::Vector3d& p_W) const {
  // Clamped so that far-away points stay representable; they are outside anyway.
  const Eigen::Vector3d g =
      ((p_W - origin_) / voxel_m_).array().floor().cwiseMax(-1e9).cwiseMin(1e9);
  return g.cast<int>();
}

}  // namespace hg::tracking
