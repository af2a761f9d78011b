// Simulator rendering: ground-truth masks of the demo cell (8 Full HD cameras,
// three walking people of 13 capsules each, the table and the rack as
// occluding obstacles) and one colour frame.
#include <benchmark/benchmark.h>

#include <cmath>
#include <string>
#include <vector>

#include "scene/demo_cell.h"
#include "sim/colour_renderer.h"
#include "sim/mask_renderer.h"
#include "sim/scene.h"
#include "support/sim_bodies.h"

namespace hg::bench {
namespace {

using testing::WalkingBody;

using Eigen::Vector3d;

constexpr int kFrames = 30;

/// Three people walking loops of their own at about 1.2 m/s, at time t_s.
std::vector<sim::BodyState> People(double t_s) {
  std::vector<sim::BodyState> people;
  for (int p = 0; p < 3; ++p) {
    const double rx = 1.1 - 0.2 * p;
    const double ry = 0.8 + 0.15 * p;
    const double cx = 2.0 + 0.2 * p;
    const double cy = 2.1 - 0.1 * p;
    const double perimeter = 2 * M_PI * std::sqrt(0.5 * (rx * rx + ry * ry));
    const double dir = p % 2 == 0 ? 1.0 : -1.0;
    const double angle = 2 * M_PI * 1.2 * t_s / perimeter * dir + 2.1 * p;
    const Vector3d base(cx + rx * std::cos(angle), cy + ry * std::sin(angle), 0.0);
    const double heading = std::atan2(dir * ry * std::cos(angle), -dir * rx * std::sin(angle));
    people.push_back(WalkingBody(base, heading, 2 * M_PI * 0.9 * t_s + p));
  }
  return people;
}

/// The demo cell's table (top and legs) and rack as boxes.
std::vector<sim::Solid> DemoObstacles() {
  auto box = [](const char* name, const Vector3d& lo, const Vector3d& hi, const sim::Rgb& colour) {
    sim::BoxSolid b;
    b.centre_W = 0.5 * (lo + hi);
    b.half_extents_m = 0.5 * (hi - lo);
    return sim::Solid{name, b, colour};
  };
  const sim::Rgb wood(0.55F, 0.4F, 0.25F);
  std::vector<sim::Solid> obstacles = {box("table_top", {2.6, 0.6, 0.72}, {3.6, 1.4, 0.78}, wood)};
  for (const double x : {2.65, 3.5}) {
    for (const double y : {0.65, 1.3}) {
      obstacles.push_back(box("table_leg", {x, y, 0.0}, {x + 0.05, y + 0.05, 0.72}, wood));
    }
  }
  obstacles.push_back(box("rack", {0.2, 3.3, 0.0}, {1.4, 3.8, 1.9}, sim::Rgb(0.3F, 0.35F, 0.4F)));
  return obstacles;
}

const std::vector<std::vector<sim::BodyState>>& Frames() {
  static const std::vector<std::vector<sim::BodyState>> frames = [] {
    std::vector<std::vector<sim::BodyState>> f;
    for (int i = 0; i < kFrames; ++i) f.push_back(People(i / 30.0));
    return f;
  }();
  return frames;
}

// One iteration renders the masks of all 8 cameras for one frame set, one
// camera after the other on this thread. Frame sets per second per core:
// divide by the number of cores the simulator may use for the cell.
void BM_SimMasks(benchmark::State& state) {
  scene::DemoCellOptions options;
  options.obstacles = false;
  const scene::DemoCell cell = scene::MakeDemoCell(options);
  const std::vector<sim::Solid> obstacles = DemoObstacles();
  std::vector<sim::MaskRenderer> renderers;
  for (const geometry::CameraModel& camera : cell.cameras) {
    renderers.emplace_back(camera, obstacles, std::vector<sim::Solid>{}, true);
  }
  std::vector<common::ImageU8> masks(renderers.size());
  const auto& frames = Frames();
  int frame = 0;
  for (auto _ : state) {
    const std::vector<sim::BodyState>& people = frames[frame++ % kFrames];
    for (std::size_t c = 0; c < renderers.size(); ++c) {
      renderers[c].Render(people, &masks[c]);
    }
    benchmark::ClobberMemory();
  }
  state.counters["frame_sets_per_s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["cameras"] = static_cast<double>(renderers.size());
}
BENCHMARK(BM_SimMasks)->Unit(benchmark::kMillisecond)->UseRealTime();

// Construction of one Full HD mask renderer with the obstacles' occlusion map.
void BM_SimMaskRendererSetup(benchmark::State& state) {
  scene::DemoCellOptions options;
  options.num_cameras = 1;
  options.obstacles = false;
  const scene::DemoCell cell = scene::MakeDemoCell(options);
  geometry::CameraModel camera = cell.cameras[0];
  if (state.range(0) != 0) camera.distortion = {-0.12, 0.03, 0.0005, -0.0005, 0.0};
  const std::vector<sim::Solid> obstacles = DemoObstacles();
  for (auto _ : state) {
    sim::MaskRenderer renderer(camera, obstacles, {}, true);
    benchmark::DoNotOptimize(&renderer);
  }
}
BENCHMARK(BM_SimMaskRendererSetup)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->Iterations(2);

// One Full HD colour frame of the demo cell with three people, shadows and noise.
void BM_SimColour(benchmark::State& state) {
  scene::DemoCellOptions options;
  options.num_cameras = 1;
  options.obstacles = false;
  const scene::DemoCell cell = scene::MakeDemoCell(options);
  sim::Scene scene;
  scene.name = "bench";
  scene.bounds = cell.bounds;
  scene.cameras.push_back({cell.cameras[0], 0.0});
  scene.obstacles = DemoObstacles();
  for (int p = 0; p < 3; ++p) {
    sim::Person person;
    person.name = std::to_string(p);
    person.shirt = sim::Rgb(0.2F + 0.3F * p, 0.3F, 0.7F - 0.2F * p);
    scene.people.push_back(person);
  }
  scene.imaging.light_change_amplitude = 0.1;
  const sim::ColourRenderer renderer(scene, 0);
  common::ImageRgb8 image;
  const auto& frames = Frames();
  std::uint64_t frame = 0;
  for (auto _ : state) {
    renderer.Render(frames[frame % kFrames], frame / 30.0, frame, &image);
    ++frame;
    benchmark::ClobberMemory();
  }
}
BENCHMARK(BM_SimColour)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace hg::bench
