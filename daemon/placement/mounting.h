#pragma once
/// @file
/// Where cameras can go: the mounting surfaces of a scene, the intrinsics of
/// the cameras to place, and the roll-free camera pose built from a mounting
/// point and a look-at point.

#include <array>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "geometry/camera.h"
#include "sim/scene.h"

namespace hg::placement {

/// Intrinsics shared by every placed camera. Value type.
struct PlacementIntrinsics {
  int width = 0;
  int height = 0;
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();  ///< Row-major pinhole matrix, K(2,2) == 1.
  /// k1 k2 p1 p2 k3, copied into the written camera block. Placement itself
  /// evaluates the pinhole model (see docs/placement.md).
  std::array<double, 5> distortion{0, 0, 0, 0, 0};
};

/// Intrinsics from a file: either a cameras file (a top-level `cameras:` list
/// in the camera block format; its first camera's width, height, K and
/// distortion are used, its pose is ignored) or a map with `width`, `height`,
/// `K` (9 numbers) and optional `distortion` (5 numbers).
/// @throws common::ConfigError "file:line: key: problem" on any error.
[[nodiscard]] PlacementIntrinsics LoadIntrinsics(const std::string& path);

/// Intrinsics of the scene's first camera.
/// @throws common::ConfigError "file: cameras: ..." when the scene has no camera.
[[nodiscard]] PlacementIntrinsics IntrinsicsFromScene(const sim::Scene& scene);

/// Height of the wall band of the default mounting surfaces (m).
inline constexpr double kDefaultWallBandM = 0.5;

/// The default mounting surfaces of a cell without a `mounting` section: the
/// top kDefaultWallBandM of the four vertical faces of `bounds` (walls, named
/// wall_south (y = min), wall_east (x = max), wall_north (y = max), wall_west
/// (x = min)) and its top face (ceiling).
[[nodiscard]] std::vector<sim::MountingSurface> DefaultMountingSurfaces(const common::Box3& bounds);

/// The surfaces a scene offers: its `mounting` section, or
/// DefaultMountingSurfaces(scene.bounds) when it has none.
/// @throws common::ConfigError "file: mounting: scene has no mounting surface"
/// when the section is an empty list.
[[nodiscard]] std::vector<sim::MountingSurface> MountingSurfacesOf(const sim::Scene& scene);

/// The point of `surface` closest to p_W, with its coordinates (s, t) in
/// [0, 1] (t = 0 for a pole).
[[nodiscard]] Eigen::Vector3d ClosestMountPoint(const sim::MountingSurface& surface,
                                                const Eigen::Vector3d& p_W, double* s, double* t);

/// A camera with `intrinsics` centred at position_W whose optical axis passes
/// through look_at_W, with the image x axis horizontal (no roll): x points
/// right, y down in the image. Looking straight up or down, +y of the world
/// points up in the image. When look_at_W is within 1 mm of position_W the
/// camera looks straight down.
[[nodiscard]] geometry::CameraModel MakeCamera(const PlacementIntrinsics& intrinsics,
                                               const std::string& name,
                                               const Eigen::Vector3d& position_W,
                                               const Eigen::Vector3d& look_at_W);

}  // namespace hg::placement
