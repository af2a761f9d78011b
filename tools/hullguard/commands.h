#pragma once
/// @file
/// Subcommands of the `hullguard` tool. Each registers itself on the app and
/// runs from its callback; bad input throws common::ConfigError (exit code 2).

#include <CLI/CLI.hpp>

namespace hg::tools {

/// Exit codes shared by the subcommands.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitBadInput = 2;

void RegisterCarve(CLI::App& app, int* exit_code);
void RegisterDemo(CLI::App& app, int* exit_code);
void RegisterSynth(CLI::App& app, int* exit_code);
void RegisterBench(CLI::App& app, int* exit_code);
void RegisterReplay(CLI::App& app, int* exit_code);
/// Records every camera of a daemon config (docs/cameras.md).
void RegisterRecord(CLI::App& app, int* exit_code);
/// Tracks a simulated scene on its reconstruction and scores it (CLEAR MOT).
void RegisterTrackEval(CLI::App& app, int* exit_code);
/// Optimises where to mount cameras (docs/placement.md).
void RegisterPlace(CLI::App& app, int* exit_code);
/// Only in builds with Cyclone DDS (HG_WITH_DDS).
void RegisterEcho(CLI::App& app, int* exit_code);

}  // namespace hg::tools
