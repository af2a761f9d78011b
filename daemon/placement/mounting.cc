#include "placement/mounting.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <yaml-cpp/yaml.h>
#include <Eigen/Geometry>

#include "common/config_error.h"
#include "common/yaml_file.h"
#include "geometry/camera_yaml.h"

namespace hg::placement {
namespace {

using common::ConfigError;

/// Reads `count` finite numbers from a list node.
std::vector<double> Numbers(const YAML::Node& node, std::size_t count, const std::string& file,
                            const std::string& key) {
  if (!node.IsSequence() || node.size() != count) {
    throw ConfigError::At(file, common::YamlLine(node),
                          key + ": expected " + std::to_string(count) + " numbers");
  }
  std::vector<double> out;
  for (const YAML::Node& element : node) {
    double value = 0.0;
    try {
      value = element.as<double>();
    } catch (const YAML::Exception&) {
      throw ConfigError::At(file, common::YamlLine(element), key + ": expected a number");
    }
    if (!std::isfinite(value)) {
      throw ConfigError::At(file, common::YamlLine(element), key + ": not finite");
    }
    out.push_back(value);
  }
  return out;
}

int Side(const YAML::Node& node, const std::string& file, const std::string& key) {
  int value = 0;
  try {
    value = node.as<int>();
  } catch (const YAML::Exception&) {
    throw ConfigError::At(file, common::YamlLine(node), key + ": expected a positive integer");
  }
  if (value < 1) {
    throw ConfigError::At(file, common::YamlLine(node), key + ": expected a positive integer");
  }
  return value;
}

/// Clamps to [0, 1].
double Unit(double x) { return std::clamp(x, 0.0, 1.0); }

}  // namespace

PlacementIntrinsics LoadIntrinsics(const std::string& path) {
  const YAML::Node root = common::LoadYamlFile(path);
  if (!root.IsMap()) {
    throw ConfigError::At(path, common::YamlLine(root),
                          "expected a map: a cameras file or width, height, K");
  }
  PlacementIntrinsics intrinsics;
  if (root["cameras"]) {
    const std::vector<geometry::CameraModel> cameras =
        geometry::ParseCameraList(root["cameras"], path);
    if (cameras.empty()) {
      throw ConfigError::At(path, common::YamlLine(root["cameras"]), "cameras: list is empty");
    }
    intrinsics.width = cameras.front().width;
    intrinsics.height = cameras.front().height;
    intrinsics.K = cameras.front().K;
    intrinsics.distortion = cameras.front().distortion;
    return intrinsics;
  }
  static const std::set<std::string> kKnown = {"width", "height", "K", "distortion"};
  for (const auto& kv : root) {
    const std::string key = kv.first.as<std::string>();
    if (kKnown.count(key) == 0) {
      throw ConfigError::At(path, common::YamlLine(kv.first),
                            "unknown key '" + key +
                                "' (known: cameras, or width, height, K, "
                                "distortion)");
    }
  }
  for (const char* key : {"width", "height", "K"}) {
    if (!root[key]) {
      throw ConfigError::At(path, common::YamlLine(root), std::string("missing key '") + key + "'");
    }
  }
  intrinsics.width = Side(root["width"], path, "width");
  intrinsics.height = Side(root["height"], path, "height");
  const std::vector<double> k = Numbers(root["K"], 9, path, "K");
  intrinsics.K = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(k.data());
  if (!(intrinsics.K(0, 0) > 0 && intrinsics.K(1, 1) > 0) || intrinsics.K(1, 0) != 0 ||
      intrinsics.K(2, 0) != 0 || intrinsics.K(2, 1) != 0 || intrinsics.K(2, 2) != 1) {
    throw ConfigError::At(path, common::YamlLine(root["K"]),
                          "K: expected [fx, s, cx, 0, fy, cy, 0, 0, 1] with fx, fy > 0");
  }
  if (root["distortion"]) {
    const std::vector<double> d = Numbers(root["distortion"], 5, path, "distortion");
    std::copy(d.begin(), d.end(), intrinsics.distortion.begin());
  }
  // The cameras file `place` writes must load in hullguardd and hullguard
  // carve: the intrinsics pass the camera loader's own checks (image size,
  // focal lengths and their ratio, principal point, distortion), with errors
  // at this file's lines. The pose is a stand-in.
  YAML::Node camera(YAML::NodeType::Map);
  camera["name"] = "intrinsics";
  for (const char* key : {"width", "height", "K", "distortion"}) {
    if (root[key]) camera[key] = root[key];
  }
  camera["R"] = std::vector<double>{1, 0, 0, 0, 1, 0, 0, 0, 1};
  camera["t"] = std::vector<double>{0, 0, 0};
  (void)geometry::ParseCamera(camera, path);
  return intrinsics;
}

PlacementIntrinsics IntrinsicsFromScene(const sim::Scene& scene) {
  if (scene.cameras.empty()) {
    throw ConfigError::At(scene.source_file.empty() ? scene.name : scene.source_file, 0,
                          "cameras: the scene has no camera to take the intrinsics from "
                          "(give --intrinsics)");
  }
  const geometry::CameraModel& model = scene.cameras.front().model;
  PlacementIntrinsics intrinsics;
  intrinsics.width = model.width;
  intrinsics.height = model.height;
  intrinsics.K = model.K;
  intrinsics.distortion = model.distortion;
  return intrinsics;
}

std::vector<sim::MountingSurface> DefaultMountingSurfaces(const common::Box3& bounds) {
  const Eigen::Vector3d& lo = bounds.min;
  const Eigen::Vector3d& hi = bounds.max;
  const double band = std::min(kDefaultWallBandM, hi.z() - lo.z());
  const double z0 = hi.z() - band;
  // Corners of the floor outline, counter-clockwise seen from above.
  const std::array<Eigen::Vector2d, 4> corners = {
      Eigen::Vector2d(lo.x(), lo.y()), Eigen::Vector2d(hi.x(), lo.y()),
      Eigen::Vector2d(hi.x(), hi.y()), Eigen::Vector2d(lo.x(), hi.y())};
  const std::array<const char*, 4> names = {"wall_south", "wall_east", "wall_north", "wall_west"};
  std::vector<sim::MountingSurface> surfaces;
  for (int i = 0; i < 4; ++i) {
    const Eigen::Vector2d& a = corners[i];
    const Eigen::Vector2d& b = corners[(i + 1) % 4];
    sim::MountingSurface wall;
    wall.name = names[i];
    wall.kind = sim::MountingSurface::Kind::kWall;
    wall.origin_W = Eigen::Vector3d(a.x(), a.y(), z0);
    wall.u_W = Eigen::Vector3d(b.x() - a.x(), b.y() - a.y(), 0.0);
    wall.v_W = Eigen::Vector3d(0.0, 0.0, band);
    surfaces.push_back(wall);
  }
  sim::MountingSurface ceiling;
  ceiling.name = "ceiling";
  ceiling.kind = sim::MountingSurface::Kind::kCeiling;
  ceiling.origin_W = Eigen::Vector3d(lo.x(), lo.y(), hi.z());
  ceiling.u_W = Eigen::Vector3d(hi.x() - lo.x(), 0.0, 0.0);
  ceiling.v_W = Eigen::Vector3d(0.0, hi.y() - lo.y(), 0.0);
  surfaces.push_back(ceiling);
  return surfaces;
}

std::vector<sim::MountingSurface> MountingSurfacesOf(const sim::Scene& scene) {
  if (!scene.mounting.has_value()) return DefaultMountingSurfaces(scene.bounds);
  if (scene.mounting->empty()) {
    throw ConfigError::At(scene.source_file.empty() ? scene.name : scene.source_file, 0,
                          "mounting: scene has no mounting surface");
  }
  return *scene.mounting;
}

Eigen::Vector3d ClosestMountPoint(const sim::MountingSurface& surface, const Eigen::Vector3d& p_W,
                                  double* s, double* t) {
  const Eigen::Vector3d d = p_W - surface.origin_W;
  if (surface.kind == sim::MountingSurface::Kind::kPole) {
    *s = Unit(d.dot(surface.u_W) / surface.u_W.squaredNorm());
    *t = 0.0;
    return surface.PointAt(*s, *t);
  }
  // Rectangles from the loader have perpendicular edges, so clamping the two
  // projections separately gives the closest point.
  *s = Unit(d.dot(surface.u_W) / surface.u_W.squaredNorm());
  *t = Unit(d.dot(surface.v_W) / surface.v_W.squaredNorm());
  return surface.PointAt(*s, *t);
}

geometry::CameraModel MakeCamera(const PlacementIntrinsics& intrinsics, const std::string& name,
                                 const Eigen::Vector3d& position_W,
                                 const Eigen::Vector3d& look_at_W) {
  Eigen::Vector3d forward = look_at_W - position_W;
  if (forward.norm() < 1e-3) forward = -Eigen::Vector3d::UnitZ();
  forward.normalize();
  // Image x = forward x up keeps x horizontal; near the vertical the cross
  // product vanishes and world +y serves as "up" instead.
  Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ());
  if (right.norm() < 1e-9) right = forward.cross(Eigen::Vector3d::UnitY());
  right.normalize();
  const Eigen::Vector3d down = forward.cross(right);
  geometry::CameraModel camera;
  camera.name = name;
  camera.width = intrinsics.width;
  camera.height = intrinsics.height;
  camera.K = intrinsics.K;
  camera.distortion = intrinsics.distortion;
  camera.R_CW.row(0) = right.transpose();
  camera.R_CW.row(1) = down.transpose();
  camera.R_CW.row(2) = forward.transpose();
  camera.t_CW = -camera.R_CW * position_W;
  return camera;
}

}  // namespace hg::placement
