// The pipeline on live simulated cameras: snapshots keep every point of the
// (standing) people occupied, a lost camera turns the status degraded and
// only grows occupancy, and the camera recovers. Plus the latest-value slot.
#include "pipeline/pipeline.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <mutex>
#include <random>
#include <thread>

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include "scene/demo_cell.h"

#include "capture/camera_health.h"
#include "capture/replay_source.h"
#include "capture/sim_source.h"
#include "common/config_error.h"
#include "common/latest_value.h"
#include "common/shared_slot.h"
#include "geometry/mesh.h"
#include "octree/octree.h"
#include "scene/exact_mask.h"
#include "scene/shapes.h"
#include "silhouette/mask_io.h"
#include "sim/colour_renderer.h"
#include "support/luma_image.h"
#include "support/random_scene.h"
#include "support/sim_bodies.h"

namespace hg::pipeline {
namespace {

using namespace std::chrono_literals;

TEST(LatestValueTest, ReaderGetsNewestAndDropsAreCounted) {
  common::LatestValue<int> slot;
  EXPECT_EQ(slot.TakeNewest(), nullptr);
  slot.BeginWrite() = 1;
  slot.Publish();
  slot.BeginWrite() = 2;
  slot.Publish();  // Overwrites 1 before it was taken.
  int* v = slot.TakeNewest();
  ASSERT_NE(v, nullptr);
  EXPECT_EQ(*v, 2);
  EXPECT_EQ(slot.drops(), 1U);
  EXPECT_EQ(slot.TakeNewest(), nullptr);
  slot.BeginWrite() = 3;
  slot.Publish();
  EXPECT_EQ(*slot.TakeNewest(), 3);
}

TEST(LatestValueTest, TwoThreadsSeeIncreasingValuesOnly) {
  common::LatestValue<std::array<std::uint64_t, 16>> slot;
  constexpr std::uint64_t kCount = 200000;
  std::thread writer([&] {
    for (std::uint64_t i = 1; i <= kCount; ++i) {
      auto& b = slot.BeginWrite();
      b.fill(i);  // Every element equal: a torn read would show.
      slot.Publish();
    }
  });
  std::uint64_t last = 0, taken = 0;
  while (last < kCount) {
    if (const auto* b = slot.TakeNewest()) {
      for (const std::uint64_t x : *b) ASSERT_EQ(x, (*b)[0]);
      ASSERT_GT((*b)[0], last);
      last = (*b)[0];
      ++taken;
    }
  }
  writer.join();
  EXPECT_EQ(taken + slot.drops(), kCount);
}

// One writer stores ever newer values, two readers load them: each value is
// whole (both fields from the same store) and no reader sees one go back.
// Under ThreadSanitizer (HG_SANITIZE=thread) this also checks the ordering.
TEST(SharedSlotTest, ReadersSeeWholeValuesThatOnlyGoForward) {
  struct Value {
    std::uint64_t a = 0, b = 0;
  };
  common::SharedSlot<const Value> slot;
  EXPECT_EQ(slot.Load(), nullptr);
  constexpr std::uint64_t kCount = 20000;
  std::atomic<bool> done{false};
  auto reader = [&] {
    std::uint64_t last = 0;
    while (!done.load()) {
      const std::shared_ptr<const Value> v = slot.Load();
      if (!v) continue;
      ASSERT_EQ(v->a, v->b);
      ASSERT_GE(v->a, last);
      last = v->a;
    }
  };
  std::thread r1(reader), r2(reader);
  for (std::uint64_t i = 1; i <= kCount; ++i) {
    slot.Store(std::make_shared<const Value>(Value{i, i}));
  }
  done = true;
  r1.join();
  r2.join();
  EXPECT_EQ(slot.Load()->a, kCount);
}

// Three small cameras around a 3 m cell; two people standing still, so the
// ground truth does not depend on when each camera captured.
std::shared_ptr<sim::Scene> StandingScene() {
  auto scene = std::make_shared<sim::Scene>();
  scene->name = "standing";
  scene->bounds.min = Eigen::Vector3d(0, 0, 0);
  scene->bounds.max = Eigen::Vector3d(3, 3, 2.5);
  const Eigen::Vector3d target(1.5, 1.5, 0.8);
  const std::vector<Eigen::Vector3d> eyes = {{-0.4, -0.4, 2.4}, {3.4, 3.4, 2.4}, {3.4, -0.4, 2.4}};
  for (std::size_t i = 0; i < eyes.size(); ++i) {
    sim::SceneCamera camera;
    camera.model = scene::LookAtCamera(eyes[i], target, 320, 240, 260);
    geometry::CameraModel& m = camera.model;
    m.name = std::string("cam").append(std::to_string(i));
    if (i == 1) m.distortion = {-0.08, 0.01, 0, 0, 0};
    scene->cameras.push_back(camera);
  }
  for (int p = 0; p < 2; ++p) {
    sim::Person person;
    person.name = std::string("p").append(std::to_string(p));
    person.start_W = Eigen::Vector3d(1.0 + p, 1.2 + 0.5 * p, 0.0);
    scene->people.push_back(person);
  }
  return scene;
}

// The standing scene's cameras at capture offsets 0, 13 and 26 ms, and a
// person walking back and forth at 2 m/s.
std::shared_ptr<sim::Scene> SkewedWalkingScene() {
  auto scene = StandingScene();
  for (std::size_t i = 0; i < scene->cameras.size(); ++i) {
    scene->cameras[i].time_offset_s = 0.013 * static_cast<double>(i);
  }
  sim::Person& walker = scene->people[0];
  walker.start_W = Eigen::Vector3d(0.7, 1.2, 0.0);
  sim::Action walk;
  walk.kind = sim::ActionKind::kWalk;
  walk.speed_mps = 2.0;
  for (int leg = 0; leg < 20; ++leg) {
    walk.path_W.emplace_back(leg % 2 == 0 ? 2.3 : 0.7, 1.2, 0.0);
  }
  walk.duration_s = 1.6 * 20 / walk.speed_mps;
  walker.actions = {walk};
  return scene;
}

struct Rig {
  std::shared_ptr<sim::Scene> scene;
  capture::SimClock clock = capture::SimClock::Now();
  std::vector<capture::SimSource*> sources;
  std::unique_ptr<Pipeline> pipeline;

  /// `stamp_shift`: the cameras stamp their frames this far from the host's
  /// CLOCK_REALTIME (as after the host clock was stepped).
  explicit Rig(std::shared_ptr<sim::Scene> s = StandingScene(), double max_speed_mps = 2.0,
               int silhouette_workers = 0, double knowledge_filter_m3 = 0.0,
               std::chrono::nanoseconds stamp_shift = {}, bool stamp_at_median = false,
               std::vector<geometry::TriangleMesh> obstacles = {})
      : scene(std::move(s)) {
    clock.epoch_ns += stamp_shift.count();
    PipelineOptions options;
    options.max_speed_mps = max_speed_mps;
    options.stamp_at_median = stamp_at_median;
    options.silhouette_workers = silhouette_workers;
    options.knowledge_filter_m3 = knowledge_filter_m3;
    options.bounds = scene->bounds;
    options.depth = 7;
    options.publish_depth = 6;
    options.rate_hz = 30;
    options.deadline_ms = 30;
    std::vector<PipelineCamera> cameras;
    for (int c = 0; c < static_cast<int>(scene->cameras.size()); ++c) {
      auto source = std::make_unique<capture::SimSource>(scene, c, 30.0, clock);
      sources.push_back(source.get());
      cameras.push_back({scene->cameras[c].model, std::move(source), 150});
    }
    pipeline = std::make_unique<Pipeline>(options, std::move(cameras), obstacles, nullptr);
    pipeline->Start();
  }

  // Waits (bounded) until the latest snapshot satisfies `pred`.
  template <class Pred>
  std::shared_ptr<const OccupancySnapshot> WaitFor(Pred pred) {
    const auto give_up = std::chrono::steady_clock::now() + 10s;
    while (std::chrono::steady_clock::now() < give_up) {
      auto s = pipeline->Latest();
      if (s && pred(*s)) return s;
      std::this_thread::sleep_for(10ms);
    }
    return nullptr;
  }

  // Points inside the people, as they were at the snapshot's stamp, that fall
  // in a cell listed neither occupied nor occluded.
  int PointsReportedFree(const OccupancySnapshot& s) const {
    const double t = static_cast<double>(s.stamp_ns - clock.epoch_ns) * 1e-9;
    return testing::PointsInUnlistedCells(testing::PointsInPeople(*scene, t, 200, 3), s.bounds.min,
                                          s.bounds.max, s.depth, {&s.occupied, &s.occluded});
  }
};

TEST(PipelineTest, LiveSnapshotsKeepPeopleOccupiedAndALostCameraOnlyGrowsOccupancy) {
  Rig rig;
  auto healthy = rig.WaitFor([](const OccupancySnapshot& s) {
    return s.sequence > 5 && !s.health.degraded && !s.occupied.empty();
  });
  ASSERT_NE(healthy, nullptr) << "no healthy snapshot within 10 s";
  EXPECT_EQ(rig.PointsReportedFree(*healthy), 0);
  EXPECT_EQ(healthy->health.cameras.size(), 3U);
  // Cameras at the cycle's rate: the cycle locks onto their frames (unless
  // the machine is so loaded that cycles are missed, when the frames' phase
  // jitters by more than the lock allows; CyclePhaseTest covers the lock).
  EXPECT_TRUE(healthy->health.phase_lock);
  EXPECT_NE(rig.WaitFor([](const OccupancySnapshot& s) {
    return s.health.phase_locked || s.health.missed_cycles > 0;
  }),
            nullptr);
  for (const CameraHealth& h : healthy->health.cameras) EXPECT_EQ(h.state, CameraState::kOk);
  const std::size_t occupied_before = OccupancySnapshot::Cells(healthy->occupied);

  rig.sources[2]->SetPaused(true);  // The camera's cable is pulled.
  auto degraded = rig.WaitFor([](const OccupancySnapshot& s) {
    return s.health.degraded && s.health.cameras[2].state == CameraState::kStale;
  });
  ASSERT_NE(degraded, nullptr) << "status did not turn degraded";
  EXPECT_EQ(rig.PointsReportedFree(*degraded), 0);
  EXPECT_GE(
      OccupancySnapshot::Cells(degraded->occupied) + OccupancySnapshot::Cells(degraded->occluded),
      occupied_before);
  EXPECT_GT(OccupancySnapshot::Cells(degraded->occupied), occupied_before)
      << "two cameras carve less than three";

  rig.sources[2]->SetPaused(false);
  auto recovered = rig.WaitFor([&](const OccupancySnapshot& s) {
    return s.sequence > degraded->sequence + 3 && !s.health.degraded;
  });
  ASSERT_NE(recovered, nullptr) << "camera did not recover";
  EXPECT_EQ(rig.PointsReportedFree(*recovered), 0);
  rig.pipeline->Stop();
}

// The host clock stepped back by a minute after the frames were stamped: their
// stamps lie in the future, so their age is negative. Cameras that fall
// silent must still turn stale within their timeout, measured on the steady
// clock from the hand-over of their last frame. (All of them: a camera
// silent while others go on turns stale anyway, by its lag behind them.)
TEST(PipelineTest, SilentCamerasTurnStaleWhateverTheStampsSay) {
  Rig rig(StandingScene(), 2.0, 0, 0.0, std::chrono::minutes(1));
  auto healthy = rig.WaitFor([](const OccupancySnapshot& s) {
    return s.sequence > 5 && !s.health.degraded && !s.occupied.empty();
  });
  ASSERT_NE(healthy, nullptr) << "no healthy snapshot within 10 s";
  EXPECT_LT(healthy->health.cameras[2].frame_age_ms, 0.0) << "the stamps are not ahead";
  for (capture::SimSource* source : rig.sources) source->SetPaused(true);
  const auto paused = std::chrono::steady_clock::now();
  auto stale = rig.WaitFor([](const OccupancySnapshot& s) {
    return s.health.degraded &&
           std::all_of(s.health.cameras.begin(), s.health.cameras.end(),
                       [](const CameraHealth& h) { return h.state == CameraState::kStale; });
  });
  ASSERT_NE(stale, nullptr) << "silent cameras with future stamps stayed live";
  // Timeout 150 ms plus a cycle or two, with room for a loaded machine.
  EXPECT_LT(std::chrono::steady_clock::now() - paused, 2s);
  EXPECT_EQ(rig.PointsReportedFree(*stale), 0);
  rig.pipeline->Stop();
}

// A camera whose centre lies inside an obstacle mesh (its housing or mount
// modelled into the meshes) is blocked: it sees nothing, for as long as the
// pipeline runs, and says so (failed, fault blocked, the status degraded)
// instead of reporting ok while it certifies nothing.
TEST(PipelineTest, ACameraInsideAnObstacleIsFailedBlocked) {
  std::shared_ptr<sim::Scene> scene = StandingScene();
  const geometry::CameraModel& model = scene->cameras[0].model;
  const Eigen::Vector3d centre_W = -model.R_CW.transpose() * model.t_CW;
  const Eigen::Vector3d half(0.0005, 0.0005, 0.0005);
  Rig rig(scene, 2.0, 0, 0.0, {}, false,
          {geometry::TriangleMesh::Box(centre_W - half, centre_W + half)});
  auto up = rig.WaitFor([](const OccupancySnapshot& s) {
    return s.sequence > 5 &&
           std::all_of(s.health.cameras.begin() + 1, s.health.cameras.end(),
                       [](const CameraHealth& h) { return h.state == CameraState::kOk; });
  });
  ASSERT_NE(up, nullptr) << "the other cameras did not come up within 10 s";
  EXPECT_EQ(up->health.cameras[0].state, CameraState::kFailed);
  EXPECT_EQ(up->health.cameras[0].fault, static_cast<std::uint8_t>(capture::CameraFault::kBlocked));
  EXPECT_TRUE(up->health.degraded);
  EXPECT_EQ(rig.PointsReportedFree(*up), 0);
  rig.pipeline->Stop();
}

// One silhouette worker shared by three cameras takes each camera's frames in
// turn: every camera stays ok, each gets its share of the frames (the rate
// itself depends on the machine's load; the shares do not), and nothing is
// reported free.
TEST(PipelineTest, ASharedSilhouetteWorkerServesEveryCamera) {
  Rig rig(StandingScene(), 2.0, /*silhouette_workers=*/1);
  auto healthy = rig.WaitFor([](const OccupancySnapshot& s) {
    if (s.health.degraded || s.occupied.empty() || s.health.cameras.size() != 3) return false;
    for (const CameraHealth& h : s.health.cameras) {
      if (h.frames < 40) return false;  // Well over a second of frames from every camera.
    }
    return true;
  });
  ASSERT_NE(healthy, nullptr) << "no healthy snapshot with every camera's frames within 10 s";
  EXPECT_EQ(rig.PointsReportedFree(*healthy), 0);
  std::uint64_t most = 0;
  for (const CameraHealth& h : healthy->health.cameras) most = std::max(most, h.frames);
  for (const CameraHealth& h : healthy->health.cameras) {
    EXPECT_EQ(h.state, CameraState::kOk) << h.name;
    EXPECT_GE(h.frames * 5, most * 4) << h.name << ": " << h.frames << " frames of " << most;
  }
  rig.pipeline->Stop();
}

// The knowledge filter drops isolated blobs below its volume. A person fills
// a connected set of cells of at least the person's volume, so with a
// threshold below that no point inside a person is ever reported free, here
// with a person walking past three cameras, captured together and at
// different instants; with the cameras in step the filter does drop the
// small blobs where the cameras' cones cross. (Out of step, the frames older
// than the newest are grown for their lag, beyond their images' edges too,
// which joins those blobs to the space the cameras do not see.) The bounds
// reach below the floor, so that blobs on the floor touch no face of them
// (which would keep them whatever their size).
TEST(PipelineTest, TheKnowledgeFilterNeverDropsAPerson) {
  for (const bool skewed : {false, true}) {
    SCOPED_TRACE(skewed ? "cameras out of step" : "cameras in step");
    auto scene = SkewedWalkingScene();
    if (!skewed) {
      for (sim::SceneCamera& c : scene->cameras) c.time_offset_s = 0.0;
    }
    scene->bounds.min.z() = -0.25;
    Rig rig(scene, 2.0, 0, /*knowledge_filter_m3=*/0.01);
    int checked = 0;
    double filtered_m3 = 0.0;
    std::uint64_t last = 0;
    const auto give_up = std::chrono::steady_clock::now() + 10s;
    while (checked < 20 && std::chrono::steady_clock::now() < give_up) {
      const auto s = rig.pipeline->Latest();
      if (s && s->sequence != last && !s->health.degraded) {
        last = s->sequence;
        EXPECT_TRUE(s->health.knowledge_filter);
        EXPECT_EQ(rig.PointsReportedFree(*s), 0) << "snapshot " << s->sequence;
        filtered_m3 += s->health.filtered_m3;
        ++checked;
      }
      std::this_thread::sleep_for(5ms);
    }
    EXPECT_EQ(checked, 20);
    if (!skewed) {
      EXPECT_GT(filtered_m3, 0.0) << "the filter dropped nothing: the test shows nothing";
    }
    std::printf("knowledge filter (%s): %.4f m^3 dropped over %d snapshots\n",
                skewed ? "out of step" : "in step", filtered_m3, checked);
    rig.pipeline->Stop();
  }
}

// Free-running cameras capture at different instants. With the skew
// compensation every point of the walking person at the snapshot's stamp is
// occupied; without it (max speed 0) older frames carve the walker's leading
// edge, which shows that the check can fail.
// The walker walks at 2 m/s; its swinging feet move at up to three times
// that (sim::WalkPose), so 6 m/s bounds every part of it.
TEST(PipelineTest, CaptureSkewIsCompensated) {
  bool stamp_at_median = false;
  auto count_free = [&stamp_at_median](double max_speed_mps, double* skew_ms) {
    Rig rig(SkewedWalkingScene(), max_speed_mps, 0, 0.0, {}, stamp_at_median);
    std::uint64_t seen = 0;
    int free = 0, snapshots = 0;
    *skew_ms = 0.0;
    const auto give_up = std::chrono::steady_clock::now() + 20s;
    while (snapshots < 40 && std::chrono::steady_clock::now() < give_up) {
      auto s = rig.pipeline->Latest();
      if (s && s->sequence != seen && !s->health.degraded && s->sequence > 3) {
        seen = s->sequence;
        free += rig.PointsReportedFree(*s);
        *skew_ms = std::max(*skew_ms, s->health.skew_ms);
        // The oldest frame's margin covers the walk over the skew (stamped
        // at the newest), or over the larger part of it (at the median).
        double widest = 0.0;
        for (const CameraHealth& h : s->health.cameras) widest = std::max(widest, h.margin_m);
        EXPECT_GE(widest + 1e-9,
                  max_speed_mps * s->health.skew_ms * 1e-3 * (stamp_at_median ? 0.5 : 1.0));
        // The gap the widest margin stands for, which births check.
        EXPECT_NEAR(s->health.margin_skew_ms,
                    max_speed_mps > 0.0 ? widest / max_speed_mps * 1e3 : 0.0, 1e-9);
        ++snapshots;
      }
      std::this_thread::sleep_for(5ms);
    }
    rig.pipeline->Stop();
    EXPECT_EQ(snapshots, 40);
    return free;
  };
  for (const bool median : {false, true}) {
    SCOPED_TRACE(median ? "stamped at the median capture time" : "stamped at the newest");
    stamp_at_median = median;
    double skew_ms = 0.0;
    EXPECT_EQ(count_free(6.0, &skew_ms), 0);
    EXPECT_GT(skew_ms, 10.0) << "cameras were expected to capture at different instants";
    EXPECT_GT(count_free(0.0, &skew_ms), 0);
  }
}

// A recording folder in the synth layout: frames play at their capture times,
// stamped with them; a corrupt frame is counted and skipped; after the last
// frame the camera falls silent. (In real time a frame whose time has passed
// while the reader was descheduled is skipped, as a camera's would be: the
// exact sequence is checked at full speed.)
TEST(ReplaySourceTest, PlaysARecordingInRealTime) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("hg_replay_" + std::to_string(getpid()));
  fs::create_directories(dir / "masks" / "cam0");
  std::ofstream(dir / "manifest.yaml")
      << "synth: {format: 1, scene: t, rate_hz: 30, start_s: 0, frames: 5, masks: true, "
         "colour: false}\ncameras:\n  - {name: cam0, time_offset_s: 0.01}\n";
  for (int i = 0; i < 5; ++i) {
    char name[16];
    std::snprintf(name, sizeof(name), "%06d.png", i);
    if (i == 2) {
      std::ofstream(dir / "masks" / "cam0" / name) << "not a png";
      continue;
    }
    common::ImageU8 mask(64, 48, 0);
    for (int p = 0; p <= i; ++p) mask.pixels[static_cast<std::size_t>(p)] = 255;
    silhouette::WriteGreyImage((dir / "masks" / "cam0" / name).string(), mask);
  }
  EXPECT_THROW((void)capture::ReadRecordingCamera(dir.string(), "cam9"), common::ConfigError);

  for (const capture::ReplayPacing pacing :
       {capture::ReplayPacing::kRealtime, capture::ReplayPacing::kFast}) {
    const bool real_time = pacing == capture::ReplayPacing::kRealtime;
    SCOPED_TRACE(real_time ? "real time" : "fast");
    const capture::SimClock clock = capture::SimClock::Now();
    capture::ReplaySource source(capture::ReadRecordingCamera(dir.string(), "cam0"), clock,
                                 capture::ReplayOptions{.pacing = pacing});
    capture::Frame frame;
    std::vector<std::uint64_t> indices;
    const auto give_up = std::chrono::steady_clock::now() + 5s;
    while ((indices.empty() || indices.back() != 4) && std::chrono::steady_clock::now() < give_up) {
      if (!source.Next(&frame, 100ms)) continue;
      ASSERT_EQ(frame.kind, capture::FrameKind::kMask);
      ASSERT_EQ(frame.grey.width, 64);
      const auto foreground = std::count(frame.grey.pixels.begin(), frame.grey.pixels.end(), 255);
      EXPECT_EQ(foreground, static_cast<long>(frame.index) + 1);
      if (real_time) {  // At full speed the stamp is the host time of delivery.
        const std::chrono::nanoseconds t(frame.stamp_ns - clock.epoch_ns);
        EXPECT_NEAR(t.count() * 1e-9, static_cast<double>(frame.index) / 30.0 + 0.01, 1e-6);
        EXPECT_GE(std::chrono::steady_clock::now(), clock.start + t)
            << "frame " << frame.index << " before its time";
      }
      indices.push_back(frame.index);
    }
    if (real_time) {
      ASSERT_FALSE(indices.empty());
      EXPECT_EQ(indices.back(), 4U);
      for (std::size_t i = 0; i < indices.size(); ++i) {
        EXPECT_NE(indices[i], 2U) << "the corrupt frame was delivered";
        if (i > 0) {
          EXPECT_LT(indices[i - 1], indices[i]);
        }
      }
      EXPECT_LE(source.corrupt_frames(), 1U);
    } else {
      EXPECT_EQ(indices, (std::vector<std::uint64_t>{0, 1, 3, 4}));
      EXPECT_EQ(source.corrupt_frames(), 1U);
    }
    EXPECT_FALSE(source.Next(&frame, 100ms)) << "the recording has ended";
  }
  fs::remove_all(dir);
}

// The colour path: a recording of colour frames (the empty cell first, then
// two people standing) replayed through the background model. Once the model
// has learned the empty cell, every point of the people is occupied.
// Polls a running pipeline (for at most 10 s) for `n` new healthy snapshots
// stamped after `from_ns` and calls check(snapshot) on each; returns how many
// it saw.
template <class Check>
int ForHealthySnapshots(const Pipeline& pipeline, std::int64_t from_ns, int n, Check check) {
  int checked = 0;
  std::uint64_t seen = 0;
  const auto give_up = std::chrono::steady_clock::now() + 10s;
  while (std::chrono::steady_clock::now() < give_up && checked < n) {
    const auto s = pipeline.Latest();
    if (s && s->sequence != seen && s->stamp_ns > from_ns && !s->health.degraded) {
      seen = s->sequence;
      check(*s);
      ++checked;
    }
    std::this_thread::sleep_for(5ms);
  }
  return checked;
}

// Points inside the (standing) people of `scene` published free in `s`.
int PeoplePointsFree(const sim::Scene& scene, const OccupancySnapshot& s) {
  return testing::PointsInUnlistedCells(testing::PointsInPeople(scene, 0.0, 100, s.sequence),
                                        s.bounds.min, s.bounds.max, s.depth,
                                        {&s.occupied, &s.occluded});
}

// The scene's cameras without sources, for lock-step Feed() and Step().
std::vector<PipelineCamera> FedCameras(const sim::Scene& scene) {
  std::vector<PipelineCamera> cameras;
  for (const sim::SceneCamera& c : scene.cameras) cameras.push_back({c.model, nullptr, 150});
  return cameras;
}

// Colour frames of a scene whose people stand still in their pose at t = 0,
// with them or without them (the empty cell), for lock-step Feed() and Step().
class StillColourFrames {
 public:
  explicit StillColourFrames(const sim::Scene& scene) {
    sim::Scene empty = scene;
    empty.people.clear();
    for (const sim::Person& p : scene.people) people_.push_back(sim::EvaluatePerson(p, 0.0));
    for (int c = 0; c < static_cast<int>(scene.cameras.size()); ++c) {
      with_people_.emplace_back(scene, c);
      without_.emplace_back(empty, c);
    }
  }
  [[nodiscard]] int cameras() const { return static_cast<int>(with_people_.size()); }
  /// Camera c's frames from now on show the view of `rendered`'s camera c (a
  /// camera moved, its calibration unchanged).
  void RenderCameraAs(int c, const sim::Scene& rendered) {
    sim::Scene empty = rendered;
    empty.people.clear();
    with_people_[c] = sim::ColourRenderer(rendered, c);
    without_[c] = sim::ColourRenderer(empty, c);
  }
  /// Frame i (at i / 30 s) of every camera, fed to `pipeline` (as Mono8 with
  /// `grey`); then one cycle.
  std::shared_ptr<const OccupancySnapshot> Cycle(Pipeline& pipeline, int i, bool present,
                                                 bool grey = false) {
    frame_.kind = grey ? capture::FrameKind::kMono : capture::FrameKind::kRgb;
    frame_.stamp_ns = 1'000'000'000LL + i * 1'000'000'000LL / 30;
    frame_.index = static_cast<std::uint64_t>(i);
    for (int c = 0; c < cameras(); ++c) {
      (present ? with_people_ : without_)[c].Render(present ? people_ : nobody_, i / 30.0,
                                                    frame_.index, &frame_.rgb);
      if (grey) testing::LumaOf(frame_.rgb, &frame_.grey);
      pipeline.Feed(c, frame_);
    }
    return pipeline.Step(frame_.stamp_ns);
  }

 private:
  std::vector<sim::BodyState> people_, nobody_;
  std::vector<sim::ColourRenderer> with_people_, without_;
  capture::Frame frame_;
};

// The daemon restarts while people stand in the cell. With the background it
// learned before kept in background_dir, they are foreground from the first
// frame on; a pipeline that learns afresh takes them for background and, once
// learning ends, reports points inside them free (the hazard this prevents).
TEST(PipelineTest, ARestartTakesUpTheSavedBackgroundAndKeepsPeopleOccupied) {
  namespace fs = std::filesystem;
  const std::shared_ptr<sim::Scene> scene = StandingScene();
  const fs::path top = fs::temp_directory_path() / ("hg_background_" + std::to_string(getpid()));
  const fs::path dir = top / "kept";  // Missing: the pipeline makes it.
  fs::remove_all(top);
  StillColourFrames frames(*scene);
  PipelineOptions options;
  options.bounds = scene->bounds;
  options.depth = 7;
  options.publish_depth = 6;
  options.background.learn_frames = 8;
  auto make = [&](const std::string& background_dir) {
    PipelineOptions o = options;
    o.background_dir = background_dir;
    return std::make_unique<Pipeline>(o, FedCameras(*scene), std::vector<geometry::TriangleMesh>{},
                                      nullptr);
  };
  // Feeds frames [first, first + n) with or without the people; the last snapshot.
  auto run = [&](Pipeline& pipeline, int first, int n, bool present) {
    std::shared_ptr<const OccupancySnapshot> last;
    for (int i = first; i < first + n; ++i) last = frames.Cycle(pipeline, i, present);
    return last;
  };
  auto reported_free = [&](const OccupancySnapshot& s) {
    return testing::PointsInUnlistedCells(testing::PointsInPeople(*scene, 0.0, 200, 5),
                                          s.bounds.min, s.bounds.max, s.depth,
                                          {&s.occupied, &s.occluded});
  };
  const std::size_t all_cells = std::size_t{1} << (3 * options.publish_depth);

  {  // The first start: the cell is empty while it learns, and the cameras say so.
    auto first = make(dir.string());
    for (int i = 0; i < options.background.learn_frames + 2; ++i) {
      const auto s = frames.Cycle(*first, i, /*present=*/false);
      ASSERT_NE(s, nullptr);
      for (const CameraHealth& c : s->health.cameras) {
        EXPECT_EQ(c.learning, i < options.background.learn_frames) << c.name << " frame " << i;
      }
    }
  }
  for (const sim::SceneCamera& c : scene->cameras) {
    EXPECT_TRUE(fs::exists(dir / ("background-" + c.model.name + ".bin"))) << c.model.name;
  }
  // The restart, with the people there from its first frame.
  auto restarted = make(dir.string());
  const auto s = run(*restarted, 100, 4, /*present=*/true);
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(reported_free(*s), 0);
  // Not merely everything occupied: the saved background certifies free
  // space at once, once the view is found to match the taught one (the first
  // frame takes it up, the next two match it).
  EXPECT_LT(OccupancySnapshot::Cells(s->occupied) + OccupancySnapshot::Cells(s->occluded),
            all_cells / 2);

  // The cameras now deliver grey frames (their pixel format changed): the
  // kept colour backgrounds are none. With learning at start off, the cameras
  // see nothing (unlearned) instead of learning the people silently, and the
  // kept files stay as they were.
  {
    const auto before =
        fs::last_write_time(dir / ("background-" + scene->cameras[0].model.name + ".bin"));
    PipelineOptions kept_only = options;
    kept_only.background_dir = dir.string();
    kept_only.background_start = PipelineOptions::BackgroundStart::kKeptOnly;
    Pipeline grey(kept_only, FedCameras(*scene), {}, nullptr);
    std::shared_ptr<const OccupancySnapshot> g;
    for (int i = 200; i < 200 + options.background.learn_frames + 3; ++i) {
      g = frames.Cycle(grey, i, /*present=*/true, /*grey=*/true);
    }
    ASSERT_NE(g, nullptr);
    EXPECT_EQ(reported_free(*g), 0);
    for (const CameraHealth& c : g->health.cameras) {
      EXPECT_EQ(c.fault, static_cast<std::uint8_t>(capture::CameraFault::kUnlearned)) << c.name;
      EXPECT_FALSE(c.learning) << c.name;
    }
    EXPECT_EQ(fs::last_write_time(dir / ("background-" + scene->cameras[0].model.name + ".bin")),
              before);
  }

  // Learning afresh with the people present learns them.
  auto fresh = make("");
  const auto learned = run(*fresh, 100, options.background.learn_frames + 3, /*present=*/true);
  ASSERT_NE(learned, nullptr);
  EXPECT_GT(reported_free(*learned), 0) << "the people were not learned: the test shows nothing";
  fs::remove_all(top);
}

// Camera 0 of the standing scene turned by `degrees` about its vertical axis,
// its calibration unchanged: the view of a camera that was moved.
sim::Scene WithCameraTurned(const sim::Scene& scene, double degrees) {
  sim::Scene turned = scene;
  geometry::CameraModel& m = turned.cameras[0].model;
  const Eigen::Matrix3d turn =
      Eigen::AngleAxisd(degrees * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
  m.R_CW = turn * m.R_CW;
  m.t_CW = turn * m.t_CW;
  return turned;
}

// Of 200 points sampled inside each of the (standing) people of `scene`, those
// in cells `s` publishes free.
int FreeOf200PerPerson(const sim::Scene& scene, const OccupancySnapshot& s) {
  return testing::PointsInUnlistedCells(testing::PointsInPeople(scene, 0.0, 200, 5), s.bounds.min,
                                        s.bounds.max, s.depth, {&s.occupied, &s.occluded});
}

// Grey (Mono8) cameras, the default pixel format of GigE cameras, see
// brightness only, and a person's clothes match the background's grey in
// places. At a threshold of 25 grey levels (hullguardd's default is 15), with
// brightness alone and the 2-pixel dilation, 1 531 of the 35 200 points
// sampled inside the two people over these 88 frames were published free,
// in every frame (the frames: the luma of the colour ones). With the texture
// test alone none are, with the enclosed background filled alone 990; with
// colour frames none.
TEST(PipelineTest, GreyCamerasFreeNoPointInsideThePeople) {
  const std::shared_ptr<sim::Scene> scene = StandingScene();
  StillColourFrames frames(*scene);
  PipelineOptions options;
  options.bounds = scene->bounds;
  options.depth = 8;
  options.publish_depth = 8;
  options.background.learn_frames = 20;
  options.background.min_threshold = 25;  // A camera set up to see less.
  Pipeline pipeline(options, FedCameras(*scene), {}, nullptr);
  int i = 0;
  for (; i < 30; ++i) frames.Cycle(pipeline, i, /*present=*/false, /*grey=*/true);
  int free = 0;
  int frames_with_free = 0;
  std::size_t most_listed = 0;
  for (; i < 30 + 88; ++i) {
    const auto s = frames.Cycle(pipeline, i, /*present=*/true, /*grey=*/true);
    ASSERT_NE(s, nullptr);
    ASSERT_FALSE(s->health.degraded) << "frame " << i;
    const int f = FreeOf200PerPerson(*scene, *s);
    free += f;
    frames_with_free += f > 0 ? 1 : 0;
    most_listed = std::max(
        most_listed, OccupancySnapshot::Cells(s->occupied) + OccupancySnapshot::Cells(s->occluded));
  }
  EXPECT_EQ(free, 0) << "in " << frames_with_free << " frames";
  // Not merely more occupied: a quarter of the cell is listed (what the
  // cameras cannot see included), as with colour frames.
  EXPECT_LT(most_listed, (std::size_t{1} << (3 * options.publish_depth)) / 4);
}

// A camera turned by 0.8 degrees while people stand in the cell: its view
// shifts by about 3.6 pixels, under the health monitor's edge grid (8 px) but
// beyond what the foreground dilation (2 px) covers, so its silhouettes land
// beside where its calibration puts them and could free points inside a
// person. A glance at a few patches of its view on its first turned frame
// (registration comes every third frame) finds the shift: the camera's
// frames are no longer used from that one on, and it is failed (moved) within
// half a second. Depth 8 (cells of 1.2 cm), so that such a shift
// frees points when it goes unnoticed (about 240 in these 60 frames).
TEST(PipelineTest, ACameraTurnedByLessThanTheEdgeGridIsFoundMoved) {
  const std::shared_ptr<sim::Scene> scene = StandingScene();
  StillColourFrames frames(*scene);
  PipelineOptions options;
  options.bounds = scene->bounds;
  options.depth = 8;
  options.publish_depth = 7;
  options.background.learn_frames = 10;
  Pipeline pipeline(options, FedCameras(*scene), {}, nullptr);
  auto reported_free = [&](const OccupancySnapshot& s) { return FreeOf200PerPerson(*scene, s); };
  int i = 0;
  for (; i < options.background.learn_frames + 2; ++i) frames.Cycle(pipeline, i, false);
  for (; i < 40; ++i) {
    const auto s = frames.Cycle(pipeline, i, true);
    ASSERT_EQ(reported_free(*s), 0) << "frame " << i;
    ASSERT_EQ(s->health.cameras[0].fault, 0) << "frame " << i;
    ASSERT_FALSE(s->health.cameras[0].shifted) << "frame " << i;
    ASSERT_LT(s->health.cameras[0].misalignment_px, 0.5) << "frame " << i;
  }
  EXPECT_GE(pipeline.Latest()->health.cameras[0].misalignment_px, 0.0) << "never registered";
  frames.RenderCameraAs(0, WithCameraTurned(*scene, 0.8));
  const int turned_at = i;
  int moved_at = -1;
  bool told_shifted = false;
  for (; i < turned_at + 60; ++i) {
    const auto s = frames.Cycle(pipeline, i, true);
    const CameraHealth& c = s->health.cameras[0];
    if (c.shifted) {
      told_shifted = true;
      EXPECT_GT(c.misalignment_px, 1.0) << "frame " << i;
    }
    if (moved_at < 0 && c.fault == static_cast<std::uint8_t>(capture::CameraFault::kMoved)) {
      moved_at = i;
    }
    if (moved_at >= 0) {
      EXPECT_EQ(c.state, CameraState::kFailed) << "frame " << i;
      EXPECT_TRUE(s->health.degraded) << "frame " << i;
    }
    // The turned frames are glanced at, or registered, before they are used.
    EXPECT_EQ(reported_free(*s), 0) << "frame " << i;
  }
  ASSERT_GE(moved_at, 0) << "the turned camera was not found moved";
  EXPECT_TRUE(told_shifted) << "the snapshots never said the view was shifted";
  EXPECT_LE(moved_at - turned_at, 15 + 3) << "found too late";
}

// Turns just beyond the 12 px registration looks for (2.6 and 2.8 degrees:
// 12 to 13 px here), where about half the edges stay at their samples and
// registration cannot tell: the edges kept fall clearly below their share
// while the view was in place, so its frames stop at the turn, and no point
// inside the people is freed (before, it stayed in use: 6 000 to 9 000
// points free over these 60 frames).
TEST(PipelineTest, ATurnJustBeyondRegistrationsReachStopsTheFrames) {
  const std::shared_ptr<sim::Scene> scene = StandingScene();
  for (const double degrees : {2.6, 2.8}) {
    SCOPED_TRACE(degrees);
    StillColourFrames frames(*scene);
    PipelineOptions options;
    options.bounds = scene->bounds;
    options.depth = 7;
    options.publish_depth = 6;
    options.background.learn_frames = 10;
    Pipeline pipeline(options, FedCameras(*scene), {}, nullptr);
    int i = 0;
    for (; i < options.background.learn_frames + 2; ++i) frames.Cycle(pipeline, i, false);
    for (; i < 40; ++i) frames.Cycle(pipeline, i, true);
    frames.RenderCameraAs(0, WithCameraTurned(*scene, degrees));
    int free = 0;
    for (; i < 100; ++i) {
      const auto s = frames.Cycle(pipeline, i, true);
      free += FreeOf200PerPerson(*scene, *s);
    }
    EXPECT_EQ(free, 0);
  }
}

// A camera moved while the daemon was stopped: its view at start is its own
// reference, so only the kept background, taught in the view the calibration
// holds for, tells. Turned by 0.8 degrees (3.6 px), it is failed (moved)
// after the first frames, and nothing of the people is freed meanwhile;
// turned by 5 or 15 degrees (23 and 70 px, beyond the 12 px looked for), its
// view is never matched (or found moved), so its frames are never used. The
// other cameras match theirs and certify free space.
TEST(PipelineTest, ACameraMovedWhileStoppedIsFoundByItsKeptBackground) {
  namespace fs = std::filesystem;
  const std::shared_ptr<sim::Scene> scene = StandingScene();
  const fs::path dir = fs::temp_directory_path() / ("hg_moved_stopped_" + std::to_string(getpid()));
  fs::remove_all(dir);
  PipelineOptions options;
  options.bounds = scene->bounds;
  options.depth = 8;
  options.publish_depth = 7;
  options.background.learn_frames = 8;
  options.background_dir = dir.string();
  auto reported_free = [&](const OccupancySnapshot& s) { return FreeOf200PerPerson(*scene, s); };
  {  // Taught with the cell empty, in the calibrated view.
    StillColourFrames frames(*scene);
    Pipeline first(options, FedCameras(*scene), {}, nullptr);
    for (int i = 0; i < options.background.learn_frames + 2; ++i) frames.Cycle(first, i, false);
  }
  ASSERT_TRUE(fs::exists(dir / "background-cam0.bin"));
  for (const double degrees : {0.8, 5.0, 15.0}) {
    SCOPED_TRACE(degrees);
    StillColourFrames frames(*scene);
    frames.RenderCameraAs(0, WithCameraTurned(*scene, degrees));
    Pipeline restarted(options, FedCameras(*scene), {}, nullptr);
    std::shared_ptr<const OccupancySnapshot> s;
    int moved_at = -1;
    for (int i = 100; i < 160; ++i) {
      s = frames.Cycle(restarted, i, true);
      ASSERT_EQ(reported_free(*s), 0) << "frame " << i;
      const CameraHealth& c = s->health.cameras[0];
      if (c.fault == static_cast<std::uint8_t>(capture::CameraFault::kMoved) && moved_at < 0) {
        moved_at = i;
      }
      if (i >= 101) {
        EXPECT_NE(c.state, CameraState::kOk) << "frame " << i;
        EXPECT_TRUE(s->health.degraded) << "frame " << i;
      }
    }
    if (degrees < 1.0) {
      EXPECT_GE(moved_at, 0) << "not found moved";
      EXPECT_LE(moved_at, 100 + capture::CameraHealthOptions{}.moved_checks + 1);
    } else if (moved_at < 0) {
      // Too far for most patches to be found: never matched, never used.
      EXPECT_EQ(s->health.cameras[0].state, CameraState::kStarting) << "a frame was used";
      EXPECT_TRUE(s->health.cameras[0].shifted);
      EXPECT_LT(s->health.cameras[0].misalignment_px, 0.0);
    }
    for (int c = 1; c < 3; ++c) {
      EXPECT_EQ(s->health.cameras[c].state, CameraState::kOk) << c;
      EXPECT_FALSE(s->health.cameras[c].shifted) << c;
    }
  }
  fs::remove_all(dir);
}

// An image frame of another size than its camera's (a damaged recording, a
// camera reconfigured behind the daemon's back) is counted corrupt and
// skipped, for RGB and Mono8 frames alike, before the background model or the
// health checks see it; the next good frame is used as usual.
TEST(PipelineTest, AnImageFrameOfTheWrongSizeIsCountedCorruptAndSkipped) {
  const std::shared_ptr<sim::Scene> scene = StandingScene();
  StillColourFrames frames(*scene);
  PipelineOptions options;
  options.bounds = scene->bounds;
  options.depth = 6;
  options.publish_depth = 6;
  options.background.learn_frames = 2;
  Pipeline pipeline(options, FedCameras(*scene), {}, nullptr);
  for (int i = 0; i < 4; ++i) ASSERT_NE(frames.Cycle(pipeline, i, /*present=*/false), nullptr);
  const int w = scene->cameras[0].model.width, h = scene->cameras[0].model.height;
  capture::Frame bad;
  bad.kind = capture::FrameKind::kRgb;
  bad.rgb = common::ImageRgb8(w / 2, h);
  bad.stamp_ns = 2'000'000'000LL;
  pipeline.Feed(0, bad);
  bad.kind = capture::FrameKind::kMono;
  bad.grey = common::ImageU8(w, h + 8);
  pipeline.Feed(0, bad);
  const auto s = frames.Cycle(pipeline, 5, /*present=*/false);
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(s->health.cameras[0].corrupt, 2u);
  EXPECT_EQ(s->health.cameras[0].state, CameraState::kOk);
  EXPECT_EQ(s->health.cameras[1].corrupt, 0u);
}

// A source whose destructor takes a while, as an AravisSource's does while it
// waits for a dead camera's release.
class SlowToCloseSource : public capture::CameraSource {
 public:
  explicit SlowToCloseSource(std::chrono::milliseconds close) : close_(close) {}
  ~SlowToCloseSource() override { std::this_thread::sleep_for(close_); }
  bool Next(capture::Frame* /*frame*/, std::chrono::milliseconds timeout) override {
    std::this_thread::sleep_for(std::min(timeout, std::chrono::milliseconds(5)));
    return false;
  }
  void Stop() override {}

 private:
  std::chrono::milliseconds close_;
};

// Shutting down with several cameras whose sources are slow to close (dead
// GigE cameras, each waiting up to its release grace) takes as long as one,
// not one after another: systemd's stop timeout holds for 16 cameras as for 1.
TEST(PipelineTest, SourcesCloseSideBySide) {
  const std::shared_ptr<sim::Scene> scene = StandingScene();
  PipelineOptions options;
  options.bounds = scene->bounds;
  options.depth = 5;
  options.publish_depth = 5;
  constexpr auto kClose = std::chrono::milliseconds(600);
  std::vector<PipelineCamera> cameras = FedCameras(*scene);
  ASSERT_GE(cameras.size(), 3u);
  for (PipelineCamera& c : cameras) c.source = std::make_unique<SlowToCloseSource>(kClose);
  auto pipeline = std::make_unique<Pipeline>(options, std::move(cameras),
                                             std::vector<geometry::TriangleMesh>{}, nullptr);
  pipeline->Start();
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  const auto before = std::chrono::steady_clock::now();
  pipeline.reset();
  const auto took = std::chrono::steady_clock::now() - before;
  EXPECT_GE(took, kClose);
  EXPECT_LT(took, 2 * kClose) << "the sources closed one after another";
}

// An octree node store too small for the scene (octree.max_nodes): the
// published grid stays conservative (no point inside a person free), and the
// status is degraded with the unsplit nodes counted; with the default store
// the same frames give neither.
TEST(PipelineTest, AFullNodeStoreIsConservativeAndDegraded) {
  const std::shared_ptr<sim::Scene> scene = StandingScene();
  std::vector<sim::BodyState> people;
  for (const sim::Person& p : scene->people) people.push_back(sim::EvaluatePerson(p, 0.0));
  // The people stand still: one mask per camera serves every frame.
  std::vector<common::ImageU8> masks(scene->cameras.size());
  for (std::size_t c = 0; c < masks.size(); ++c) {
    sim::MaskRenderer(scene->cameras[c].model, scene->obstacles, scene->foreground_objects,
                      scene->mask_occlusion)
        .Render(people, &masks[c]);
  }
  auto run = [&](std::int64_t max_nodes) {
    PipelineOptions options;
    options.bounds = scene->bounds;
    options.depth = 7;
    options.publish_depth = 7;
    options.max_nodes = max_nodes;
    Pipeline pipeline(options, FedCameras(*scene), {}, nullptr);
    capture::Frame frame;
    frame.kind = capture::FrameKind::kMask;
    std::shared_ptr<const OccupancySnapshot> last;
    for (int i = 0; i < 3; ++i) {
      frame.stamp_ns = 1'000'000'000LL + i * 1'000'000'000LL / 30;
      frame.index = static_cast<std::uint64_t>(i);
      for (std::size_t c = 0; c < masks.size(); ++c) {
        frame.grey = masks[c];
        pipeline.Feed(static_cast<int>(c), frame);
      }
      last = pipeline.Step(frame.stamp_ns);
    }
    return last;
  };
  const auto full = run(0);
  const auto small = run(3000);
  ASSERT_NE(full, nullptr);
  ASSERT_NE(small, nullptr);
  EXPECT_EQ(full->health.unsplit_nodes, 0);
  EXPECT_FALSE(full->health.degraded);
  EXPECT_GT(small->health.unsplit_nodes, 0);
  EXPECT_TRUE(small->health.degraded);
  // Unsplit nodes are occupied leaves coarser than asked: the cycle is not
  // complete, nor refined to the finest cell (which tracking would trust).
  EXPECT_TRUE(full->complete);
  EXPECT_FALSE(small->complete);
  EXPECT_GT(small->refined_cell_m, full->refined_cell_m);
  EXPECT_LT(*std::min_element(small->root_levels.begin(), small->root_levels.end()), 7);
  EXPECT_EQ(PeoplePointsFree(*scene, *small), 0);
  EXPECT_EQ(PeoplePointsFree(*scene, *full), 0);
  EXPECT_GT(OccupancySnapshot::Cells(small->occupied), OccupancySnapshot::Cells(full->occupied));
}

// Two people stand motionless for a minute of simulated time, in colour
// frames through the background model, while the light breathes by +-15 %:
// the background model never absorbs them, so no point inside them is ever
// published free, while the rest of the cell stays certified free.
TEST(PipelineTest, PeopleStandingStillForAMinuteStayOccupied) {
  std::shared_ptr<sim::Scene> scene = StandingScene();
  scene->imaging.light_change_amplitude = 0.15;
  scene->imaging.light_change_period_s = 20.0;
  StillColourFrames frames(*scene);
  PipelineOptions options;
  options.bounds = scene->bounds;
  options.depth = 6;
  options.publish_depth = 6;
  options.background.learn_frames = 20;
  Pipeline pipeline(options, FedCameras(*scene), {}, nullptr);
  constexpr int kLearn = 30, kStill = 60 * 30;  // Frames at 30 Hz.
  const auto points = testing::PointsInPeople(*scene, 0.0, 300, 9);
  int checked = 0, free = 0;
  std::size_t most_listed = 0, first_listed = 0;
  for (int i = 0; i < kLearn + kStill; ++i) {
    const bool present = i >= kLearn;
    const auto s = frames.Cycle(pipeline, i, present);
    if (present && (i - kLearn) % 10 == 0) {
      free += testing::PointsInUnlistedCells(points, s->bounds.min, s->bounds.max, s->depth,
                                             {&s->occupied, &s->occluded});
      const std::size_t listed =
          OccupancySnapshot::Cells(s->occupied) + OccupancySnapshot::Cells(s->occluded);
      if (checked == 0) first_listed = listed;
      most_listed = std::max(most_listed, listed);
      ++checked;
    }
  }
  EXPECT_EQ(checked, kStill / 10);
  EXPECT_EQ(free, 0) << "points inside a person still for a minute were published free";
  // Not merely all occupied: the rest of the cell stayed certified free
  // throughout (what the cameras cannot see is listed too, about a third).
  EXPECT_LT(most_listed, (std::size_t{1} << (3 * options.publish_depth)) / 2);
  EXPECT_LT(most_listed, first_listed + first_listed / 10) << first_listed;
}

// The sim source's colour mode: the empty cell (plus noise) while the model
// learns, then the people painted in, which the background model finds: no
// point inside them is published free, and the rest of the cell is.
// Sim colour frames, RGB or the raw Bayer mosaic, through the background
// model: no point inside a person is free once the people are in.
// The simulator's people stay out of the colour frames, past the empty
// period, until every camera of the gate has had its background learned; then
// they come in, and the source says from which frame.
TEST(SimSourceTest, PeopleWaitForEveryCameraToHaveLearned) {
  const std::shared_ptr<sim::Scene> scene = StandingScene();
  const capture::SimClock clock = capture::SimClock::Now();
  const auto gate = std::make_shared<capture::SimSource::PeopleGate>(2);
  capture::SimSource a(scene, 0, 30.0, clock), b(scene, 1, 30.0, clock);
  a.EnableColour(0.0);  // No empty period: only the gate holds them.
  b.EnableColour(0.0);
  a.HoldPeopleUntilLearned(gate);
  b.HoldPeopleUntilLearned(gate);
  common::ImageRgb8 empty;
  sim::ColourRenderer(*scene, 0).RenderEmpty(&empty);
  auto largest_change = [&](const capture::Frame& frame) {
    int largest = 0;
    for (std::size_t i = 0; i < empty.pixels.size(); ++i) {
      largest = std::max(largest, std::abs(frame.rgb.pixels[i] - empty.pixels[i]));
    }
    return largest;
  };
  capture::Frame frame;
  ASSERT_TRUE(a.Next(&frame, 500ms));
  EXPECT_LT(largest_change(frame), 20) << "people in before any model learned";
  a.BackgroundLearned();
  a.BackgroundLearned();  // Counted once.
  ASSERT_TRUE(a.Next(&frame, 500ms));
  EXPECT_LT(largest_change(frame), 20) << "people in before the second camera's model learned";
  EXPECT_EQ(a.people_shown_from_ns(), 0);
  b.BackgroundLearned();
  ASSERT_TRUE(a.Next(&frame, 500ms));
  EXPECT_GT(largest_change(frame), 50) << "the people (100 grey levels off) did not come in";
  EXPECT_EQ(a.people_shown_from_ns(), frame.stamp_ns);
}

void SimColourFramesThroughTheBackgroundModel(bool bayer) {
  const std::shared_ptr<sim::Scene> scene = StandingScene();
  const capture::SimClock clock = capture::SimClock::Now();
  PipelineOptions options;
  options.bounds = scene->bounds;
  options.depth = 6;
  options.publish_depth = 6;
  options.background.learn_frames = 10;
  // The empty cell for 2 s: the model needs 10 of its 60 frames, the rest is
  // room for a loaded machine, on which the sources skip the frames whose
  // time has passed (a model that learned a person would report it free).
  constexpr double kEmptyS = 2.0;
  std::vector<PipelineCamera> cameras;
  std::vector<capture::SimSource*> sources;
  // And until every camera's model has learned (as hullguardd's sim does).
  const auto gate =
      std::make_shared<capture::SimSource::PeopleGate>(static_cast<int>(scene->cameras.size()));
  for (int c = 0; c < static_cast<int>(scene->cameras.size()); ++c) {
    auto source = std::make_unique<capture::SimSource>(scene, c, 30.0, clock);
    source->EnableColour(kEmptyS, bayer);
    source->HoldPeopleUntilLearned(gate);
    sources.push_back(source.get());
    cameras.push_back({scene->cameras[c].model, std::move(source), 150});
  }
  // What a camera delivers: colour, the empty cell within the noise at first.
  {
    capture::SimSource probe(scene, 0, 30.0, clock);
    probe.EnableColour(kEmptyS, bayer);
    capture::Frame frame;
    ASSERT_TRUE(probe.Next(&frame, 500ms));
    ASSERT_EQ(frame.kind, bayer ? capture::FrameKind::kMono : capture::FrameKind::kRgb);
    common::ImageRgb8 empty;
    sim::ColourRenderer(*scene, 0).RenderEmpty(&empty);
    int largest = 0;
    if (bayer) {
      // BayerRG8: red at (even, even), blue at (odd, odd), green elsewhere.
      ASSERT_EQ(frame.grey.width, empty.width);
      ASSERT_EQ(frame.grey.height, empty.height);
      for (int v = 0; v < empty.height; ++v) {
        for (int u = 0; u < empty.width; ++u) {
          const int site = empty.Pixel(u, v)[(u & 1) + (v & 1)];
          largest = std::max(largest, std::abs(frame.grey.At(u, v) - site));
        }
      }
    } else {
      ASSERT_EQ(frame.rgb.pixels.size(), empty.pixels.size());
      for (std::size_t i = 0; i < empty.pixels.size(); ++i) {
        largest = std::max(largest, std::abs(frame.rgb.pixels[i] - empty.pixels[i]));
      }
    }
    EXPECT_LT(largest, 20) << "people or more than noise in the learning frames";
  }
  Pipeline pipeline(options, std::move(cameras), {}, nullptr);
  pipeline.Start();
  // From when the last camera showed the people, and a little after.
  std::int64_t shown_ns = 0;
  for (const auto give_up = std::chrono::steady_clock::now() + 30s;
       std::chrono::steady_clock::now() < give_up;) {
    shown_ns = 0;
    for (const capture::SimSource* source : sources) {
      const std::int64_t from = source->people_shown_from_ns();
      shown_ns = from == 0 || shown_ns < 0 ? -1 : std::max(shown_ns, from);
    }
    if (shown_ns > 0) break;
    std::this_thread::sleep_for(20ms);
  }
  ASSERT_GT(shown_ns, 0) << "the people never came in: a model did not learn";
  EXPECT_GE(shown_ns, clock.epoch_ns + static_cast<std::int64_t>(kEmptyS * 1e9));
  const std::int64_t people_from = shown_ns + 200'000'000;
  int free = 0;
  std::size_t fewest_listed = std::numeric_limits<std::size_t>::max();
  const int checked =
      ForHealthySnapshots(pipeline, people_from, 10, [&](const OccupancySnapshot& s) {
        free += PeoplePointsFree(*scene, s);
        fewest_listed = std::min(fewest_listed, OccupancySnapshot::Cells(s.occupied) +
                                                    OccupancySnapshot::Cells(s.occluded));
      });
  pipeline.Stop();
  EXPECT_EQ(checked, 10) << "too few healthy cycles with the people in";
  EXPECT_EQ(free, 0);
  // Not merely all occupied: the models tell the people from the cell. Of
  // the fewest cycles listed, since on a loaded machine a late frame grows
  // every camera's margin (by 0.17 m, held a while), and with it what is
  // listed, past half the cell in some cycles (seen at 60 %).
  EXPECT_LT(fewest_listed, (std::size_t{1} << (3 * options.publish_depth)) / 2);
}

TEST(PipelineTest, SimColourFramesGoThroughTheBackgroundModel) {
  SimColourFramesThroughTheBackgroundModel(/*bayer=*/false);
}

TEST(PipelineTest, SimBayerMosaicsGoThroughTheBackgroundModel) {
  SimColourFramesThroughTheBackgroundModel(/*bayer=*/true);
}

// A colour camera that, once told to, delivers its last image again and again
// with fresh stamps (a hung driver re-delivering its buffer).
class RepeatingSource : public capture::CameraSource {
 public:
  explicit RepeatingSource(std::unique_ptr<capture::CameraSource> inner)
      : inner_(std::move(inner)) {}
  bool Next(capture::Frame* frame, std::chrono::milliseconds timeout) override {
    if (!repeat.load()) {
      if (!inner_->Next(frame, timeout)) return false;
      last_ = frame->rgb;  // The pipeline hands in a ring of frames: keep our own copy.
      fresh.fetch_add(1);
      return true;
    }
    if (!inner_->Next(&scratch_, timeout)) return false;
    frame->kind = capture::FrameKind::kRgb;
    frame->rgb = last_;                   // Pixels as before,
    frame->stamp_ns = scratch_.stamp_ns;  // stamp of now.
    frame->index = scratch_.index;
    return true;
  }
  void Stop() override { inner_->Stop(); }
  std::atomic<bool> repeat{false};
  std::atomic<std::uint64_t> fresh{0};  ///< Frames handed out before the repeats.

 private:
  std::unique_ptr<capture::CameraSource> inner_;
  capture::Frame scratch_;
  common::ImageRgb8 last_;
};

// A colour camera whose left half of the image goes dark on request (a bank
// of lamps switched off over part of its view).
class HalfDimmingSource : public capture::CameraSource {
 public:
  explicit HalfDimmingSource(std::unique_ptr<capture::CameraSource> inner)
      : inner_(std::move(inner)) {}
  bool Next(capture::Frame* frame, std::chrono::milliseconds timeout) override {
    if (!inner_->Next(frame, timeout)) return false;
    if (dim.load() && frame->kind == capture::FrameKind::kRgb) {
      common::ImageRgb8& image = frame->rgb;
      for (int v = 0; v < image.height; ++v) {
        for (int u = 0; u < image.width / 2; ++u) {
          std::uint8_t* p = image.Pixel(u, v);
          for (int k = 0; k < 3; ++k) p[k] = static_cast<std::uint8_t>(p[k] / 2);
        }
      }
    }
    return true;
  }
  void Stop() override { inner_->Stop(); }
  void BackgroundLearned() override { inner_->BackgroundLearned(); }
  std::atomic<bool> dim{false};

 private:
  std::unique_ptr<capture::CameraSource> inner_;
};

// Half of one camera's view going dark while the other half keeps its light
// is no light change a single gain follows: the gain keeps to the half that
// kept its light (a person covering most of the view must not set it), and
// the dark half stays foreground, occupied. The pipeline tells so
// (ForegroundHeavySince(), hullguardd warns after a minute); the empty
// cell's cameras do not.
TEST(PipelineTest, PartOfTheViewGoingDarkIsForegroundAndTold) {
  std::shared_ptr<sim::Scene> scene = StandingScene();
  scene->people.clear();
  const capture::SimClock clock = capture::SimClock::Now();
  PipelineOptions options;
  options.bounds = scene->bounds;
  options.depth = 6;
  options.publish_depth = 5;
  options.background.learn_frames = 10;
  std::vector<PipelineCamera> cameras;
  HalfDimmingSource* dimming = nullptr;
  for (int c = 0; c < static_cast<int>(scene->cameras.size()); ++c) {
    auto sim = std::make_unique<capture::SimSource>(scene, c, 30.0, clock);
    sim->EnableColour(0.5);
    auto source = std::make_unique<HalfDimmingSource>(std::move(sim));
    if (c == 0) dimming = source.get();
    cameras.push_back({scene->cameras[c].model, std::move(source), 150});
  }
  Pipeline pipeline(options, std::move(cameras), {}, nullptr);
  pipeline.Start();
  auto wait_until = [](const std::function<bool()>& done) {
    for (const auto give_up = std::chrono::steady_clock::now() + 20s;
         std::chrono::steady_clock::now() < give_up; std::this_thread::sleep_for(10ms)) {
      if (done()) return true;
    }
    return false;
  };
  // Learned, and 20 cycles of the empty cell after that.
  std::uint64_t learned_at = 0;
  ASSERT_TRUE(wait_until([&] {
    const auto s = pipeline.Latest();
    if (!s ||
        !std::all_of(s->health.cameras.begin(), s->health.cameras.end(), [](const CameraHealth& h) {
          return h.state == CameraState::kOk && !h.learning;
        })) {
      return false;
    }
    if (learned_at == 0) learned_at = s->sequence;
    return s->sequence >= learned_at + 20;
  })) << "the cameras never learned";
  for (int c = 0; c < 3; ++c) {
    EXPECT_FALSE(pipeline.ForegroundHeavySince(c).has_value()) << "camera " << c;
  }
  const auto dimmed_at = std::chrono::steady_clock::now();
  dimming->dim = true;
  ASSERT_TRUE(wait_until([&] { return pipeline.ForegroundHeavySince(0).has_value(); }))
      << "half a view dark was not told";
  const auto since = *pipeline.ForegroundHeavySince(0);
  EXPECT_GE(since, dimmed_at);
  // It stays so (the dark half never becomes background on its own).
  const std::uint64_t frames = pipeline.Latest()->health.cameras[0].frames;
  ASSERT_TRUE(
      wait_until([&] { return pipeline.Latest()->health.cameras[0].frames > frames + 30; }));
  ASSERT_TRUE(pipeline.ForegroundHeavySince(0).has_value());
  EXPECT_EQ(*pipeline.ForegroundHeavySince(0), since);
  EXPECT_EQ(pipeline.Latest()->health.cameras[0].state, CameraState::kOk);
  EXPECT_FALSE(pipeline.ForegroundHeavySince(1).has_value());
  EXPECT_FALSE(pipeline.ForegroundHeavySince(2).has_value());
  pipeline.Stop();
}

// A frame that repeats the one before (the simplest of the repeats the health
// monitor finds among a camera's last four frames) is no new view of the cell: the camera
// gets no fresh frame from the first repeat on and turns stale at its timeout,
// well before the repeats count as frozen; it never certifies anything free
// on its old image meanwhile.
TEST(PipelineTest, ARepeatedColourFrameIsNotAFreshView) {
  const std::shared_ptr<sim::Scene> scene = StandingScene();
  const capture::SimClock clock = capture::SimClock::Now();
  PipelineOptions options;
  options.bounds = scene->bounds;
  options.depth = 6;
  options.publish_depth = 5;
  options.deadline_ms = 30;
  options.background.learn_frames = 10;
  std::vector<PipelineCamera> cameras;
  RepeatingSource* repeating = nullptr;
  for (int c = 0; c < static_cast<int>(scene->cameras.size()); ++c) {
    auto sim = std::make_unique<capture::SimSource>(scene, c, 30.0, clock);
    sim->EnableColour(0.5);
    auto source = std::make_unique<RepeatingSource>(std::move(sim));
    if (c == 2) repeating = source.get();
    cameras.push_back({scene->cameras[c].model, std::move(source), 150});
  }
  // Every cycle's snapshot, as the fusion thread publishes it: the first one
  // with camera 2 not ok once the repeats are on, whoever polls when.
  std::atomic<bool> watching{false};
  std::mutex first_mutex;
  std::shared_ptr<const OccupancySnapshot> first_not_ok;
  auto consumer = [&](const std::shared_ptr<const OccupancySnapshot>& s) {
    if (!watching.load() || s->health.cameras[2].state == CameraState::kOk) return;
    const std::lock_guard<std::mutex> lock(first_mutex);
    if (first_not_ok == nullptr) first_not_ok = s;
  };
  Pipeline pipeline(options, std::move(cameras), {}, consumer);
  pipeline.Start();
  const auto give_up = std::chrono::steady_clock::now() + 10s;
  std::shared_ptr<const OccupancySnapshot> ok;
  while (std::chrono::steady_clock::now() < give_up) {
    ok = pipeline.Latest();
    if (ok && ok->sequence > 5 && ok->health.cameras[2].state == CameraState::kOk) break;
    ok = nullptr;
    std::this_thread::sleep_for(5ms);
  }
  ASSERT_NE(ok, nullptr) << "camera 2 never ok";
  watching = true;
  repeating->repeat = true;
  // Frames still in the pipeline's queues when the repeats start are counted
  // later, so the bound is what the source handed out, not what a snapshot
  // had counted by then.
  const std::uint64_t fresh_frames = repeating->fresh.load();
  const auto give_up_stale = std::chrono::steady_clock::now() + 10s;
  while (std::chrono::steady_clock::now() < give_up_stale) {
    {
      const std::lock_guard<std::mutex> lock(first_mutex);
      if (first_not_ok != nullptr) break;
    }
    std::this_thread::sleep_for(2ms);
  }
  pipeline.Stop();
  ASSERT_NE(first_not_ok, nullptr) << "a camera repeating its frame stayed ok";
  const CameraHealth& h = first_not_ok->health.cameras[2];
  EXPECT_EQ(h.state, CameraState::kStale) << "frozen (fault " << int{h.fault} << ") came first";
  EXPECT_EQ(h.fault, 0);
  // No repeat is counted as a frame; one fresh frame may have been on its way
  // out of the source as the repeats were switched on.
  EXPECT_LE(h.frames, fresh_frames + 1);
  EXPECT_TRUE(first_not_ok->health.degraded);
}

TEST(PipelineTest, ColourRecordingThroughTheBackgroundModel) {
  namespace fs = std::filesystem;
  const std::shared_ptr<sim::Scene> scene = StandingScene();
  sim::Scene empty = *scene;
  empty.people.clear();
  constexpr int kEmptyFrames = 36, kFrames = 75;
  const fs::path dir = fs::temp_directory_path() / ("hg_colour_" + std::to_string(getpid()));
  std::ofstream manifest(dir / "manifest.yaml");
  fs::create_directories(dir);
  std::ofstream(dir / "manifest.yaml")
      << "synth: {format: 1, scene: standing, rate_hz: 30, start_s: 0, frames: " << kFrames
      << ", masks: false, colour: true}\ncameras:\n";
  std::vector<sim::BodyState> people;
  for (const sim::Person& p : scene->people) people.push_back(sim::EvaluatePerson(p, 0.0));
  for (int c = 0; c < static_cast<int>(scene->cameras.size()); ++c) {
    const std::string name = scene->cameras[c].model.name;
    std::ofstream(dir / "manifest.yaml", std::ios::app) << "  - {name: " << name << "}\n";
    fs::create_directories(dir / "colour" / name);
    const sim::ColourRenderer with_people(*scene, c), without(empty, c);
    common::ImageRgb8 image;
    for (int i = 0; i < kFrames; ++i) {
      if (i < kEmptyFrames) {
        without.Render({}, i / 30.0, static_cast<std::uint64_t>(i), &image);
      } else {
        with_people.Render(people, i / 30.0, static_cast<std::uint64_t>(i), &image);
      }
      char file[16];
      std::snprintf(file, sizeof(file), "%06d.png", i);
      silhouette::WriteRgbImage((dir / "colour" / name / file).string(), image);
    }
  }

  PipelineOptions options;
  options.bounds = scene->bounds;
  options.depth = 7;
  options.publish_depth = 6;
  options.deadline_ms = 30;
  options.background.learn_frames = 20;
  const capture::SimClock clock = capture::SimClock::Now();
  std::vector<PipelineCamera> cameras;
  // The frames with people loop, so that a loaded machine, whose missed
  // deadlines degrade some cycles, still gets its healthy ones.
  const capture::ReplayOptions replay{.loop = true, .loop_start_s = kEmptyFrames / 30.0};
  for (const sim::SceneCamera& c : scene->cameras) {
    cameras.push_back({c.model,
                       std::make_unique<capture::ReplaySource>(
                           capture::ReadRecordingCamera(dir.string(), c.model.name), clock, replay),
                       150});
  }
  Pipeline pipeline(options, std::move(cameras), {}, nullptr);
  pipeline.Start();
  const std::int64_t people_from = clock.epoch_ns + (kEmptyFrames + 3) * 1'000'000'000LL / 30;
  int free = 0;
  const int checked =
      ForHealthySnapshots(pipeline, people_from, 10, [&](const OccupancySnapshot& s) {
        free += PeoplePointsFree(*scene, s);
        EXPECT_GT(OccupancySnapshot::Cells(s.occupied), 0U);
      });
  pipeline.Stop();
  fs::remove_all(dir);
  EXPECT_EQ(checked, 10);
  EXPECT_EQ(free, 0);
}

}  // namespace
}  // namespace hg::pipeline

namespace hg::pipeline {
namespace {

// Published cells whose centres lie inside `shape` and that are listed neither
// occupied nor occluded, and how many cells lie inside it.
std::pair<int, int> FreeCellsInside(const OccupancySnapshot& s, const scene::Shape& shape) {
  const int n = 1 << s.depth;
  const std::vector<std::uint8_t> listed =
      testing::ListedCells(s.depth, {&s.occupied, &s.occluded});
  int free = 0, inside = 0;
  for (int z = 0; z < n; ++z) {
    for (int y = 0; y < n; ++y) {
      for (int x = 0; x < n; ++x) {
        const common::Box3 box = octree::CellBox(
            s.bounds, {s.depth, static_cast<std::uint32_t>(x), static_cast<std::uint32_t>(y),
                       static_cast<std::uint32_t>(z)});
        if (!scene::Contains(shape, 0.5 * (box.min + box.max))) continue;
        ++inside;
        free +=
            listed[static_cast<std::size_t>(x) + static_cast<std::size_t>(n) * (y + n * z)] ? 0 : 1;
      }
    }
  }
  return {free, inside};
}

// A camera whose frame is 50 ms older than the newest (A) saw nothing of a
// ball moving at 2 m/s (the default max_speed_mps): in the first case it was
// just outside A's image, in the second hidden from A behind a post. By the
// newest frame (B, from above) it has moved 0.1 m, into A's view. A's mask,
// grown for its lag, must not certify the ball's cells free: what lay beyond
// its image's edges, and what its obstacles hid, may have moved in.
TEST(PipelineLagTest, WhatALaggingCameraCouldNotSeeIsNotCertifiedFree) {
  const common::Box3 bounds{{0, 0, 0}, {2, 2, 2}};
  struct Case {
    const char* what;
    geometry::CameraModel a;
    std::vector<geometry::TriangleMesh> obstacles;
    scene::Shape then, now;
    int depth;
  };
  std::vector<Case> cases;
  {
    // A looks along +y; at y = 1 its image starts near x = 0.2. The ball is
    // at the largest x where A's mask is still empty.
    const geometry::CameraModel a = scene::LookAtCamera({1, -2, 1}, {1, 1, 1}, 160, 120, 300);
    double x0 = 0.0;
    for (double x = 0.0; x < 1.0; x += 0.001) {
      const common::ImageU8 m = scene::RenderExactMask(a, {scene::Sphere{{x, 1, 1}, 0.06}});
      if (std::any_of(m.pixels.begin(), m.pixels.end(), [](std::uint8_t p) { return p != 0; })) {
        break;
      }
      x0 = x;
    }
    cases.push_back({"entering the view",
                     a,
                     {},
                     scene::Sphere{{x0, 1, 1}, 0.06},
                     scene::Sphere{{x0 + 0.1, 1, 1}, 0.06},
                     7});
  }
  cases.push_back({"stepping out from behind a post",
                   scene::LookAtCamera({1, -2, 1}, {1, 1, 1}, 640, 480, 1200),
                   {geometry::TriangleMesh::Box({0.9, 0.3, 0.6}, {1.0, 0.35, 1.4})},
                   scene::Sphere{{0.93, 1.2, 1.0}, 0.02},
                   scene::Sphere{{1.03, 1.2, 1.0}, 0.02},
                   8});
  for (Case& c : cases) {
    SCOPED_TRACE(c.what);
    c.a.name = "A";
    geometry::CameraModel b = scene::LookAtCamera({1, 1, 4.5}, {1, 1, 1}, 160, 120, 60);
    b.name = "B";
    // The premise: A saw nothing of the ball (outside its image: its exact
    // mask is empty; behind the post: no point of it is in view).
    if (c.obstacles.empty()) {
      const common::ImageU8 m = scene::RenderExactMask(c.a, {c.then});
      ASSERT_TRUE(
          std::all_of(m.pixels.begin(), m.pixels.end(), [](std::uint8_t p) { return p == 0; }));
    } else {
      std::mt19937_64 rng(3);
      std::uniform_real_distribution<double> u(0, 1);
      for (int i = 0; i < 2000; ++i) {
        const Eigen::Vector3d q = scene::SampleInside(c.then, [&] { return u(rng); });
        ASSERT_FALSE(testing::VisibleFrom(c.a, c.obstacles, q)) << q.transpose();
      }
    }
    PipelineOptions options;
    options.bounds = bounds;
    options.depth = c.depth;
    options.publish_depth = c.depth;
    options.boundary_coarsening = 0;
    options.coarse_first_depth = 0;
    std::vector<PipelineCamera> cameras(2);
    cameras[0].model = c.a;
    cameras[1].model = b;
    Pipeline pipeline(options, std::move(cameras), c.obstacles, nullptr);
    const std::int64_t t0 = 1'000'000'000'000, t1 = t0 + 50'000'000;
    capture::Frame fa, fb;
    fa.kind = fb.kind = capture::FrameKind::kMask;
    fa.grey = common::ImageU8(c.a.width, c.a.height, 0);  // Nothing of the ball.
    fa.stamp_ns = t0;
    fb.grey = scene::RenderExactMask(b, {c.now});
    fb.stamp_ns = t1;
    pipeline.Feed(0, fa);
    pipeline.Feed(1, fb);
    const auto s = pipeline.Step(t1 + 1'000'000);
    ASSERT_EQ(s->health.cameras[0].state, CameraState::kOk);
    EXPECT_NEAR(s->health.skew_ms, 50.0, 1e-6);
    const auto [free, inside] = FreeCellsInside(*s, c.now);
    EXPECT_GT(inside, 50);
    EXPECT_EQ(free, 0) << "of " << inside << " cells inside the ball";
  }
}

}  // namespace
}  // namespace hg::pipeline
