// Octree update on the benchmark workload: 8 Full HD cameras around a 4 m cube,
// depth 10 (1024^3 cells), three walking people, table and rack.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <thread>
#include <vector>

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

// Median, 99th percentile and maximum of per-frame update times, as counters.
void ReportFrameTimes(benchmark::State& state, std::vector<double> ms) {
  std::sort(ms.begin(), ms.end());
  auto at = [&](double q) {
    return ms[std::min(ms.size() - 1, static_cast<std::size_t>(q * (ms.size() - 1) + 0.5))];
  };
  state.counters["median_ms"] = at(0.5);
  state.counters["p99_ms"] = at(0.99);
  state.counters["max_ms"] = ms.back();
}

// Args: cameras, depth, threads, settle level (0: the full tree; otherwise
// octree::OctreeConfig::settle_level, as the daemon runs it at its published
// grid's level).
octree::OctreeConfig BenchConfig(const BenchScene& s, const benchmark::State& state) {
  octree::OctreeConfig config{s.cell.bounds, static_cast<int>(state.range(1)),
                              static_cast<int>(state.range(2))};
  config.settle_level = static_cast<int>(state.range(3));
  return config;
}

// The standard set: depth, cameras and threads varied around 8 cameras,
// depth 10, 2 threads, and that with the daemon's settle level.
void OctreeArgs(benchmark::internal::Benchmark* b) {
  b->ArgNames({"cams", "depth", "threads", "settle"});
  for (const auto& a : std::vector<std::vector<std::int64_t>>{{8, 10, 1, 0},
                                                              {8, 10, 2, 0},
                                                              {4, 10, 2, 0},
                                                              {8, 9, 2, 0},
                                                              {8, 8, 2, 0},
                                                              {8, 7, 2, 0},
                                                              {8, 10, 2, 7}}) {
    b->Args(a);
  }
  // On a machine with more cores: the full depth-10 tree on 4, 8, ... of them
  // (the 512 roots are shared out through an atomic counter).
  const unsigned cores = std::thread::hardware_concurrency();
  for (std::int64_t threads = 4; threads <= static_cast<std::int64_t>(cores); threads *= 2) {
    b->Args({8, 10, threads, 0});
  }
}

// Incremental update, frame after frame (args: BenchConfig). Each
// iteration is one frame: the quadtrees are rebuilt from the next masks
// (untimed), then the octree is updated.
void BM_OctreeIncremental(benchmark::State& state) {
  const int cams = static_cast<int>(state.range(0));
  const BenchScene& s = GetBenchScene(cams, kFrames);
  octree::Octree tree(BenchConfig(s, state), BenchViews(s));
  Rig rig(s);
  rig.Build(s, 0);
  tree.Update(rig.ptrs);
  int frame = 1;
  double visited = 0;
  std::vector<double> ms;
  for (auto _ : state) {
    state.PauseTiming();
    if (frame == kFrames) {  // Wrap around: start again from a complete tree of frame 0.
      rig.Build(s, 0);
      tree.Update(rig.ptrs);
      frame = 1;
    }
    rig.Build(s, frame++);
    state.ResumeTiming();
    const octree::UpdateStats stats = tree.Update(rig.ptrs);
    ms.push_back(stats.update_ms);
    visited += static_cast<double>(stats.nodes_visited);
  }
  state.counters["nodes"] = static_cast<double>(tree.NumNodes());
  state.counters["visited_per_frame"] = visited / static_cast<double>(state.iterations());
  ReportFrameTimes(state, ms);
}
BENCHMARK(BM_OctreeIncremental)
    ->Apply(OctreeArgs)
    ->Iterations(kFrames - 1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

// From scratch: an empty tree and every pixel changed, every frame.
void BM_OctreeFromScratch(benchmark::State& state) {
  const int cams = static_cast<int>(state.range(0));
  const BenchScene& s = GetBenchScene(cams, kFrames);
  octree::Octree tree(BenchConfig(s, state), BenchViews(s));
  Rig rig(s);
  int frame = 0;
  std::vector<double> ms;
  for (auto _ : state) {
    state.PauseTiming();
    rig.Build(s, frame);
    for (auto& t : rig.trees) t.MarkAllChanged();
    tree.Reset();
    frame = (frame + 1) % kFrames;
    state.ResumeTiming();
    ms.push_back(tree.Update(rig.ptrs).update_ms);
  }
  state.counters["nodes"] = static_cast<double>(tree.NumNodes());
  state.counters["leaves"] = static_cast<double>(tree.NumLeaves());
  ReportFrameTimes(state, ms);
}
BENCHMARK(BM_OctreeFromScratch)
    ->Apply(OctreeArgs)
    ->Iterations(8)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

// The approach the paper compares with: every voxel of a dense R^3 grid
// projected into every camera (centre point, one mask look-up), no hierarchy.
void BM_DenseCarve(benchmark::State& state) {
  const int res = static_cast<int>(state.range(0));
  const BenchScene& s = GetBenchScene(8, kFrames);
  std::vector<geometry::BoxProjector> proj;
  for (const auto& c : s.cell.cameras) proj.emplace_back(c.K, c.R_CW, c.t_CW);
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
