// Quadtree build from a Full HD mask, changed flags included, against the cost
// of merely reading the mask.
#include <benchmark/benchmark.h>

#include <algorithm>

#include "bench/bench_scene.h"
#include "silhouette/quadtree.h"
#include "silhouette/tile_dilation.h"
#include "silhouette/undistort.h"

namespace hg::bench {
namespace {

void BM_ReadMask(benchmark::State& state) {
  const BenchScene& s = GetBenchScene(1, 2);
  const common::ImageU8& m = s.frames[0][0];
  for (auto _ : state) {
    std::uint64_t count = 0;
    for (const std::uint8_t px : m.pixels) count += px > 127;
    benchmark::DoNotOptimize(count);
  }
  state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(m.pixels.size()));
}
BENCHMARK(BM_ReadMask)->Unit(benchmark::kMillisecond);

void BM_QuadtreeBuild1080p(benchmark::State& state) {
  const BenchScene& s = GetBenchScene(1, 2);
  silhouette::SilhouetteQuadtree tree(1920, 1080);
  int i = 0;
  for (auto _ : state) {
    // Alternate two consecutive frames so that changed flags are real work.
    tree.Build(s.frames[i++ & 1][0].View(), 127);
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(state.iterations() * 1920 * 1080);
}
BENCHMARK(BM_QuadtreeBuild1080p)->Unit(benchmark::kMillisecond);

// The background model's 2-pixel dilation of a Full HD foreground mask (the
// colour path of the pipeline), copy of the mask included.
void BM_DilateSquare1080p(benchmark::State& state) {
  const BenchScene& s = GetBenchScene(1, 2);
  common::ImageU8 mask = s.frames[0][0];
  silhouette::DilateScratch scratch;
  for (auto _ : state) {
    std::copy(s.frames[0][0].pixels.begin(), s.frames[0][0].pixels.end(), mask.pixels.begin());
    silhouette::DilateSquare(&mask, 2, &scratch);
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(state.iterations() * 1920 * 1080);
}
BENCHMARK(BM_DilateSquare1080p)->Unit(benchmark::kMillisecond);

// The same with the map of tiles holding foreground that the background model
// hands over: only the surroundings of the people are read and written.
void BM_DilateSquare1080pForegroundTiles(benchmark::State& state) {
  const BenchScene& s = GetBenchScene(1, 2);
  const common::ImageU8& source = s.frames[0][0];
  common::ImageU8 mask = source;
  const int tx_n = (source.width + 7) / 8;
  std::vector<std::uint8_t> tiles(static_cast<std::size_t>(tx_n) * ((source.height + 7) / 8), 0);
  for (int v = 0; v < source.height; ++v) {
    for (int u = 0; u < source.width; ++u) {
      if (source.At(u, v) != 0) tiles[static_cast<std::size_t>(v / 8) * tx_n + u / 8] = 1;
    }
  }
  silhouette::DilateScratch scratch;
  for (auto _ : state) {
    std::copy(source.pixels.begin(), source.pixels.end(), mask.pixels.begin());
    silhouette::DilateSquare(&mask, 2, &scratch, tiles.data());
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(state.iterations() * 1920 * 1080);
}
BENCHMARK(BM_DilateSquare1080pForegroundTiles)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace hg::bench

namespace hg::bench {
namespace {

// Conservative undistortion of a Full HD mask through a typical wide-angle lens.
void BM_UndistortApply1080p(benchmark::State& state) {
  const BenchScene& s = GetBenchScene(1, 2);
  geometry::CameraModel cam = s.cell.cameras[0];
  cam.distortion = {-0.12, 0.03, 0.0005, -0.0005, 0.0};
  silhouette::ConservativeUndistorter undistort(cam);
  common::ImageU8 out(cam.width, cam.height);
  for (auto _ : state) {
    undistort.Apply(s.frames[0][0].View(), 127, &out);
    benchmark::ClobberMemory();
  }
}
BENCHMARK(BM_UndistortApply1080p)->Unit(benchmark::kMillisecond);

// The same map pixel by pixel (the reference Apply() reproduces).
void BM_UndistortPerPixel1080p(benchmark::State& state) {
  const BenchScene& s = GetBenchScene(1, 2);
  geometry::CameraModel cam = s.cell.cameras[0];
  cam.distortion = {-0.12, 0.03, 0.0005, -0.0005, 0.0};
  const silhouette::ConservativeUndistorter undistort(cam);
  common::ImageU8 out(cam.width, cam.height);
  for (auto _ : state) {
    undistort.ApplyPerPixel(s.frames[0][0].View(), 127, &out);
    benchmark::ClobberMemory();
  }
}
BENCHMARK(BM_UndistortPerPixel1080p)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace hg::bench
