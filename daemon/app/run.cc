#include "app/run.h"

#include <csignal>
#include <cstdio>
#include <map>
#include <thread>

#include "app/pipeline_setup.h"
#include "app/service.h"
#ifdef HG_WITH_ARAVIS
#include "capture/aravis_source.h"
#endif
#include "capture/replay_source.h"
#include "capture/sim_source.h"
#include "capture/v4l2_source.h"
#include "common/config_error.h"
#include "common/heartbeat.h"
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

// One line of health: the periodic log line and systemd's STATUS=.
std::string HealthLine(const pipeline::OccupancySnapshot& s) {
  const double cell = s.bounds.Size().prod() / static_cast<double>(1ULL << (3 * s.depth));
  char head[256];
  std::snprintf(head, sizeof(head),
                "cycle %llu %s%s occupied %.3f m^3 occluded %.3f m^3 octree %.1f ms cycle %.1f ms "
                "skew %.1f ms deadline misses %llu |",
                static_cast<unsigned long long>(s.sequence), s.health.degraded ? "DEGRADED" : "ok",
                s.complete ? "" : " (aborted)",
                cell * static_cast<double>(pipeline::OccupancySnapshot::Cells(s.occupied)),
                cell * static_cast<double>(pipeline::OccupancySnapshot::Cells(s.occluded)),
                s.health.octree_ms, s.health.cycle_ms, s.health.skew_ms,
                static_cast<unsigned long long>(s.health.deadline_misses));
  std::string line = head;
  for (const pipeline::CameraHealth& c : s.health.cameras) {
    char cam[128];
    std::snprintf(cam, sizeof(cam), " %s %s %.0f fps", c.name.c_str(), StateName(c.state), c.fps);
    line += cam;
    if (c.corrupt > 0) line += std::string(" corrupt ").append(std::to_string(c.corrupt));
    if (c.fault != 0) {
      line += std::string(" (").append(ToString(static_cast<capture::CameraFault>(c.fault))) + ")";
    }
  }
  return line;
}

}  // namespace

int RunPipeline(const Config& config, double duration_s) {
  const pipeline::PipelineOptions options = MakePipelineOptions(config);
  const std::vector<geometry::TriangleMesh> obstacles = LoadObstacles(config);

  std::map<std::string, std::shared_ptr<const sim::Scene>> scenes;
  const auto start = std::chrono::steady_clock::now();
  const capture::SimClock sim_clock = capture::SimClock::Now();
  std::vector<pipeline::PipelineCamera> cameras;
  for (const CameraConfig& c : config.cameras) {
    if (const auto* replay = std::get_if<ReplaySourceConfig>(&c.source)) {
      if (!replay->realtime) {
        throw common::ConfigError(config.source_file + ": camera '" + c.model.name +
                                  "': source.realtime: false needs a lock-step consumer; the "
                                  "daemon replays in real time (as fast as possible and "
                                  "deterministic: hullguard replay)");
      }
      auto source = std::make_unique<capture::ReplaySource>(
          capture::ReadRecordingCamera(replay->directory, replay->camera), sim_clock);
      cameras.push_back({c.model, std::move(source), c.timeout_ms});
      continue;
    }
#ifdef HG_WITH_ARAVIS
    if (const auto* gige = std::get_if<AravisSourceConfig>(&c.source)) {
      // The config's enums list the same values in the same order.
      static_assert(static_cast<int>(capture::AravisOptions::Pixel::kRGB8) ==
                    static_cast<int>(PixelFormat::kRGB8));
      static_assert(static_cast<int>(capture::AravisOptions::Trigger::kHardware) ==
                    static_cast<int>(Trigger::kHardware));
      capture::AravisOptions o;
      o.device = gige->device;
      o.pixel_format = static_cast<capture::AravisOptions::Pixel>(gige->pixel_format);
      o.exposure_us = gige->exposure_us;
      o.gain_db = gige->gain_db;
      o.frame_rate_hz = gige->frame_rate_hz;
      o.trigger = static_cast<capture::AravisOptions::Trigger>(gige->trigger);
      o.packet_size = gige->packet_size;
      o.socket_buffer_bytes = gige->socket_buffer_bytes;
      o.width = c.model.width;
      o.height = c.model.height;
      o.frame_timeout = std::chrono::milliseconds(c.timeout_ms);
      cameras.push_back(
          {c.model, std::make_unique<capture::AravisSource>(std::move(o)), c.timeout_ms});
      continue;
    }
#endif
    if (const auto* usb = std::get_if<V4l2SourceConfig>(&c.source)) {
      static_assert(static_cast<int>(capture::V4l2Options::Format::kMjpeg) ==
                    static_cast<int>(V4l2Format::kMjpeg));
      capture::V4l2Options o;
      o.device = usb->device;
      o.format = static_cast<capture::V4l2Options::Format>(usb->format);
      o.frame_rate_hz = usb->frame_rate_hz;
      o.exposure = usb->exposure;
      o.width = c.model.width;
      o.height = c.model.height;
      cameras.push_back(
          {c.model, std::make_unique<capture::V4l2Source>(std::move(o)), c.timeout_ms});
      continue;
    }
    const auto* sim_source = std::get_if<SimSourceConfig>(&c.source);
    if (sim_source == nullptr) {
      throw common::ConfigError(config.source_file + ": camera '" + c.model.name +
                                "': source type '" + ToString(TypeOf(c.source)) +
                                "' is not available in this build (sim, replay, v4l2 and, with "
                                "libaravis-dev, aravis are)");
    }
    auto& scene = scenes[sim_source->scene];
    if (!scene) scene = std::make_shared<const sim::Scene>(sim::LoadScene(sim_source->scene));
    int index = -1;
    for (std::size_t i = 0; i < scene->cameras.size(); ++i) {
      if (scene->cameras[i].model.name == sim_source->camera) index = static_cast<int>(i);
    }
    // The loader checked that the scene defines the camera.
    auto source = std::make_unique<capture::SimSource>(scene, index, scene->rate_hz, sim_clock);
    if (sim_source->stop_after_s) source->SetStopAfter(*sim_source->stop_after_s);
    cameras.push_back({c.model, std::move(source), c.timeout_ms});
  }

  pipeline::Pipeline::Consumer consumer;
#ifdef HG_WITH_DDS
  // Publish never blocks or throws; it runs on the fusion thread after each cycle.
  publish::DdsPublisher publisher(
      {config.dds.domain_id, config.dds.topic_prefix, config.dds.enabled}, config.timing.rate_hz);
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
  common::Heartbeats heartbeats;
  pipeline::Pipeline pipeline(options, std::move(cameras), obstacles, consumer, &heartbeats);
  const int main_heartbeat = heartbeats.Register("main");
  // systemd (Type=notify): READY=1 once the cameras are open and the first
  // cycle is published; WATCHDOG=1 only while every stage's heartbeat moves.
  const ServiceNotifier notifier;
  ServiceWatchdog watchdog(heartbeats, notifier);
  std::signal(SIGTERM, OnSignal);
  std::signal(SIGINT, OnSignal);
  pipeline.Start();
  watchdog.Start();
  std::fprintf(stderr, "hullguardd: running %s\n", Summary(config).c_str());
  // Lets a test or a viewer relate stamps to scene or recording time.
  std::fprintf(stderr, "hullguardd: sim/replay time 0 is %lld ns (CLOCK_REALTIME)\n",
               static_cast<long long>(sim_clock.epoch_ns));
  bool ready = false;
  auto next_report = std::chrono::steady_clock::now() + std::chrono::seconds(1);
  while (!g_stop.load()) {
    heartbeats.Beat(main_heartbeat);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const auto now = std::chrono::steady_clock::now();
    if (duration_s > 0 && now - start >= std::chrono::duration<double>(duration_s)) break;
    if (!ready) {
      if (const auto s = pipeline.Latest()) {
        notifier.Ready();
        watchdog.SetStatus(HealthLine(*s));
        ready = true;
      }
    }
    if (now >= next_report) {
      next_report += std::chrono::seconds(1);
      if (const auto s = pipeline.Latest()) {
        const std::string line = HealthLine(*s);
        std::fprintf(stderr, "hullguardd: %s\n", line.c_str());
        watchdog.SetStatus(line);
      }
    }
  }
  notifier.Stopping();
  watchdog.Stop();
  pipeline.Stop();
  if (const auto s = pipeline.Latest()) {
    std::fprintf(stderr, "hullguardd: %s\n", HealthLine(*s).c_str());
  }
  std::fprintf(stderr, "hullguardd: stopped\n");
  return 0;
}

}  // namespace hg::app
