#pragma once
/// @file
/// Runs the pipeline described by a validated config until a signal (or for a
/// given time), reporting health once per second.

#include "app/config.h"

namespace hg::app {

/// Builds the sources and the pipeline from `config`, runs until SIGTERM or
/// SIGINT (or `duration_s` seconds when > 0), stops cleanly. Returns the exit
/// code: 0 after a clean stop, 2 when the config names what cannot run here.
int RunPipeline(const Config& config, double duration_s);

}  // namespace hg::app
