#pragma once
/// @file
/// hullguardd's one line of health: the periodic log line (once a second) and
/// systemd's STATUS=. Its words are documented in docs/operations.md.

#include <optional>
#include <string>

#include "app/tracking_stage.h"
#include "pipeline/snapshot.h"

namespace hg::app {

/// "starting", "ok", "stale" or "failed".
[[nodiscard]] const char* StateName(pipeline::CameraState s);

/// The health line of snapshot `s`: cycle, ok or DEGRADED (also while
/// `foreign_publisher`: another publisher writes this daemon's topics, as
/// the status samples say), how far an aborted update refined, volumes,
/// times, then the tracker's figures (`tracking`, when it runs) and each
/// camera's state, frame rate and fault.
[[nodiscard]] std::string HealthLine(const pipeline::OccupancySnapshot& s,
                                     const std::optional<TrackingStats>& tracking,
                                     bool foreign_publisher);

}  // namespace hg::app
