#pragma once
/// @file
/// Multi-person tracking on the occupancy snapshots (Ober-Gecks et al.): one
/// particle filter per person, births from unexplained UNKNOWN components,
/// deaths after a time without support, and a Voronoi split of the evidence
/// between tracks whose particle clouds overlap.

#include <array>
#include <atomic>
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
  double voxel_m = 0.05;
  LikelihoodWeights likelihood;
  ParticleFilterOptions filter;
  /// Particles of an object track (at most filter.num_particles; a person's
  /// track has filter.num_particles). An object track is not published and
  /// only holds its share of the evidence: a parcel does not walk away.
  int object_particles = 100;
  /// Tracks held at most (filters are allocated up front); births beyond are dropped.
  int max_tracks = 16;
  /// Components of UNKNOWN voxels: 26-connected (faces, edges, corners) when
  /// true, 6-connected (faces) otherwise.
  bool connect_26 = true;
  /// A component starts a track when at least this volume of it is evidence
  /// of a new person (outside every track's gate, standing on something, seen
  /// past the tracks; m^3). A crawling adult's hull is about 0.15 m^3; the
  /// occupancy the reconstruction leaves between the shelves of a rack is
  /// smaller.
  double birth_min_volume_m3 = 0.06;
  /// A track's gate: its estimate ellipsoid grown by this margin plus two
  /// standard deviations of the centre along each axis (m).
  double birth_gate_margin_m = 0.2;
  /// People do not float: a component starts a track only when some of its
  /// evidence voxels stand on something. Going down from such a voxel,
  /// through unexplained UNKNOWN and OCCLUDED voxels (a person's legs may be
  /// where no camera sees) and at most this much FREE space (m), one reaches
  /// the floor (the grid's bottom) or an obstacle (KNOWN). Occupancy hanging
  /// in seen-empty space is a reconstruction artefact: silhouette cones near
  /// the cameras' height that few cameras bound, or the space a person hides
  /// from the only cameras that see under a table. Negative: no check.
  double birth_max_floating_m = 0.1;
  /// People come in standing: a new track is a person's when its evidence
  /// reaches this height above the grid's bottom (m): some layer of voxels
  /// there holds at least a head's cross-section (kHeadAreaM2) of it, counted
  /// without the layer's boundary voxels (the occupancy's cells make the
  /// evidence up to one voxel wider than what they hold). A
  /// parcel or a cart put down in the cell occupies space like a person (and
  /// its silhouette cones leave a thin tip above it): it gets an object track,
  /// filtered like a person's (with object_particles) so that it holds its
  /// share of the evidence (a person passing it is not drawn onto it) but not
  /// published. A person who
  /// crouches or crawls once tracked stays a person. 0: every track is a
  /// person's.
  double birth_min_height_m = 1.0;
  /// Births wait for a whole snapshot (pipeline::WholeForBirths): every camera
  /// ok, the update refined to the tracking voxel, and frames captured within
  /// this many milliseconds of each other. A lagging camera's mask is dilated
  /// by the distance a person may have moved meanwhile; at start-up and under
  /// load those fattened cones leave person-sized occupancy at obstacle edges
  /// and between people before any track could explain it. Tracks follow
  /// their people through every trackable snapshot.
  double birth_max_skew_ms = 20.0;
  /// An object track becomes a person's when its estimate ellipsoid's top
  /// reaches this height above the grid's bottom (m): someone who was
  /// crouching when tracking started stands up.
  double promote_min_top_m = 1.4;
  /// Explaining away (with cameras: the constructor from a StaticScene). A
  /// voxel outside every gate counts towards a birth only when some camera
  /// sees it and every camera that sees it looks at it past every supported
  /// track: each line of sight misses each track's estimate ellipsoid grown
  /// by this margin (m). Otherwise a tracked person in some camera's line of
  /// sight may be all that makes the voxel occupied: visual-hull ghosts
  /// between people, the long tips of a hull that only two cameras bound, the
  /// shadow a person casts into space that only cameras behind them see, or
  /// the octree's coarse leaves at view and obstacle edges, which are
  /// occupied when any one camera sees foreground in them. Negative: off.
  double explain_margin_m = 0.1;
  /// With cameras: a voxel counts towards a birth only when at least this
  /// many cameras see it. What one camera alone sees occupied may be anywhere
  /// along its line of sight (and the octree's coarse leaves at obstacle
  /// edges, inside a rack's shelves, are occupied when one camera sees
  /// foreground anywhere in them).
  int birth_min_views = 2;
  /// With cameras: a camera counts as seeing a voxel for births only when it
  /// sees the centres of all voxels within this many voxels of it (a cube).
  /// The octree certifies a leaf free only when some camera sees all of it, so
  /// along an obstacle's silhouette edge (space under a table seen through
  /// the gap at its rim) leaves stay occupied although the cameras see their
  /// centres; with this margin they are not evidence of a person.
  int birth_view_margin_voxels = 2;
  /// A component that would start a track is instead given to the nearest
  /// track without support whose centre lies within reacquire_radius_m +
  /// reacquire_speed_mps * (its time without support, at most
  /// death_timeout_s): the person who disappeared (under a table, behind a
  /// rack) is taken to have come back, and keeps the id.
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
  /// A track younger than tentative_age_s dies after tentative_death_timeout_s
  /// without support, occluded or not: what the reconstruction shows for a
  /// moment and then never again (an artefact at an obstacle's edge) is not
  /// followed for a whole death timeout.
  double tentative_age_s = 1.0;
  double tentative_death_timeout_s = 0.2;
  /// A track is occluded when at least this share of its estimate ellipsoid's
  /// voxels is OCCLUDED.
  double occluded_min_share = 0.5;
  /// Two tracks split the evidence (Voronoi) while the bounds of their particle
  /// clouds, grown by this margin, overlap (m).
  double overlap_margin_m = 0.1;
  /// Time step of the first cycle and largest step of the filters' motion
  /// model between two cycles (s): steps are clamped to [1e-3, max_dt_s].
  /// Track ages and times without support count the whole time between
  /// cycles.
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
  std::uint64_t object_births = 0;   ///< Object tracks started (not people, not published).
  std::uint64_t promotions = 0;      ///< Object tracks that became people (counted in births).
  /// Cycles whose snapshot was aborted short of the tracking voxel but had
  /// roots finished that far (births only from components wholly in those).
  std::uint64_t cycles_with_births_by_root = 0;
  /// Of their births (and reacquisitions), those such a cycle started.
  std::uint64_t births_by_root = 0;
};

/// The multi-person tracker. One cycle (Step) per occupancy snapshot:
/// 1. tracks whose particle-cloud bounds overlap get, for each pair, the
///    bisector half-space of their previous centres as their own region: each
///    filter scores only the UNKNOWN voxels nearer its own centre and counts
///    the other's as free (a Voronoi split of the evidence, so two people
///    passing close never feed one filter);
/// 2. every filter steps; its estimate ellipsoid gives support (own UNKNOWN
///    volume) and the occluded share;
/// 3. deaths: the estimate ellipsoid entirely outside the grid, or time
///    without support above the timeout (the occluded one for occluded
///    tracks; such a track dies after the births, which may still re-acquire
///    it);
/// 4. births: connected components of the unexplained UNKNOWN voxels (those
///    outside every track's gate; searched from the UNKNOWN list, never over
///    the grid) whose voxels that the cameras see past every supported track
///    (explain_margin_m, birth_min_views) reach birth_min_volume_m3, some of
///    them standing on something (the floor, an obstacle, or space no camera
///    sees: birth_max_floating_m), start a
///    track on those voxels (centre = mean, half-axes from their spread),
///    unless a track without support is
///    near enough to re-acquire them (its filter restarts there, same id);
///    a new track is an object's (not published) unless its evidence reaches
///    birth_min_height_m, and becomes a person's when it stands up
///    (promote_min_top_m).
///    The search is skipped when all unexplained voxels together stay below
///    birth_min_volume_m3 (everybody tracked: one gate test per UNKNOWN
///    voxel). A component whose evidence above birth_min_height_m falls into
///    several pieces in the floor plan, each with a head's cross-section
///    (people standing one behind the other, their hulls joined lower down),
///    starts a track per piece whose share, the evidence nearest it, would
///    start a track on its own (standing on something, at least
///    birth_min_volume_m3); the shares of the other pieces (something held
///    out at arm's length) go to the nearest such piece, and with fewer than
///    two such pieces the component starts one track.
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
  /// at the snapshot's stamp; new tracks only from a whole snapshot
  /// (pipeline::WholeForBirths), or, from an aborted one, from components
  /// lying wholly in octree roots it finished to the tracking voxel
  /// (pipeline::RootsWholeForBirths).
  void Update(const pipeline::OccupancySnapshot& snapshot);

  /// Runs a cycle on the current voxel states (set UNKNOWN through
  /// voxel_map() first). stamp_ns: capture time of the data; the filters'
  /// step is the time since the previous cycle, clamped to [1 ms, max_dt_s];
  /// deaths count the whole time. births false: existing tracks only.
  void Step(std::int64_t stamp_ns, bool births = true);

  [[nodiscard]] VoxelMap& voxel_map() { return map_; }
  [[nodiscard]] const VoxelMap& voxel_map() const { return map_; }
  [[nodiscard]] const CollisionWorld& collision_world() const { return world_; }
  [[nodiscard]] const TrackerOptions& options() const { return options_; }

  /// Makes a cycle in progress (on another thread) return soon, and every
  /// later one at once, leaving the tracks in no defined state: for stopping
  /// a tracker that is discarded (a daemon's shutdown). Any thread.
  void Abort() { abort_.store(true, std::memory_order_relaxed); }
  [[nodiscard]] bool aborted() const { return abort_.load(std::memory_order_relaxed); }

  /// The live tracks after the last cycle, by ascending id.
  [[nodiscard]] const std::vector<Track>& tracks() const { return tracks_; }
  /// The filter behind a live track (nullptr for an unknown id).
  [[nodiscard]] const ParticleFilter* filter(std::uint32_t id) const;
  [[nodiscard]] const TrackerStats& stats() const { return stats_; }

 private:
  /// Two ellipsoids whose heights overlap by at least this share of the
  /// shorter one stand side by side: their evidence is split by a vertical
  /// plane (Step(), 1.).
  static constexpr double kSideBySideShare = 0.5;
  [[nodiscard]] static bool SideBySide(const Ellipsoid& a, const Ellipsoid& b);

  struct Slot {
    std::unique_ptr<ParticleFilter> filter;
    bool alive = false;
    bool dying = false;  // Past its timeout this cycle; dies unless a birth re-acquires it.
    bool person = true;  // False: an object track (not published).
    std::uint32_t id = 0;
    double age_s = 0.0;
    double time_since_support_s = 0.0;
    bool occluded = false;
    double occluded_fraction = 0.0;
    std::vector<HalfSpace> region;  // Own Voronoi region this cycle.
  };

  struct Built;
  static Built BuildStatic(const TrackerOptions& options, const common::Box3& bounds,
                           const StaticScene& scene);
  Tracker(const TrackerOptions& options, Built&& built);
  void Init();
  void Assess(Slot* slot, double dt_s);
  void Births();
  /// With births by region this cycle: whether every voxel of the component
  /// in queue_ lies wholly in roots that allow births.
  [[nodiscard]] bool InBirthRoots() const;
  /// A component with `unexplained` voxels outside every gate (sum and sum of
  /// squares of their centres): re-acquired by a lost track, or a new track.
  /// `tall`: the evidence reaches birth_min_height_m (a new track is a
  /// person's, else an object's; a re-acquired track keeps its kind).
  void StartOrReacquire(int unexplained, const Eigen::Vector3d& sum, const Eigen::Vector3d& sum_sq,
                        bool tall);
  /// The column below unexplained UNKNOWN voxel `index` reaches the floor or
  /// an obstacle (TrackerOptions::birth_max_floating_m). Memoised in marks_.
  [[nodiscard]] bool Grounded(std::uint32_t index);
  /// At least birth_min_views cameras see the voxel, and every camera that
  /// sees it looks at it past every supported track.
  [[nodiscard]] bool SeenPastTracks(std::uint32_t index, const Eigen::Vector3d& p_W) const;
  /// The line-of-sight tests of this cycle's supported tracks.
  void PrepareSightTests();
  void Publish();

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
  std::vector<std::uint32_t> path_;  // Grounded(): the column walked.
  // Births by region (Update from an aborted snapshot): the roots that allow
  // them, over the snapshot's bounds; off outside such a cycle.
  bool births_by_root_ = false;
  std::array<bool, pipeline::kRootsPerAxis * pipeline::kRootsPerAxis * pipeline::kRootsPerAxis>
      birth_roots_{};
  common::Box3 root_bounds_;
  std::atomic<bool> abort_{false};  // Abort().  The filters hold its address.
  // Explaining away: per voxel the cameras that see it, the cameras' centres,
  // and per camera and supported track the ellipsoid in its unit-sphere frame.
  struct SightTest {
    Eigen::Vector3d centre_W;
    Eigen::Vector3d inv_half_axes;
    Eigen::Vector3d camera_S;  // Camera centre in the unit-sphere frame.
    double camera_norm2_minus_1 = 0.0;
  };
  /// Interior evidence voxels per layer of the component being examined
  /// (zero between).
  std::vector<int> layer_evidence_;
  /// Cross-section of evidence that counts as a head in a layer (m^2): about a
  /// third of an adult head's, less than the tip of a low object's hull.
  static constexpr double kHeadAreaM2 = 0.01;
  /// Interior evidence: the voxel and its four horizontal neighbours are
  /// evidence of the component being examined (kEvidenceMark).
  [[nodiscard]] bool InteriorEvidence(std::uint32_t index) const;
  /// The people of the component in queue_ (its evidence marked): the
  /// 8-connected pieces of the floor plan of its interior evidence at or above
  /// layer z_tall of which a single layer holds a head's cross-section, at
  /// most max_tracks of them, the largest. Fills heads_; returns their number.
  int FindHeads(int z_tall);
  /// Gives every evidence voxel of the component to the nearest of the first
  /// `heads` heads_ in the floor plan (their evidence, sum and sum of squares)
  /// and notes whether some voxel of each share stands on something
  /// (Grounded()).
  void SplitEvidence(int heads);
  /// Keeps of the first `heads` heads_, split by SplitEvidence(), those whose
  /// share would start a track as a component of its own (grounded, at least
  /// birth_min_volume_m3); returns their number.
  int KeepStandingHeads(int heads);
  struct Head {
    std::uint16_t label = 0;  // In column_labels_ while FindHeads() runs.
    int columns = 0;
    double x = 0.0;  // Centre of the piece's columns.
    double y = 0.0;
    int evidence = 0;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    Eigen::Vector3d sum_sq = Eigen::Vector3d::Zero();
    bool grounded = false;
  };
  static constexpr std::uint16_t kUnlabelledColumn = 0xFFFF;
  std::vector<std::uint16_t> column_labels_;  // Per floor column; 0 between searches.
  std::vector<std::uint32_t> columns_;        // Columns labelled this search.
  std::vector<std::uint32_t> column_stack_;
  std::vector<Head> heads_;           // Capacity max_tracks.
  std::vector<std::uint16_t> views_;  // Eroded by birth_view_margin_voxels.
  void ErodeViews();
  std::vector<Eigen::Vector3d> camera_centres_W_;
  std::vector<SightTest> sight_tests_;  // Camera-major, sight_tracks_ per camera.
  int sight_tracks_ = 0;
  std::uint32_t next_id_ = 1;
  std::int64_t last_stamp_ns_ = 0;
  bool has_stamp_ = false;
  TrackerStats stats_;
};

}  // namespace hg::tracking
