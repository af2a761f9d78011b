#pragma once
/// @file
/// Reading and writing the camera block (the `cameras:` list of a cameras file
/// or of the daemon config).

#include <optional>
#include <string>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "geometry/camera.h"

namespace hg::geometry {

/// Parses one camera entry: `name`, `width`, `height`, optional `distortion`
/// (k1 k2 p1 p2 k3) and one of three forms of the projection:
///  - `K` (9, row-major), `R` (9, world->camera) and `t` (3);
///  - `K`, `position` (3, camera centre in world) and `look_at` (3, a world point
///    on the optical axis), optional `up` (3, default +z; when the view is within
///    ~8 degrees of vertical and `up` is not given, +y is used). The camera frame
///    has x right, y down and z forward, so `up` points upwards in the image;
///  - `P` (12, row-major, any scale), decomposed into K, R, t.
/// Mixing the forms (R/t with position/look_at/up, or P with any other) is an
/// error. Unknown keys are rejected.
/// @throws common::ConfigError naming `file`, the line and the key.
[[nodiscard]] CameraModel ParseCamera(const YAML::Node& node, const std::string& file);

/// Parses one camera entry as ParseCamera does, but goes on past a problem:
/// every problem found is appended to `errors` (one message each, as
/// ParseCamera would throw it), so that a loader can report them all. Checks
/// that depend on a failed one are skipped (a mix of projection forms stops
/// the projection's checks).
/// @returns the camera, or nullopt when any problem was found.
[[nodiscard]] std::optional<CameraModel> ParseCameraReportingAll(const YAML::Node& node,
                                                                 const std::string& file,
                                                                 std::vector<std::string>* errors);

/// Why `name` cannot name a camera's files and folders (synth's
/// masks/<camera>/, kept backgrounds, recordings): letters, digits, '_', '-'
/// and '.', not starting with '.', so that nothing leaves its folder or
/// spells a path two ways; "" when it can.
[[nodiscard]] std::string FileNameProblem(const std::string& name);

/// Parses a `cameras:` sequence node (every entry, names unique; with
/// `file_names`, every name one that FileNameProblem() accepts).
/// @throws common::ConfigError naming `file`, the line and the key.
[[nodiscard]] std::vector<CameraModel> ParseCameraList(const YAML::Node& node,
                                                       const std::string& file,
                                                       bool file_names = false);

/// Loads a YAML file with a top-level `cameras:` list (and no other key).
/// @throws common::ConfigError on a missing file, malformed YAML or a bad entry.
[[nodiscard]] std::vector<CameraModel> LoadCamerasFile(const std::string& path);

/// Writes cameras in the form LoadCamerasFile reads (K, distortion, R, t),
/// whatever form they were read from.
/// @throws common::ConfigError when the file cannot be written.
void WriteCamerasFile(const std::string& path, const std::vector<CameraModel>& cameras);

}  // namespace hg::geometry
