#include "app/pipeline_setup.h"

namespace hg::app {

pipeline::PipelineOptions MakePipelineOptions(const Config& config) {
  pipeline::PipelineOptions options;
  options.bounds = config.cell.bounds;
  options.depth = config.octree.depth;
  options.boundary_coarsening = config.octree.boundary_coarsening;
  options.octree_threads = config.threads.octree;
  options.rate_hz = config.timing.rate_hz;
  options.deadline_ms = config.timing.deadline_ms;
  options.publish_depth = config.octree.publish_depth;
  options.max_speed_mps = config.motion.max_speed_mps;
  options.min_camera_distance_m = config.motion.min_camera_distance_m;
  const BackgroundConfig& b = config.background;
  options.background.learn_frames = b.learn_frames;
  options.background.min_threshold = b.threshold;
  options.background.adapt_rate = b.adapt_rate;
  options.background.shadows_are_foreground = b.shadows_are_foreground;
  options.background.noise_sigmas = b.noise_sigmas;
  options.background.max_threshold = b.max_threshold;
  options.background.guard_px = b.guard_px;
  options.background.compensate_gain = b.compensate_gain;
  options.background_dilate_px = b.dilate_px;
  return options;
}

std::vector<geometry::TriangleMesh> LoadObstacles(const Config& config) {
  std::vector<geometry::TriangleMesh> obstacles;
  for (const ObstacleConfig& o : config.obstacles) obstacles.push_back(geometry::LoadMesh(o.file));
  return obstacles;
}

}  // namespace hg::app
