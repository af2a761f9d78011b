// The pipeline on live simulated cameras: snapshots keep every point of the
// (standing) people occupied, a lost camera turns the status degraded and
// only grows occupancy, and the camera recovers. Plus the latest-value slot.
#include "pipeline/pipeline.h"

#include <chrono>
#include <random>
#include <thread>

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include "scene/demo_cell.h"

#include "capture/sim_source.h"
#include "common/latest_value.h"

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

struct Rig {
  std::shared_ptr<sim::Scene> scene = StandingScene();
  std::vector<capture::SimSource*> sources;
  std::unique_ptr<Pipeline> pipeline;

  Rig() {
    PipelineOptions options;
    options.bounds = scene->bounds;
    options.depth = 7;
    options.publish_depth = 6;
    options.rate_hz = 30;
    options.deadline_ms = 30;
    std::vector<PipelineCamera> cameras;
    const auto start = std::chrono::steady_clock::now();
    for (int c = 0; c < static_cast<int>(scene->cameras.size()); ++c) {
      auto source = std::make_unique<capture::SimSource>(scene, c, 30.0, start);
      sources.push_back(source.get());
      cameras.push_back({scene->cameras[c].model, std::move(source), 150});
    }
    pipeline = std::make_unique<Pipeline>(options, std::move(cameras),
                                          std::vector<geometry::TriangleMesh>{}, nullptr);
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

  // Points inside the people that fall in a cell listed neither occupied nor occluded.
  int PointsReportedFree(const OccupancySnapshot& s) const {
    const int n = 1 << s.depth;
    std::vector<std::uint8_t> listed(static_cast<std::size_t>(n) * n * n, 0);
    for (const auto* cells : {&s.occupied, &s.occluded}) {
      for (const GridCell& c : *cells)
        listed[c.x + n * (c.y + static_cast<std::size_t>(n) * c.z)] = 1;
    }
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    int free = 0;
    for (const sim::Person& person : scene->people) {
      const sim::BodyState body = sim::EvaluatePerson(person, 0.0);
      for (const sim::BodyCapsule& cap : body.parts) {
        for (int i = 0; i < 200; ++i) {
          // A point of the capsule's segment pushed out by up to the radius.
          const Eigen::Vector3d dir =
              Eigen::Vector3d(u01(rng) - 0.5, u01(rng) - 0.5, u01(rng) - 0.5);
          const Eigen::Vector3d p =
              cap.a_W + u01(rng) * (cap.b_W - cap.a_W) +
              (dir.norm() > 0 ? dir.normalized() : dir) * cap.radius_m * u01(rng);
          const Eigen::Vector3d rel = (p - s.bounds.min).cwiseQuotient(s.bounds.Size()) * n;
          const int x = static_cast<int>(rel.x()), y = static_cast<int>(rel.y()),
                    z = static_cast<int>(rel.z());
          if (x < 0 || y < 0 || z < 0 || x >= n || y >= n || z >= n) continue;
          free += listed[x + n * (y + static_cast<std::size_t>(n) * z)] == 0;
        }
      }
    }
    return free;
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
  for (const CameraHealth& h : healthy->health.cameras) EXPECT_EQ(h.state, CameraState::kOk);
  const std::size_t occupied_before = healthy->occupied.size();

  rig.sources[2]->SetPaused(true);  // The camera's cable is pulled.
  auto degraded = rig.WaitFor([](const OccupancySnapshot& s) {
    return s.health.degraded && s.health.cameras[2].state == CameraState::kStale;
  });
  ASSERT_NE(degraded, nullptr) << "status did not turn degraded";
  EXPECT_EQ(rig.PointsReportedFree(*degraded), 0);
  EXPECT_GE(degraded->occupied.size() + degraded->occluded.size(), occupied_before);
  EXPECT_GT(degraded->occupied.size(), occupied_before) << "two cameras carve less than three";

  rig.sources[2]->SetPaused(false);
  auto recovered = rig.WaitFor([&](const OccupancySnapshot& s) {
    return s.sequence > degraded->sequence + 3 && !s.health.degraded;
  });
  ASSERT_NE(recovered, nullptr) << "camera did not recover";
  EXPECT_EQ(rig.PointsReportedFree(*recovered), 0);
  rig.pipeline->Stop();
}

}  // namespace
}  // namespace hg::pipeline
