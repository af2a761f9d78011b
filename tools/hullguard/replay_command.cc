// `hullguard replay`: the daemon's pipeline run lock-step over a recording, as
// fast as it goes and deterministically, with a digest of the output stream
// for regression checks, and for synth recordings a check of every cycle's
// snapshot against the ground truth (no point inside a person published free).
#include <algorithm>
#include <array>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include <Eigen/Core>

#include "app/config.h"
#include "app/health_line.h"
#include "app/pipeline_setup.h"
#include "capture/replay_source.h"
#include "common/cli_checks.h"
#include "common/config_error.h"
#include "hullguard/commands.h"
#include "hullguard/snapshot_picture.h"
#include "pipeline/pipeline.h"
#include "sim/ground_truth.h"

namespace hg::tools {
namespace {

struct ReplayFlags {
  std::string config;
  std::string recording;
  int threads = 0;  // 0: the config's.
  int frames = 0;   // 0: all.
  bool digest = false;
  std::string expect;
  std::string snapshot;
  std::string truth;  // Empty: the synth recording's ground_truth.yaml, if any.
  bool no_truth = false;
};

// FNV-1a, 64 bit: enough to tell two output streams apart in a regression
// check, and simple enough to reproduce anywhere.
class Digest {
 public:
  void Add(const void* data, std::size_t size) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < size; ++i) hash_ = (hash_ ^ p[i]) * 0x100000001b3ULL;
  }
  template <class T>
  void AddValue(T v) {
    Add(&v, sizeof(v));
  }
  [[nodiscard]] std::string Hex() const {
    char buf[17];
    std::snprintf(buf, sizeof(buf), "%016" PRIx64, hash_);
    return buf;
  }

 private:
  std::uint64_t hash_ = 0xcbf29ce484222325ULL;
};

void AddSnapshot(const pipeline::OccupancySnapshot& s, Digest* d) {
  d->AddValue(s.sequence);
  d->AddValue(s.stamp_ns);
  d->AddValue(static_cast<std::uint8_t>(s.complete));
  d->AddValue(static_cast<std::int32_t>(s.depth));
  for (const auto* runs : {&s.occupied, &s.occluded}) {
    d->AddValue(static_cast<std::uint64_t>(runs->size()));
    for (const pipeline::GridRun& r : *runs) {
      const std::uint16_t v[4] = {r.x, r.y, r.z, r.length};
      d->Add(v, sizeof(v));
    }
  }
  for (const pipeline::CameraHealth& c : s.health.cameras) {
    d->AddValue(static_cast<std::uint8_t>(c.state));
    d->AddValue(c.fault);
  }
}

// What became of each camera over a replay: cycles per state, the first
// cycle of each fault, and the registrations that found its view shifted.
// Thread-compatible.
class CameraTally {
 public:
  explicit CameraTally(std::size_t cameras) : cameras_(cameras) {}
  void Add(std::int64_t cycle, const pipeline::OccupancySnapshot& s) {
    for (std::size_t c = 0; c < cameras_.size() && c < s.health.cameras.size(); ++c) {
      const pipeline::CameraHealth& h = s.health.cameras[c];
      Camera& t = cameras_[c];
      t.name = h.name;
      ++t.in_state[static_cast<std::size_t>(h.state)];
      if (h.fault != 0 && h.fault < t.first_fault.size() && t.first_fault[h.fault] < 0) {
        t.first_fault[h.fault] = cycle;
      }
      if (h.shifted) ++t.shifted;
      t.largest_px = std::max(t.largest_px, h.misalignment_px);
    }
  }
  // Cycles counted, not run, in a silence of every camera: all stale.
  void AddSilence(std::int64_t cycles) {
    for (Camera& t : cameras_) {
      t.in_state[static_cast<std::size_t>(pipeline::CameraState::kStale)] +=
          static_cast<std::uint64_t>(cycles);
    }
  }
  // One line per camera that was not ok after it started, or was shifted.
  void Print() const {
    for (const Camera& t : cameras_) {
      const std::size_t ok = static_cast<std::size_t>(pipeline::CameraState::kOk);
      const std::size_t starting = static_cast<std::size_t>(pipeline::CameraState::kStarting);
      std::uint64_t troubled = 0;
      for (std::size_t k = 0; k < t.in_state.size(); ++k) {
        if (k != ok && k != starting) troubled += t.in_state[k];
      }
      if (troubled == 0 && t.shifted == 0 && t.in_state[ok] > 0) continue;
      std::string line = "  " + t.name + ":";
      const char* sep = " ";
      for (std::size_t k = 0; k < t.in_state.size(); ++k) {
        if (t.in_state[k] == 0) continue;
        line += sep;
        line += app::StateName(static_cast<pipeline::CameraState>(k));
        line += " " + std::to_string(t.in_state[k]);
        sep = ", ";
      }
      line += " cycles";
      for (std::size_t f = 1; f < t.first_fault.size(); ++f) {
        if (t.first_fault[f] < 0) continue;
        line += std::string("; ") + capture::ToString(static_cast<capture::CameraFault>(f)) +
                " from cycle " + std::to_string(t.first_fault[f]);
      }
      if (t.shifted > 0) {
        char part[96];
        std::snprintf(part, sizeof(part), "; view shifted in %" PRIu64 " cycles", t.shifted);
        line += part;
      }
      if (t.largest_px >= 0.0) {
        char part[96];
        std::snprintf(part, sizeof(part), "; largest misalignment %.2f px", t.largest_px);
        line += part;
      }
      std::printf("%s\n", line.c_str());
    }
  }

 private:
  struct Camera {
    std::string name;
    std::array<std::uint64_t, 4> in_state{};  // By pipeline::CameraState.
    std::array<std::int64_t, 8> first_fault{-1, -1, -1, -1, -1, -1, -1, -1};
    std::uint64_t shifted = 0;
    double largest_px = -1.0;
  };
  std::vector<Camera> cameras_;
};

// Ground truth check of a synth recording: points sampled inside every person
// of truth frame i are looked up in the snapshot of frame set i. A point
// inside a person must never lie in a cell the snapshot publishes free
// (neither occupied nor occluded).
//
// Capture offsets: camera c captured frame i at the truth's time plus its
// offset, so it saw each person up to max |offset| away from the pose in the
// truth (and the snapshot is stamped at the newest capture time of the set).
// A point counts only where it lies inside some body part deeper than that
// part can move in max |offset|: its speed times max |offset|, plus 1 cm for
// motion that is not straight within the frame; such a point was inside the
// body at every camera's capture time, so inside every camera's silhouette.
// A part's speed is the fastest of the person's velocity (of the feet, from
// the truth) and the speeds of the part's ends between consecutive truth
// frames over the capture times, max |offset| either way, and one frame
// beyond (a swinging forearm or shin moves faster than the feet; a person
// who starts to walk within them is faster there than around this frame).
// Without offsets the truth is exactly what the cameras saw: no margin.
//
// No cycle is skipped. The snapshot has no background-learning state (the
// background model reports all foreground while it learns), and a camera
// without frames yet (CameraState::kStarting) certifies nothing: every
// snapshot is conservative in every state, so skipping cycles would only
// hide the failure this check looks for.
//
// Thread-compatible.
class TruthCoverage {
 public:
  static constexpr int kPointsPerPerson = 200;
  static constexpr double kMarginM = 0.01;
  static constexpr std::size_t kShown = 5;  // Offending points printed.

  TruthCoverage(sim::GroundTruth truth, double max_offset_s)
      : truth_(std::move(truth)), max_offset_s_(max_offset_s) {}

  [[nodiscard]] int truth_frames() const { return static_cast<int>(truth_.frames.size()); }

  /// Samples the points of truth frame `frame` (deterministic: a seed per
  /// frame) and looks them up in `s`. Frames past the truth are not checked.
  void Check(int frame, const pipeline::OccupancySnapshot& s) {
    if (frame >= truth_frames()) return;
    ++frame_sets_;
    const std::vector<pipeline::GridRun>& occupied = SortedRuns(s.occupied, &occupied_scratch_);
    const std::vector<pipeline::GridRun>& occluded = SortedRuns(s.occluded, &occluded_scratch_);
    const sim::FrameTruth& ft = truth_.frames[static_cast<std::size_t>(frame)];
    std::mt19937_64 rng(0x9e3779b97f4a7c15ULL * static_cast<std::uint64_t>(frame + 1));
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    for (std::size_t person = 0; person < ft.people.size(); ++person) {
      const sim::BodyState& body = ft.people[person].state;
      const std::array<double, sim::kNumBodyParts> margin = Margins(frame, person);
      for (int k = 0; k < kPointsPerPerson; ++k) {
        // Uniform over parts, as tools/hullguard/scene_engine.cc samples:
        // small parts (hands, feet) get more points, where errors show first.
        const std::size_t part =
            static_cast<std::size_t>(u01(rng) * sim::kNumBodyParts) % sim::kNumBodyParts;
        const sim::BodyCapsule& c = body.parts[part];
        const Eigen::Vector3d lo = c.a_W.cwiseMin(c.b_W).array() - c.radius_m;
        const Eigen::Vector3d hi = c.a_W.cwiseMax(c.b_W).array() + c.radius_m;
        Eigen::Vector3d p_W;
        do {
          p_W = lo + Eigen::Vector3d(u01(rng), u01(rng), u01(rng)).cwiseProduct(hi - lo);
        } while (Depth(c, p_W) < 0.0);
        bool deep = false;
        for (std::size_t j = 0; j < body.parts.size() && !deep; ++j) {
          deep = Depth(body.parts[j], p_W) >= margin[j];
        }
        if (!deep) continue;
        const std::optional<std::array<int, 3>> cell = CellOf(s, p_W);
        if (!cell) continue;  // Outside the bounds: nothing is published there.
        ++points_;
        if (InRuns(occupied, *cell) || InRuns(occluded, *cell)) continue;
        if (free_++ < static_cast<std::int64_t>(kShown)) {
          char line[256];
          std::snprintf(line, sizeof(line),
                        "frame %d, %s (%s): point (%.3f, %.3f, %.3f) m is in cell (%d, %d, %d) "
                        "at depth %d, published free",
                        frame, ft.people[person].name.c_str(),
                        sim::BodyPartName(static_cast<sim::BodyPart>(part)), p_W.x(), p_W.y(),
                        p_W.z(), (*cell)[0], (*cell)[1], (*cell)[2], s.depth);
          offenders_.emplace_back(line);
        }
      }
    }
  }

  [[nodiscard]] std::int64_t points() const { return points_; }
  [[nodiscard]] std::int64_t published_free() const { return free_; }
  [[nodiscard]] int frame_sets() const { return frame_sets_; }
  /// The first kShown points published free, one line each.
  [[nodiscard]] const std::vector<std::string>& offenders() const { return offenders_; }

 private:
  // How deep p_W lies inside capsule c (m): its radius minus the distance to
  // its segment; negative outside. At most the distance to the surface of
  // the whole body, which is the union of the capsules.
  static double Depth(const sim::BodyCapsule& c, const Eigen::Vector3d& p_W) {
    const Eigen::Vector3d ab = c.b_W - c.a_W;
    const double len2 = ab.squaredNorm();
    const double t = len2 > 0.0 ? std::clamp((p_W - c.a_W).dot(ab) / len2, 0.0, 1.0) : 0.0;
    return c.radius_m - (p_W - (c.a_W + t * ab)).norm();
  }

  // Per part of person `person` in truth frame `frame`: how deep a point must
  // lie in it to stay inside at every capture time (see the class comment).
  std::array<double, sim::kNumBodyParts> Margins(int frame, std::size_t person) const {
    std::array<double, sim::kNumBodyParts> margin{};
    if (max_offset_s_ <= 0.0) return margin;
    const sim::FrameTruth& ft = truth_.frames[static_cast<std::size_t>(frame)];
    const sim::PersonTruth& pt = ft.people[person];
    std::array<double, sim::kNumBodyParts> speed_mps{};
    speed_mps.fill(pt.state.velocity_W.norm());
    // Every step between truth frames that overlaps the cameras' capture
    // times (max |offset| either way): a person starting to walk within
    // them moves faster there than around this frame.
    const auto near = [&](int f) {
      return f >= 0 && f < truth_frames() &&
             std::abs(truth_.frames[static_cast<std::size_t>(f)].time_s - ft.time_s) <=
                 max_offset_s_;
    };
    int first = frame, last = frame;
    while (near(first - 1)) --first;
    while (near(last + 1)) ++last;
    first = std::max(0, first - 1);  // The steps into and out of the window.
    last = std::min(truth_frames() - 1, last + 1);
    for (int f = first; f < last; ++f) {
      const sim::FrameTruth& from = truth_.frames[static_cast<std::size_t>(f)];
      const sim::FrameTruth& to = truth_.frames[static_cast<std::size_t>(f + 1)];
      const double dt_s = std::abs(to.time_s - from.time_s);
      const sim::PersonTruth* p = FindPerson(from, pt.name);
      const sim::PersonTruth* q = FindPerson(to, pt.name);
      if (dt_s <= 0.0 || p == nullptr || q == nullptr) continue;
      for (std::size_t j = 0; j < margin.size(); ++j) {
        const sim::BodyCapsule& a = p->state.parts[j];
        const sim::BodyCapsule& b = q->state.parts[j];
        speed_mps[j] =
            std::max({speed_mps[j], (a.a_W - b.a_W).norm() / dt_s, (a.b_W - b.b_W).norm() / dt_s});
      }
    }
    for (std::size_t j = 0; j < margin.size(); ++j) {
      margin[j] = speed_mps[j] * max_offset_s_ + kMarginM;
    }
    return margin;
  }

  static const sim::PersonTruth* FindPerson(const sim::FrameTruth& frame, const std::string& name) {
    for (const sim::PersonTruth& p : frame.people) {
      if (p.name == name) return &p;
    }
    return nullptr;
  }

  // The published cell holding p_W, nullopt outside the bounds.
  static std::optional<std::array<int, 3>> CellOf(const pipeline::OccupancySnapshot& s,
                                                  const Eigen::Vector3d& p_W) {
    const int n = 1 << s.depth;
    std::array<int, 3> cell{};
    for (int axis = 0; axis < 3; ++axis) {
      const double lo = s.bounds.min[axis];
      const double hi = s.bounds.max[axis];
      if (!(p_W[axis] >= lo && p_W[axis] <= hi)) return std::nullopt;
      const double i = std::floor((p_W[axis] - lo) / (hi - lo) * n);
      cell[static_cast<std::size_t>(axis)] = std::clamp(static_cast<int>(i), 0, n - 1);
    }
    return cell;
  }

  static auto Key(const pipeline::GridRun& r) { return std::make_tuple(r.z, r.y, r.x); }

  // The pipeline emits runs in cell order (z, then y, then x); a copy is
  // sorted only if some other producer did not.
  static const std::vector<pipeline::GridRun>& SortedRuns(
      const std::vector<pipeline::GridRun>& runs, std::vector<pipeline::GridRun>* scratch) {
    const auto less = [](const pipeline::GridRun& a, const pipeline::GridRun& b) {
      return Key(a) < Key(b);
    };
    if (std::is_sorted(runs.begin(), runs.end(), less)) return runs;
    scratch->assign(runs.begin(), runs.end());
    std::sort(scratch->begin(), scratch->end(), less);
    return *scratch;
  }

  static bool InRuns(const std::vector<pipeline::GridRun>& runs, const std::array<int, 3>& cell) {
    const auto key = std::make_tuple(cell[2], cell[1], cell[0]);
    // The last run starting at or before the cell.
    auto it = std::upper_bound(runs.begin(), runs.end(), key,
                               [](const std::tuple<int, int, int>& k, const pipeline::GridRun& r) {
                                 return k < std::tuple<int, int, int>(r.z, r.y, r.x);
                               });
    if (it == runs.begin()) return false;
    --it;
    return it->z == cell[2] && it->y == cell[1] && cell[0] < it->x + it->length;
  }

  sim::GroundTruth truth_;
  double max_offset_s_ = 0.0;
  std::int64_t points_ = 0;
  std::int64_t free_ = 0;
  int frame_sets_ = 0;
  std::vector<std::string> offenders_;
  std::vector<pipeline::GridRun> occupied_scratch_, occluded_scratch_;
};

/// Whether a frame has its camera's size (a synth recording does not state
/// its frames' size: one of another size is unreadable, as a damaged one).
bool FitsCamera(const capture::Frame& frame, const geometry::CameraModel& model) {
  const bool rgb = frame.kind == capture::FrameKind::kRgb;
  return (rgb ? frame.rgb.width : frame.grey.width) == model.width &&
         (rgb ? frame.rgb.height : frame.grey.height) == model.height;
}

/// The earliest recorded capture time of frame set `set` over the cameras.
std::int64_t FirstCaptureNs(const std::vector<std::unique_ptr<capture::ReplaySource>>& readers,
                            int set) {
  std::int64_t first = std::numeric_limits<std::int64_t>::max();
  for (const auto& reader : readers) {
    if (set < reader->frames()) {
      first = std::min(first, reader->recording().frames[static_cast<std::size_t>(set)].time_ns);
    }
  }
  return first;
}

int RunReplay(const ReplayFlags& f) {
  const app::Config config = app::LoadConfig(f.config);
  app::CheckRecordingForConfig(config, f.recording);
  pipeline::PipelineOptions options = app::MakePipelineOptions(config);
  if (f.threads > 0) options.octree_threads = f.threads;
  // Recording time 0 is the epoch 0: stamps are the frames' capture times.
  capture::SimClock clock;
  std::vector<std::unique_ptr<capture::ReplaySource>> readers;
  std::vector<pipeline::PipelineCamera> cameras;
  int frames = 0;
  bool synth = true;
  std::int64_t end_ns = 0;  // Recording time of the last frame of any camera.
  for (const app::CameraConfig& c : config.cameras) {
    readers.push_back(std::make_unique<capture::ReplaySource>(
        capture::ReadRecordingCamera(f.recording, app::RecordedCameraName(c)), clock));
    const capture::RecordingCamera& r = readers.back()->recording();
    frames = std::max(frames, readers.back()->frames());
    synth = r.layout == capture::RecordingLayout::kSynth;
    for (const capture::RecordedFrame& rf : r.frames) end_ns = std::max(end_ns, rf.time_ns);
    // Timeouts are measured between recorded stamps here, as in the daemon.
    cameras.push_back({c.model, nullptr, c.timeout_ms});
    if (r.frames.empty()) {
      // A camera lost before the recording (or the black box's dump)
      // began: it sees nothing in every cycle, as it did then.
      std::printf(
          "replay: camera '%s' has no frames in the recording: it replays as a camera "
          "that never delivers (sees nothing, every cycle degraded)\n",
          c.model.name.c_str());
    }
  }
  // The ground truth, read before anything runs (a bad file is bad input).
  std::optional<TruthCoverage> truth;
  std::string truth_note;  // Why a synth recording is not checked.
  std::string truth_path = f.truth;
  if (!f.truth.empty() && !synth) {
    throw common::ConfigError("--truth " + f.truth + ": " + f.recording +
                              " is not a synth recording (truth frames match frame sets by index)");
  }
  if (truth_path.empty() && synth && !f.no_truth) {
    truth_path = (std::filesystem::path(f.recording) / "ground_truth.yaml").string();
    if (!std::filesystem::exists(truth_path)) {
      truth_note = "no ground_truth.yaml in the recording";
      truth_path.clear();
    }
  }
  if (f.no_truth) truth_note = "--no-truth";
  if (!truth_path.empty()) {
    double max_offset_s = 0.0;
    for (const auto& r : readers) {
      max_offset_s = std::max(max_offset_s, std::abs(r->recording().time_offset_s));
    }
    truth.emplace(sim::ReadGroundTruth(truth_path), max_offset_s);
  }
  pipeline::Pipeline pipeline(options, std::move(cameras), app::LoadObstacles(config), nullptr);

  Digest digest;
  CameraTally tally(config.cameras.size());
  capture::Frame frame;
  std::uint64_t missing = 0, degraded = 0;
  std::shared_ptr<const pipeline::OccupancySnapshot> last;
  if (synth) {
    // Synth recordings share one frame grid: a cycle per frame set, at the
    // newest capture time of the set.
    if (f.frames > 0) frames = std::min(frames, f.frames);
    for (int i = 0; i < frames; ++i) {
      // The set's capture time from the recording's frame times, whether or
      // not its frames can be read: a set missing for every camera is a gap
      // in time, after which cameras time out as in the daemon.
      std::int64_t newest = std::numeric_limits<std::int64_t>::min();
      for (const auto& reader : readers) {
        if (i < reader->frames()) {
          newest =
              std::max(newest, reader->recording().frames[static_cast<std::size_t>(i)].time_ns);
        }
      }
      for (std::size_t c = 0; c < readers.size(); ++c) {
        if (!readers[c]->ReadFrame(i, &frame) || !FitsCamera(frame, config.cameras[c].model)) {
          ++missing;
          continue;
        }
        pipeline.Feed(static_cast<int>(c), frame);
      }
      last = pipeline.Step(newest);
      degraded += last->health.degraded ? 1 : 0;
      tally.Add(i, *last);
      AddSnapshot(*last, &digest);
      if (truth) {
        // The occupancy holds for its stamp (docs/dds.md): checked against
        // the frame set captured then, the latest whose first capture is not
        // after the stamp (the set itself unless its frames are missing).
        int held = i;
        while (held > 0 && FirstCaptureNs(readers, held) > last->stamp_ns) --held;
        truth->Check(held, *last);
      }
    }
    std::printf("replay: %d frame sets of %zu cameras, %" PRIu64
                " frames missing or unreadable, %" PRIu64 " cycles degraded\n",
                frames, readers.size(), missing, degraded);
    tally.Print();
    if (truth) {
      std::printf(
          "ground truth: %" PRId64 " points inside people over %d frame sets, %" PRId64
          " in cells published free%s\n",
          truth->points(), truth->frame_sets(), truth->published_free(),
          truth->truth_frames() < frames ? " (the truth has fewer frames than the replay)" : "");
    } else {
      std::printf("ground truth: not checked (%s)\n", truth_note.c_str());
    }
  } else {
    // Recorded cameras run on their own clocks: a cycle every 1 / rate_hz of
    // recording time, after every frame captured by then has been fed in
    // capture order (the background model sees them all, as in the daemon).
    const double period_ns = 1e9 / config.timing.rate_hz;
    // The last cycle at or after the last frame: every frame is fed.
    std::int64_t cycles =
        static_cast<std::int64_t>(std::ceil(static_cast<double>(end_ns) / period_ns)) + 1;
    if (f.frames > 0) cycles = std::min<std::int64_t>(cycles, f.frames);
    // Where every camera has timed out and the next frame of any is further
    // off than the longest timeout and a second, the cycles until just before
    // it are all alike (every camera stale, degraded): they are counted, not
    // run, so that a recording with a gap of days does not replay for hours.
    int longest_timeout_ms = 0;
    for (const app::CameraConfig& c : config.cameras) {
      longest_timeout_ms = std::max(longest_timeout_ms, c.timeout_ms);
    }
    const std::int64_t skip_gap_ns = (std::int64_t{longest_timeout_ms} + 1000) * 1'000'000;
    std::int64_t skipped = 0;
    std::vector<int> next(readers.size(), 0);
    for (std::int64_t k = 0; k < cycles; ++k) {
      const auto now_ns =
          static_cast<std::int64_t>(std::llround(static_cast<double>(k) * period_ns));
      for (std::size_t c = 0; c < readers.size(); ++c) {
        const capture::RecordingCamera& r = readers[c]->recording();
        for (; next[c] < readers[c]->frames() && r.frames[next[c]].time_ns <= now_ns; ++next[c]) {
          if (!readers[c]->ReadFrame(next[c], &frame) ||
              !FitsCamera(frame, config.cameras[c].model)) {
            ++missing;
            continue;
          }
          pipeline.Feed(static_cast<int>(c), frame);
        }
      }
      last = pipeline.Step(now_ns);
      degraded += last->health.degraded ? 1 : 0;
      tally.Add(k, *last);
      AddSnapshot(*last, &digest);
      const bool all_stale = std::none_of(last->health.cameras.begin(), last->health.cameras.end(),
                                          [](const pipeline::CameraHealth& h) {
                                            return h.state == pipeline::CameraState::kOk ||
                                                   h.state == pipeline::CameraState::kStarting;
                                          });
      std::optional<std::int64_t> next_ns;
      for (std::size_t c = 0; c < readers.size(); ++c) {
        if (next[c] < readers[c]->frames()) {
          const std::int64_t t = readers[c]->recording().frames[next[c]].time_ns;
          next_ns = next_ns ? std::min(*next_ns, t) : t;
        }
      }
      if (all_stale && next_ns && *next_ns - now_ns > skip_gap_ns) {
        // Cycles k + 1 .. before - 1 are skipped; `before`, at or just before
        // the next frame, runs.
        const auto before = std::min<std::int64_t>(
            cycles,
            static_cast<std::int64_t>(std::floor(static_cast<double>(*next_ns) / period_ns)));
        if (const std::int64_t n = before - 1 - k; n > 0) {
          skipped += n;
          degraded += static_cast<std::uint64_t>(n);
          tally.AddSilence(n);
          k = before - 1;
        }
      }
    }
    std::printf("replay: %" PRId64 " cycles at %g Hz over %.3f s of %zu recorded cameras, %" PRIu64
                " frames missing or unreadable, %" PRIu64 " cycles degraded",
                cycles, config.timing.rate_hz, end_ns * 1e-9, readers.size(), missing, degraded);
    if (skipped > 0) {
      std::printf(" (%" PRId64 " of them in silences of every camera, counted, not run)", skipped);
    }
    std::printf("\n");
    tally.Print();
  }
  if (f.digest || !f.expect.empty()) std::printf("digest %s\n", digest.Hex().c_str());
  if (!f.snapshot.empty() && last) {
    std::vector<SnapshotBox> boxes;
    const double n = static_cast<double>(1 << last->depth);
    const Eigen::Vector3d cell = last->bounds.Size() / n;
    for (const auto* runs : {&last->occupied, &last->occluded}) {
      for (const pipeline::GridRun& r : *runs) {
        common::Box3 box;
        box.min = last->bounds.min + Eigen::Vector3d(r.x, r.y, r.z).cwiseProduct(cell);
        box.max = box.min + Eigen::Vector3d(r.length, 1, 1).cwiseProduct(cell);
        boxes.push_back({box, runs == &last->occupied});
      }
    }
    std::vector<geometry::CameraModel> models;
    for (const app::CameraConfig& c : config.cameras) models.push_back(c.model);
    WriteSnapshotPicture(boxes, last->bounds, models, app::LoadObstacles(config),
                         "Last cycle of the replay.", f.snapshot);
  }
  int code = kExitOk;
  if (truth && truth->published_free() > 0) {
    std::fprintf(stderr,
                 "hullguard replay: %" PRId64
                 " points inside people lie in cells published free; the first:\n",
                 truth->published_free());
    for (const std::string& line : truth->offenders()) std::fprintf(stderr, "  %s\n", line.c_str());
    code = kExitFailure;
  }
  if (!f.expect.empty() && f.expect != digest.Hex()) {
    std::fprintf(stderr, "hullguard replay: digest %s differs from the expected %s\n",
                 digest.Hex().c_str(), f.expect.c_str());
    code = kExitFailure;
  }
  return code;
}

}  // namespace

void RegisterReplay(CLI::App& app, int* exit_code) {
  auto flags = std::make_shared<ReplayFlags>();
  CLI::App* cmd = app.add_subcommand(
      "replay",
      "Run the daemon's pipeline lock-step over a recording, deterministically, with a digest");
  cmd->add_option("--config", flags->config, "Daemon config (cameras, octree, motion, background)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--recording", flags->recording,
                  "Recording folder (hullguard synth or record layout)")
      ->required()
      ->check(CLI::ExistingDirectory);
  cmd->add_option("--threads", flags->threads, "Octree threads (0: the config's)")
      ->check(hg::cli::Range(0, 64));
  cmd->add_option("--frames", flags->frames,
                  "Replay at most this many frame sets, or cycles of a recorded recording (0: all)")
      ->check(hg::cli::kNonNegative);
  cmd->add_flag("--digest", flags->digest, "Print a digest of the output stream");
  cmd->add_option("--expect", flags->expect, "Fail (exit 1) unless the digest equals this");
  cmd->add_option("--snapshot", flags->snapshot, "Write a picture of the last cycle (PNG)");
  CLI::Option* truth =
      cmd->add_option("--truth", flags->truth,
                      "Ground truth to check a synth recording against (default: its "
                      "ground_truth.yaml); fail (exit 1) if a point inside a person is free")
          ->check(CLI::ExistingFile);
  cmd->add_flag("--no-truth", flags->no_truth, "Do not check against the ground truth")
      ->excludes(truth);
  cmd->callback([flags, exit_code] {
    try {
      *exit_code = RunReplay(*flags);
    } catch (const common::ConfigError& e) {
      std::fprintf(stderr, "hullguard replay: %s\n", e.what());
      *exit_code = kExitBadInput;
    }
  });
}

}  // namespace hg::tools
