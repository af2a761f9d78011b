#pragma once
/// @file
/// From a validated daemon config to what the pipeline needs. Shared by
/// hullguardd and the tools that run the pipeline (`hullguard replay`).

#include <vector>

#include "app/config.h"
#include "capture/sim_source.h"
#include "geometry/mesh.h"
#include "pipeline/black_box.h"
#include "pipeline/pipeline.h"

namespace hg::app {

/// The pipeline's options: cell, octree, timing, motion and background model.
[[nodiscard]] pipeline::PipelineOptions MakePipelineOptions(const Config& config);

/// The configured obstacle meshes, loaded.
/// @throws common::ConfigError naming a file that cannot be read.
[[nodiscard]] std::vector<geometry::TriangleMesh> LoadObstacles(const Config& config);

/// Every configured camera with its source, built the one way the daemon and
/// `hullguard record` share. `clock` is time 0 of sim and replay sources.
/// Sources open their devices here (Aravis, V4L2), but only once every scene
/// and recording has been read and every source type found available, so
/// that none of those failures comes after a camera was opened.
/// @throws common::ConfigError for a source this build cannot run, or a
/// scene or recording that cannot be read; a camera's own errors as its
/// source throws them.
[[nodiscard]] std::vector<pipeline::PipelineCamera> MakeCameras(const Config& config,
                                                                const capture::SimClock& clock);

/// What the black box keeps of each camera: the largest frame kind its source
/// delivers and its frame rate (the source's configured rate, the scene's or
/// the recording's, else blackbox.camera_rate_hz).
/// @throws common::ConfigError when a scene or recording cannot be read.
[[nodiscard]] std::vector<pipeline::BlackBoxCamera> BlackBoxCameras(const Config& config);

}  // namespace hg::app
