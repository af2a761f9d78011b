// Tracking cost per person and frame: a 5 x 4 x 2.5 m cell of 4 cm voxels
// (125 x 100 x 63), four cameras, a table and a rack, people walking circles
// at about 0.9 m/s as UNKNOWN ellipsoid blobs, 300 particles per person.
#include <cmath>
#include <numbers>
#include <vector>

#include <benchmark/benchmark.h>

#include "scene/demo_cell.h"
#include "tracking/tracker.h"

namespace hg::bench {
namespace {

using Eigen::Vector3d;

constexpr int kFramesPerLap = 120;  // 4 s at 30 Hz.

tracking::StaticScene BenchCell() {
  tracking::StaticScene scene;
  const Vector3d target(2.5, 2.0, 0.8);
  for (const Vector3d& eye : {Vector3d(-0.2, -0.2, 2.6), Vector3d(5.2, -0.2, 2.6),
                              Vector3d(5.2, 4.2, 2.6), Vector3d(-0.2, 4.2, 2.6)}) {
    scene.cameras.push_back(scene::LookAtCamera(eye, target, 640, 480, 350));
  }
  scene.meshes.push_back(geometry::TriangleMesh::Box({0.2, 3.0, 0.85}, {1.2, 3.8, 0.9}));
  sim::BoxSolid rack;
  rack.centre_W = {4.6, 3.5, 1.0};
  rack.half_extents_m = {0.3, 0.4, 1.0};
  scene.solids.emplace_back(rack);
  return scene;
}

// Person p walks a circle of 0.6 m radius, one lap per kFramesPerLap frames.
Vector3d PersonCentre(int p, int frame) {
  static const Vector3d kCentres[] = {{1.3, 1.3, 0.9}, {3.7, 1.3, 0.9}, {2.5, 2.9, 0.9}};
  const double a = 2.0 * std::numbers::pi * frame / kFramesPerLap + p;
  return kCentres[p % 3] + 0.6 * Vector3d(std::cos(a), std::sin(a), 0.0);
}

// Args: people (1..3), voxel edge in mm. One iteration = one tracker cycle
// (UNKNOWN update + filters + births/deaths); the blob voxel lists are built
// beforehand. per_person = CPU time per cycle / people.
void BM_TrackerStep(benchmark::State& state) {
  const int people = static_cast<int>(state.range(0));
  tracking::TrackerOptions options;
  options.voxel_m = 0.001 * static_cast<double>(state.range(1));
  options.filter.num_particles = 300;
  tracking::Tracker tracker(options, {Vector3d::Zero(), Vector3d(5, 4, 2.5)}, BenchCell());
  const tracking::VoxelGrid& g = tracker.voxel_map().grid();
  std::vector<std::vector<std::uint32_t>> frames(kFramesPerLap);
  for (int f = 0; f < kFramesPerLap; ++f) {
    for (int p = 0; p < people; ++p) {
      tracking::AppendVoxelsInside(g, {PersonCentre(p, f), Vector3d(0.25, 0.2, 0.85)}, &frames[f]);
    }
  }
  // Warm-up: one lap, so every track is born and converged.
  std::int64_t stamp = 0;
  int frame = 0;
  auto cycle = [&] {
    tracker.voxel_map().SetUnknown(frames[frame % kFramesPerLap]);
    tracker.Step(stamp);
    stamp += 33'333'333;
    ++frame;
  };
  for (int k = 0; k < kFramesPerLap; ++k) cycle();
  for (auto _ : state) cycle();
  state.counters["per_person"] =
      benchmark::Counter(static_cast<double>(state.iterations()) * people,
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["tracks"] = static_cast<double>(tracker.tracks().size());
  state.counters["births"] = static_cast<double>(tracker.stats().births);
}
BENCHMARK(BM_TrackerStep)
    ->Args({1, 40})
    ->Args({3, 40})
    ->Args({1, 50})
    ->Unit(benchmark::kMillisecond);

// One likelihood sum of a standing person's ellipsoid on the same grid;
// argument: 0 auto (z columns here), 1 x rows, 2 z columns.
void BM_EllipsoidCount(benchmark::State& state) {
  const auto axis = static_cast<tracking::SumAxis>(state.range(0));
  const tracking::VoxelGrid g({Vector3d::Zero(), Vector3d(5, 4, 2.5)}, 0.04);
  tracking::VoxelMap map(g,
                         std::vector<tracking::VoxelState>(g.size(), tracking::VoxelState::kFree));
  std::vector<std::uint32_t> blob;
  tracking::AppendVoxelsInside(g, {{2.5, 2.0, 0.9}, {0.25, 0.2, 0.85}}, &blob);
  map.SetUnknown(blob);
  int k = 0;
  for (auto _ : state) {
    const tracking::Ellipsoid e{{2.5 + 0.001 * (k % 50), 2.0, 0.9}, {0.3, 0.25, 0.85}};
    benchmark::DoNotOptimize(tracking::CountVoxels(map, e, {}, axis));
    ++k;
  }
}
BENCHMARK(BM_EllipsoidCount)->Arg(0)->Arg(1)->Arg(2);

}  // namespace
}  // namespace hg::bench
