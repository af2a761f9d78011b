#pragma once
/// @file
/// Runs the pipeline described by a validated config until a signal (or for a
/// given time), reporting health once per second.

#include "app/config.h"

namespace hg::app {

/// SIGTERM and SIGINT ask a running (or starting) RunPipeline to stop;
/// SIGUSR1 asks for a black-box dump. hullguardd installs them first thing,
/// so that a signal while it loads its config ends it cleanly too.
void InstallStopSignals();
/// Whether SIGTERM or SIGINT came since InstallStopSignals().
[[nodiscard]] bool StopRequested();

/// Builds the sources and the pipeline from `config`, runs until SIGTERM or
/// SIGINT (or `duration_s` seconds when > 0), stops cleanly. Returns the exit
/// code: 0 after a clean stop, 2 when the config names what cannot run here.
int RunPipeline(const Config& config, double duration_s);

/// Teaches the background (`hullguardd --learn-background`): opens the
/// cameras and runs their silhouette stage only (no fusion cycle is
/// published), has every camera with a background model learn afresh from
/// its first background.learn_frames frames and keeps what it learned in
/// background.keep_dir, then stops. The cell must be empty meanwhile.
/// Returns the exit code: 0 when every such camera kept its background, 1
/// when one could not (no frames within `timeout_s`, a faulty image, a file
/// that could not be written), 2 when the config cannot teach (no keep_dir,
/// or no camera delivers images).
int LearnBackground(const Config& config, double timeout_s);

}  // namespace hg::app
