#include "app/tracking_stage.h"

#include <chrono>
#include <utility>

#include "common/log.h"

namespace hg::app {
namespace {

using SteadyClock = std::chrono::steady_clock;

void AtomicMax(std::atomic<double>* target, double value) {
  double seen = target->load(std::memory_order_relaxed);
  while (value > seen && !target->compare_exchange_weak(seen, value, std::memory_order_relaxed)) {
  }
}

/// A complete (or refined enough) update with every camera delivering (or
/// lost after it did); with `starting_ok`, also with cameras that have not
/// delivered yet (they see nothing, as lost ones).
bool Trackable(const pipeline::OccupancySnapshot& s, double voxel_m, bool starting_ok) {
  if (!pipeline::RefinedForTracking(s, voxel_m)) return false;
  if (starting_ok) return true;
  for (const pipeline::CameraHealth& c : s.health.cameras) {
    if (c.state == pipeline::CameraState::kStarting) return false;
  }
  return true;
}

}  // namespace

tracking::TrackerOptions MakeTrackerOptions(const TrackingConfig& config, double rate_hz) {
  tracking::TrackerOptions o;
  o.voxel_m = config.voxel_m;
  o.filter.num_particles = config.particles;
  o.max_tracks = config.max_tracks;
  o.likelihood.unknown = config.rho_unknown;
  o.likelihood.occluded = config.sigma_occluded;
  o.likelihood.known = config.tau_known;
  o.likelihood.free = config.epsilon_free;
  o.likelihood.below_floor = config.below_floor_weight;
  o.filter.support_reach_m = config.support_reach_m;
  o.filter.posture_noise_m_per_sqrt_s = config.posture_noise_m_per_sqrt_s;
  o.filter.collision_radius_m = config.collision_radius_m;
  o.birth_min_volume_m3 = config.birth_min_volume_m3;
  o.birth_min_height_m = config.birth_min_height_m;
  o.birth_max_skew_ms = config.birth_max_skew_ms;
  o.death_timeout_s = config.death_timeout_s;
  o.occluded_death_timeout_s = config.occluded_death_timeout_s;
  o.reacquire_radius_m = config.reacquire_radius_m;
  o.reacquire_speed_mps = config.reacquire_speed_mps;
  if (rate_hz > 0.0) o.first_dt_s = 1.0 / rate_hz;
  return o;
}

tracking::StaticScene MakeStaticScene(const Config& config,
                                      std::vector<geometry::TriangleMesh> obstacles) {
  tracking::StaticScene scene;
  for (const CameraConfig& c : config.cameras) scene.cameras.push_back(c.model.Pinhole());
  scene.meshes = std::move(obstacles);
  return scene;
}

TrackingStage::TrackingStage(const tracking::TrackerOptions& options, const common::Box3& bounds,
                             const tracking::StaticScene& scene, Consumer consumer,
                             common::Heartbeats* heartbeats)
    : tracker_(options, bounds, scene),
      consumer_(std::move(consumer)),
      stage_(
          "tracking", [this](const pipeline::OccupancySnapshot& s) { RunOnce(s); }, heartbeats,
          kTrackingNice, kTrackingStallAllowance) {}

TrackingStage::~TrackingStage() { Stop(); }

void TrackingStage::Start() { stage_.Start(); }

void TrackingStage::Stop() {
  // A cycle of many particles may take seconds: it is cut short (its tracks
  // are not handed on), so that the daemon stops within its second.
  tracker_.Abort();
  stage_.Stop();
}

void TrackingStage::Offer(const std::shared_ptr<const pipeline::OccupancySnapshot>& snapshot) {
  stage_.Offer(snapshot);
}

bool TrackingStage::RunOnce(const pipeline::OccupancySnapshot& snapshot) {
  if (first_stamp_ns_ == 0) first_stamp_ns_ = snapshot.stamp_ns;
  // A camera that has not delivered within kStartingWait of the first cycle
  // (the daemon's READY=1 wait) is taken as lost rather than holding
  // tracking back for ever.
  const bool starting_ok = snapshot.stamp_ns - first_stamp_ns_ >= kStartingWaitNs;
  if (!Trackable(snapshot, tracker_.options().voxel_m, starting_ok)) {
    untracked_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  const SteadyClock::time_point start = SteadyClock::now();
  tracker_.Update(snapshot);
  if (tracker_.aborted()) return false;
  const double ms = std::chrono::duration<double, std::milli>(SteadyClock::now() - start).count();
  if (ms >= static_cast<double>(kSlowTrackingCycle.count()) &&
      (slow_logged_ms_ == 0.0 || ms >= 2.0 * slow_logged_ms_)) {
    // Once, and again when it gets twice as slow: not per cycle.
    slow_logged_ms_ = ms;
    log::Warn(
        "tracking: a cycle took {:.0f} ms (tracks skip occupancy samples meanwhile; the "
        "occupancy is not held up): lower tracking.particles or tracking.max_tracks, or coarsen "
        "tracking.voxel_m",
        ms);
  }
  const std::vector<tracking::Track>& tracks = tracker_.tracks();
  last_ms_.store(ms, std::memory_order_relaxed);
  AtomicMax(&max_ms_, ms);
  tracks_.store(static_cast<int>(tracks.size()), std::memory_order_relaxed);
  cycles_.fetch_add(1, std::memory_order_relaxed);
  if (consumer_) {
    consumer_(TrackedCycle{snapshot.sequence, snapshot.stamp_ns, snapshot.health.degraded,
                           std::span<const tracking::Track>(tracks), ms});
  }
  return true;
}

TrackingStats TrackingStage::stats() const {
  TrackingStats s;
  s.cycles = cycles_.load(std::memory_order_relaxed);
  s.skipped = stage_.skipped();
  s.untracked = untracked_.load(std::memory_order_relaxed);
  s.tracks = tracks_.load(std::memory_order_relaxed);
  s.last_ms = last_ms_.load(std::memory_order_relaxed);
  s.max_ms = max_ms_.load(std::memory_order_relaxed);
  return s;
}

}  // namespace hg::app
