// `hullguard replay`: the daemon's pipeline run lock-step over a recording, as
// fast as it goes and deterministically, with a digest of the output stream
// for regression checks.
#include <algorithm>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "app/config.h"
#include "app/pipeline_setup.h"
#include "capture/replay_source.h"
#include "common/config_error.h"
#include "hullguard/commands.h"
#include "hullguard/snapshot_picture.h"
#include "pipeline/pipeline.h"

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

int RunReplay(const ReplayFlags& f) {
  const app::Config config = app::LoadConfig(f.config);
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
        capture::ReadRecordingCamera(f.recording, c.model.name), clock));
    const capture::RecordingCamera& r = readers.back()->recording();
    frames = std::max(frames, readers.back()->frames());
    synth = r.layout == capture::RecordingLayout::kSynth;
    for (const capture::RecordedFrame& rf : r.frames) end_ns = std::max(end_ns, rf.time_ns);
    // Timeouts are measured between recorded stamps here, as in the daemon.
    cameras.push_back({c.model, nullptr, c.timeout_ms});
  }
  pipeline::Pipeline pipeline(options, std::move(cameras), app::LoadObstacles(config), nullptr);

  Digest digest;
  capture::Frame frame;
  std::uint64_t missing = 0, degraded = 0;
  std::shared_ptr<const pipeline::OccupancySnapshot> last;
  if (synth) {
    // Synth recordings share one frame grid: a cycle per frame set, at the
    // newest capture time of the set.
    if (f.frames > 0) frames = std::min(frames, f.frames);
    for (int i = 0; i < frames; ++i) {
      std::int64_t newest = 0;
      for (std::size_t c = 0; c < readers.size(); ++c) {
        if (!readers[c]->ReadFrame(i, &frame)) {
          ++missing;
          continue;
        }
        newest = std::max(newest, frame.stamp_ns);
        pipeline.Feed(static_cast<int>(c), frame);
      }
      last = pipeline.Step(newest);
      degraded += last->health.degraded ? 1 : 0;
      AddSnapshot(*last, &digest);
    }
    std::printf("replay: %d frame sets of %zu cameras, %" PRIu64
                " frames missing or unreadable, %" PRIu64 " cycles degraded\n",
                frames, readers.size(), missing, degraded);
  } else {
    // Recorded cameras run on their own clocks: a cycle every 1 / rate_hz of
    // recording time, after every frame captured by then has been fed in
    // capture order (the background model sees them all, as in the daemon).
    const double period_ns = 1e9 / config.timing.rate_hz;
    int cycles = static_cast<int>(std::floor(static_cast<double>(end_ns) / period_ns)) + 1;
    if (f.frames > 0) cycles = std::min(cycles, f.frames);
    std::vector<int> next(readers.size(), 0);
    for (int k = 0; k < cycles; ++k) {
      const auto now_ns = static_cast<std::int64_t>(std::llround(k * period_ns));
      for (std::size_t c = 0; c < readers.size(); ++c) {
        const capture::RecordingCamera& r = readers[c]->recording();
        for (; next[c] < readers[c]->frames() && r.frames[next[c]].time_ns <= now_ns; ++next[c]) {
          if (!readers[c]->ReadFrame(next[c], &frame)) {
            ++missing;
            continue;
          }
          pipeline.Feed(static_cast<int>(c), frame);
        }
      }
      last = pipeline.Step(now_ns);
      degraded += last->health.degraded ? 1 : 0;
      AddSnapshot(*last, &digest);
    }
    std::printf("replay: %d cycles at %g Hz over %.3f s of %zu recorded cameras, %" PRIu64
                " frames missing or unreadable, %" PRIu64 " cycles degraded\n",
                cycles, config.timing.rate_hz, end_ns * 1e-9, readers.size(), missing, degraded);
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
  if (!f.expect.empty() && f.expect != digest.Hex()) {
    std::fprintf(stderr, "hullguard replay: digest %s differs from the expected %s\n",
                 digest.Hex().c_str(), f.expect.c_str());
    return kExitFailure;
  }
  return kExitOk;
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
      ->check(CLI::Range(0, 64));
  cmd->add_option("--frames", flags->frames,
                  "Replay at most this many frame sets, or cycles of a recorded recording (0: all)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_flag("--digest", flags->digest, "Print a digest of the output stream");
  cmd->add_option("--expect", flags->expect, "Fail (exit 1) unless the digest equals this");
  cmd->add_option("--snapshot", flags->snapshot, "Write a picture of the last cycle (PNG)");
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
