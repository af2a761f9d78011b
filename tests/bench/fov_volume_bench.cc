// The exact field-of-view volume on the paper cell (config/paper_cell.yaml:
// a 4 x 4 x 3 m cell, the obstacles of config/paper_cell/obstacles.obj, eight
// Full HD cameras): one evaluation per iteration, cycling over the cameras.

#include <array>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "placement/fov_volume.h"

namespace hg::placement {
namespace {

struct PaperCell {
  FovScene scene;
  std::vector<CameraPose> poses;
  std::vector<Intrinsics> intrinsics;
};

Intrinsics FullHd(double f) {
  Intrinsics in;
  in.width = 1920;
  in.height = 1080;
  in.K << f, 0, 959.5, 0, f, 539.5, 0, 0, 1;
  return in;
}

const PaperCell& Cell() {
  static const PaperCell cell = [] {
    common::Box3 bounds;
    bounds.min = Eigen::Vector3d(0, 0, 0);
    bounds.max = Eigen::Vector3d(4, 4, 3);
    PaperCell c{FovScene(bounds, geometry::LoadMesh(std::string(HG_SOURCE_DIR) +
                                                    "/config/paper_cell/obstacles.obj")),
                {},
                {}};
    const Eigen::Vector3d target(2, 2, 1);
    const std::array<Eigen::Vector3d, 8> positions = {
        Eigen::Vector3d(-0.3, -0.3, 3.6), Eigen::Vector3d(4.3, 4.3, 3.6),
        Eigen::Vector3d(4.3, -0.3, 3.6),  Eigen::Vector3d(-0.3, 4.3, 3.6),
        Eigen::Vector3d(2, -0.4, 2.6),    Eigen::Vector3d(2, 4.4, 2.6),
        Eigen::Vector3d(-0.4, 2, 2.6),    Eigen::Vector3d(4.4, 2, 2.6)};
    for (int i = 0; i < 8; ++i) {
      c.poses.push_back(CameraPose::LookAt(positions[i], target));
      c.intrinsics.push_back(FullHd(i < 4 ? 1083.5787063372297 : 980.1749836231245));
    }
    return c;
  }();
  return cell;
}

void BM_FovVolumePaperCell(benchmark::State& state) {
  const PaperCell& cell = Cell();
  FovEvaluator evaluator;
  size_t i = 0;
  for (auto _ : state) {
    const size_t k = i++ % cell.poses.size();
    benchmark::DoNotOptimize(evaluator.Volume(cell.scene, cell.poses[k], cell.intrinsics[k]));
  }
  state.counters["faces"] = evaluator.stats().obstacle_faces;
}
BENCHMARK(BM_FovVolumePaperCell)->Unit(benchmark::kMicrosecond);

void BM_FovVolumeGradientPaperCell(benchmark::State& state) {
  const PaperCell& cell = Cell();
  FovEvaluator evaluator;
  size_t i = 0;
  for (auto _ : state) {
    const size_t k = i++ % cell.poses.size();
    benchmark::DoNotOptimize(
        evaluator.VolumeAndGradient(cell.scene, cell.poses[k], cell.intrinsics[k]));
  }
}
BENCHMARK(BM_FovVolumeGradientPaperCell)->Unit(benchmark::kMicrosecond);

// With a person (five capsules, 16 facets around) standing in the middle.
void BM_ObjectFreeVolumePaperCell(benchmark::State& state) {
  const PaperCell& cell = Cell();
  const std::vector<Capsule> person = {{{1.9, 2.0, 0.1}, {1.95, 2.0, 0.85}, 0.08},
                                       {{2.1, 2.0, 0.1}, {2.05, 2.0, 0.85}, 0.08},
                                       {{2.0, 2.0, 0.9}, {2.0, 2.0, 1.45}, 0.17},
                                       {{2.2, 2.0, 1.4}, {2.5, 2.2, 1.2}, 0.05},
                                       {{2.0, 2.0, 1.62}, {2.0, 2.0, 1.62}, 0.11}};
  const OccluderMesh object = CapsulesOccluder(person, 16);
  FovEvaluator evaluator;
  size_t i = 0;
  for (auto _ : state) {
    const size_t k = i++ % cell.poses.size();
    benchmark::DoNotOptimize(
        evaluator.Volume(cell.scene, cell.poses[k], cell.intrinsics[k], &object));
  }
}
BENCHMARK(BM_ObjectFreeVolumePaperCell)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace hg::placement
