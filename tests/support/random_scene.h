#pragma once
/// @file
/// Seeded random scenes for property tests: cameras around a cell, analytic
/// objects, box and mesh obstacles, and their exact masks.

#include <cstdint>
#include <random>
#include <vector>

#include "common/box.h"
#include "common/image.h"
#include "geometry/camera.h"
#include "geometry/mesh.h"
#include "octree/camera_view.h"
#include "scene/demo_cell.h"
#include "scene/shapes.h"

namespace hg::testing {

using scene::LookAtCamera;

struct RandomSceneOptions {
  int num_cameras = 4;
  int width = 160;
  int height = 120;
  int num_objects = 3;
  int num_obstacles = 0;  ///< Half boxes, half random triangle soups.
};

struct RandomScene {
  common::Box3 bounds;
  std::vector<geometry::CameraModel> cameras;  ///< Pinhole.
  std::vector<scene::Shape> objects;
  std::vector<geometry::TriangleMesh> obstacles;
};

/// How many times more seeds the seeded property tests run: the environment
/// variable HG_SOAK, a positive integer (default 1), for long runs that hunt
/// rare cases (tests/README.md). Anything else there stops the test binary.
int SoakFactor();

/// `seeds` times SoakFactor(): the seed count of a seeded property test.
int SoakSeeds(int seeds);

/// A random scene in the cell [0, 2]^3: cameras on a shell around it looking at
/// random points near the middle (some see part of the cell outside the image,
/// some stand inside the cell's bounding sphere), objects inside the cell.
RandomScene MakeRandomScene(std::uint64_t seed, const RandomSceneOptions& options);

/// A random object (sphere, box or capsule) inside `bounds`.
scene::Shape RandomObject(std::mt19937_64& rng, const common::Box3& bounds);

/// Exact masks of the objects in every camera (obstacles do not hide objects:
/// a superset of what the cameras would see).
std::vector<common::ImageU8> RenderMasks(const std::vector<geometry::CameraModel>& cameras,
                                         const std::vector<scene::Shape>& objects);

std::vector<octree::CameraView> MakeViews(const std::vector<geometry::CameraModel>& cameras,
                                          const std::vector<geometry::TriangleMesh>& obstacles);

/// True iff the segment from the camera centre to p_W crosses no obstacle triangle.
bool VisibleFrom(const geometry::CameraModel& camera,
                 const std::vector<geometry::TriangleMesh>& obstacles, const Eigen::Vector3d& p_W);

}  // namespace hg::testing
