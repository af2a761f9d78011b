#pragma once
/// @file
/// The built-in demo cell: a 4 m cube work cell with a table and a rack, cameras
/// on the upper corners and walls, and person-shaped bodies walking through it.
/// Used by `hullguard demo`, the benchmarks and the tests.

#include <vector>

#include "common/box.h"
#include "geometry/camera.h"
#include "geometry/mesh.h"
#include "scene/shapes.h"

namespace hg::scene {

struct DemoCellOptions {
  int num_cameras = 8;  ///< 1..8: corners first, then wall centres.
  int width = 1920;
  int height = 1080;
  int num_people = 3;  ///< 0..3.
  bool obstacles = true;
};

struct DemoCell {
  common::Box3 bounds;
  std::vector<geometry::CameraModel> cameras;  ///< Pinhole.
  std::vector<geometry::TriangleMesh> obstacles;
};

/// Pinhole camera at `eye` looking at `target` (z up in the world; near-vertical
/// views take y as up), focal length fx pixels, principal point at the centre.
[[nodiscard]] geometry::CameraModel LookAtCamera(const Eigen::Vector3d& eye,
                                                 const Eigen::Vector3d& target, int width,
                                                 int height, double fx);

/// The static part of the cell.
[[nodiscard]] DemoCell MakeDemoCell(const DemoCellOptions& options);

/// Person-like bodies (capsule limbs and a head) at time t_s: person i walks
/// its own loop at about 1.2 m/s, swinging arms and legs.
[[nodiscard]] std::vector<Shape> DemoPeople(int num_people, double t_s);

}  // namespace hg::scene
