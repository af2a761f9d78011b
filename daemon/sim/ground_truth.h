#pragma once
/// @file
/// Per-frame ground truth of a simulated sequence (every body part's capsule,
/// each person's centre and bounding ellipsoid) and its file format, documented
/// in docs/synth.md. Written by `hullguard synth`, read by replay and evaluation.

#include <fstream>
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

/// Writes the same file frame by frame, holding none of them: a long run's
/// ground truth needs no memory of its own (hullguard synth).
class GroundTruthWriter {
 public:
  /// Starts `path` for `frames` frames of scene `scene` at `rate_hz`.
  /// @throws common::ConfigError when the file cannot be written.
  GroundTruthWriter(const std::string& path, const std::string& scene, double rate_hz,
                    std::size_t frames);
  /// Appends the next frame. @throws common::ConfigError (a value that is not
  /// finite, naming it; a write error; more frames than announced).
  void Add(const FrameTruth& frame);
  /// Ends the file. @throws common::ConfigError on a write error, or when
  /// fewer frames were added than announced.
  void Finish();

 private:
  std::string path_;
  std::size_t frames_;
  std::size_t added_ = 0;
  std::ofstream file_;
};

/// Reads a file written by WriteGroundTruth.
/// @throws common::ConfigError naming the file, line and key on malformed input.
[[nodiscard]] GroundTruth ReadGroundTruth(const std::string& path);

}  // namespace hg::sim
