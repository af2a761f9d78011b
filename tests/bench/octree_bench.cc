// Octree update on the benchmark workload: 8 Full HD cameras around a 4 m cube,
// depth 10 (1024^3 cells), three walking people, table and rack.
#include <cmath>

#include <benchmark/benchmark.h>

#include "bench/bench_scene.h"
#include "geometry/footprint.h"
#include "octree/octree.h"
#include "silhouette/quadtree.h"

namespace hg::bench {
namespace {

constexpr int kFrames = 16;

struct Rig {
  std::vector<silhouette::SilhouetteQuadtree> trees;
  std::vector<const silhouette::SilhouetteQuadtree*> ptrs;
  explicit Rig(const BenchScene& s) {
    for (const auto& c : s.cell.cameras) trees.emplace_back(c.width, c.height);
    for (const auto& t : trees) ptrs.push_back(&t);
  }
  void Build(const BenchScene& s, int frame) {
    for (std::size_t c = 0; c < trees.size(); ++c) trees[c].Build(s.frames[frame][c].View(), 127);
  }
};

// Incremental update, frame after frame (args: cameras, depth, threads).
void BM_OctreeIncremental(benchmark::State& state) {
  const int cams = static_cast<int>(state.range(0));
  const BenchScene& s = GetBenchScene(cams, kFrames);
  octree::Octree tree(
      {s.cell.bounds, static_cast<int>(state.range(1)), static_cast<int>(state.range(2))},
      BenchViews(s));
  Rig rig(s);
  rig.Build(s, 0);
  tree.Update(rig.ptrs);
  int frame = 1;
  double visited = 0;
  for (auto _ : state) {
    state.PauseTiming();
    rig.Build(s, frame);
    frame = (frame + 1) % kFrames;
    if (frame == 0) {  // Wrap around: start the sequence again from a complete tree.
      rig.Build(s, 0);
      tree.Update(rig.ptrs);
      frame = 1;
      rig.Build(s, frame);
    }
    state.ResumeTiming();
    visited += static_cast<double>(tree.Update(rig.ptrs).nodes_visited);
  }
  state.counters["nodes"] = static_cast<double>(tree.NumNodes());
  state.counters["visited_per_frame"] = visited / static_cast<double>(state.iterations());
}
BENCHMARK(BM_OctreeIncremental)
    ->Args({8, 10, 1})
    ->Args({8, 10, 2})
    ->Args({4, 10, 2})
    ->Args({8, 9, 2})
    ->Args({8, 8, 2})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

// From scratch: a fresh tree every frame (args: cameras, depth, threads).
void BM_OctreeFromScratch(benchmark::State& state) {
  const int cams = static_cast<int>(state.range(0));
  const BenchScene& s = GetBenchScene(cams, kFrames);
  octree::Octree tree(
      {s.cell.bounds, static_cast<int>(state.range(1)), static_cast<int>(state.range(2))},
      BenchViews(s));
  Rig rig(s);
  int frame = 0;
  for (auto _ : state) {
    state.PauseTiming();
    rig.Build(s, frame);
    for (auto& t : rig.trees) t.MarkAllChanged();
    tree.Reset();
    frame = (frame + 1) % kFrames;
    state.ResumeTiming();
    tree.Update(rig.ptrs);
  }
  state.counters["nodes"] = static_cast<double>(tree.NumNodes());
  state.counters["leaves"] = static_cast<double>(tree.NumLeaves());
}
BENCHMARK(BM_OctreeFromScratch)
    ->Args({8, 10, 1})
    ->Args({8, 10, 2})
    ->Args({4, 10, 2})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

// The approach the paper compares with: every voxel of a dense R^3 grid
// projected into every camera (centre point, one mask look-up), no hierarchy.
void BM_DenseCarve(benchmark::State& state) {
  const int res = static_cast<int>(state.range(0));
  const BenchScene& s = GetBenchScene(8, kFrames);
  std::vector<geometry::BoxProjector> proj;
  for (const auto& c : s.cell.cameras) proj.emplace_back(c.ProjectionMatrix());
  std::vector<std::uint8_t> occupied(static_cast<std::size_t>(res) * res * res);
  const Eigen::Vector3d lo = s.cell.bounds.min;
  const Eigen::Vector3d step = s.cell.bounds.Size() / res;
  int frame = 0;
  for (auto _ : state) {
    const auto& masks = s.frames[frame];
    frame = (frame + 1) % kFrames;
    std::int64_t count = 0;
    for (int z = 0; z < res; ++z) {
      for (int y = 0; y < res; ++y) {
        for (int x = 0; x < res; ++x) {
          const Eigen::Vector4d p(lo.x() + (x + 0.5) * step.x(), lo.y() + (y + 0.5) * step.y(),
                                  lo.z() + (z + 0.5) * step.z(), 1.0);
          bool occ = true;
          for (std::size_t c = 0; c < proj.size() && occ; ++c) {
            const Eigen::Vector3d q = proj[c].P * p;
            if (q.z() <= 0) continue;
            const int u = static_cast<int>(std::floor(q.x() / q.z() + 0.5));
            const int v = static_cast<int>(std::floor(q.y() / q.z() + 0.5));
            if (u < 0 || v < 0 || u >= masks[c].width || v >= masks[c].height) continue;
            occ = masks[c].At(u, v) > 127;
          }
          occupied[(static_cast<std::size_t>(z) * res + y) * res + x] = occ;
          count += occ;
        }
      }
    }
    benchmark::DoNotOptimize(count);
  }
}
BENCHMARK(BM_DenseCarve)->Arg(128)->Arg(256)->Unit(benchmark::kMillisecond)->Iterations(3);

}  // namespace
}  // namespace hg::bench
