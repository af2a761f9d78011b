#include "app/run.h"

#include <semaphore.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include "app/health_line.h"
#include "app/pipeline_setup.h"
#include "app/service.h"
#include "app/snapshot_stage.h"
#include "app/tracking_stage.h"
#include "capture/sim_source.h"
#include "common/config_error.h"
#include "common/heartbeat.h"
#include "common/log.h"
#include "common/version.h"
#include "geometry/mesh.h"
#include "pipeline/black_box.h"
#include "pipeline/pipeline.h"
#ifdef HG_WITH_DDS
#include "publish/dds_publisher.h"
#endif

namespace hg::app {
namespace {

std::atomic<bool> g_stop{false};

/// Longest wait for every camera's first frame before READY=1 (systemd's
/// TimeoutStartSec in systemd/hullguardd.service leaves room for it).
constexpr std::chrono::seconds kReadyWait{15};

// Posted by OnSignal (sem_post is async-signal-safe) and by MarkRunning():
// wakes the start-up stop guard.
sem_t g_stop_posted;
// The daemon's main loop runs (RunPipeline, LearnBackground): a stop from
// here on is handled there, within its second.
std::atomic<bool> g_running{false};
// How long a stop during start-up may wait for the next step boundary.
constexpr std::chrono::milliseconds kStartUpStopGrace{500};

void OnSignal(int /*signal*/) {
  g_stop.store(true);
  sem_post(&g_stop_posted);
}

// Start-up runs steps that take seconds without looking at g_stop (loading
// scenes, the tracking voxels of a fine grid, obstacle depth maps): a stop
// that no step boundary takes up within kStartUpStopGrace ends the process
// here, with the exit code of a clean stop. Nothing is running yet that a
// clean stop would finish: no sample was published, nothing is being written.
void StartUpStopGuard() {
  for (;;) {
    while (sem_wait(&g_stop_posted) != 0) {
    }
    if (g_running.load()) return;
    if (!g_stop.load()) continue;
    const auto until = std::chrono::steady_clock::now() + kStartUpStopGrace;
    while (std::chrono::steady_clock::now() < until) {
      if (g_running.load()) return;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    if (g_running.load()) return;
    static constexpr char kMessage[] = "hullguardd: stopped during start-up\n";
    (void)!write(STDERR_FILENO, kMessage, sizeof(kMessage) - 1);
    _exit(0);
  }
}

// The main loop runs: the start-up guard leaves stops to it.
void MarkRunning() {
  g_running.store(true);
  sem_post(&g_stop_posted);
}

std::atomic<bool> g_dump{false};

void OnDumpSignal(int /*signal*/) { g_dump.store(true); }

std::atomic<bool> g_hangup{false};

void OnHangupSignal(int /*signal*/) { g_hangup.store(true); }

/// The black box of `config` (blackbox.seconds > 0), logging every dump.
std::unique_ptr<pipeline::BlackBox> MakeBlackBox(const Config& config) {
  std::error_code ec;
  std::filesystem::create_directories(config.blackbox.dir, ec);
  if (ec) {
    throw common::ConfigError(config.source_file + ": blackbox.dir: cannot create '" +
                              config.blackbox.dir + "': " + ec.message());
  }
  pipeline::BlackBoxOptions o;
  o.seconds = config.blackbox.seconds;
  o.directory = config.blackbox.dir;
  o.max_memory_mb = config.blackbox.max_memory_mb;
  o.on_dump = [](const pipeline::BlackBoxDump& d) {
    if (!d.error.empty()) {
      log::Error("black box ({}): {} frames written, {} failed: {}", d.reason, d.frames, d.failed,
                 d.error);
      return;
    }
    log::Info("black box ({}): wrote {} frames ({:.2f} s, {} torn) to {}", d.reason, d.frames,
              (d.last_ns - d.first_ns) * 1e-9, d.torn, d.directory);
  };
  auto box = std::make_unique<pipeline::BlackBox>(std::move(o), BlackBoxCameras(config));
  log::Info("black box: {:.3g} s of {} cameras in {:.0f} MiB, dumps to {}", config.blackbox.seconds,
            config.cameras.size(), static_cast<double>(box->bytes()) / (1024.0 * 1024.0),
            config.blackbox.dir);
  return box;
}

std::optional<TrackingStats> StatsOf(const TrackingStage* tracking) {
  if (tracking == nullptr) return std::nullopt;
  return tracking->stats();
}

/// A camera mostly foreground this long is worth a warning (ForegroundWatch).
constexpr std::chrono::seconds kForegroundWarnAfter{60};

/// The health line at info while all is well, at warning while degraded (so
/// that `logging.level: warn` still shows what went wrong, once a second).
// `foreign_publisher`: another publisher writes this daemon's topics (the
// status samples say degraded while it does).
void LogHealth(const pipeline::OccupancySnapshot& s, const std::string& line,
               bool foreign_publisher) {
  log::Write(s.health.degraded || foreign_publisher ? log::Level::kWarn : log::Level::kInfo, line);
}

}  // namespace

void InstallStopSignals() {
  static std::once_flag guard_started;
  std::call_once(guard_started, [] {
    sem_init(&g_stop_posted, 0, 0);
    std::thread(StartUpStopGuard).detach();
  });
  std::signal(SIGTERM, OnSignal);
  std::signal(SIGINT, OnSignal);
  // Also without a black box: SIGUSR1's default action would end the daemon.
  std::signal(SIGUSR1, OnDumpSignal);
  // SIGHUP asks a daemon to reload, which this one does not: it goes on
  // monitoring and says so (its default action would end the stream, and
  // systemd would not restart a daemon ended by it). A closed pipe on stdout
  // or stderr is an error of that write, not the end of the daemon.
  std::signal(SIGHUP, OnHangupSignal);
  std::signal(SIGPIPE, SIG_IGN);
}

bool StopRequested() { return g_stop.load(); }

int RunPipeline(const Config& config, double duration_s) {
  log::Configure("hullguardd", config.logging.level,
                 config.logging.journald ? log::Sink::kJournal : log::Sink::kStderr);
  InstallStopSignals();  // Again: RunPipeline may be called without hullguardd's main.
  // A signal during start-up (which can take seconds: obstacle depth maps,
  // tracking voxels, the cameras) ends the daemon cleanly between its steps.
  auto stopped_starting = [] {
    if (!g_stop.load()) return false;
    log::Info("stopped during start-up");
    return true;
  };
  const pipeline::PipelineOptions options = MakePipelineOptions(config);
  const std::vector<geometry::TriangleMesh> obstacles = LoadObstacles(config);
  if (stopped_starting()) return 0;

  const capture::SimClock sim_clock = capture::SimClock::Now();
  // The black box's rings are allocated (and touched) before capture starts,
  // and before any camera is opened: what can fail here fails first.
  std::unique_ptr<pipeline::BlackBox> black_box;
  if (config.blackbox.seconds > 0.0) black_box = MakeBlackBox(config);
  if (stopped_starting()) return 0;
  std::vector<pipeline::PipelineCamera> cameras = MakeCameras(config, sim_clock);

  pipeline::Pipeline::Consumer consumer;
  // Set before the pipeline starts, read by the fusion thread.
  std::unique_ptr<TrackingStage> tracking;
  TrackingStage::Consumer on_tracks;
  common::Heartbeats heartbeats;
  // Publishing runs on a thread of its own (the fusion thread only offers
  // each snapshot, a shared-pointer copy), tracks on the tracking thread:
  // the fusion cycle never waits on the network.
  std::unique_ptr<SnapshotStage> publish_stage;
  std::function<void()> check_publisher = [] {};
  // DDS writes refused since start (0 without DDS).
  std::function<std::uint64_t()> failed_writes_total = [] { return std::uint64_t{0}; };
  // Writers of the daemon's topics besides its own (checked from the main
  // loop): while there are any, the health line, STATUS= and the black box's
  // trigger say degraded, as the status samples do.
  int other_publishers = 0;
#ifdef HG_WITH_DDS
  int longest_timeout_ms = 0;
  for (const CameraConfig& c : config.cameras) {
    longest_timeout_ms = std::max(longest_timeout_ms, c.timeout_ms);
  }
  const std::chrono::nanoseconds max_age =
      publish::MaxSampleAge(std::chrono::milliseconds(longest_timeout_ms), config.timing.rate_hz);
  publish::DdsPublisher publisher({config.dds.domain_id, config.dds.topic_prefix,
                                   config.dds.enabled, config.tracking.enabled, max_age},
                                  config.timing.rate_hz);
  if (config.dds.enabled) {
    publish_stage = std::make_unique<SnapshotStage>(
        "publish", [&publisher](const pipeline::OccupancySnapshot& s) { publisher.Publish(s); },
        &heartbeats);
    consumer =
        [stage = publish_stage.get()](const std::shared_ptr<const pipeline::OccupancySnapshot>& s) {
          stage->Offer(s);
        };
    on_tracks = [&publisher](const TrackedCycle& c) {
      publisher.PublishTracks(c.sequence, c.stamp_ns, c.degraded, c.tracks);
    };
  }
  // From the main loop: another publisher on the topics, and samples too old
  // to send, each logged when it changes; refused writes at most every 10 s.
  std::uint64_t stale_seen = 0;
  std::uint64_t failures_logged = 0;
  std::chrono::steady_clock::time_point failures_logged_at;
  failed_writes_total = [&publisher] {
    return publisher.write_failures() + publisher.tracks_write_failures();
  };
  check_publisher = [&] {
    const int others = publisher.CheckOtherPublishers();
    if (others > 0 && other_publishers == 0) {
      log::Error(
          "another publisher writes {} on DDS domain {} ({} writer(s) besides this daemon): a "
          "controller cannot tell its samples from this cell's; every status sample says "
          "degraded until it is gone (give each cell its own dds.topic_prefix or domain_id)",
          publisher.status_topic(), config.dds.domain_id, others);
    } else if (others == 0 && other_publishers > 0) {
      log::Info("the other publisher of {} is gone", publisher.status_topic());
    }
    other_publishers = others;
    const std::uint64_t stale = publisher.stale_dropped();
    if (stale != stale_seen) {
      log::Warn(
          "{} sample(s) not published: older than {:.2f} s when their turn came (the daemon was "
          "stopped or starved of CPU, or no camera had a newer frame); {} since start",
          stale - stale_seen, std::chrono::duration<double>(max_age).count(), stale);
      stale_seen = stale;
    }
    const std::uint64_t failures = failed_writes_total();
    const auto now = std::chrono::steady_clock::now();
    if (failures != failures_logged &&
        (failures_logged_at == std::chrono::steady_clock::time_point{} ||
         now - failures_logged_at >= std::chrono::seconds(10))) {
      log::Error(
          "DDS: {} write(s) refused by Cyclone DDS ({} since start; occupancy and status {}, "
          "tracks {}): the controllers miss what was refused",
          failures - failures_logged, failures, publisher.write_failures(),
          publisher.tracks_write_failures());
      failures_logged = failures;
      failures_logged_at = now;
    }
  };
#else
  if (config.dds.enabled) {
    log::Warn("built without Cyclone DDS: nothing is published");
  }
#endif
  if (stopped_starting()) return 0;
  if (config.tracking.enabled) {
    // Static voxel states from the cameras and obstacles, once, before READY=1.
    const auto build_start = std::chrono::steady_clock::now();
    tracking = std::make_unique<TrackingStage>(
        MakeTrackerOptions(config.tracking, config.timing.rate_hz), config.cell.bounds,
        MakeStaticScene(config, obstacles), std::move(on_tracks), &heartbeats);
    log::Info(
        "tracking on {} voxels of {:g} m, built in {:.2f} s",
        tracking->tracker().voxel_map().grid().size(), config.tracking.voxel_m,
        std::chrono::duration<double>(std::chrono::steady_clock::now() - build_start).count());
    // The fusion thread only hands the snapshot over (a shared_ptr copy).
    consumer = [publish = std::move(consumer), stage = tracking.get()](
                   const std::shared_ptr<const pipeline::OccupancySnapshot>& s) {
      if (publish) publish(s);
      stage->Offer(s);
    };
  }
  pipeline::Pipeline pipeline(options, std::move(cameras), obstacles, consumer, &heartbeats);
  if (black_box) pipeline.SetBlackBox(black_box.get());
  const int main_heartbeat = heartbeats.Register("main");
  // systemd (Type=notify): READY=1 once the cameras are open and the first
  // cycle is published; WATCHDOG=1 only while every stage's heartbeat moves.
  const ServiceNotifier notifier;
  ServiceWatchdog watchdog(heartbeats, notifier);
  if (stopped_starting()) return 0;
  if (tracking) tracking->Start();
  if (publish_stage) publish_stage->Start();
  pipeline.Start();
  watchdog.Start();
  log::Info("hullguardd {} ({}) running {}", common::Version(), common::Commit(), Summary(config));
  // Lets a test or a viewer relate stamps to scene or recording time.
  log::Info("sim/replay time 0 is {} ns (CLOCK_REALTIME)", sim_clock.epoch_ns);
  bool ready = false;
  ForegroundWatch foreground_watch(config.cameras.size(), kForegroundWarnAfter);
  std::uint64_t blackbox_seen = 0;
  pipeline::DegradedDumpTrigger degraded_trigger(
      std::chrono::duration_cast<std::chrono::steady_clock::duration>(
          std::chrono::duration<double>(config.blackbox.seconds)));
  // --duration counts from here: the time running, start-up not included.
  const auto start = std::chrono::steady_clock::now();
  auto next_report = start + std::chrono::seconds(1);
  auto next_publisher_check = start;
  std::uint64_t failed_writes_seen = 0;  // At the last health line.
  std::uint64_t failed_writes_last_second = 0;
  MarkRunning();
  while (!g_stop.load()) {
    heartbeats.Beat(main_heartbeat);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const auto now = std::chrono::steady_clock::now();
    if (duration_s > 0 && now - start >= std::chrono::duration<double>(duration_s)) break;
    if (now >= next_publisher_check) {
      next_publisher_check = now + std::chrono::milliseconds(200);
      check_publisher();
    }
    if (g_hangup.exchange(false)) {
      log::Warn(
          "SIGHUP ignored: the config is not reloaded; restart to apply a change "
          "(systemctl restart hullguardd)");
    }
    if (g_dump.exchange(false)) {
      if (!black_box) {
        log::Warn("SIGUSR1: the black box is off (blackbox.seconds: 0)");
      } else if (!black_box->RequestDump("SIGUSR1")) {
        log::Warn(
            "SIGUSR1 ignored: two black-box dumps are in flight (one written, the next waiting "
            "for it)");
      }
    }
    if (black_box && config.blackbox.on_degraded) {
      if (const auto s = pipeline.Latest(); s && s->sequence != blackbox_seen) {
        blackbox_seen = s->sequence;
        degraded_trigger.Observe(s->health.degraded || other_publishers > 0 ||
                                 failed_writes_last_second > 0);
      }
      if (degraded_trigger.ShouldDump(now, black_box->accepting()) &&
          black_box->RequestDump("degraded")) {
        degraded_trigger.Dumped(now);
      }
    }
    if (!ready) {
      // READY=1 once a cycle in which every camera had delivered a frame is
      // published. A camera that never comes up does not keep the service
      // from starting: after kReadyWait it is ready, degraded, naming that
      // camera in its status (and the stream has been published all along).
      if (const auto s = pipeline.Latest()) {
        const bool cameras_open = std::none_of(s->health.cameras.begin(), s->health.cameras.end(),
                                               [](const pipeline::CameraHealth& h) {
                                                 return h.state == pipeline::CameraState::kStarting;
                                               });
        if (cameras_open || now - start >= kReadyWait) {
          const std::string line = HealthLine(*s, StatsOf(tracking.get()), other_publishers > 0,
                                              failed_writes_last_second);
          if (!cameras_open) log::Warn("ready without every camera: {}", line);
          notifier.Ready();
          watchdog.SetStatus(line);
          ready = true;
        }
      }
    }
    if (now >= next_report) {
      next_report += std::chrono::seconds(1);
      for (std::size_t c = 0; c < config.cameras.size(); ++c) {
        const auto since = pipeline.ForegroundHeavySince(static_cast<int>(c));
        if (foreground_watch.Due(c, since, now)) {
          log::Warn("{}", ForegroundWarning(config.cameras[c].model.name,
                                            std::chrono::duration<double>(now - *since).count()));
        }
      }
      const std::uint64_t failed_writes = failed_writes_total();
      failed_writes_last_second = failed_writes - failed_writes_seen;
      failed_writes_seen = failed_writes;
      if (const auto s = pipeline.Latest()) {
        const std::string line = HealthLine(*s, StatsOf(tracking.get()), other_publishers > 0,
                                            failed_writes_last_second);
        LogHealth(*s, line, other_publishers > 0 || failed_writes_last_second > 0);
        watchdog.SetStatus(line);
      }
    }
  }
  notifier.Stopping();
  watchdog.Stop();
  pipeline.Stop();
  // A turn to degraded not dumped yet (inside the interval after the last
  // dump) is dumped now: the rings hold it, and they are not filled again.
  if (black_box && config.blackbox.on_degraded && degraded_trigger.due() &&
      !black_box->RequestDump("degraded")) {
    log::Warn(
        "black box: a turn to degraded was not dumped: two dumps were still in flight at "
        "shutdown");
  }
  if (publish_stage) publish_stage->Stop();
  if (tracking) tracking->Stop();
  if (const auto s = pipeline.Latest()) {
    LogHealth(
        *s,
        HealthLine(*s, StatsOf(tracking.get()), other_publishers > 0, failed_writes_last_second),
        other_publishers > 0 || failed_writes_last_second > 0);
  }
  log::Info("stopped");
  return 0;
}

int LearnBackground(const Config& config, double timeout_s) {
  log::Configure("hullguardd", config.logging.level,
                 config.logging.journald ? log::Sink::kJournal : log::Sink::kStderr);
  InstallStopSignals();
  if (config.background.keep_dir.empty()) {
    log::Error(
        "--learn-background: background.keep_dir is not set: nowhere to keep what is "
        "learned");
    return 2;
  }
  pipeline::PipelineOptions options = MakePipelineOptions(config);
  options.background_start = pipeline::PipelineOptions::BackgroundStart::kRelearn;
  const std::vector<geometry::TriangleMesh> obstacles = LoadObstacles(config);
  if (g_stop.load()) return 1;
  const capture::SimClock sim_clock = capture::SimClock::Now();
  std::vector<pipeline::PipelineCamera> cameras = MakeCameras(config, sim_clock);
  const int n = static_cast<int>(cameras.size());
  // Only the cameras' silhouettes are wanted; the cycles that also run are
  // handed to nobody.
  pipeline::Pipeline pipeline(options, std::move(cameras), obstacles, nullptr);
  log::Info("learning the background of {} cameras into {}; the cell must be empty", n,
            config.background.keep_dir);
  pipeline.Start();
  MarkRunning();
  const auto start = std::chrono::steady_clock::now();
  const auto limit = std::chrono::duration<double>(timeout_s);
  // Per camera: whether it is done (kept, failed to keep, or a mask source
  // that learns nothing).
  std::vector<bool> done(n, false);
  bool stopped = false;
  while (true) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const auto s = pipeline.Latest();
    int finished = 0;
    for (int c = 0; c < n; ++c) {
      const bool masks_only =
          !pipeline.HasBackgroundModel(c) && s != nullptr && s->health.cameras[c].frames > 0;
      done[c] = masks_only || pipeline.BackgroundSaved(c).has_value();
      finished += done[c] ? 1 : 0;
    }
    if (finished == n) break;
    if (g_stop.load()) {
      stopped = true;
      break;
    }
    if (std::chrono::steady_clock::now() - start >= limit) break;
  }
  const auto last = pipeline.Latest();
  pipeline.Stop();
  int kept = 0, failed = 0, image_cameras = 0;
  for (int c = 0; c < n; ++c) {
    const std::string& name = config.cameras[c].model.name;
    if (!pipeline.HasBackgroundModel(c)) {
      if (done[c]) {
        std::printf("%s: delivers masks (no background model): nothing to learn\n", name.c_str());
        continue;
      }
    } else {
      ++image_cameras;
    }
    const std::optional<bool> saved = pipeline.BackgroundSaved(c);
    if (saved == true) {
      ++kept;
      std::printf("%s: background kept in %s\n", name.c_str(), pipeline.BackgroundFile(c).c_str());
      continue;
    }
    ++failed;
    std::string why = saved == false ? "learned, but the file could not be written (see the log)"
                                     : "did not finish learning";
    if (!saved.has_value() && last != nullptr) {
      const pipeline::CameraHealth& h = last->health.cameras[c];
      why += std::string(" (") + StateName(h.state);
      if (h.fault != 0) {
        why += std::string(", ") + capture::ToString(static_cast<capture::CameraFault>(h.fault));
      }
      why += ", " + std::to_string(h.frames) + " frames)";
    }
    std::printf("%s: %s\n", name.c_str(), why.c_str());
  }
  std::fflush(stdout);
  if (stopped) {
    log::Warn("--learn-background: stopped by a signal before every camera was done");
    return 1;
  }
  if (failed > 0) {
    log::Error("--learn-background: {} of {} cameras kept no background", failed, n);
    return 1;
  }
  if (image_cameras == 0) {
    log::Error(
        "--learn-background: no camera of this config delivers images (sim masks or mask "
        "recordings): nothing to learn");
    return 2;
  }
  log::Info("--learn-background: {} cameras kept their background in {}", kept,
            config.background.keep_dir);
  return 0;
}

}  // namespace hg::app
