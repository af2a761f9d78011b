#pragma once
/// @file
/// The daemon's tracking thread: tracks people on the newest occupancy
/// snapshot, away from the fusion thread, and hands each tracked cycle to a
/// consumer (the DDS publisher).

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>

#include "app/config.h"
#include "app/snapshot_stage.h"
#include "common/box.h"
#include "common/heartbeat.h"
#include "pipeline/snapshot.h"
#include "tracking/static_scene.h"
#include "tracking/tracker.h"

namespace hg::app {

/// The tracker's options from the `tracking` section; the first cycle's time
/// step is one fusion period (1 / rate_hz). Options the section does not name
/// keep tracking::TrackerOptions' defaults.
[[nodiscard]] tracking::TrackerOptions MakeTrackerOptions(const TrackingConfig& config,
                                                          double rate_hz);

/// The cell as the tracker sees it: the cameras (pinhole part) and the
/// obstacle meshes the pipeline uses.
[[nodiscard]] tracking::StaticScene MakeStaticScene(const Config& config,
                                                    std::vector<geometry::TriangleMesh> obstacles);

/// Niceness of the tracking thread: below the fusion and capture threads.
inline constexpr int kTrackingNice = 10;

/// How long one tracking cycle may run before the watchdog counts the
/// tracking stage stalled. Tracks are no safety output and a cycle of many
/// particles on a loaded machine may take seconds; restarting the daemon for
/// that (systemd, WatchdogSec=2) would cut the occupancy stream. A cycle
/// longer than kSlowTrackingCycle is logged instead.
inline constexpr std::chrono::seconds kTrackingStallAllowance{15};
inline constexpr std::chrono::milliseconds kSlowTrackingCycle{1000};

/// One tracked cycle, as handed to the consumer; valid during the call only.
struct TrackedCycle {
  std::uint64_t sequence = 0;               ///< Of the occupancy snapshot tracked.
  std::int64_t stamp_ns = 0;                ///< Of that snapshot.
  bool degraded = false;                    ///< That snapshot's health was degraded.
  std::span<const tracking::Track> tracks;  ///< By ascending id.
  double tracking_ms = 0.0;                 ///< Tracker time of this cycle.
};

/// Counters of the stage, readable from any thread.
struct TrackingStats {
  std::uint64_t cycles = 0;   ///< Snapshots tracked.
  std::uint64_t skipped = 0;  ///< Snapshots overwritten before tracking took them.
  /// Snapshots taken but not tracked: of aborted updates, or of cameras
  /// without a first frame (see TrackingStage).
  std::uint64_t untracked = 0;
  int tracks = 0;        ///< Live tracks after the last cycle.
  double last_ms = 0.0;  ///< Tracker time of the last cycle.
  double max_ms = 0.0;   ///< Longest tracker time since start.
};

/// A tracker on its own thread. The fusion thread offers each snapshot
/// (Offer: a copy of the shared pointer into a lock-free latest-value slot
/// and a semaphore post, so fusion is never held up); the tracking thread
/// takes the newest one, runs a tracker cycle on it and calls the consumer.
/// When tracking is slower than fusion it skips to the newest snapshot
/// (counted in TrackingStats::skipped); the thread runs at a lower priority
/// (nice kTrackingNice) than fusion and capture, so on a busy machine tracking
/// skips snapshots rather than delaying the occupancy. Snapshots of aborted
/// updates (unless coarse first refined them everywhere to cells of at most
/// two tracking voxels: pipeline::RefinedForTracking), and those made while
/// some camera has not delivered its first frame yet (start-up), are not
/// tracked: they report space as occupied that no camera could look at (at
/// start-up, the whole cell), which is no evidence of a person. A camera lost later (stale, failed)
/// does not stop tracking; the cycle's degraded flag travels with the tracks. The static voxel
/// states (KNOWN from the obstacles, OCCLUDED from the cameras) are built once, in the constructor.
/// After warm-up a cycle allocates nothing (the consumer must not either).
///
/// Thread safety: construct, Start(), Stop() and destroy from one owning
/// thread; Offer() from one producer thread (the fusion thread); stats() from
/// any thread. RunOnce() is for lock-step use without Start().
class TrackingStage {
 public:
  using Consumer = std::function<void(const TrackedCycle&)>;

  /// Builds the tracker over `bounds` (start-up work: one obstacle depth map
  /// per camera and one projection per voxel and camera). `heartbeats`
  /// (optional, must outlive the stage) gets one stage, "tracking", beaten
  /// every loop iteration (every 100 ms while idle), which may stay still for
  /// kTrackingStallAllowance before the watchdog counts it stalled.
  /// @throws common::ConfigError on bad options.
  TrackingStage(const tracking::TrackerOptions& options, const common::Box3& bounds,
                const tracking::StaticScene& scene, Consumer consumer,
                common::Heartbeats* heartbeats = nullptr);
  ~TrackingStage();
  TrackingStage(const TrackingStage&) = delete;
  TrackingStage& operator=(const TrackingStage&) = delete;

  /// Starts the tracking thread. Precondition: not running.
  void Start();
  /// Ends the thread, cutting a cycle in progress short (its tracks are not
  /// handed to the consumer); tracking is over for good. Idempotent.
  void Stop();

  /// Hands the newest snapshot to the tracking thread. Never blocks, never
  /// allocates; a snapshot not taken before the next Offer is skipped.
  void Offer(const std::shared_ptr<const pipeline::OccupancySnapshot>& snapshot);

  /// Tracks `snapshot` on the calling thread and calls the consumer (tests,
  /// lock-step replay); returns false, tracking nothing, for a snapshot that
  /// is not tracked (see above). Not while the thread runs.
  bool RunOnce(const pipeline::OccupancySnapshot& snapshot);

  [[nodiscard]] TrackingStats stats() const;
  /// The tracker (for tests and tools; not while the thread runs).
  [[nodiscard]] const tracking::Tracker& tracker() const { return tracker_; }

 private:
  tracking::Tracker tracker_;
  Consumer consumer_;
  SnapshotStage stage_;  // The thread, the handoff and the heartbeat ("tracking").
  std::atomic<std::uint64_t> cycles_{0};
  std::atomic<std::uint64_t> untracked_{0};
  /// Tracking waits this long (snapshot time) for every camera's first frame.
  static constexpr std::int64_t kStartingWaitNs = 15'000'000'000;
  std::int64_t first_stamp_ns_ = 0;  // Of the first snapshot offered (tracking thread).
  std::atomic<int> tracks_{0};
  std::atomic<double> last_ms_{0.0};
  std::atomic<double> max_ms_{0.0};
  double slow_logged_ms_ = 0.0;  // Tracking thread: the slow cycle last logged.
};

}  // namespace hg::app
