#pragma once
/// @file
/// hullguardd's one line of health: the periodic log line (once a second) and
/// systemd's STATUS=. Its words are documented in docs/operations.md.

#include <chrono>
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "app/tracking_stage.h"
#include "pipeline/snapshot.h"

namespace hg::app {

/// "starting", "ok", "stale" or "failed".
[[nodiscard]] const char* StateName(pipeline::CameraState s);

/// The health line of snapshot `s`: cycle, ok or DEGRADED (also while
/// `foreign_publisher`: another publisher writes this daemon's topics, as
/// the status samples say), how far an aborted update refined, volumes,
/// times, then the tracker's figures (`tracking`, when it runs) and each
/// camera's state, frame rate and fault. `failed_writes`: DDS writes refused
/// in the last second (DEGRADED while there are any: what the controllers
/// should have received did not go out).
[[nodiscard]] std::string HealthLine(const pipeline::OccupancySnapshot& s,
                                     const std::optional<TrackingStats>& tracking,
                                     bool foreign_publisher, std::uint64_t failed_writes = 0);

/// Tells once per run when a camera has been mostly foreground
/// (pipeline::Pipeline::ForegroundHeavySince()) for `after` or longer.
/// Thread-compatible: the daemon's main loop calls it.
class ForegroundWatch {
 public:
  using Clock = std::chrono::steady_clock;
  ForegroundWatch(std::size_t cameras, Clock::duration after)
      : after_(after), told_(cameras, false), run_(cameras) {}
  /// `since`: the camera's ForegroundHeavySince(). True the first time in a
  /// run that it reaches `after`; the run ends when `since` is nullopt or
  /// another instant.
  [[nodiscard]] bool Due(std::size_t camera, std::optional<Clock::time_point> since,
                         Clock::time_point now);

 private:
  Clock::duration after_;
  std::vector<bool> told_;
  std::vector<Clock::time_point> run_;  ///< Per camera: the start of the run told or watched.
};

/// The warning for camera `name` mostly foreground for `seconds`.
[[nodiscard]] std::string ForegroundWarning(const std::string& name, double seconds);

}  // namespace hg::app
