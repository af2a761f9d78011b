#pragma once
/// @file
/// Camera placement: the parameterisation of a camera layout, the corner
/// heuristic baseline and the optimiser (pagmo2 CMA-ES over the whole layout,
/// then NLopt BOBYQA on one camera at a time).

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "geometry/camera.h"
#include "placement/coverage.h"
#include "placement/placement_scene.h"

namespace hg::placement {

/// One placed camera: a point on a mounting surface and the point it looks
/// at (inside the cell). The image x axis is horizontal (MakeCamera).
struct CameraPlacement {
  int surface = 0;  ///< Index into PlacementScene::surfaces.
  double s = 0.0;   ///< Coordinates on the surface, in [0, 1] (t unused on poles).
  double t = 0.0;
  Eigen::Vector3d position_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d look_at_W = Eigen::Vector3d::Zero();
};

/// Number of optimisation variables per camera in the global search: the
/// surface selector, s, t and the look-at point (three, normalised to the
/// cell). All lie in [0, 1]; the surface is floor(selector * surfaces),
/// clamped to the last one.
inline constexpr int kGenesPerCamera = 6;

/// The placement encoded by kGenesPerCamera values in [0, 1].
[[nodiscard]] CameraPlacement DecodePlacement(const PlacementScene& scene, const double* genes);
/// The genes of a placement (inverse of DecodePlacement).
void EncodePlacement(const PlacementScene& scene, const CameraPlacement& placement, double* genes);

/// The cameras of a layout, named cam0, cam1, ... in order.
[[nodiscard]] std::vector<geometry::CameraModel> CamerasOf(
    const PlacementScene& scene, const std::vector<CameraPlacement>& placements);

/// The corner heuristic: cameras at the mounting points nearest to the top
/// corners of the cell (in the order (min x, min y), (max x, max y),
/// (max x, min y), (min x, max y)), then, for more than four cameras, at the
/// points nearest to evenly spaced points of the top edges (south, north,
/// east, west edge in turn), all looking at the centre of the cell.
[[nodiscard]] std::vector<CameraPlacement> CornerHeuristic(const PlacementScene& scene,
                                                           int cameras);

/// Checks a request: at least one camera, 1 <= min_views <= cameras.
/// @throws common::ConfigError "source: --cameras: ..." or "source: --min-views: ...".
void CheckRequest(int cameras, int min_views, const std::string& source);

/// Settings of the search. Plain struct.
struct OptimiserOptions {
  int cameras = 4;
  std::uint64_t seed = 1;
  /// Objective evaluations of the global search (CMA-ES); 0: 2000 + 1000 per camera.
  int global_evaluations = 0;
  /// Objective evaluations of the local refinement; 0: 150 per camera.
  int local_evaluations = 0;
  /// CMA-ES population; 0: twice CMA-ES's default 4 + 3 ln(variables).
  int population = 0;
  /// Initial CMA-ES step, as a share of each variable's range.
  double sigma0 = 0.25;
  /// Worker threads of the evaluator; results do not depend on it.
  int threads = 2;
};

/// A report on the search, for progress output.
struct Progress {
  std::string stage;      ///< "global" or "local".
  long long evaluations;  ///< Done in this stage.
  long long budget;       ///< Planned in this stage.
  double best_score;      ///< Best score so far (whole run).
};
using ProgressFn = std::function<void(const Progress&)>;

/// Result of OptimisePlacement.
struct PlacementResult {
  std::vector<CameraPlacement> placements;
  std::vector<geometry::CameraModel> cameras;
  CoverageMetrics metrics;
  long long global_evaluations = 0;
  long long local_evaluations = 0;
  double global_seconds = 0.0;
  double local_seconds = 0.0;
};

/// Optimises a layout of options.cameras cameras: CMA-ES (pagmo2, seeded,
/// started from the corner heuristic and random layouts, bounds enforced)
/// over every variable, then BOBYQA (NLopt) over one camera's continuous
/// variables at a time with the others fixed, in sweeps over the cameras
/// until the local budget is spent or a sweep improves nothing, keeping only
/// improvements. The result is never worse than the corner heuristic and is
/// the same for the same scene, options and seed, whatever the thread count.
/// @throws common::ConfigError on a bad request (CheckRequest).
[[nodiscard]] PlacementResult OptimisePlacement(const PlacementScene& scene,
                                                const ObjectiveOptions& objective,
                                                const OptimiserOptions& options,
                                                const ProgressFn& progress = {});

}  // namespace hg::placement
