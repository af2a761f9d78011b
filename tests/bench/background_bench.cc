// Background model: one Full HD frame of the demo cell's first camera (three
// walking people, their shadows, sensor noise, a global light change) into a
// foreground mask, on one core. The daemon's budget is 3 ms per RGB frame
// (8 cameras at 30 Hz on two cores, next to the rest of the pipeline).
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "capture/camera_health.h"
#include "capture/view_registration.h"
#include "common/image.h"
#include "scene/demo_cell.h"
#include "silhouette/background_model.h"
#include "silhouette/hole_fill.h"
#include "silhouette/tile_dilation.h"
#include "sim/colour_renderer.h"
#include "sim/scene.h"
#include "support/luma_image.h"
#include "support/sim_bodies.h"

namespace hg::bench {
namespace {

using Eigen::Vector3d;

constexpr int kFrames = 8;

struct Workload {
  std::vector<common::ImageRgb8> empty;   ///< Learning frames.
  std::vector<common::ImageRgb8> frames;  ///< Frames with people, after learning.
};

sim::Scene BenchCell() {
  scene::DemoCellOptions options;
  options.num_cameras = 1;
  options.obstacles = false;
  const scene::DemoCell cell = scene::MakeDemoCell(options);
  sim::Scene scene;
  scene.name = "background_bench";
  scene.bounds = cell.bounds;
  scene.cameras.push_back({cell.cameras[0], 0.0});
  for (int p = 0; p < 3; ++p) {
    sim::Person person;
    person.name = std::to_string(p);
    person.shirt = sim::Rgb(0.2F + 0.3F * p, 0.3F, 0.7F - 0.2F * p);
    scene.people.push_back(person);
  }
  scene.imaging.light_change_amplitude = 0.1;
  scene.imaging.light_change_period_s = 20.0;
  return scene;
}

/// Rendered once per run and shared by the benchmarks.
const Workload& GetWorkload() {
  static const Workload workload = [] {
    const sim::Scene scene = BenchCell();
    const sim::ColourRenderer renderer(scene, 0);
    const silhouette::BackgroundModelOptions defaults;
    Workload w;
    w.empty.resize(defaults.learn_frames);
    for (int i = 0; i < defaults.learn_frames; ++i) {
      renderer.Render({}, i / 30.0, static_cast<std::uint64_t>(i), &w.empty[i]);
    }
    w.frames.resize(kFrames);
    for (int i = 0; i < kFrames; ++i) {
      const double t = 2.0 + i / 30.0;
      std::vector<sim::BodyState> people;
      for (int p = 0; p < 3; ++p) {
        const double angle = 0.6 * t + 2.1 * p;
        const Vector3d base(2.0 + 1.0 * std::cos(angle), 2.0 + 0.9 * std::sin(angle), 0.0);
        people.push_back(testing::WalkingBody(base, angle + M_PI / 2, 5.6 * t + p));
      }
      renderer.Render(people, t, static_cast<std::uint64_t>(1000 + i), &w.frames[i]);
    }
    return w;
  }();
  return workload;
}

/// The workload as Mono8 frames, converted once per run.
struct GreyWorkload {
  std::vector<common::ImageU8> empty;
  std::vector<common::ImageU8> frames;
};
const GreyWorkload& GetGreyWorkload() {
  static const GreyWorkload grey = [] {
    const Workload& w = GetWorkload();
    GreyWorkload g;
    for (const auto& f : w.empty) g.empty.push_back(testing::LumaOf(f));
    for (const auto& f : w.frames) g.frames.push_back(testing::LumaOf(f));
    return g;
  }();
  return grey;
}

template <typename Image>
void RunModel(benchmark::State& state, const std::vector<Image>& empty,
              const std::vector<Image>& frames, const silhouette::BackgroundModelOptions& options) {
  silhouette::BackgroundModel model(frames[0].width, frames[0].height, options);
  common::ImageU8 mask;
  for (const Image& frame : empty) model.Apply(frame, &mask);
  double foreground = 0.0;
  std::size_t i = 0;
  for (auto _ : state) {
    model.Apply(frames[i++ % frames.size()], &mask);
    foreground += model.foreground_fraction();
    benchmark::ClobberMemory();
  }
  state.counters["foreground_share"] =
      foreground / static_cast<double>(std::max<std::int64_t>(1, state.iterations()));
  state.counters["gain"] = model.gain();
  state.counters["Mpixel_per_s"] =
      benchmark::Counter(static_cast<double>(frames[0].width) * frames[0].height * 1e-6 *
                             static_cast<double>(state.iterations()),
                         benchmark::Counter::kIsRate);
}

void BM_BackgroundModelFullHd(benchmark::State& state) {
  const Workload& w = GetWorkload();
  RunModel(state, w.empty, w.frames, silhouette::BackgroundModelOptions{});
}
BENCHMARK(BM_BackgroundModelFullHd)->Unit(benchmark::kMillisecond);

/// The default options without the texture test (brightness alone).
silhouette::BackgroundModelOptions BrightnessOnly() {
  silhouette::BackgroundModelOptions options;
  options.texture_threshold = 0;
  return options;
}

// The same without the texture test: what the test costs on colour frames.
void BM_BackgroundModelFullHdBrightnessOnly(benchmark::State& state) {
  const Workload& w = GetWorkload();
  RunModel(state, w.empty, w.frames, BrightnessOnly());
}
BENCHMARK(BM_BackgroundModelFullHdBrightnessOnly)->Unit(benchmark::kMillisecond);

// Shadows reported as background: a second, scalar pass over foreground pixels.
void BM_BackgroundModelFullHdShadowsAsBackground(benchmark::State& state) {
  const Workload& w = GetWorkload();
  silhouette::BackgroundModelOptions options;
  options.shadows_are_foreground = false;
  RunModel(state, w.empty, w.frames, options);
}
BENCHMARK(BM_BackgroundModelFullHdShadowsAsBackground)->Unit(benchmark::kMillisecond);

void BM_BackgroundModelFullHdMono8(benchmark::State& state) {
  const GreyWorkload& g = GetGreyWorkload();
  RunModel(state, g.empty, g.frames, silhouette::BackgroundModelOptions{});
}
BENCHMARK(BM_BackgroundModelFullHdMono8)->Unit(benchmark::kMillisecond);

// The same without the texture test (brightness alone): what the test costs.
void BM_BackgroundModelFullHdMono8BrightnessOnly(benchmark::State& state) {
  const GreyWorkload& g = GetGreyWorkload();
  RunModel(state, g.empty, g.frames, BrightnessOnly());
}
BENCHMARK(BM_BackgroundModelFullHdMono8BrightnessOnly)->Unit(benchmark::kMillisecond);

// Filling the background that the silhouettes enclose, on the Mono8 model's
// dilated foreground of one frame (the pipeline's next step). Each iteration
// fills the same mask again: the same scan and runs, without the holes'
// writes after the first.
void BM_FillEnclosedBackgroundFullHd(benchmark::State& state) {
  const GreyWorkload& g = GetGreyWorkload();
  silhouette::BackgroundModel model(g.frames[0].width, g.frames[0].height,
                                    silhouette::BackgroundModelOptions{});
  common::ImageU8 mask;
  for (const auto& f : g.empty) model.Apply(f, &mask);
  model.Apply(g.frames[0], &mask);
  silhouette::DilateScratch dilate;
  silhouette::DilateSquare(&mask, 2, &dilate);
  silhouette::HoleFillScratch scratch;
  const int filled = silhouette::FillEnclosedBackground(&mask, &scratch);
  for (auto _ : state) {
    benchmark::DoNotOptimize(silhouette::FillEnclosedBackground(&mask, &scratch));
    benchmark::ClobberMemory();
  }
  state.counters["filled_px"] = filled;
}
BENCHMARK(BM_FillEnclosedBackgroundFullHd)->Unit(benchmark::kMillisecond);

// The BayerRG8 mosaic of the same frames, as a GigE colour camera sends them
// and the aravis source passes them on by default: one byte per photosite.
std::vector<common::ImageU8> Mosaics(const std::vector<common::ImageRgb8>& frames) {
  std::vector<common::ImageU8> out;
  for (const common::ImageRgb8& f : frames) {
    common::ImageU8 m(f.width, f.height);
    for (int v = 0; v < f.height; ++v) {
      for (int u = 0; u < f.width; ++u) m.At(u, v) = f.Pixel(u, v)[(u & 1) + (v & 1)];
    }
    out.push_back(std::move(m));
  }
  return out;
}

void BM_BackgroundModelFullHdBayerRaw(benchmark::State& state) {
  const Workload& w = GetWorkload();
  RunModel(state, Mosaics(w.empty), Mosaics(w.frames), silhouette::BackgroundModelOptions{});
}
BENCHMARK(BM_BackgroundModelFullHdBayerRaw)->Unit(benchmark::kMillisecond);

// What `debayer: true` adds on the capture thread: OpenCV's demosaic of a
// Full HD BayerRG8 frame to RGB (GenICam RG is OpenCV's BG).
void BM_DebayerFullHd(benchmark::State& state) {
  const Workload& w = GetWorkload();
  const std::vector<common::ImageU8> mosaics = Mosaics({w.frames[0]});
  const common::ImageU8& m = mosaics[0];
  common::ImageRgb8 rgb(m.width, m.height);
  const cv::Mat mosaic(m.height, m.width, CV_8UC1, const_cast<std::uint8_t*>(m.pixels.data()));
  cv::Mat out(m.height, m.width, CV_8UC3, rgb.pixels.data());
  for (auto _ : state) {
    cv::cvtColor(mosaic, out, cv::COLOR_BayerBG2RGB);
    benchmark::ClobberMemory();
  }
}
BENCHMARK(BM_DebayerFullHd)->Unit(benchmark::kMillisecond);

// Learning the empty cell at start-up: the whole learning of one camera (30
// frames by default) per iteration, reported per frame.
void BM_BackgroundLearningFullHd(benchmark::State& state) {
  const Workload& w = GetWorkload();
  common::ImageU8 mask;
  for (auto _ : state) {
    silhouette::BackgroundModel model(w.empty[0].width, w.empty[0].height,
                                      silhouette::BackgroundModelOptions{});
    for (const common::ImageRgb8& frame : w.empty) model.Apply(frame, &mask);
    benchmark::DoNotOptimize(model.learning());
  }
  state.counters["time_per_frame"] = benchmark::Counter(
      static_cast<double>(state.iterations() * w.empty.size()),
      benchmark::Counter::kIsRate | benchmark::Counter::kInvert, benchmark::Counter::kIs1000);
}
BENCHMARK(BM_BackgroundLearningFullHd)->Unit(benchmark::kMillisecond);

// The images as RGB camera frames.
std::vector<capture::Frame> RgbFrames(const std::vector<common::ImageRgb8>& images) {
  std::vector<capture::Frame> frames(images.size());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    frames[i].kind = capture::FrameKind::kRgb;
    frames[i].rgb = images[i];
  }
  return frames;
}

// The health checks of one Full HD RGB frame after the reference view is
// taken: the edge grid and the frozen check on every frame, registration of
// the view on every third (CameraHealthOptions::shift_check_every).
void BM_CameraHealthFullHd(benchmark::State& state) {
  const Workload& w = GetWorkload();
  capture::CameraHealthMonitor monitor;
  const std::vector<capture::Frame> empty = RgbFrames(w.empty);
  for (std::size_t i = 0; !monitor.has_reference(); ++i) monitor.Check(empty[i % empty.size()]);
  const std::vector<capture::Frame> frames = RgbFrames(w.frames);
  std::size_t i = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(monitor.Check(frames[i++ % frames.size()]));
  }
  state.counters["patches"] = monitor.reference_patches();
  state.counters["misalignment_px"] = monitor.misalignment_px();
}
BENCHMARK(BM_CameraHealthFullHd)->Unit(benchmark::kMillisecond);

// One registration of a Full HD RGB frame's view against the reference
// (ViewRegistration::Measure()), with three people walking in front of it.
void BM_ViewRegistrationFullHd(benchmark::State& state) {
  const Workload& w = GetWorkload();
  capture::ViewRegistration registration;
  const std::vector<capture::Frame> empty = RgbFrames(w.empty);
  for (std::size_t i = 0; i < 10; ++i) registration.Accumulate(empty[i]);
  registration.TakeReference();
  const std::vector<capture::Frame> frames = RgbFrames(w.frames);
  std::size_t i = 0;
  double misalignment = 0.0;
  for (auto _ : state) misalignment = registration.Measure(frames[i++ % frames.size()]);
  state.counters["patches"] = registration.patches();
  state.counters["matched"] = registration.matched();
  state.counters["misalignment_px"] = misalignment;
}
BENCHMARK(BM_ViewRegistrationFullHd)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace hg::bench
