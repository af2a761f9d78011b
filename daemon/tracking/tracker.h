#pragma once
/// @file
/// Multi-person tracking on the occupancy snapshots (Ober-Gecks et al.): one
/// particle filter per person, births from unexplained UNKNOWN components,
/// deaths after a time without support, and a Voronoi split of the evidence
/// between tracks whose particle clouds overlap.

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "common/box.h"
#include "pipeline/snapshot.h"
#include "tracking/collision.h"
#include "tracking/likelihood.h"
#include "tracking/particle_filter.h"
#include "tracking/static_scene.h"
#include "tracking/voxel_map.h"

namespace hg::tracking {

/// Every parameter of the tracking stage, with its default.
struct TrackerOptions {
  /// Edge of the tracking voxels (m).
  double voxel_m = 0.04;
  LikelihoodWeights likelihood;
  ParticleFilterOptions filter;
  /// Tracks held at most (filters are allocated up front); births beyond are dropped.
  int max_tracks = 16;
  /// Components of UNKNOWN voxels: 26-connected (faces, edges, corners) when
  /// true, 6-connected (faces) otherwise.
  bool connect_26 = true;
  /// A component starts a track when at least this volume of it lies outside
  /// every track's gate (m^3).
  double birth_min_volume_m3 = 0.03;
  /// A track's gate: its estimate ellipsoid grown by this margin plus two
  /// standard deviations of the centre along each axis (m).
  double birth_gate_margin_m = 0.2;
  /// A component that would start a track is instead given to the nearest
  /// track without support whose centre lies within reacquire_radius_m +
  /// reacquire_speed_mps * (its time without support): the person who
  /// disappeared (under a table, behind a rack) is taken to have come back,
  /// and keeps the id.
  double reacquire_radius_m = 0.5;
  double reacquire_speed_mps = 1.5;
  /// A track is supported in a cycle when its estimate ellipsoid holds at least
  /// this volume of its own UNKNOWN voxels (m^3).
  double support_min_volume_m3 = 0.01;
  /// A visible track dies after this long without support (s).
  double death_timeout_s = 1.0;
  /// An occluded track (a person hiding under a table) dies after this long
  /// without support (s).
  double occluded_death_timeout_s = 30.0;
  /// A track is occluded when at least this share of its estimate ellipsoid's
  /// voxels is OCCLUDED.
  double occluded_min_share = 0.5;
  /// Two tracks split the evidence (Voronoi) while the bounds of their particle
  /// clouds, grown by this margin, overlap (m).
  double overlap_margin_m = 0.1;
  /// Time step of the first cycle and largest step between two cycles (s);
  /// steps are clamped to [1e-3, max_dt_s].
  double first_dt_s = 1.0 / 30.0;
  double max_dt_s = 0.5;
  /// Seed of the filters' random engines (each track mixes in its id).
  std::uint64_t seed = 1;
};

/// A bad option: `key` is the option's path ("filter.num_particles").
struct OptionProblem {
  std::string key;
  std::string problem;
};

/// Every bad option (empty when the options are valid); a config loader maps
/// the keys to file lines.
[[nodiscard]] std::vector<OptionProblem> CheckOptions(const TrackerOptions& options);

/// One tracked person, as published.
struct Track {
  std::uint32_t id = 0;  ///< Stable for the track's life; never reused.
  Eigen::Vector3d centre_W = Eigen::Vector3d::Zero();     ///< Ellipsoid centre (m).
  Eigen::Vector3d half_axes_m = Eigen::Vector3d::Zero();  ///< k, l, m along x, y, z.
  Eigen::Vector3d velocity_W_mps = Eigen::Vector3d::Zero();
  Eigen::Matrix3d centre_covariance_m2 = Eigen::Matrix3d::Zero();
  /// Share of the estimate ellipsoid's voxels that are OCCLUDED.
  double occluded_fraction = 0.0;
  /// occluded_fraction >= TrackerOptions::occluded_min_share: the person is
  /// (mostly) where no camera sees, kept alive by the longer timeout.
  bool occluded = false;
  double age_s = 0.0;                 ///< Since birth.
  double time_since_support_s = 0.0;  ///< 0 in a supported cycle.
};

/// Counters since construction.
struct TrackerStats {
  std::uint64_t cycles = 0;
  std::uint64_t births = 0;
  std::uint64_t deaths = 0;
  std::uint64_t births_dropped = 0;  ///< Wanted a track while max_tracks were alive.
  std::uint64_t reacquisitions = 0;  ///< Components given back to a track without support.
};

/// The multi-person tracker. One cycle (Step) per occupancy snapshot:
/// 1. tracks whose particle-cloud bounds overlap get, for each pair, the
///    bisector half-space of their previous centres as their own region: each
///    filter scores only the UNKNOWN voxels nearer its own centre and counts
///    the other's as free (a Voronoi split of the evidence, so two people
///    passing close never feed one filter);
/// 2. every filter steps; its estimate ellipsoid gives support (own UNKNOWN
///    volume) and the occluded share;
/// 3. deaths: time without support above the timeout (the occluded one for
///    occluded tracks), or the estimate ellipsoid entirely outside the grid;
/// 4. births: connected components of the UNKNOWN voxels (searched from the
///    UNKNOWN list, never over the grid) whose voxels outside every track's
///    gate reach birth_min_volume_m3 start a track on those voxels (centre =
///    mean, half-axes from their spread), unless a track without support is
///    near enough to re-acquire them (its filter restarts there, same id).
///    The search is skipped when all unexplained voxels together stay below
///    birth_min_volume_m3 (everybody tracked: one gate test per UNKNOWN
///    voxel). One component gives at most one track per cycle; two people who
///    enter touching get their second track in a later cycle, once the first
///    track's gate no longer covers the second.
/// After warm-up a cycle allocates nothing. Memory beyond the VoxelMap: 5
/// bytes per voxel (component search) and the filters of max_tracks tracks.
/// Single-thread.
class Tracker {
 public:
  /// Builds the grid over `bounds`, the static voxel states and the collision
  /// shapes from the scene (start-up work: one obstacle depth map per camera
  /// and one projection per voxel and camera).
  /// @throws common::ConfigError on bad options (every problem in one message).
  Tracker(const TrackerOptions& options, const common::Box3& bounds, const StaticScene& scene);
  /// Uses hand-built voxel states and obstacles (tests, tools); the map's grid
  /// replaces options.voxel_m.
  /// @throws common::ConfigError on bad options.
  Tracker(const TrackerOptions& options, VoxelMap map, CollisionWorld world);

  /// Takes the snapshot's occupied cells as the UNKNOWN voxels and runs a cycle
  /// at the snapshot's stamp.
  void Update(const pipeline::OccupancySnapshot& snapshot);

  /// Runs a cycle on the current voxel states (set UNKNOWN through
  /// voxel_map() first). stamp_ns: capture time of the data; the step is the
  /// time since the previous cycle, clamped to [1 ms, max_dt_s].
  void Step(std::int64_t stamp_ns);

  [[nodiscard]] VoxelMap& voxel_map() { return map_; }
  [[nodiscard]] const VoxelMap& voxel_map() const { return map_; }
  [[nodiscard]] const CollisionWorld& collision_world() const { return world_; }
  [[nodiscard]] const TrackerOptions& options() const { return options_; }

  /// The live tracks after the last cycle, by ascending id.
  [[nodiscard]] const std::vector<Track>& tracks() const { return tracks_; }
  /// The filter behind a live track (nullptr for an unknown id).
  [[nodiscard]] const ParticleFilter* filter(std::uint32_t id) const;
  [[nodiscard]] const TrackerStats& stats() const { return stats_; }

 private:
  struct Slot {
    std::unique_ptr<ParticleFilter> filter;
    bool alive = false;
    std::uint32_t id = 0;
    double age_s = 0.0;
    double time_since_support_s = 0.0;
    bool occluded = false;
    double occluded_fraction = 0.0;
    std::vector<HalfSpace> region;  // Own Voronoi region this cycle.
  };

  Tracker(const TrackerOptions& options, std::pair<VoxelMap, CollisionWorld>&& built);
  void Init();
  void Assess(Slot* slot, double dt_s);
  void Births();
  /// A component with `unexplained` voxels outside every gate (sum and sum of
  /// squares of their centres): re-acquired by a lost track, or a new track.
  void StartOrReacquire(int unexplained, const Eigen::Vector3d& sum, const Eigen::Vector3d& sum_sq);
  void Publish();
  /// Inside a live track's gate.
  [[nodiscard]] bool Explained(const Eigen::Vector3d& p_W) const;

  struct Gate {
    Eigen::Vector3d centre_W;
    Eigen::Vector3d inv_half_axes;  // 1 / half-axes.
  };

  TrackerOptions options_;
  VoxelMap map_;
  CollisionWorld world_;
  std::vector<Slot> slots_;
  std::vector<Gate> gates_;  // Per live slot, rebuilt each cycle.
  std::vector<Track> tracks_;
  std::vector<std::uint8_t> marks_;   // Per voxel: explained / unexplained / visited.
  std::vector<std::uint32_t> queue_;  // Component search order.
  std::vector<Eigen::Vector3i> neighbours_;
  std::uint32_t next_id_ = 1;
  std::int64_t last_stamp_ns_ = 0;
  bool has_stamp_ = false;
  TrackerStats stats_;
};

}  // namespace hg::tracking
