#pragma once
/// @file
/// A simulated work cell: bounds, cameras, static obstacles and foreground
/// objects, people with scripts, lighting and sensor settings. Loaded from the
/// scene YAML format documented in docs/scenes.md.

#include <optional>
#include <string>
#include <vector>

#include "common/box.h"
#include "geometry/camera.h"
#include "sim/body.h"
#include "sim/solids.h"

namespace hg::sim {

/// Image formation settings for colour frames.
struct ImagingSettings {
  double noise_sigma = 2.0;  ///< Sensor noise, grey levels (0..255 scale), Gaussian.
  Eigen::Vector3d light_W = Eigen::Vector3d(2.0, 1.5, 3.8);  ///< Point light (ceiling lamp).
  double ambient = 0.35;            ///< Ambient share of the light, [0, 1].
  bool shadows = true;              ///< Obstacles' hard shadows, people's soft ones.
  double shadow_softness_m = 0.15;  ///< Width of the penumbra.
  /// Global light changes: gain(t) = 1 + amplitude * sin(2 pi t / period_s).
  double light_change_amplitude = 0.0;
  double light_change_period_s = 20.0;
  std::uint64_t seed = 1;  ///< Noise seed; frames are deterministic for a seed.
};

/// One camera of the scene: the calibrated model and its capture time offset.
struct SceneCamera {
  geometry::CameraModel model;
  double time_offset_s = 0.0;  ///< This camera captures at t + time_offset_s.
};

/// A surface cameras may be mounted on (the scene's `mounting` section, used by
/// camera placement): the rectangle origin_W + s u_W + t v_W with s, t in
/// [0, 1], or for a pole the segment origin_W + s u_W. Value type.
struct MountingSurface {
  enum class Kind { kWall, kCeiling, kPole };
  std::string name;
  Kind kind = Kind::kWall;
  Eigen::Vector3d origin_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d u_W = Eigen::Vector3d::Zero();  ///< First edge; a pole's axis (m).
  Eigen::Vector3d v_W = Eigen::Vector3d::Zero();  ///< Second edge; zero for a pole (m).

  /// Number of free coordinates of a point on the surface: 2, or 1 for a pole.
  [[nodiscard]] int Dimensions() const { return kind == Kind::kPole ? 1 : 2; }
  /// The point at (s, t); t is ignored for a pole.
  [[nodiscard]] Eigen::Vector3d PointAt(double s, double t) const {
    if (kind == Kind::kPole) return origin_W + s * u_W;
    return origin_W + s * u_W + t * v_W;
  }
};

struct Scene {
  std::string name;
  std::string source_file;  ///< Path the scene was loaded from (empty if built in code).
  common::Box3 bounds;      ///< Surveillance volume.
  double rate_hz = 30.0;    ///< Frame rate of `hullguard synth`.
  std::vector<SceneCamera> cameras;
  std::vector<Solid> obstacles;           ///< Static, known: hide what is behind them.
  std::vector<Solid> foreground_objects;  ///< Static, unknown to the daemon: crates.
  std::vector<Person> people;
  ImagingSettings imaging;
  bool mask_occlusion = true;  ///< Ground-truth masks leave out what obstacles hide.
  /// Where cameras may be mounted: nullopt when the file has no `mounting`
  /// section (camera placement then uses its documented default), an empty
  /// list when it says there is no such place (`mounting: []`).
  std::optional<std::vector<MountingSurface>> mounting;

  /// The calibrated camera models, in order.
  [[nodiscard]] std::vector<geometry::CameraModel> CameraModels() const;
  /// Every obstacle as a circumscribing triangle mesh, in order.
  [[nodiscard]] std::vector<geometry::TriangleMesh> ObstacleMeshes() const;
};

/// Parses a scene file. Relative mesh paths are resolved against the file's directory.
/// @throws common::ConfigError naming the file, the line and the key on any error
/// (unknown key, missing key, wrong type, bad value, unreadable mesh).
[[nodiscard]] Scene LoadScene(const std::string& path);

/// Parses scene YAML text; `file` names it in messages, `base_dir` resolves mesh paths.
[[nodiscard]] Scene ParseScene(const std::string& yaml_text, const std::string& file,
                               const std::string& base_dir);

}  // namespace hg::sim
