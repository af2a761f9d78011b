#include "hullguard/open3d_baseline.h"

#include <open3d/camera/PinholeCameraParameters.h>
#include <open3d/geometry/Image.h>
#include <open3d/geometry/VoxelGrid.h>

namespace hg::tools {

struct Open3dCarver::Impl {
  common::Box3 bounds;
  double voxel_size = 0.0;
  std::vector<open3d::camera::PinholeCameraParameters> cameras;
  std::vector<open3d::geometry::Image> masks;  // Float, one channel, as CarveSilhouette reads.
  std::shared_ptr<open3d::geometry::VoxelGrid> grid;
};

Open3dCarver::Open3dCarver(const common::Box3& bounds, int resolution,
                           const std::vector<geometry::CameraModel>& cameras)
    : impl_(std::make_unique<Impl>()) {
  impl_->bounds = bounds;
  // Open3D's voxels are cubes: R along the longest side of the bounds.
  impl_->voxel_size = bounds.Size().maxCoeff() / resolution;
  for (const geometry::CameraModel& c : cameras) {
    open3d::camera::PinholeCameraParameters p;
    p.intrinsic_ = open3d::camera::PinholeCameraIntrinsic(c.width, c.height, c.K(0, 0), c.K(1, 1),
                                                          c.K(0, 2), c.K(1, 2));
    p.extrinsic_.setIdentity();
    p.extrinsic_.block<3, 3>(0, 0) = c.R_CW;
    p.extrinsic_.block<3, 1>(0, 3) = c.t_CW;
    impl_->cameras.push_back(p);
    open3d::geometry::Image mask;
    mask.Prepare(c.width, c.height, 1, 4);
    impl_->masks.push_back(std::move(mask));
  }
}

Open3dCarver::~Open3dCarver() = default;

std::int64_t Open3dCarver::Carve(const std::vector<const common::ImageU8*>& masks) {
  const Eigen::Vector3d size = impl_->bounds.Size();
  impl_->grid =
      open3d::geometry::VoxelGrid::CreateDense(impl_->bounds.min, Eigen::Vector3d(0.5, 0.5, 0.5),
                                               impl_->voxel_size, size.x(), size.y(), size.z());
  for (std::size_t c = 0; c < masks.size(); ++c) {
    open3d::geometry::Image& m = impl_->masks[c];
    for (int v = 0; v < m.height_; ++v) {
      for (int u = 0; u < m.width_; ++u) {
        *m.PointerAt<float>(u, v) = masks[c]->At(u, v) > 127 ? 1.0F : 0.0F;
      }
    }
    impl_->grid->CarveSilhouette(m, impl_->cameras[c], /*keep_voxels_outside_image=*/true);
  }
  return static_cast<std::int64_t>(impl_->grid->voxels_.size());
}

bool Open3dCarver::Occupied(const Eigen::Vector3d& p_W) const {
  return impl_->grid && impl_->grid->voxels_.count(impl_->grid->GetVoxel(p_W)) != 0;
}

}  // namespace hg::tools
