#include "app/tracking_stage.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <chrono>
#include <ctime>
#include <utility>

#include "common/check.h"

namespace hg::app {
namespace {

using SteadyClock = std::chrono::steady_clock;

/// Longest wait for a snapshot: the thread beats its heartbeat at least this often.
constexpr long kWaitNs = 100'000'000;

void AtomicMax(std::atomic<double>* target, double value) {
  double seen = target->load(std::memory_order_relaxed);
  while (value > seen && !target->compare_exchange_weak(seen, value, std::memory_order_relaxed)) {
  }
}

/// A complete (or refined enough) update with every camera delivering (or
/// lost after it did).
bool Trackable(const pipeline::OccupancySnapshot& s, double voxel_m) {
  if (!pipeline::RefinedForTracking(s, voxel_m)) return false;
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
    : tracker_(options, bounds, scene), consumer_(std::move(consumer)), heartbeats_(heartbeats) {
  HG_CHECK(sem_init(&offered_, 0, 0) == 0);
  if (heartbeats_ != nullptr) heartbeat_ = heartbeats_->Register("tracking");
}

TrackingStage::~TrackingStage() {
  Stop();
  sem_destroy(&offered_);
}

void TrackingStage::Start() {
  HG_CHECK(!thread_.joinable());
  stop_.store(false);
  thread_ = std::thread([this] { Loop(); });
}

void TrackingStage::Stop() {
  stop_.store(true);
  if (thread_.joinable()) {
    sem_post(&offered_);  // Wakes the thread at once.
    thread_.join();
  }
}

void TrackingStage::Offer(const std::shared_ptr<const pipeline::OccupancySnapshot>& snapshot) {
  slot_.BeginWrite() = snapshot;  // A reference count, no allocation.
  slot_.Publish();
  sem_post(&offered_);  // Lock-free; a futex wake only when the thread waits.
}

bool TrackingStage::RunOnce(const pipeline::OccupancySnapshot& snapshot) {
  if (!Trackable(snapshot, tracker_.options().voxel_m)) {
    untracked_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  const SteadyClock::time_point start = SteadyClock::now();
  tracker_.Update(snapshot);
  const double ms = std::chrono::duration<double, std::milli>(SteadyClock::now() - start).count();
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

void TrackingStage::Loop() {
  // Per thread on Linux; raising one's own niceness needs no privilege. On
  // failure the thread just keeps the default priority.
  (void)setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), kTrackingNice);
  while (!stop_.load(std::memory_order_relaxed)) {
    if (heartbeat_ >= 0) heartbeats_->Beat(heartbeat_);
    timespec until{};
    clock_gettime(CLOCK_MONOTONIC, &until);
    until.tv_nsec += kWaitNs;
    if (until.tv_nsec >= 1'000'000'000L) {
      until.tv_nsec -= 1'000'000'000L;
      ++until.tv_sec;
    }
    if (sem_clockwait(&offered_, CLOCK_MONOTONIC, &until) != 0) continue;  // Timeout or signal.
    while (sem_trywait(&offered_) == 0) {
    }  // One cycle on the newest snapshot for every post so far.
    if (stop_.load(std::memory_order_relaxed)) break;
    std::shared_ptr<const pipeline::OccupancySnapshot>* newest = slot_.TakeNewest();
    if (newest == nullptr || !*newest) continue;
    RunOnce(**newest);
    newest->reset();  // The pipeline may reuse the snapshot from now on.
  }
}

TrackingStats TrackingStage::stats() const {
  TrackingStats s;
  s.cycles = cycles_.load(std::memory_order_relaxed);
  s.skipped = slot_.drops();
  s.untracked = untracked_.load(std::memory_order_relaxed);
  s.tracks = tracks_.load(std::memory_order_relaxed);
  s.last_ms = last_ms_.load(std::memory_order_relaxed);
  s.max_ms = max_ms_.load(std::memory_order_relaxed);
  return s;
}

}  // namespace hg::app
