#pragma once
/// @file
/// Pictures of an occupancy: a top view, a side view and a perspective view,
/// optionally with tracked people drawn over it.

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/box.h"
#include "geometry/camera.h"
#include "geometry/mesh.h"
#include "octree/octree.h"

namespace hg::tools {

/// A box of the occupancy that is not free.
struct SnapshotBox {
  common::Box3 box;
  bool occupied = true;  ///< False: occluded (no camera sees it).
};

/// A tracked person: an axis-aligned ellipsoid with its track id.
struct SnapshotTrack {
  std::uint32_t id = 0;
  Eigen::Vector3d centre_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d half_axes_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity_W_mps = Eigen::Vector3d::Zero();
  bool occluded = false;  ///< Drawn thinner: mostly where no camera sees.
};

/// Writes a PNG with three views of `boxes` inside `bounds`: top (x right, y
/// up) and side (x right, z up), occupied boxes shaded by height or depth over
/// grey occluded space; and a perspective view from above a corner of the cell
/// with occupied boxes as shaded cubes. Cameras are blue dots, obstacles green
/// outlines; `tracks` are magenta ellipsoid outlines labelled with their id in
/// every view (with the velocity over half a second as an arrow in the top
/// view). `caption` is printed under the views.
/// @throws common::ConfigError when the file cannot be written.
void WriteSnapshotPicture(const std::vector<SnapshotBox>& boxes, const common::Box3& bounds,
                          const std::vector<geometry::CameraModel>& cameras,
                          const std::vector<geometry::TriangleMesh>& obstacles,
                          const std::string& caption, const std::string& path,
                          const std::vector<SnapshotTrack>& tracks = {});

/// The octree's non-free leaves as boxes.
[[nodiscard]] std::vector<SnapshotBox> LeafBoxes(const octree::Octree& tree);

}  // namespace hg::tools
