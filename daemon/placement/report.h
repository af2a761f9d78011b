#pragma once
/// @file
/// The placement report: report.md, report.json and pictures (top view of the
/// coverage count, horizontal slices, the free space around a sample person,
/// the camera frusta from above) for the optimised layout and the corner
/// heuristic.

#include <string>
#include <vector>

#include "placement/coverage.h"
#include "placement/optimiser.h"
#include "placement/placement_scene.h"

namespace hg::placement {

/// One layout in the report.
struct LayoutReport {
  std::string key;    ///< File-name prefix and JSON key: "optimised", "corner".
  std::string title;  ///< "optimised", "corner heuristic".
  std::vector<CameraPlacement> placements;
};

/// How the run went, for the report. Plain struct.
struct RunInfo {
  std::string command;       ///< The command line, as the user can repeat it.
  std::string cameras_file;  ///< Where the camera block was written.
  int cameras = 0;
  std::uint64_t seed = 0;
  int threads = 0;
  ObjectiveOptions objective;
  long long global_evaluations = 0;
  long long local_evaluations = 0;
  double global_seconds = 0.0;
  double local_seconds = 0.0;
  double total_seconds = 0.0;
};

/// Heights of the horizontal slices in the pictures (m above the floor).
inline constexpr double kSliceHeightsM[] = {0.5, 1.0, 1.5};

/// Writes report.md, report.json and the pictures <key>_coverage_top.png,
/// <key>_slices.png, <key>_free.png and <key>_frusta.png of every layout into
/// `dir` (created if missing). `evaluator` recomputes each layout (its
/// objective options are those reported). The exact single-camera field-of-view
/// volume (hg::placement_fov) of every camera is reported next to the voxel
/// count.
/// @throws common::ConfigError when the directory or a file cannot be written.
void WriteReport(const std::string& dir, const PlacementScene& scene, Evaluator* evaluator,
                 const RunInfo& run, const std::vector<LayoutReport>& layouts);

}  // namespace hg::placement
