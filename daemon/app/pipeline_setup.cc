#include "app/pipeline_setup.h"

#include <map>
#include <memory>
#include <optional>
#include <variant>

#ifdef HG_WITH_ARAVIS
#include "capture/aravis_source.h"
#endif
#include "capture/replay_source.h"
#include "capture/v4l2_source.h"
#include "common/config_error.h"
#include "common/log.h"
#include "sim/scene.h"

namespace hg::app {
namespace {

/// Whether a GigE camera's frames reach the pipeline as raw Bayer mosaics:
/// one byte per photosite, each in its own colour (Mono8 is one byte a pixel
/// too, grey; RGB8 and debayered frames are RGB).
bool RawBayer(const AravisSourceConfig& a) {
  return a.pixel_format != PixelFormat::kMono8 && a.pixel_format != PixelFormat::kRGB8 &&
         !a.debayer;
}

}  // namespace

pipeline::PipelineOptions MakePipelineOptions(const Config& config) {
  pipeline::PipelineOptions options;
  options.bounds = config.cell.bounds;
  options.depth = config.octree.depth;
  options.boundary_coarsening = config.octree.boundary_coarsening;
  options.coarse_first_depth = config.octree.coarse_first_depth;
  options.max_nodes = config.octree.max_nodes;
  if (config.tracking.enabled) {
    // Tracks start only from updates refined to the tracking voxel
    // (pipeline::WholeForBirths): the coarse passes reach that level first.
    options.key_level = pipeline::TrackingKeyLevel(config.cell.bounds, config.octree.depth,
                                                   config.tracking.voxel_m);
  }
  options.octree_threads = config.threads.octree;
  options.rate_hz = config.timing.rate_hz;
  options.deadline_ms = config.timing.deadline_ms;
  options.align_to_frames = config.timing.align_to_frames;
  options.align_margin_ms = config.timing.align_margin_ms;
  options.silhouette_workers = config.threads.silhouette_workers;
  options.fusion_realtime_priority = config.threads.realtime_priority;
  options.knowledge_filter_m3 = config.octree.knowledge_filter_m3;
  options.publish_depth = config.octree.publish_depth;
  options.max_speed_mps = config.motion.max_speed_mps;
  options.stamp_at_median = config.motion.stamp_at_median;
  const BackgroundConfig& b = config.background;
  options.background.learn_frames = b.learn_frames;
  options.background.min_threshold = b.threshold;
  options.background.adapt_rate = b.adapt_rate;
  options.background.shadows_are_foreground = b.shadows_are_foreground;
  options.background.noise_sigmas = b.noise_sigmas;
  options.background.max_threshold = b.max_threshold;
  options.background.texture_threshold = b.texture_threshold;
  options.background.guard_px = b.guard_px;
  options.background.compensate_gain = b.compensate_gain;
  options.background_dir = b.keep_dir;
  options.background_start = b.learn_at_start
                                 ? pipeline::PipelineOptions::BackgroundStart::kLearn
                                 : pipeline::PipelineOptions::BackgroundStart::kKeptOnly;
  options.background_dilate_px = b.dilate_px;
  options.background_fill_holes = b.fill_holes;
  return options;
}

std::vector<geometry::TriangleMesh> LoadObstacles(const Config& config) {
  std::vector<geometry::TriangleMesh> obstacles;
  for (const ObstacleConfig& o : config.obstacles) obstacles.push_back(geometry::LoadMesh(o.file));
  return obstacles;
}

std::vector<pipeline::PipelineCamera> MakeCameras(const Config& config,
                                                  const capture::SimClock& clock) {
  // First everything that can fail: the scenes and recordings read, the
  // source types checked. Only then are the sources made, in config order,
  // since making one opens its camera (V4L2) or starts connecting (Aravis).
  std::map<std::string, std::shared_ptr<const sim::Scene>> scenes;
  std::vector<int> scene_camera(config.cameras.size(), -1);
  std::vector<std::optional<capture::RecordingCamera>> recordings(config.cameras.size());
  // The simulated colour cameras show their people only once every one of
  // them has its background learned.
  int colour_sims = 0;
  for (const CameraConfig& c : config.cameras) {
    const auto* sim_source = std::get_if<SimSourceConfig>(&c.source);
    if (sim_source != nullptr && (sim_source->colour || sim_source->bayer)) ++colour_sims;
  }
  const auto people_gate = std::make_shared<capture::SimSource::PeopleGate>(colour_sims);
  for (std::size_t i = 0; i < config.cameras.size(); ++i) {
    const CameraConfig& c = config.cameras[i];
    const std::string where = config.source_file + ": camera '" + c.model.name + "': ";
    if (const auto* replay = std::get_if<ReplaySourceConfig>(&c.source)) {
      recordings[i] = capture::ReadRecordingCamera(replay->directory, replay->camera);
    } else if (const auto* sim_source = std::get_if<SimSourceConfig>(&c.source)) {
      auto& scene = scenes[sim_source->scene];
      if (!scene) scene = std::make_shared<const sim::Scene>(sim::LoadScene(sim_source->scene));
      for (std::size_t k = 0; k < scene->cameras.size(); ++k) {
        if (scene->cameras[k].model.name == sim_source->camera) {
          scene_camera[i] = static_cast<int>(k);
        }
      }
      if (scene_camera[i] < 0) {  // The loader checked it; the file may have changed since.
        throw common::ConfigError(where + "scene '" + sim_source->scene + "' has no camera '" +
                                  sim_source->camera + "'");
      }
#ifndef HG_WITH_ARAVIS
    } else if (std::holds_alternative<AravisSourceConfig>(c.source)) {
      throw common::ConfigError(where +
                                "source type 'aravis' is not available in this build (sim, "
                                "replay, v4l2 and, with libaravis-dev, aravis are)");
#endif
    }
  }

  // Looping replay cameras share one loop period, the longest of theirs
  // (capture::ReplayOptions::loop_period_ns), so that they stay in step.
  std::int64_t loop_period_ns = 0;
  for (std::size_t i = 0; i < config.cameras.size(); ++i) {
    const auto* replay = std::get_if<ReplaySourceConfig>(&config.cameras[i].source);
    if (replay == nullptr || !replay->loop) continue;
    loop_period_ns =
        std::max(loop_period_ns, capture::LoopLengthNs(*recordings[i], replay->loop_start_s));
  }
  std::vector<pipeline::PipelineCamera> cameras;
  for (std::size_t i = 0; i < config.cameras.size(); ++i) {
    const CameraConfig& c = config.cameras[i];
    if (const auto* replay = std::get_if<ReplaySourceConfig>(&c.source)) {
      auto source = std::make_unique<capture::ReplaySource>(
          std::move(*recordings[i]), clock,
          capture::ReplayOptions{.pacing = replay->realtime ? capture::ReplayPacing::kRealtime
                                                            : capture::ReplayPacing::kFast,
                                 .preload = replay->preload,
                                 .loop = replay->loop,
                                 .loop_start_s = replay->loop_start_s,
                                 .loop_period_ns = loop_period_ns});
      if (replay->preload) {
        log::Info("camera '{}': {} frames of '{}' preloaded, {:.0f} MB", c.model.name,
                  source->frames(), replay->directory,
                  static_cast<double>(source->preloaded_bytes()) / 1e6);
      }
      cameras.push_back({c.model, std::move(source), c.timeout_ms});
      continue;
    }
    if (const auto* sim_source = std::get_if<SimSourceConfig>(&c.source)) {
      const std::shared_ptr<const sim::Scene>& scene = scenes.at(sim_source->scene);
      auto source =
          std::make_unique<capture::SimSource>(scene, scene_camera[i], scene->rate_hz, clock);
      if (sim_source->stop_after_s) source->SetStopAfter(*sim_source->stop_after_s);
      if (sim_source->colour || sim_source->bayer) {
        // Twice the learning frames, and after that until every colour
        // camera's model has learned: the cell is learned empty however late
        // start-up ends or however many frames a loaded worker drops.
        source->EnableColour(2.0 * config.background.learn_frames / scene->rate_hz + 1.0,
                             sim_source->bayer);
        source->HoldPeopleUntilLearned(people_gate);
      }
      cameras.push_back({c.model, std::move(source), c.timeout_ms, sim_source->bayer});
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
      o.debayer = gige->debayer;
      o.exposure_us = gige->exposure_us;
      o.gain_db = gige->gain_db;
      o.frame_rate_hz = gige->frame_rate_hz;
      o.trigger = static_cast<capture::AravisOptions::Trigger>(gige->trigger);
      o.packet_size = gige->packet_size;
      o.socket_buffer_bytes = gige->socket_buffer_bytes;
      o.width = c.model.width;
      o.height = c.model.height;
      o.frame_timeout = std::chrono::milliseconds(c.timeout_ms);
      cameras.push_back({c.model, std::make_unique<capture::AravisSource>(std::move(o)),
                         c.timeout_ms, RawBayer(*gige)});
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
  }
  return cameras;
}

std::vector<pipeline::BlackBoxCamera> BlackBoxCameras(const Config& config) {
  using capture::FrameKind;
  std::map<std::string, double> scene_rates;
  std::vector<pipeline::BlackBoxCamera> out;
  for (const CameraConfig& c : config.cameras) {
    pipeline::BlackBoxCamera b;
    b.model = c.model;
    b.rate_hz = config.blackbox.camera_rate_hz;
    if (const auto* s = std::get_if<SimSourceConfig>(&c.source)) {
      b.kind = s->bayer ? FrameKind::kMono : s->colour ? FrameKind::kRgb : FrameKind::kMask;
      auto [it, inserted] = scene_rates.emplace(s->scene, 0.0);
      if (inserted) it->second = sim::LoadScene(s->scene).rate_hz;  // ConfigError if bad.
      b.rate_hz = it->second;
    } else if (const auto* r = std::get_if<ReplaySourceConfig>(&c.source)) {
      const capture::RecordingCamera rec = capture::ReadRecordingCamera(r->directory, r->camera);
      b.kind = rec.kind;
      if (rec.rate_hz > 0.0) b.rate_hz = rec.rate_hz;
    } else if (const auto* a = std::get_if<AravisSourceConfig>(&c.source)) {
      // Mono8, and Bayer mosaics passed on raw, are one byte per pixel.
      const bool rgb = a->pixel_format != PixelFormat::kMono8 && !RawBayer(*a);
      b.kind = rgb ? FrameKind::kRgb : FrameKind::kMono;
      if (a->frame_rate_hz) b.rate_hz = *a->frame_rate_hz;
    } else if (const auto* v = std::get_if<V4l2SourceConfig>(&c.source)) {
      b.kind = v->format == V4l2Format::kGrey ? FrameKind::kMono : FrameKind::kRgb;
      if (v->frame_rate_hz) b.rate_hz = *v->frame_rate_hz;
    }
    out.push_back(std::move(b));
  }
  return out;
}

}  // namespace hg::app
