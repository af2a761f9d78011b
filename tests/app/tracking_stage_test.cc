// The daemon's tracking stage: lock-step cycles that allocate nothing after
// warm-up, and the thread fed through Offer() as the fusion thread does. This
// file replaces the global operator new to count calls while a test asks.
#include "app/tracking_stage.h"

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <new>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "scene/demo_cell.h"
#include "support/allocation_counter.h"
#include "support/grid_runs.h"

namespace hg::app {
namespace {

using Eigen::Vector3d;

constexpr std::int64_t kPeriodNs = 33'333'333;

/// A person-sized blob walking along +x at 1 m/s: snapshot `frame` of a 4 m
/// cube at depth 7, occupied runs inside the blob.
void FillSnapshot(int frame, pipeline::OccupancySnapshot* snap) {
  const Vector3d centre(1.0 + frame * kPeriodNs * 1e-9, 2.0, 0.9);
  const tracking::Ellipsoid blob{centre, Vector3d(0.25, 0.2, 0.85)};
  snap->occupied = test::RunsInside(7, 4.0, [&](const Vector3d& p) { return blob.Contains(p); });
  snap->bounds = {Vector3d::Zero(), Vector3d::Constant(4.0)};
  snap->depth = 7;
  snap->sequence = static_cast<std::uint64_t>(frame) + 1;
  snap->stamp_ns = 1'000'000'000 + frame * kPeriodNs;
  snap->health.degraded = frame % 10 == 3;
}

/// The demo cell's four corner cameras: a birth needs two views.
tracking::StaticScene CornerCamerasScene() {
  tracking::StaticScene scene;
  for (const Vector3d& eye : {Vector3d(-0.3, -0.3, 3.6), Vector3d(4.3, 4.3, 3.6),
                              Vector3d(4.3, -0.3, 3.6), Vector3d(-0.3, 4.3, 3.6)}) {
    scene.cameras.push_back(scene::LookAtCamera(eye, {2, 2, 1}, 640, 360, 360));
  }
  return scene;
}

const common::Box3 kBounds{Vector3d::Zero(), Vector3d(4, 4, 2.2)};

TEST(TrackingStageTest, OptionsFromTheConfigSection) {
  TrackingConfig c;
  c.particles = 50;
  c.rho_unknown = 3.0;
  c.collision_radius_m = 0.1;
  const tracking::TrackerOptions o = MakeTrackerOptions(c, 15.0);
  EXPECT_EQ(o.filter.num_particles, 50);
  EXPECT_EQ(o.likelihood.unknown, 3.0);
  EXPECT_EQ(o.filter.collision_radius_m, 0.1);
  EXPECT_DOUBLE_EQ(o.first_dt_s, 1.0 / 15.0);
  EXPECT_EQ(o.max_dt_s, tracking::TrackerOptions{}.max_dt_s);  // Not in the config.
}

TEST(TrackingStageTest, StaticSceneHasThePinholeCamerasAndTheMeshes) {
  Config config;
  CameraConfig cam;
  cam.model = scene::LookAtCamera({0, 0, 3}, {2, 2, 0}, 320, 240, 200);
  cam.model.distortion[0] = -0.2;
  config.cameras.push_back(cam);
  geometry::TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  mesh.triangles = {{0, 1, 2}};
  const tracking::StaticScene scene = MakeStaticScene(config, {mesh});
  ASSERT_EQ(scene.cameras.size(), 1u);
  EXPECT_EQ(scene.cameras[0].distortion[0], 0.0);
  EXPECT_EQ(scene.cameras[0].K, cam.model.K);
  ASSERT_EQ(scene.meshes.size(), 1u);
  EXPECT_EQ(scene.meshes[0].triangles.size(), 1u);
}

// Lock-step: each cycle hands the consumer the snapshot's sequence, stamp and
// degraded flag with the tracks; after warm-up nothing is allocated.
TEST(TrackingStageTest, CyclesReachTheConsumerAndAllocateNothingAfterWarmUp) {
  const int frames = 60;
  std::vector<pipeline::OccupancySnapshot> snaps(frames);
  for (int f = 0; f < frames; ++f) FillSnapshot(f, &snaps[f]);
  std::vector<std::uint64_t> sequences;
  sequences.reserve(frames);
  int last_tracks = -1;
  bool degraded_seen = false;
  TrackingStage stage(
      tracking::TrackerOptions{}, kBounds, CornerCamerasScene(), [&](const TrackedCycle& c) {
        sequences.push_back(c.sequence);
        last_tracks = static_cast<int>(c.tracks.size());
        degraded_seen = degraded_seen || c.degraded;
        EXPECT_EQ(c.stamp_ns,
                  1'000'000'000 + static_cast<std::int64_t>(c.sequence - 1) * kPeriodNs);
        EXPECT_EQ(c.degraded, (c.sequence - 1) % 10 == 3);
        EXPECT_GE(c.tracking_ms, 0.0);
      });
  for (int f = 0; f < 10; ++f) stage.RunOnce(snaps[f]);
  ASSERT_EQ(last_tracks, 1);
  long allocations = 0;
  {
    const hg::testing::AllocationCounter counter;
    for (int f = 10; f < frames; ++f) stage.RunOnce(snaps[f]);
    allocations = counter.count();
  }
  EXPECT_EQ(allocations, 0);
  ASSERT_EQ(sequences.size(), static_cast<std::size_t>(frames));
  for (int f = 0; f < frames; ++f) EXPECT_EQ(sequences[f], static_cast<std::uint64_t>(f) + 1);
  EXPECT_TRUE(degraded_seen);
  const TrackingStats stats = stage.stats();
  EXPECT_EQ(stats.cycles, static_cast<std::uint64_t>(frames));
  EXPECT_EQ(stats.tracks, 1);
  EXPECT_EQ(stats.skipped, 0u);
  EXPECT_GE(stats.max_ms, stats.last_ms);
  const tracking::Track& t = stage.tracker().tracks().at(0);
  const Vector3d truth(1.0 + (frames - 1) * kPeriodNs * 1e-9, 2.0, 0.9);
  EXPECT_LT((t.centre_W - truth).norm(), 0.1);
}

// An aborted update, or one made while a camera has no frame yet, reports
// space as occupied that no camera looked at: no evidence of a person, so the
// stage leaves it out (no cycle, no consumer call), unless coarse first refined
// the aborted update everywhere to cells of at most two tracking voxels. A
// camera lost later does not stop tracking, nor, after 15 s, one that never
// delivered.
TEST(TrackingStageTest, UnrefinedAbortedAndStartingSnapshotsAreNotTracked) {
  int calls = 0;
  bool degraded = false;
  TrackingStage stage(tracking::TrackerOptions{}, kBounds, CornerCamerasScene(),
                      [&](const TrackedCycle& c) {
                        ++calls;
                        degraded = c.degraded;
                      });
  pipeline::OccupancySnapshot snap;
  FillSnapshot(0, &snap);
  snap.health.cameras.resize(2);
  for (pipeline::CameraHealth& c : snap.health.cameras) c.state = pipeline::CameraState::kOk;
  snap.complete = false;
  EXPECT_FALSE(stage.RunOnce(snap));  // Regions left unvisited.
  const double voxel = tracking::TrackerOptions{}.voxel_m;
  snap.refined_cell_m = 2.5 * voxel;
  EXPECT_FALSE(stage.RunOnce(snap));  // Refined, but coarser than two voxels.
  snap.complete = true;
  snap.health.cameras[1].state = pipeline::CameraState::kStarting;
  EXPECT_FALSE(stage.RunOnce(snap));
  EXPECT_EQ(calls, 0);
  EXPECT_EQ(stage.tracker().stats().cycles, 0u);
  snap.health.cameras[1].state = pipeline::CameraState::kStale;
  snap.health.degraded = true;
  EXPECT_TRUE(stage.RunOnce(snap));
  EXPECT_EQ(calls, 1);
  EXPECT_TRUE(degraded);
  snap.complete = false;
  snap.refined_cell_m = 1.5 * voxel;
  EXPECT_TRUE(stage.RunOnce(snap));  // Aborted after refining to 1.5 voxels.
  EXPECT_EQ(calls, 2);
  const TrackingStats stats = stage.stats();
  EXPECT_EQ(stats.cycles, 2u);
  EXPECT_EQ(stats.untracked, 3u);
  // A camera that never delivers holds tracking back only for 15 s of
  // snapshot time from the first cycle; then it counts as lost.
  const std::int64_t first = snap.stamp_ns;
  snap.complete = true;
  snap.health.cameras[1].state = pipeline::CameraState::kStarting;
  snap.stamp_ns = first + 14'900'000'000LL;
  EXPECT_FALSE(stage.RunOnce(snap));
  snap.stamp_ns = first + 15'000'000'000LL;
  EXPECT_TRUE(stage.RunOnce(snap));
  EXPECT_EQ(calls, 3);
}

// The thread: snapshots offered before it takes them are skipped, never
// queued (the newest wins); each one offered while it waits is tracked; it
// beats its heartbeat while idle.
TEST(TrackingStageTest, ThreadTracksTheNewestOfferedSnapshot) {
  const int frames = 45;
  std::vector<std::shared_ptr<pipeline::OccupancySnapshot>> snaps;
  for (int f = 0; f < frames; ++f) {
    snaps.push_back(std::make_shared<pipeline::OccupancySnapshot>());
    FillSnapshot(f, snaps.back().get());
  }
  std::mutex mutex;  // Test bookkeeping only.
  std::vector<std::uint64_t> sequences;
  auto tracked = [&] {
    const std::lock_guard<std::mutex> lock(mutex);
    return sequences.size();
  };
  // Polls (no timing assertion): true once `done` holds, false after 20 s.
  auto eventually = [](const auto& done) {
    for (int i = 0; i < 2000; ++i) {
      if (done()) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return false;
  };
  common::Heartbeats heartbeats;
  TrackingStage stage(
      tracking::TrackerOptions{}, kBounds, CornerCamerasScene(),
      [&](const TrackedCycle& c) {
        const std::lock_guard<std::mutex> lock(mutex);
        sequences.push_back(c.sequence);
      },
      &heartbeats);
  ASSERT_EQ(heartbeats.size(), 1);
  (void)heartbeats.AllMoved(nullptr);  // Baseline.

  // Offered before the thread runs: only the newest is tracked.
  for (int f = 0; f < 15; ++f) stage.Offer(snaps[f]);
  stage.Start();
  ASSERT_TRUE(eventually([&] { return tracked() == 1; }));
  // Idle, waiting for a snapshot: the heartbeat still moves.
  EXPECT_TRUE(eventually([&] { return heartbeats.AllMoved(nullptr); }));
  // One at a time: each is tracked.
  for (int f = 15; f < frames; ++f) {
    stage.Offer(snaps[f]);
    ASSERT_TRUE(eventually([&] { return tracked() == static_cast<std::size_t>(f - 13); }));
  }
  stage.Stop();
  stage.Stop();  // Idempotent.

  const std::lock_guard<std::mutex> lock(mutex);
  ASSERT_EQ(sequences.size(), static_cast<std::size_t>(frames - 14));
  EXPECT_EQ(sequences.front(), 15u);
  for (std::size_t i = 1; i < sequences.size(); ++i) {
    EXPECT_EQ(sequences[i], sequences[i - 1] + 1);
  }
  const TrackingStats stats = stage.stats();
  EXPECT_EQ(stats.cycles, sequences.size());
  EXPECT_EQ(stats.skipped, 14u);
  EXPECT_EQ(stats.tracks, 1);
  // A tracked snapshot is released at once, so the pipeline can reuse it.
  EXPECT_EQ(snaps.back().use_count(), 1);
}

}  // namespace
}  // namespace hg::app
