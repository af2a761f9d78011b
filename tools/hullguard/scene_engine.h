#pragma once
/// @file
/// The reconstruction engine driven by the simulator, frame by frame: render
/// masks, undistort them conservatively, build quadtrees, update the octree.
/// Shared by `hullguard bench` and `hullguard demo`.

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "common/image.h"
#include "octree/octree.h"
#include "silhouette/quadtree.h"
#include "silhouette/undistort.h"
#include "sim/simulator.h"

namespace hg::tools {

struct SceneEngineOptions {
  int depth = 10;
  int threads = 2;
  int boundary_coarsening = octree::OctreeConfig{}.boundary_coarsening;
  int coarse_first_depth = octree::OctreeConfig{}.coarse_first_depth;
  int key_level = 0;     ///< octree::OctreeConfig::key_level.
  int settle_level = 0;  ///< octree::OctreeConfig::settle_level.
  /// Capture skew compensated as the daemon does (PipelineOptions::max_speed_mps):
  /// each camera's octree margin is the distance a person at this speed covers
  /// between its capture offset and the scene's latest (or their median,
  /// `stamp_at_median`). 0: off.
  double max_speed_mps = 0.0;
  bool stamp_at_median = false;  ///< PipelineOptions::stamp_at_median.
};

/// The capture offset (s) a compensated tree holds the scene for: the
/// latest of the cameras', or their (lower) median.
[[nodiscard]] double StampOffset(const sim::Scene& scene, bool median);

/// Wall-clock times of one frame's stages.
struct FrameTimes {
  double render_ms = 0.0;  ///< Simulator: masks of every camera (on the worker threads).
  double quadtree_ms =
      0.0;  ///< Undistortion where needed + quadtree build, all cameras, one thread.
  octree::UpdateStats octree;
};

class SceneEngine {
 public:
  SceneEngine(sim::Scene scene, const SceneEngineOptions& options);

  /// Renders the scene at t_s and updates the octree under `control`; with
  /// octree_budget_ms > 0, the update's deadline is that long after it starts.
  FrameTimes Step(double t_s, const octree::UpdateControl& control = {},
                  double octree_budget_ms = 0.0);

  [[nodiscard]] const octree::Octree& tree() const { return *tree_; }
  [[nodiscard]] const sim::Scene& scene() const { return simulator_.scene(); }
  [[nodiscard]] sim::Simulator& simulator() { return simulator_; }
  /// Masks of the last Step() as the cameras saw them (with lens distortion).
  [[nodiscard]] const std::vector<common::ImageU8>& masks() const { return masks_; }
  /// Masks of the last Step() in the pinhole cameras (what the octree used).
  [[nodiscard]] const common::ImageU8& PinholeMask(int camera) const;
  [[nodiscard]] const std::vector<geometry::CameraModel>& pinholes() const { return pinholes_; }

 private:
  sim::Simulator simulator_;
  std::vector<geometry::CameraModel> pinholes_;
  std::vector<std::unique_ptr<silhouette::ConservativeUndistorter>> undistorters_;
  std::unique_ptr<octree::Octree> tree_;
  std::vector<common::ImageU8> masks_;
  std::vector<common::ImageU8> undistorted_;
  std::vector<silhouette::SilhouetteQuadtree> quadtrees_;
  std::vector<const silhouette::SilhouetteQuadtree*> quadtree_ptrs_;
  std::vector<double> margins_;  // Per camera (empty: none).
};

/// Points sampled inside people, checked against the tree.
struct TruthCheck {
  std::int64_t points = 0;         ///< Points inside a person at every camera's capture time.
  std::int64_t reported_free = 0;  ///< Of those, reported free by the tree (must be 0).
};

/// Samples `per_person` points inside each person's body at scene time t_s and
/// keeps those that are inside the body at every camera's capture time too
/// (with capture offsets a camera saw the body elsewhere; only points every
/// camera saw inside are guaranteed occupied). With `stamp_offset_s` (skew
/// compensation on, SceneEngineOptions::max_speed_mps), the points are
/// sampled in the body as it was at t_s + stamp_offset_s instead
/// (StampOffset()), which the compensated tree holds for. Deterministic for
/// `seed`.
[[nodiscard]] std::vector<Eigen::Vector3d> SampleTruthPoints(
    const sim::Scene& scene, double t_s, int per_person, std::uint64_t seed,
    std::optional<double> stamp_offset_s = std::nullopt);

[[nodiscard]] TruthCheck CheckTruth(const octree::Octree& tree,
                                    const std::vector<Eigen::Vector3d>& points);

}  // namespace hg::tools
