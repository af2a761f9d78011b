#pragma once
/// @file
/// The placement objective on the voxel grid: which voxels each camera
/// certifies, the definitely-object-free volume around sample people and the
/// share of the cell seen by at least K cameras.
///
/// A camera certifies a voxel when the whole voxel is seen: its eight corners
/// project into the image (the frustum is convex, so the box is inside it), and
/// every pixel of the voxel's footprint (the pixels whose squares touch the
/// projected corners' bounding rectangle) shows obstacles only behind the
/// voxel's farthest corner. Both use a reduced image of
/// ModelOptions::render_width_px columns with a conservative (min-depth over
/// the pixel square) obstacle depth map, which can only certify less than the
/// full-resolution camera would. With a sample person in the cell a camera
/// certifies a voxel only when, in addition, no footprint pixel holds the
/// person: the daemon cannot call a voxel free through foreground pixels, so
/// the person removes its whole viewing cone (in front of and behind it).

#include <algorithm>
#include <cstdint>
#include <memory>
#include <vector>

#include "common/worker_pool.h"
#include "geometry/camera.h"
#include "geometry/mesh.h"
#include "placement/placement_scene.h"

namespace hg::placement {

/// Inclusive pixel rectangle in the reduced image (16-bit to keep lists small).
struct Footprint {
  std::int16_t u0 = 0;
  std::int16_t v0 = 0;
  std::int16_t u1 = -1;
  std::int16_t v1 = -1;
};

/// Conservative silhouette of one sample person in one reduced image: the
/// bounding rectangle of its pixels and a summed-area table over it.
struct Silhouette {
  int u0 = 0;
  int v0 = 0;
  int u1 = -1;  ///< u1 < u0: the person is not in the image.
  int v1 = -1;
  std::vector<std::int32_t> sat;  ///< (width + 1) * (height + 1) prefix sums.

  [[nodiscard]] bool Empty() const { return u1 < u0; }
  /// True when some silhouette pixel lies inside `rect`.
  [[nodiscard]] bool Touches(const Footprint& rect) const;
};

/// What one camera certifies, without and with each sample person. Buffers
/// are reused between computations. Thread-compatible.
struct CameraView {
  std::vector<std::int32_t> voxels;     ///< Certified voxels (no person), ascending.
  std::vector<Footprint> footprints;    ///< Footprint of each of them.
  std::vector<Silhouette> silhouettes;  ///< One per sample person.

  /// Entries (indices into `voxels`) whose footprint is at most
  /// kFootprintTile pixels on each side, grouped by the tile of the reduced
  /// image that holds the footprint's first pixel: tile t's entries are
  /// tile_entries[tile_start[t] .. tile_start[t + 1]). A silhouette then
  /// needs only the tiles near its bounding rectangle.
  static constexpr int kFootprintTile = 16;
  int tiles_x = 0;
  int tiles_y = 0;
  std::vector<std::int32_t> tile_start;
  std::vector<std::int32_t> tile_entries;
  std::vector<std::int32_t> large_entries;  ///< Entries with larger footprints.

  /// Calls fn(entry) for every entry whose footprint may meet the rectangle
  /// [u0, u1] x [v0, v1] (a superset; each entry once).
  template <class Fn>
  void ForEachNear(int u0, int v0, int u1, int v1, const Fn& fn) const {
    const int t = kFootprintTile;
    const int tx0 = std::max(0, (u0 - t + 1) / t);
    const int ty0 = std::max(0, (v0 - t + 1) / t);
    const int tx1 = std::min(tiles_x - 1, u1 / t);
    const int ty1 = std::min(tiles_y - 1, v1 / t);
    for (int ty = ty0; ty <= ty1; ++ty) {
      for (int tx = tx0; tx <= tx1; ++tx) {
        const int tile = ty * tiles_x + tx;
        for (int k = tile_start[tile]; k < tile_start[tile + 1]; ++k) fn(tile_entries[k]);
      }
    }
    for (const std::int32_t e : large_entries) fn(e);
  }
};

/// Reusable buffers of ComputeView. Thread-compatible.
struct ViewScratch {
  std::vector<float> u;
  std::vector<float> v;
  std::vector<double> z;
  std::vector<std::uint8_t> ok;  ///< Corner in front of the camera and in the image.
  std::vector<std::uint8_t> mask;
  std::vector<std::int32_t> obstacle_sat;
  std::vector<std::int32_t> tile_fill;
  std::vector<geometry::TriangleMesh> facing;  ///< Obstacle faces towards the camera.
};

/// The camera with the same pose and field of view on an image about
/// `width_px` pixels wide: pixel (u, v) of it covers the full-resolution
/// pixels whose centres fall in its square.
[[nodiscard]] geometry::CameraModel ReducedCamera(const geometry::CameraModel& camera,
                                                  int width_px);

/// Computes what `camera` certifies in `scene` (pinhole model; the
/// distortion is ignored). A camera whose centre lies inside a closed
/// obstacle certifies nothing.
void ComputeView(const PlacementScene& scene, const geometry::CameraModel& camera, CameraView* view,
                 ViewScratch* scratch);

/// How the objective weighs its parts. Plain struct.
struct ObjectiveOptions {
  int min_views = 2;             ///< K of the K-coverage.
  double coverage_weight = 0.5;  ///< Weight of the K-coverage in the score.
};

/// Figures of one camera layout. Volumes are of the surveillance volume
/// (the cell without the voxels that touch obstacles).
struct CoverageMetrics {
  int min_views = 0;
  double target_volume_m3 = 0.0;
  double seen_fraction = 0.0;  ///< Certified by >= 1 camera, empty cell.
  double k_coverage = 0.0;     ///< Certified by >= min_views cameras, empty cell.
  /// Per sample person: share certified free by >= 1 camera.
  std::vector<double> free_fraction;
  double mean_free_fraction = 0.0;
  double min_free_fraction = 0.0;
  double mean_free_m3 = 0.0;
  /// mean_free_fraction + coverage_weight * k_coverage.
  double score = 0.0;
};

/// Evaluates camera layouts on one scene, in parallel over cameras and
/// sample people on a worker pool; the result does not depend on the number
/// of threads (every figure is an integer count). Buffers are reused, so
/// evaluations after the first allocate nothing per voxel.
/// Thread-compatible: one evaluation at a time.
class Evaluator {
 public:
  Evaluator(const PlacementScene& scene, const ObjectiveOptions& objective, int threads);
  ~Evaluator();
  Evaluator(const Evaluator&) = delete;
  Evaluator& operator=(const Evaluator&) = delete;

  [[nodiscard]] const PlacementScene& scene() const { return *scene_; }
  [[nodiscard]] const ObjectiveOptions& objective() const { return objective_; }

  /// Figures of a whole layout.
  [[nodiscard]] CoverageMetrics Evaluate(const std::vector<geometry::CameraModel>& cameras);

  /// After Evaluate: per voxel, the number of cameras that certify it (empty cell).
  [[nodiscard]] const std::vector<std::uint8_t>& counts() const { return counts_; }
  /// After Evaluate: per voxel, 1 when some camera certifies it free with
  /// sample person `sample` in the cell.
  void CertifiedFree(int sample, std::vector<std::uint8_t>* free);
  /// After Evaluate: the number of voxels each camera certifies (empty cell).
  [[nodiscard]] std::vector<int> SeenVoxelsPerCamera() const;

  /// Fixes every camera of `cameras` but `varying`, for EvaluateVarying.
  void Freeze(const std::vector<geometry::CameraModel>& cameras, int varying);
  /// Figures of the frozen layout with camera `varying` replaced by `camera`;
  /// equal to Evaluate of that layout, at the cost of one camera.
  [[nodiscard]] CoverageMetrics EvaluateVarying(const geometry::CameraModel& camera);

 private:
  struct WorkerScratch;
  [[nodiscard]] CoverageMetrics Finish(long long seen1, long long seen_k,
                                       const std::vector<long long>& certified) const;
  void ComputeViews(const std::vector<geometry::CameraModel>& cameras, int skip);
  /// Blocked counts of sample s over views_ (skipping `skip`) into the
  /// worker's scratch; returns the number of voxels with blocked == counts.
  long long LostVoxels(int sample, int skip, WorkerScratch* scratch);

  const PlacementScene* scene_;
  ObjectiveOptions objective_;
  std::unique_ptr<common::WorkerPool> pool_;
  std::vector<WorkerScratch> workers_;
  std::vector<geometry::CameraModel> cameras_;
  std::vector<CameraView> views_;
  std::vector<std::uint8_t> counts_;
  std::vector<long long> certified_;
  // Freeze state.
  int varying_ = -1;
  CameraView varying_view_;
  std::vector<std::vector<std::uint8_t>> others_free_;  // Per sample, per voxel.
  std::vector<long long> others_free_count_;
  long long others_seen1_ = 0;
  long long others_seen_k_ = 0;
};

}  // namespace hg::placement
