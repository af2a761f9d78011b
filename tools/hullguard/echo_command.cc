// `hullguard echo`: subscribe to the daemon's DDS topics and print one line per
// sample, plus a line whenever a requested deadline is missed (docs/dds.md).
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <deque>
#include <memory>
#include <string>
#include <vector>

#include "capture/camera_health.h"
#include "common/cli_checks.h"
#include "common/json.h"
#include "hullguard.h"
#include "hullguard/commands.h"
#include "hullguard/snapshot_picture.h"
#include "publish/dds.h"
#include "publish/dds_publisher.h"

namespace hg::tools {
namespace {

using Clock = std::chrono::steady_clock;
namespace dds = publish::dds;

struct EchoFlags {
  int domain = 0;
  std::string prefix = "hullguard";
  int count = 0;         // 0 = until the timeout (or forever).
  double timeout_s = 0;  // 0 = no timeout.
  double deadline_ms = 500;
  bool json = false;
  std::string topic = "all";  // occupancy, status, tracks or all.
  std::string snapshot;       // PNG of the last occupancy sample; empty: none.
  std::string latency_out;    // Every occupancy sample's latency, one per line; empty: none.
};

bool Shows(const EchoFlags& f, const char* topic) { return f.topic == "all" || f.topic == topic; }

// The cells of one occupancy sample (for --snapshot).
struct OccupancyCells {
  std::vector<hullguard_GridRun> occupied, occluded;
  common::Box3 bounds;
  int depth = 0;
  std::uint64_t sequence = 0;
};

// Occupancy samples kept for --snapshot: tracks arrive after the occupancy
// they were computed from, and are drawn over that one when it is still here.
constexpr std::size_t kRecentOccupancy = 16;

// What the last samples held (for --snapshot) and the latencies seen.
struct EchoRecord {
  std::deque<OccupancyCells> recent;    // Newest last.
  std::vector<hullguard_Track> tracks;  // Of the last tracks sample.
  std::uint64_t tracks_sequence = 0;
  bool has_tracks = false;
  std::vector<double> latency_ms;  // Received (CLOCK_REALTIME) minus stamp.
};

std::int64_t RealtimeNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

void Record(const hullguard_Occupancy& s, bool keep_cells, EchoRecord* r) {
  r->latency_ms.push_back(static_cast<double>(RealtimeNs() - s.stamp_ns) * 1e-6);
  if (!keep_cells) return;
  if (r->recent.size() == kRecentOccupancy) r->recent.pop_front();
  OccupancyCells& o = r->recent.emplace_back();
  o.occupied.assign(s.occupied._buffer, s.occupied._buffer + s.occupied._length);
  o.occluded.assign(s.occluded._buffer, s.occluded._buffer + s.occluded._length);
  o.bounds.min = Eigen::Vector3d(s.bounds_min[0], s.bounds_min[1], s.bounds_min[2]);
  o.bounds.max = Eigen::Vector3d(s.bounds_max[0], s.bounds_max[1], s.bounds_max[2]);
  o.depth = s.depth;
  o.sequence = s.sequence;
}

void RecordTracks(const hullguard_Tracks& s, EchoRecord* r) {
  r->tracks.assign(s.tracked._buffer, s.tracked._buffer + s.tracked._length);
  r->tracks_sequence = s.sequence;
  r->has_tracks = true;
}

Eigen::Vector3d Vec(const float (&v)[3]) { return {v[0], v[1], v[2]}; }

// The newest occupancy sample, or the one the last tracks sample was computed
// from while it is still kept, with those tracks drawn over it.
void WriteEchoSnapshot(const EchoRecord& r, const std::string& path) {
  if (r.recent.empty()) return;
  const OccupancyCells* shown = &r.recent.back();
  for (const OccupancyCells& o : r.recent) {
    if (r.has_tracks && o.sequence == r.tracks_sequence) shown = &o;
  }
  std::vector<SnapshotBox> boxes;
  const double n = static_cast<double>(1 << shown->depth);
  const Eigen::Vector3d cell = shown->bounds.Size() / n;
  for (const auto* cells : {&shown->occupied, &shown->occluded}) {
    for (const hullguard_GridRun& c : *cells) {
      common::Box3 box;
      box.min = shown->bounds.min + Eigen::Vector3d(c.x, c.y, c.z).cwiseProduct(cell);
      box.max = box.min + Eigen::Vector3d(c.length, 1, 1).cwiseProduct(cell);
      boxes.push_back({box, cells == &shown->occupied});
    }
  }
  std::vector<SnapshotTrack> tracks;
  for (const hullguard_Track& t : r.tracks) {
    tracks.push_back({t.id, Vec(t.centre), Vec(t.half_axes), Vec(t.velocity), t.occluded});
  }
  char caption[160];
  const int side = 1 << shown->depth;
  if (!r.has_tracks) {
    std::snprintf(caption, sizeof(caption), "Occupancy sample %llu, %d x %d x %d grid.",
                  static_cast<unsigned long long>(shown->sequence), side, side, side);
  } else if (r.tracks_sequence == shown->sequence) {
    std::snprintf(
        caption, sizeof(caption), "Occupancy sample %llu, %d x %d x %d grid; tracks: %zu.",
        static_cast<unsigned long long>(shown->sequence), side, side, side, tracks.size());
  } else {
    std::snprintf(caption, sizeof(caption),
                  "Occupancy sample %llu, %d x %d x %d grid; tracks of sample %llu: %zu.",
                  static_cast<unsigned long long>(shown->sequence), side, side, side,
                  static_cast<unsigned long long>(r.tracks_sequence), tracks.size());
  }
  WriteSnapshotPicture(boxes, shown->bounds, {}, {}, caption, path, tracks);
}

void PrintLatency(const EchoRecord& r, bool json) {
  if (r.latency_ms.empty()) return;
  std::vector<double> v = r.latency_ms;
  std::sort(v.begin(), v.end());
  auto at = [&](double q) {
    return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size())))];
  };
  if (json) {
    std::printf(
        "{\"summary\": \"latency\", \"samples\": %zu, \"median_ms\": %.3f, \"p99_ms\": %.3f, "
        "\"max_ms\": %.3f}\n",
        v.size(), at(0.5), at(0.99), v.back());
  } else {
    std::printf("latency stamp->received: samples=%zu median=%.2f ms p99=%.2f ms max=%.2f ms\n",
                v.size(), at(0.5), at(0.99), v.back());
  }
}

constexpr dds_attach_t kOccupancyToken = 1;
constexpr dds_attach_t kStatusToken = 2;
constexpr dds_attach_t kTracksToken = 3;
constexpr std::uint32_t kStatusMask =
    DDS_DATA_AVAILABLE_STATUS | DDS_REQUESTED_DEADLINE_MISSED_STATUS |
    DDS_LIVELINESS_CHANGED_STATUS | DDS_REQUESTED_INCOMPATIBLE_QOS_STATUS;

// SIGINT or SIGTERM: stop waiting, then summarise (and write the snapshot)
// as at the end of --count or --timeout.
std::atomic<bool> g_interrupted{false};
extern "C" void OnInterrupt(int /*signal*/) { g_interrupted.store(true); }

const char* CameraStateName(std::uint8_t state) {
  switch (state) {
    case 0:
      return "starting";
    case 1:
      return "ok";
    case 2:
      return "stale";
    case 3:
      return "failed";
    default:
      return "unknown";
  }
}

std::uint64_t Cells(const dds_sequence_hullguard_GridRun& runs) {
  std::uint64_t n = 0;
  for (std::uint32_t i = 0; i < runs._length; ++i) n += runs._buffer[i].length;
  return n;
}

const char* FaultName(std::uint8_t fault) {
  return capture::ToString(static_cast<capture::CameraFault>(fault));
}

double OccupiedVolumeM3(const hullguard_Occupancy& s) {
  double volume = 1.0;
  for (int i = 0; i < 3; ++i) volume *= static_cast<double>(s.bounds_max[i]) - s.bounds_min[i];
  const double cells_per_axis = static_cast<double>(std::uint64_t{1} << std::min<int>(s.depth, 21));
  return volume / (cells_per_axis * cells_per_axis * cells_per_axis) *
         static_cast<double>(Cells(s.occupied));
}

// Camera names come from the daemon's config; keep JSON valid whatever they hold.
std::string JsonString(const char* s) { return common::JsonString(s != nullptr ? s : ""); }

void PrintOccupancy(const hullguard_Occupancy& s, bool json) {
  if (json) {
    std::printf(
        "{\"topic\": \"occupancy\", \"sequence\": %llu, \"stamp_ns\": %lld, \"complete\": %s, "
        "\"refined_cell_m\": %.5g, \"depth\": %d, \"occupied\": %llu, \"occluded\": %llu, "
        "\"runs\": %u, "
        "\"occupied_m3\": %.6g, \"knowledge_filter\": %s, \"filtered_m3\": %.6g, "
        "\"degraded\": %s}\n",
        static_cast<unsigned long long>(s.sequence), static_cast<long long>(s.stamp_ns),
        s.complete ? "true" : "false", s.refined_cell_m, s.depth,
        static_cast<unsigned long long>(Cells(s.occupied)),
        static_cast<unsigned long long>(Cells(s.occluded)), s.occupied._length + s.occluded._length,
        OccupiedVolumeM3(s), s.knowledge_filter ? "true" : "false", s.filtered_m3,
        s.degraded ? "true" : "false");
  } else {
    std::printf(
        "occupancy seq=%llu complete=%d refined_cell_m=%.5g depth=%d occupied=%llu occluded=%llu "
        "runs=%u occupied_m3=%.6g",
        static_cast<unsigned long long>(s.sequence), s.complete ? 1 : 0, s.refined_cell_m, s.depth,
        static_cast<unsigned long long>(Cells(s.occupied)),
        static_cast<unsigned long long>(Cells(s.occluded)), s.occupied._length + s.occluded._length,
        OccupiedVolumeM3(s));
    // Only with the filter on, so the usual line stays as it was.
    if (s.knowledge_filter) std::printf(" knowledge_filter=1 filtered_m3=%.6g", s.filtered_m3);
    if (s.degraded) std::printf(" degraded=1");
    std::printf("\n");
  }
}

void PrintStatus(const hullguard_Status& s, bool json) {
  std::string cameras;
  for (std::uint32_t i = 0; i < s.cameras._length; ++i) {
    const hullguard_CameraStatus& c = s.cameras._buffer[i];
    char buf[256];
    if (json) {
      std::snprintf(buf, sizeof(buf), "%s{\"name\": ", i == 0 ? "" : ", ");
      cameras += buf + JsonString(c.name);
      std::snprintf(
          buf, sizeof(buf),
          ", \"state\": \"%s\", \"fps\": %.2f, \"frame_age_ms\": %.1f, \"frames\": %llu, "
          "\"drops\": %llu, \"corrupt\": %llu, \"fault\": \"%s\", \"completed\": %llu, "
          "\"failed\": %llu, \"underruns\": %llu, \"resends\": %llu, \"margin_m\": %.3f}",
          CameraStateName(c.state), c.fps, c.frame_age_ms,
          static_cast<unsigned long long>(c.frames), static_cast<unsigned long long>(c.drops),
          static_cast<unsigned long long>(c.corrupt), FaultName(c.fault),
          static_cast<unsigned long long>(c.completed), static_cast<unsigned long long>(c.failed),
          static_cast<unsigned long long>(c.underruns), static_cast<unsigned long long>(c.resends),
          c.margin_m);
      cameras += buf;
    } else {
      std::snprintf(buf, sizeof(buf), ":%s@%.1ffps:age=%.0fms%s%s", CameraStateName(c.state), c.fps,
                    c.frame_age_ms, c.fault != 0 ? ":" : "",
                    c.fault != 0 ? FaultName(c.fault) : "");
      cameras += (i == 0 ? "" : " ") + std::string(c.name != nullptr ? c.name : "") + buf;
      if (c.drops + c.corrupt > 0) {
        std::snprintf(buf, sizeof(buf), ":drops=%llu,corrupt=%llu",
                      static_cast<unsigned long long>(c.drops),
                      static_cast<unsigned long long>(c.corrupt));
        cameras += buf;
      }
      if (c.margin_m > 0.0F) {
        std::snprintf(buf, sizeof(buf), ":margin=%.1fcm", c.margin_m * 100.0F);
        cameras += buf;
      }
      // Transport counters: GigE Vision sources only (all zero otherwise).
      if (c.completed + c.failed + c.underruns + c.resends > 0) {
        std::snprintf(buf, sizeof(buf), ":completed=%llu,failed=%llu,underruns=%llu,resends=%llu",
                      static_cast<unsigned long long>(c.completed),
                      static_cast<unsigned long long>(c.failed),
                      static_cast<unsigned long long>(c.underruns),
                      static_cast<unsigned long long>(c.resends));
        cameras += buf;
      }
    }
  }
  if (json) {
    std::printf(
        "{\"topic\": \"status\", \"sequence\": %llu, \"stamp_ns\": %lld, \"latency_ms\": %.3f, "
        "\"degraded\": %s, \"deadline_misses\": %llu, "
        "\"missed_cycles\": %llu, \"silhouette_ms\": %.3f, \"skew_ms\": %.3f, "
        "\"octree_ms\": %.3f, \"cycle_ms\": %.3f, \"cameras\": [%s]}\n",
        static_cast<unsigned long long>(s.sequence), static_cast<long long>(s.stamp_ns),
        static_cast<double>(RealtimeNs() - s.stamp_ns) * 1e-6, s.degraded ? "true" : "false",
        static_cast<unsigned long long>(s.deadline_misses),
        static_cast<unsigned long long>(s.missed_cycles), s.silhouette_ms, s.skew_ms, s.octree_ms,
        s.cycle_ms, cameras.c_str());
  } else {
    std::printf(
        "status seq=%llu degraded=%d deadline_misses=%llu missed_cycles=%llu cycle_ms=%.2f "
        "cameras=[%s]\n",
        static_cast<unsigned long long>(s.sequence), s.degraded ? 1 : 0,
        static_cast<unsigned long long>(s.deadline_misses),
        static_cast<unsigned long long>(s.missed_cycles), s.cycle_ms, cameras.c_str());
  }
}

// "[1.23,0.90,0.95]" / "(1.23 0.90 0.95)".
std::string Triple(const float (&v)[3], bool json) {
  char buf[96];
  std::snprintf(buf, sizeof(buf), json ? "[%.4g, %.4g, %.4g]" : "(%.2f %.2f %.2f)", v[0], v[1],
                v[2]);
  return buf;
}

void PrintTracks(const hullguard_Tracks& s, bool json) {
  std::string tracks;
  for (std::uint32_t i = 0; i < s.tracked._length; ++i) {
    const hullguard_Track& t = s.tracked._buffer[i];
    char buf[160];
    if (json) {
      std::snprintf(buf, sizeof(buf), "%s{\"id\": %u, \"centre\": ", i == 0 ? "" : ", ", t.id);
      tracks += buf + Triple(t.centre, true) + ", \"half_axes\": " + Triple(t.half_axes, true) +
                ", \"velocity\": " + Triple(t.velocity, true) +
                ", \"spread\": " + Triple(t.spread, true);
      std::snprintf(buf, sizeof(buf),
                    ", \"occluded\": %s, \"occluded_fraction\": %.3f, \"age_s\": %.3f, "
                    "\"time_since_support_s\": %.3f}",
                    t.occluded ? "true" : "false", t.occluded_fraction, t.age_s,
                    t.time_since_support_s);
      tracks += buf;
    } else {
      std::snprintf(buf, sizeof(buf), " [#%u c=", t.id);
      tracks += buf + Triple(t.centre, false) + " r=" + Triple(t.half_axes, false) +
                " v=" + Triple(t.velocity, false) + " sd=" + Triple(t.spread, false);
      std::snprintf(buf, sizeof(buf), " age=%.1fs%s", t.age_s, t.occluded ? " occluded" : "");
      tracks += buf;
      if (t.time_since_support_s > 0) {
        std::snprintf(buf, sizeof(buf), " unsupported=%.2fs", t.time_since_support_s);
        tracks += buf;
      }
      tracks += "]";
    }
  }
  if (json) {
    std::printf(
        "{\"topic\": \"tracks\", \"sequence\": %llu, \"stamp_ns\": %lld, \"degraded\": %s, "
        "\"tracks\": [%s]}\n",
        static_cast<unsigned long long>(s.sequence), static_cast<long long>(s.stamp_ns),
        s.degraded ? "true" : "false", tracks.c_str());
  } else {
    std::printf("tracks seq=%llu degraded=%d count=%u%s\n",
                static_cast<unsigned long long>(s.sequence), s.degraded ? 1 : 0, s.tracked._length,
                tracks.c_str());
  }
}

void PrintEvent(const char* stream, const char* event, std::uint32_t total, bool json) {
  if (json) {
    std::printf("{\"topic\": \"%s\", \"event\": \"%s\", \"total\": %u}\n", stream, event, total);
  } else {
    std::printf("%s stream %s (total %u)\n", stream, event, total);
  }
}

// One subscribed topic: its reader and whether it currently counts as stale.
struct Stream {
  const char* name;
  dds::Reader reader;
  bool stale = false;
  bool alive = false;
};

// Reads (and so resets) the deadline, liveliness and QoS statuses of
// `stream`, every time the waitset wakes for it: a status left set would wake
// it again at once, forever. Reports deadline and liveliness changes once per
// transition when `print`, and a writer whose QoS does not match, on stderr.
void CheckEvents(Stream& stream, bool json, bool print, double deadline_ms) {
  dds_requested_deadline_missed_status_t missed{};
  if (dds_get_requested_deadline_missed_status(stream.reader.handle(), &missed) == DDS_RETCODE_OK &&
      missed.total_count_change > 0 && !stream.stale) {
    stream.stale = true;
    if (print) PrintEvent(stream.name, "stale", missed.total_count, json);
  }
  dds_liveliness_changed_status_t live{};
  if (dds_get_liveliness_changed_status(stream.reader.handle(), &live) == DDS_RETCODE_OK) {
    if (print && stream.alive && live.alive_count == 0) {
      PrintEvent(stream.name, "writer lost", 0, json);
    }
    stream.alive = live.alive_count > 0;
  }
  dds_requested_incompatible_qos_status_t qos{};
  if (dds_get_requested_incompatible_qos_status(stream.reader.handle(), &qos) == DDS_RETCODE_OK &&
      qos.total_count_change > 0) {
    if (qos.last_policy_id == DDS_DEADLINE_QOS_POLICY_ID) {
      std::fprintf(stderr,
                   "hullguard echo: a %s writer offers a longer deadline than --deadline-ms %.0f "
                   "(a daemon at a low rate_hz): its samples are not received; raise "
                   "--deadline-ms\n",
                   stream.name, deadline_ms);
    } else {
      std::fprintf(stderr,
                   "hullguard echo: a %s writer's QoS does not match this reader's (policy %d): "
                   "its samples are not received\n",
                   stream.name, static_cast<int>(qos.last_policy_id));
    }
  }
}

// Takes and prints every available sample; returns how many were valid.
template <typename Sample, typename PrintFn>
int TakeAll(Stream& stream, bool json, PrintFn print) {
  constexpr int kBatch = 16;
  int taken = 0;
  for (;;) {
    std::array<void*, kBatch> samples{};
    std::array<dds_sample_info_t, kBatch> infos{};
    const dds_return_t n =
        dds_take(stream.reader.handle(), samples.data(), infos.data(), kBatch, kBatch);
    if (n <= 0) break;
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      print(*static_cast<const Sample*>(samples[i]), json);
      stream.stale = false;
      ++taken;
    }
    dds_return_loan(stream.reader.handle(), samples.data(), n);
  }
  std::fflush(stdout);
  return taken;
}

int RunEcho(const EchoFlags& f) {
  const auto deadline = std::chrono::nanoseconds(static_cast<std::int64_t>(f.deadline_ms * 1e6));
  dds::Participant participant(static_cast<dds_domainid_t>(f.domain));
  dds::Topic occupancy_topic(participant, &hullguard_Occupancy_desc,
                             publish::OccupancyTopicName(f.prefix));
  dds::Topic status_topic(participant, &hullguard_Status_desc, publish::StatusTopicName(f.prefix));
  Stream occupancy{"occupancy", dds::Reader(participant, occupancy_topic,
                                            publish::OccupancyReaderQos(deadline).get())};
  Stream status{"status",
                dds::Reader(participant, status_topic, publish::StatusReaderQos(deadline).get())};
  dds::Topic tracks_topic(participant, &hullguard_Tracks_desc, publish::TracksTopicName(f.prefix));
  Stream tracks{"tracks",
                dds::Reader(participant, tracks_topic, publish::TracksReaderQos(deadline).get())};
  dds::WaitSet waitset(participant);
  for (Stream* s : {&occupancy, &status, &tracks}) {
    dds::Check(dds_set_status_mask(s->reader.handle(), kStatusMask), "dds_set_status_mask");
  }
  waitset.Attach(occupancy.reader, kOccupancyToken);
  waitset.Attach(status.reader, kStatusToken);
  waitset.Attach(tracks.reader, kTracksToken);

  const auto start = Clock::now();
  const auto end = start + std::chrono::duration_cast<Clock::duration>(
                               std::chrono::duration<double>(f.timeout_s));
  int received = 0;
  bool told_waiting = false;
  EchoRecord record;
  g_interrupted.store(false);
  struct sigaction action {};
  action.sa_handler = OnInterrupt;
  sigemptyset(&action.sa_mask);
  struct sigaction old_int {
  }, old_term{};
  sigaction(SIGINT, &action, &old_int);
  sigaction(SIGTERM, &action, &old_term);
  while ((f.count == 0 || received < f.count) && !g_interrupted.load()) {
    if (received == 0 && !told_waiting && Clock::now() - start > std::chrono::seconds(3)) {
      told_waiting = true;
      std::fprintf(stderr,
                   "hullguard echo: no occupancy sample yet on domain %d, topic %s (is hullguardd "
                   "running, with this dds.domain_id and topic_prefix?)\n",
                   f.domain, publish::OccupancyTopicName(f.prefix).c_str());
    }
    // Short waits, so that a signal ends the wait promptly.
    auto wait = std::chrono::nanoseconds(std::chrono::milliseconds(200));
    if (f.timeout_s > 0) {
      const auto left = end - Clock::now();
      if (left <= Clock::duration::zero()) break;
      wait = std::min<std::chrono::nanoseconds>(wait, left);
    }
    std::array<dds_attach_t, 3> triggered{};
    const int n = waitset.Wait(triggered.data(), triggered.size(), wait);
    for (int i = 0; i < n; ++i) {
      if (triggered[i] == kOccupancyToken) {
        received += TakeAll<hullguard_Occupancy>(occupancy, f.json,
                                                 [&](const hullguard_Occupancy& sample, bool json) {
                                                   Record(sample, !f.snapshot.empty(), &record);
                                                   if (Shows(f, "occupancy"))
                                                     PrintOccupancy(sample, json);
                                                 });
        CheckEvents(occupancy, f.json, Shows(f, "occupancy"), f.deadline_ms);
      } else if (triggered[i] == kTracksToken) {
        TakeAll<hullguard_Tracks>(tracks, f.json, [&](const hullguard_Tracks& sample, bool json) {
          RecordTracks(sample, &record);
          if (Shows(f, "tracks")) PrintTracks(sample, json);
        });
        CheckEvents(tracks, f.json, Shows(f, "tracks"), f.deadline_ms);
      } else {
        TakeAll<hullguard_Status>(status, f.json, [&](const hullguard_Status& sample, bool json) {
          if (Shows(f, "status")) PrintStatus(sample, json);
        });
        CheckEvents(status, f.json, Shows(f, "status"), f.deadline_ms);
      }
    }
    std::fflush(stdout);
  }
  sigaction(SIGINT, &old_int, nullptr);
  sigaction(SIGTERM, &old_term, nullptr);
  if (received == 0) {
    std::fprintf(stderr, "hullguard echo: no occupancy sample on domain %d, topic %s\n", f.domain,
                 publish::OccupancyTopicName(f.prefix).c_str());
    return kExitFailure;
  }
  PrintLatency(record, f.json);
  if (!f.latency_out.empty()) {
    std::FILE* out = std::fopen(f.latency_out.c_str(), "w");
    bool ok = out != nullptr;
    for (std::size_t i = 0; ok && i < record.latency_ms.size(); ++i) {
      ok = std::fprintf(out, "%.3f\n", record.latency_ms[i]) > 0;
    }
    if (out != nullptr) ok = std::fclose(out) == 0 && ok;
    if (!ok) {
      std::fprintf(stderr, "hullguard echo: cannot write %s\n", f.latency_out.c_str());
      return kExitFailure;
    }
  }
  if (!f.snapshot.empty()) {
    WriteEchoSnapshot(record, f.snapshot);
    std::fprintf(stderr, "hullguard echo: wrote %s\n", f.snapshot.c_str());
  }
  return kExitOk;
}

}  // namespace

void RegisterEcho(CLI::App& app, int* exit_code) {
  auto flags = std::make_shared<EchoFlags>();
  CLI::App* cmd = app.add_subcommand(
      "echo", "Print the occupancy, status and tracks samples hullguardd publishes over DDS");
  cmd->add_option("--domain", flags->domain, "DDS domain id")->check(hg::cli::Range(0, 232));
  cmd->add_option("--prefix", flags->prefix, "Topic prefix (dds.topic_prefix of the daemon)");
  cmd->add_option("--count", flags->count, "Exit after this many occupancy samples (0: never)")
      ->check(hg::cli::kNonNegative);
  cmd->add_option("--timeout", flags->timeout_s, "Give up after this many seconds (0: never)")
      ->check(hg::cli::kNonNegative)
      ->check(hg::cli::kFinite);
  cmd->add_option("--deadline-ms", flags->deadline_ms,
                  "Requested deadline (ms); must be >= the daemon's two cycles to match")
      ->check(hg::cli::Range(1.0, 3.6e6))
      ->check(hg::cli::kFinite);
  cmd->add_flag("--json", flags->json, "One JSON object per line");
  cmd->add_option("--topic", flags->topic, "Print samples of this topic only")
      ->check(CLI::IsMember({"occupancy", "status", "tracks", "all"}));
  cmd->add_option("--snapshot", flags->snapshot,
                  "Write a picture (PNG: top, side and perspective views) of the last occupancy "
                  "sample at exit, with the tracks computed from it");
  cmd->add_option("--latency-out", flags->latency_out,
                  "Write each occupancy sample's latency (ms, capture stamp to arrival) to this "
                  "file at exit, one per line in arrival order");
  cmd->callback([flags, exit_code] { *exit_code = RunEcho(*flags); });
}

}  // namespace hg::tools
