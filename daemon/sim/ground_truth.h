#pragma once
/// @file
/// Per-frame ground truth of a simulated sequence (every body part's capsule,
/// each person's centre and bounding ellipsoid) and its file format, documented
/// in docs/synth.md. Written by `hullguard synth`, read by replay and evaluation.

#include <string>
#include <vector>

#include "sim/body.h"

namespace hg::sim {

struct PersonTruth {
  std::string name;
  BodyState state;
};

struct FrameTruth {
  int frame = 0;
  double time_s = 0.0;  ///< Scene time of the frame (cameras add their offsets).
  std::vector<PersonTruth> people;
};

struct GroundTruth {
  std::string scene;      ///< Scene name.
  double rate_hz = 30.0;  ///< Frame rate.
  std::vector<FrameTruth> frames;
};

/// Writes the ground truth as YAML; numbers keep full double precision, so
/// ReadGroundTruth returns exactly what was written.
/// @throws common::ConfigError when the file cannot be written.
void WriteGroundTruth(const std::string& path, const GroundTruth& truth);

/// Reads a file written by WriteGroundTruth.
/// @throws common::ConfigError naming the file, line and key on malformed input.
[[nodiscard]] GroundTruth ReadGroundTruth(const std::string& path);

}  // namespace hg::sim
