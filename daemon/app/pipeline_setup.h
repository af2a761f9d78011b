#pragma once
/// @file
/// From a validated daemon config to what the pipeline needs. Shared by
/// hullguardd and the tools that run the pipeline (`hullguard replay`).

#include <vector>

#include "app/config.h"
#include "geometry/mesh.h"
#include "pipeline/pipeline.h"

namespace hg::app {

/// The pipeline's options: cell, octree, timing, motion and background model.
[[nodiscard]] pipeline::PipelineOptions MakePipelineOptions(const Config& config);

/// The configured obstacle meshes, loaded.
/// @throws common::ConfigError naming a file that cannot be read.
[[nodiscard]] std::vector<geometry::TriangleMesh> LoadObstacles(const Config& config);

}  // namespace hg::app
