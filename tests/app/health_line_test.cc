#include "app/health_line.h"

#include <string>

#include <gtest/gtest.h>

#include "capture/camera_health.h"

namespace hg::app {
namespace {

/// A complete cycle of a 4 m cube published at 2^5 cells per axis (12.5 cm
/// cells: 1/512 m^3 each), two cameras well.
pipeline::OccupancySnapshot Snapshot() {
  pipeline::OccupancySnapshot s;
  s.sequence = 42;
  s.bounds = {Eigen::Vector3d::Zero(), Eigen::Vector3d(4, 4, 4)};
  s.depth = 5;
  s.occupied = {{1, 2, 3, 256}};  // 0.5 m^3.
  s.occluded = {{1, 2, 4, 128}};  // 0.25 m^3.
  s.health.octree_ms = 12.34;
  s.health.cycle_ms = 20.0;
  s.health.skew_ms = 1.5;
  s.health.deadline_misses = 3;
  s.health.missed_cycles = 1;
  for (const char* name : {"cam0", "cam1"}) {
    pipeline::CameraHealth c;
    c.name = name;
    c.state = pipeline::CameraState::kOk;
    c.fps = 30.0;
    s.health.cameras.push_back(c);
  }
  return s;
}

// The words docs/operations.md describes, in its order: what a reader of the
// journal or of `systemctl status` goes by.
TEST(HealthLineTest, AWellCycle) {
  EXPECT_EQ(HealthLine(Snapshot(), std::nullopt, false),
            "cycle 42 ok occupied 0.500 m^3 occluded 0.250 m^3 octree 12.3 ms cycle 20.0 ms skew "
            "1.5 ms deadline misses 3 missed cycles 1 | cam0 ok 30 fps cam1 ok 30 fps");
}

TEST(HealthLineTest, DegradedAbortedAndCameraFaults) {
  pipeline::OccupancySnapshot s = Snapshot();
  s.health.degraded = true;
  s.complete = false;
  s.aborted = true;
  s.refined_cell_m = 0.0625;
  s.health.cameras[0].state = pipeline::CameraState::kFailed;
  s.health.cameras[0].fps = 0.0;
  s.health.cameras[0].fault = static_cast<std::uint8_t>(capture::CameraFault::kBlocked);
  s.health.cameras[1].margin_m = 0.034;
  s.health.cameras[1].corrupt = 2;
  const std::string line = HealthLine(s, std::nullopt, false);
  EXPECT_EQ(line,
            "cycle 42 DEGRADED (aborted, refined to 6.2 cm) occupied 0.500 m^3 occluded 0.250 m^3 "
            "octree 12.3 ms cycle 20.0 ms skew 1.5 ms deadline misses 3 missed cycles 1 | cam0 "
            "failed 0 fps (blocked) cam1 ok 30 fps margin 3.4 cm corrupt 2");
  // A view found shifted: its frames wait, so it goes stale, and the line says why.
  s.health.cameras[1].state = pipeline::CameraState::kStale;
  s.health.cameras[1].margin_m = 0.0;
  s.health.cameras[1].corrupt = 0;
  s.health.cameras[1].misalignment_px = 3.62;
  s.health.cameras[1].shifted = true;
  EXPECT_NE(HealthLine(s, std::nullopt, false).find("cam1 stale 30 fps shifted 3.6 px"),
            std::string::npos)
      << HealthLine(s, std::nullopt, false);
  // Not matched to the view its kept background was taught in (yet).
  s.health.cameras[1].misalignment_px = -1.0;
  EXPECT_NE(HealthLine(s, std::nullopt, false).find("cam1 stale 30 fps view not matched"),
            std::string::npos)
      << HealthLine(s, std::nullopt, false);
}

// Another publisher of the same topics (a second daemon with a copied
// config) makes the line say DEGRADED and why, as the status samples do,
// even while the pipeline itself is well.
TEST(HealthLineTest, AnotherPublisherIsDegradedAndNamed) {
  const std::string line = HealthLine(Snapshot(), std::nullopt, true);
  EXPECT_EQ(line,
            "cycle 42 DEGRADED occupied 0.500 m^3 occluded 0.250 m^3 octree 12.3 ms cycle 20.0 ms "
            "skew 1.5 ms deadline misses 3 missed cycles 1 another publisher on the topics | cam0 "
            "ok 30 fps cam1 ok 30 fps");
}

// DDS writes refused in the last second (Cyclone DDS out of resources, a
// writer's history full): what the controllers should have had did not go
// out, so the line says DEGRADED and how many, though the pipeline is well.
TEST(HealthLineTest, RefusedDdsWritesAreDegradedAndCounted) {
  EXPECT_EQ(HealthLine(Snapshot(), std::nullopt, false, 0).find("DEGRADED"), std::string::npos);
  const std::string line = HealthLine(Snapshot(), std::nullopt, false, 61);
  EXPECT_EQ(line,
            "cycle 42 DEGRADED occupied 0.500 m^3 occluded 0.250 m^3 octree 12.3 ms cycle 20.0 ms "
            "skew 1.5 ms deadline misses 3 missed cycles 1 DDS writes failed 61 | cam0 "
            "ok 30 fps cam1 ok 30 fps");
}

TEST(HealthLineTest, TrackerFigures) {
  TrackingStats t;
  t.tracks = 2;
  t.last_ms = 4.25;
  t.skipped = 5;
  t.untracked = 7;
  t.cycles = 93;
  const std::string line = HealthLine(Snapshot(), t, false);
  EXPECT_NE(line.find("missed cycles 1 tracks 2 tracking 4.2 ms skipped 5 untracked 7 of 100 |"),
            std::string::npos)
      << line;
}

// A camera mostly foreground is told once it has been so for the set time,
// once per run; a new run (the share dropped, then rose again) is told again.
TEST(ForegroundWatchTest, TellsOncePerRun) {
  using Clock = ForegroundWatch::Clock;
  using std::chrono::seconds;
  const Clock::time_point t0{};
  ForegroundWatch watch(2, seconds(60));
  EXPECT_FALSE(watch.Due(0, std::nullopt, t0));
  EXPECT_FALSE(watch.Due(0, t0, t0 + seconds(59)));
  EXPECT_TRUE(watch.Due(0, t0, t0 + seconds(60)));
  EXPECT_FALSE(watch.Due(0, t0, t0 + seconds(61))) << "once per run";
  EXPECT_FALSE(watch.Due(1, t0 + seconds(30), t0 + seconds(61))) << "cameras apart";
  EXPECT_FALSE(watch.Due(0, std::nullopt, t0 + seconds(62)));
  EXPECT_FALSE(watch.Due(0, t0 + seconds(63), t0 + seconds(100)));
  EXPECT_TRUE(watch.Due(0, t0 + seconds(63), t0 + seconds(123)));
  // A run that restarts between two looks is a new one.
  EXPECT_TRUE(watch.Due(1, t0 + seconds(30), t0 + seconds(90)));
  EXPECT_TRUE(watch.Due(1, t0 + seconds(40), t0 + seconds(100)));
}

TEST(ForegroundWatchTest, Warning) {
  EXPECT_EQ(ForegroundWarning("cam3", 60.4),
            "cam3: a third of the view or more has been foreground for 60 s. If nobody stands "
            "that close to the camera, the light has changed in part of the view (a bank of "
            "lamps, daylight) while the rest kept it: the changed part stays foreground, "
            "occupied, until the background is learned again with the cell empty (hullguardd "
            "--config FILE --learn-background, then restart)");
}

}  // namespace
}  // namespace hg::app
