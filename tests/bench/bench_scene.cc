#include "bench/bench_scene.h"

#include <map>
#include <thread>

#include "scene/exact_mask.h"

namespace hg::bench {

const BenchScene& GetBenchScene(int num_cameras, int num_frames) {
  static std::map<std::pair<int, int>, std::unique_ptr<BenchScene>> cache;
  auto& slot = cache[{num_cameras, num_frames}];
  if (slot) return *slot;
  slot = std::make_unique<BenchScene>();
  scene::DemoCellOptions opt;
  opt.num_cameras = num_cameras;
  opt.num_people = 3;
  slot->cell = scene::MakeDemoCell(opt);
  slot->frames.resize(num_frames);
  for (int f = 0; f < num_frames; ++f) {
    const auto people = scene::DemoPeople(3, 2.0 + f / 30.0);
    auto& masks = slot->frames[f];
    masks.resize(num_cameras);
    std::vector<std::thread> workers;
    for (int c = 0; c < num_cameras; ++c) {
      workers.emplace_back(
          [&, c] { masks[c] = scene::RenderExactMask(slot->cell.cameras[c], people); });
    }
    for (auto& w : workers) w.join();
  }
  return *slot;
}

std::vector<octree::CameraView> BenchViews(const BenchScene& scene) {
  std::vector<octree::CameraView> views;
  for (const auto& cam : scene.cell.cameras) views.emplace_back(cam, scene.cell.obstacles);
  return views;
}

}  // namespace hg::bench
