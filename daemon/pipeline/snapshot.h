#pragma once
/// @file
/// What one fusion cycle hands to its consumers: an immutable occupancy
/// snapshot and the pipeline's health. Publishers read these, never the octree.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "common/box.h"

namespace hg::pipeline {

enum class CameraState : std::uint8_t {
  kStarting = 0,  ///< No frame yet.
  kOk = 1,        ///< Frames arrive within the timeout.
  kStale = 2,     ///< No frame for longer than the timeout: treated as seeing nothing.
  kFailed = 3,    ///< The source failed or its images are faulty (see CameraHealth::fault).
};

struct CameraHealth {
  std::string name;
  CameraState state = CameraState::kStarting;
  double fps = 0.0;           ///< Frames per second over the last second.
  double frame_age_ms = 0.0;  ///< Age of the newest frame at the cycle's start.
  std::uint64_t frames = 0;   ///< Frames received.
  std::uint64_t drops = 0;    ///< Frames overwritten before use (latest wins).
  std::uint64_t corrupt = 0;  ///< Frames counted and skipped as unreadable.
  /// Image fault (capture::CameraFault: 0 none, 1 frozen, 2 black, 3 saturated,
  /// 4 moved, 5 unlearned, 6 blocked); a faulty camera sees nothing, as a
  /// stale one.
  std::uint8_t fault = 0;
  /// The frame used is one the background model was still learning from
  /// (all foreground: this camera certifies nothing free through it).
  bool learning = false;
  /// The source's transport counters (capture::TransportStats: GigE Vision;
  /// zero for other sources), totals over reconnections.
  std::uint64_t completed = 0;  ///< Complete frames the source delivered.
  std::uint64_t failed = 0;     ///< Failed, incomplete or unusable frames.
  std::uint64_t underruns = 0;  ///< Frames lost for lack of a free buffer.
  std::uint64_t resends = 0;    ///< Packets the camera resent on request.
  /// How far beyond what this camera saw free it certifies nothing this
  /// cycle (m): the distance a person covers between its frame's capture
  /// and the snapshot's stamp (PipelineOptions::max_speed_mps), rounded up
  /// and held a while. 0 for a frame of the snapshot's instant.
  double margin_m = 0.0;
  /// Image cameras: the view's misalignment against its reference view at the
  /// last registration (pixels; capture::CameraHealthMonitor); negative when
  /// unknown (masks, before the reference, too little of the view seen).
  double misalignment_px = -1.0;
  /// The view was last found shifted beyond what is tolerated: its frames
  /// are not used (stale after its timeout) until it is found back in place,
  /// or failed (moved) after a few registrations more.
  bool shifted = false;
};

struct PipelineHealth {
  bool degraded = false;  ///< Some camera is not kOk, or the last update aborted.
  std::vector<CameraHealth> cameras;
  double silhouette_ms = 0.0;  ///< Capture stamp -> quadtree built, slowest camera this cycle.
  double skew_ms = 0.0;        ///< Newest minus oldest capture time of the frames used.
  /// The widest capture gap the live cameras' margins stand for (ms; margin
  /// over max_speed_mps, so rounded up as the margins are): a margin is
  /// raised at once and lowered only after a hold, so after a late frame it
  /// stands for a wider gap than this cycle's skew for a while.
  double margin_skew_ms = 0.0;
  double octree_ms = 0.0;  ///< Last octree update.
  /// Nodes the last update left occupied unsplit: the octree's node store
  /// (octree.max_nodes) was full. 0 normally; the status is degraded otherwise.
  std::int64_t unsplit_nodes = 0;
  double cycle_ms = 0.0;              ///< Cycle start -> snapshot published.
  std::uint64_t deadline_misses = 0;  ///< Updates aborted by the deadline since start.
  std::uint64_t cycles = 0;
  /// Periods of the fixed rate that passed without a cycle since start: a
  /// cycle overran its period and the next start was skipped. 0 while the
  /// rate holds.
  std::uint64_t missed_cycles = 0;
  /// With timing.align_to_frames: whether the cycle is phase-locked to the
  /// cameras' frames (CyclePhase::locked(); false while it settles, and when
  /// the frames come at another rate than the cycle).
  bool phase_lock = false;
  bool phase_locked = false;
  /// Knowledge filter (octree.knowledge_filter_m3): whether it is on, and
  /// what it dropped from this snapshot's occupied cells.
  bool knowledge_filter = false;
  int filtered_blobs = 0;
  double filtered_m3 = 0.0;
};

/// Cells (x .. x + length - 1, y, z) of the published grid (2^depth cells
/// per axis over the bounds): a run along x. Runs keep a sample small where
/// occupied or occluded space is large (the space above the cameras, say).
struct GridRun {
  std::uint16_t x = 0;
  std::uint16_t y = 0;
  std::uint16_t z = 0;
  std::uint16_t length = 1;
};

/// Occupancy of one cycle at the publishing resolution. Conservative: a cell
/// is listed as occupied (or occluded) when any part of it is not certified
/// free; every cell not listed is free. Immutable once published.
struct OccupancySnapshot {
  std::uint64_t sequence = 0;
  /// The instant (CLOCK_REALTIME) the occupancy holds for: the newest capture
  /// time of the frames used; older frames were dilated by the distance a
  /// person can move since their own capture.
  std::int64_t stamp_ns = 0;
  /// False when the update was aborted, or the node store could not split
  /// some nodes (health.unsplit_nodes): still conservative.
  bool complete = true;
  bool aborted = false;  ///< The update was aborted at its deadline.
  /// The occupancy is exact down to octree cells of this size (m, longest
  /// side): such a cell that needed finer work is listed whole. The finest
  /// cell size when complete; 0 when an abort left whole regions unvisited
  /// (listed occupied).
  double refined_cell_m = 0.0;
  /// Per octree root (8 x 8 x 8 over the bounds, numbered x + 8 y + 64 z),
  /// the level the update left it exact down to (octree::Octree::RootLevels):
  /// an aborted update finishes some roots further than refined_cell_m says
  /// for the whole cell. Empty: not known.
  std::vector<std::uint8_t> root_levels;
  common::Box3 bounds;
  int depth = 0;  ///< Publishing grid: 2^depth cells per axis.
  /// Cells that may hold a person: seen as foreground, or not worked out (an
  /// aborted or settled update's cells).
  std::vector<GridRun> occupied;
  /// Not occupied, and not certified free by any camera: unseen (behind
  /// obstacles, outside the views) or only partly seen.
  std::vector<GridRun> occluded;

  /// Number of cells the runs cover.
  [[nodiscard]] static std::size_t Cells(const std::vector<GridRun>& runs) {
    std::size_t n = 0;
    for (const GridRun& r : runs) n += r.length;
    return n;
  }
  PipelineHealth health;
};

/// Longest side of an octree cell at `level` over `bounds` (0 for level 0:
/// nothing refined).
[[nodiscard]] inline double RefinedCellSize(const common::Box3& bounds, int level) {
  return level > 0 ? std::ldexp((bounds.max - bounds.min).maxCoeff(), -level) : 0.0;
}

/// The coarsest level (at most `depth`) whose cells are no larger than
/// `voxel_m`: the octree's key level when tracking with such voxels, since
/// births need an update refined that far (WholeForBirths).
[[nodiscard]] inline int TrackingKeyLevel(const common::Box3& bounds, int depth, double voxel_m) {
  int level = 1;
  while (level < depth && RefinedCellSize(bounds, level) > voxel_m) ++level;
  return level;
}

/// Whether tracking may use the snapshot: complete, or aborted after coarse
/// first refined it everywhere to cells of at most two tracking voxels (what
/// it lists beyond a complete update then lies within such cells).
[[nodiscard]] inline bool RefinedForTracking(const OccupancySnapshot& s, double voxel_m) {
  return s.complete || (s.refined_cell_m > 0.0 && s.refined_cell_m <= 2.0 * voxel_m);
}

/// Whether a snapshot holds the whole evidence a new track needs: every
/// camera delivered, and none from its background model's learning (a camera
/// that is out, lags too far or is still learning sees nothing, so the
/// others' silhouette cones stay occupied where it would have cut them:
/// person-sized blobs with nobody in them), and the update refined the cell
/// to cells of at most one tracking voxel everywhere, from frames captured
/// within max_skew_ms of each other (older frames are dilated by the
/// distance a person may have moved meanwhile, which fattens every cone the
/// same way). Tracks follow their people through other snapshots
/// (RefinedForTracking); births wait.
/// The cameras' part of it: every camera ok and none learning, frames within
/// max_skew_ms.
[[nodiscard]] inline bool CamerasWholeForBirths(const OccupancySnapshot& s, double max_skew_ms) {
  // The margins still held from a wider gap fatten the cones as that gap did.
  if (std::max(s.health.skew_ms, s.health.margin_skew_ms) > max_skew_ms) return false;
  for (const CameraHealth& c : s.health.cameras) {
    if (c.state != CameraState::kOk || c.learning) return false;
  }
  return true;
}

/// The whole-snapshot rule above: the cameras (CamerasWholeForBirths) and
/// the refinement everywhere.
[[nodiscard]] inline bool WholeForBirths(const OccupancySnapshot& s, double voxel_m,
                                         double max_skew_ms) {
  return CamerasWholeForBirths(s, max_skew_ms) &&
         (s.complete || (s.refined_cell_m > 0.0 && s.refined_cell_m <= voxel_m));
}

/// Octree roots per axis (root_levels).
inline constexpr int kRootsPerAxis = 8;

/// WholeForBirths region by region: where an aborted update finished octree
/// roots to cells of at most one tracking voxel, a new track may start from
/// what lies wholly inside them, the cameras and the skew permitting as in
/// WholeForBirths. Sets (*roots)[r] for those roots (root_levels numbering)
/// and returns whether there is any; false, with none set, when the
/// snapshot is whole (WholeForBirths holds everywhere) or says nothing of
/// its roots.
[[nodiscard]] inline bool RootsWholeForBirths(
    const OccupancySnapshot& s, double voxel_m, double max_skew_ms,
    std::array<bool, kRootsPerAxis * kRootsPerAxis * kRootsPerAxis>* roots) {
  roots->fill(false);
  if (s.complete || s.root_levels.size() != roots->size()) return false;
  if (s.refined_cell_m > 0.0 && s.refined_cell_m <= voxel_m) return false;  // Whole.
  if (!CamerasWholeForBirths(s, max_skew_ms)) return false;
  bool any = false;
  for (std::size_t r = 0; r < roots->size(); ++r) {
    const double cell = RefinedCellSize(s.bounds, s.root_levels[r]);
    (*roots)[r] = cell > 0.0 && cell <= voxel_m;
    any = any || (*roots)[r];
  }
  return any;
}

}  // namespace hg::pipeline
