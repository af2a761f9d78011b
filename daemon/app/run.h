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

}  // namespace hg::app
