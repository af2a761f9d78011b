#include "app/run.h"

#include <csignal>
#include <cstdio>
#include <map>
#include <thread>

#include "capture/sim_source.h"
#include "common/config_error.h"
#include "geometry/mesh.h"
#include "pipeline/pipeline.h"
#include "sim/scene.h"
#ifdef HG_WITH_DDS
#include "publish/dds_publisher.h"
#endif

namespace hg::app {
namespace {

std::atomic<bool> g_stop{false};

void OnSignal(int /*signal*/) { g_stop.store(true); }

const char* StateName(pipeline::CameraState s) {
  switch (s) {
    case pipeline::CameraState::kStarting:
      return "starting";
    case pipeline::CameraState::kOk:
      return "ok";
    case pipeline::CameraState::kStale:
      return "stale";
    case pipeline::CameraState::kFailed:
      return "failed";
  }
  return "?";
}

void PrintHealth(const pipeline::OccupancySnapshot& s) {
  const double cell = s.bounds.Size().prod() / static_cast<double>(1ULL << (3 * s.depth));
  std::fprintf(stderr,
               "hullguardd: cycle %llu %s%s occupied %.3f m^3 occluded %.3f m^3 octree %.1f ms "
               "cycle %.1f ms deadline misses %llu |",
               static_cast<unsigned long long>(s.sequence), s.health.degraded ? "DEGRADED" : "ok",
               s.complete ? "" : " (aborted)", cell * static_cast<double>(s.occupied.size()),
               cell * static_cast<double>(s.occluded.size()), s.health.octree_ms, s.health.cycle_ms,
               static_cast<unsigned long long>(s.health.deadline_misses));
  for (const pipeline::CameraHealth& c : s.health.cameras) {
    std::fprintf(stderr, " %s %s %.0f fps", c.name.c_str(), StateName(c.state), c.fps);
  }
  std::fprintf(stderr, "\n");
}

}  // namespace

int RunPipeline(const Config& config, double duration_s) {
  pipeline::PipelineOptions options;
  options.bounds = config.cell.bounds;
  options.depth = config.octree.depth;
  options.boundary_coarsening = config.octree.boundary_coarsening;
  options.octree_threads = config.threads.octree;
  options.rate_hz = config.timing.rate_hz;
  options.deadline_ms = config.timing.deadline_ms;
  options.publish_depth = std::min(config.octree.depth, 7);

  std::vector<geometry::TriangleMesh> obstacles;
  for (const ObstacleConfig& o : config.obstacles) obstacles.push_back(geometry::LoadMesh(o.file));

  std::map<std::string, std::shared_ptr<const sim::Scene>> scenes;
  const auto start = std::chrono::steady_clock::now();
  const capture::SimClock sim_clock = capture::SimClock::Now();
  std::vector<pipeline::PipelineCamera> cameras;
  for (const CameraConfig& c : config.cameras) {
    const auto* sim_source = std::get_if<SimSourceConfig>(&c.source);
    if (sim_source == nullptr) {
      throw common::ConfigError(config.source_file + ": camera '" + c.model.name +
                                "': source type '" + ToString(TypeOf(c.source)) +
                                "' is not available in this build yet (only 'sim')");
    }
    auto& scene = scenes[sim_source->scene];
    if (!scene) scene = std::make_shared<const sim::Scene>(sim::LoadScene(sim_source->scene));
    int index = -1;
    for (std::size_t i = 0; i < scene->cameras.size(); ++i) {
      if (scene->cameras[i].model.name == sim_source->camera) index = static_cast<int>(i);
    }
    // The loader checked that the scene defines the camera.
    cameras.push_back(
        {c.model, std::make_unique<capture::SimSource>(scene, index, scene->rate_hz, sim_clock),
         c.timeout_ms});
  }

  pipeline::Pipeline::Consumer consumer;
#ifdef HG_WITH_DDS
  // Publish never blocks or throws; it runs on the fusion thread after each cycle.
  publish::DdsPublisher publisher(config.dds, config.timing.rate_hz);
  if (config.dds.enabled) {
    consumer = [&publisher](const std::shared_ptr<const pipeline::OccupancySnapshot>& s) {
      publisher.Publish(*s);
    };
  }
#else
  if (config.dds.enabled) {
    std::fprintf(stderr, "hullguardd: built without Cyclone DDS: nothing is published\n");
  }
#endif
  pipeline::Pipeline pipeline(options, std::move(cameras), obstacles, consumer);
  std::signal(SIGTERM, OnSignal);
  std::signal(SIGINT, OnSignal);
  pipeline.Start();
  std::fprintf(stderr, "hullguardd: running %s\n", Summary(config).c_str());
  if (!scenes.empty()) {
    // Lets a test or a viewer evaluate the scene's ground truth for a stamp.
    std::fprintf(stderr, "hullguardd: sim scene time 0 is %lld ns (CLOCK_REALTIME)\n",
                 static_cast<long long>(sim_clock.epoch_ns));
  }
  auto next_report = std::chrono::steady_clock::now() + std::chrono::seconds(1);
  while (!g_stop.load()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    const auto now = std::chrono::steady_clock::now();
    if (duration_s > 0 && now - start >= std::chrono::duration<double>(duration_s)) break;
    if (now >= next_report) {
      next_report += std::chrono::seconds(1);
      if (const auto s = pipeline.Latest()) PrintHealth(*s);
    }
  }
  pipeline.Stop();
  if (const auto s = pipeline.Latest()) PrintHealth(*s);
  std::fprintf(stderr, "hullguardd: stopped\n");
  return 0;
}

}  // namespace hg::app
