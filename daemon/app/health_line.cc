#include "app/health_line.h"

#include <cstdio>
#include <cstring>

#include <fmt/format.h>

#include "capture/camera_health.h"

namespace hg::app {

const char* StateName(pipeline::CameraState s) {
  switch (s) {
    case pipeline::CameraState::kStarting:
      return "starting";
    case pipeline::CameraState::kOk:
      return "ok";
    case pipeline::CameraState::kStale:
      return "stale";
    case pipeline::CameraState::kFailed:
      return "failed";
  }
  return "?";
}

std::string HealthLine(const pipeline::OccupancySnapshot& s,
                       const std::optional<TrackingStats>& tracking, bool foreign_publisher,
                       std::uint64_t failed_writes) {
  const double cell = s.bounds.Size().prod() / static_cast<double>(1ULL << (3 * s.depth));
  // An aborted update says how far it refined: cells of that size everywhere.
  char aborted[96] = "";
  if (!s.complete) {
    // Aborted at the deadline, or (only) short of nodes: said below.
    const char* what = s.aborted ? "aborted" : "incomplete";
    if (s.refined_cell_m > 0.0) {
      std::snprintf(aborted, sizeof(aborted), " (%s, refined to %.1f cm)", what,
                    s.refined_cell_m * 100.0);
    } else {
      std::snprintf(aborted, sizeof(aborted), " (%s)", what);
    }
  }
  if (s.health.unsplit_nodes > 0) {
    const std::size_t used = std::strlen(aborted);
    std::snprintf(aborted + used, sizeof(aborted) - used, " (node store full: %lld unsplit)",
                  static_cast<long long>(s.health.unsplit_nodes));
  }
  char head[256];
  std::snprintf(head, sizeof(head),
                "cycle %llu %s%s occupied %.3f m^3 occluded %.3f m^3 octree %.1f ms cycle %.1f ms "
                "skew %.1f ms deadline misses %llu missed cycles %llu |",
                static_cast<unsigned long long>(s.sequence),
                s.health.degraded || foreign_publisher || failed_writes > 0 ? "DEGRADED" : "ok",
                aborted, cell * static_cast<double>(pipeline::OccupancySnapshot::Cells(s.occupied)),
                cell * static_cast<double>(pipeline::OccupancySnapshot::Cells(s.occluded)),
                s.health.octree_ms, s.health.cycle_ms, s.health.skew_ms,
                static_cast<unsigned long long>(s.health.deadline_misses),
                static_cast<unsigned long long>(s.health.missed_cycles));
  std::string line = head;
  if (foreign_publisher) line.insert(line.size() - 2, " another publisher on the topics");
  if (failed_writes > 0) {
    line.insert(line.size() - 2, " DDS writes failed " + std::to_string(failed_writes));
  }
  if (s.health.phase_lock && !s.health.phase_locked) {
    line.insert(line.size() - 2, " phase unlocked");  // Before " |".
  }
  if (s.health.knowledge_filter) {
    char part[64];
    std::snprintf(part, sizeof(part), " filtered %.4f m^3 (%d blobs)", s.health.filtered_m3,
                  s.health.filtered_blobs);
    line.insert(line.size() - 2, part);  // Before " |".
  }
  if (tracking.has_value()) {
    // The last tracked cycle's, which may be a cycle or two behind.
    const TrackingStats& t = *tracking;
    char part[96];
    std::snprintf(part, sizeof(part), " tracks %d tracking %.1f ms", t.tracks, t.last_ms);
    line.insert(line.size() - 2, part);  // Before " |".
    if (t.skipped > 0) {
      line.insert(line.size() - 2, std::string(" skipped ").append(std::to_string(t.skipped)));
    }
    // Snapshots of updates that did not refine far enough to track on: at a
    // depth the machine cannot finish within the deadline, most of them.
    if (t.untracked > 0) {
      line.insert(line.size() - 2, std::string(" untracked ")
                                       .append(std::to_string(t.untracked))
                                       .append(" of ")
                                       .append(std::to_string(t.untracked + t.cycles)));
    }
  }
  for (const pipeline::CameraHealth& c : s.health.cameras) {
    char cam[128];
    std::snprintf(cam, sizeof(cam), " %s %s %.0f fps", c.name.c_str(), StateName(c.state), c.fps);
    line += cam;
    if (c.margin_m > 0.0) {
      std::snprintf(cam, sizeof(cam), " margin %.1f cm", c.margin_m * 100.0);
      line += cam;
    }
    if (c.shifted && c.misalignment_px < 0.0) {
      // Its view has yet to be found (against its taught view): frames wait.
      line += " view not matched";
    } else if (c.shifted) {
      // Its frames wait for the view to be found back in place (or moved).
      std::snprintf(cam, sizeof(cam), " shifted %.1f px", c.misalignment_px);
      line += cam;
    }
    if (c.learning) line += " learning";  // The background: all foreground meanwhile.
    if (c.corrupt > 0) line += std::string(" corrupt ").append(std::to_string(c.corrupt));
    // Transport trouble of a GigE Vision camera: lost packets, host too slow.
    if (c.failed > 0) line += std::string(" failed ").append(std::to_string(c.failed));
    if (c.underruns > 0) line += std::string(" underruns ").append(std::to_string(c.underruns));
    if (c.fault != 0) {
      line += std::string(" (").append(ToString(static_cast<capture::CameraFault>(c.fault))) + ")";
    }
  }
  return line;
}

bool ForegroundWatch::Due(std::size_t camera, std::optional<Clock::time_point> since,
                          Clock::time_point now) {
  if (!since || *since != run_[camera]) told_[camera] = false;
  if (!since) return false;
  run_[camera] = *since;
  if (told_[camera] || now - *since < after_) return false;
  told_[camera] = true;
  return true;
}

std::string ForegroundWarning(const std::string& name, double seconds) {
  return fmt::format(
      "{}: a third of the view or more has been foreground for {:.0f} s. If nobody stands that "
      "close to the camera, the light has changed in part of the view (a bank of lamps, "
      "daylight) while the rest kept it: the changed part stays foreground, occupied, until the "
      "background is learned again with the cell empty (hullguardd --config FILE "
      "--learn-background, then restart)",
      name, seconds);
}

}  // namespace hg::app
