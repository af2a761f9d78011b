#include "app/service.h"

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <mutex>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "capture/sim_source.h"
#include "common/heartbeat.h"
#include "pipeline/pipeline.h"
#include "scene/demo_cell.h"

namespace hg::app {
namespace {

using common::Heartbeats;
using std::chrono::microseconds;
using std::chrono::milliseconds;

// Generous bounds for "eventually": they only end a broken test, they are
// not what the tests measure.
constexpr milliseconds kEventually{10000};

std::string StageName(const char* prefix, int i) {
  std::string name = prefix;
  name += std::to_string(i);
  return name;
}

// ---------------------------------------------------------------------------
// Heartbeats

TEST(HeartbeatsTest, RegisterHandsOutIdsInOrder) {
  Heartbeats beats;
  EXPECT_EQ(beats.size(), 0);
  EXPECT_EQ(beats.Register("capture cam0"), 0);
  EXPECT_EQ(beats.Register("fusion"), 1);
  EXPECT_EQ(beats.size(), 2);
  EXPECT_EQ(beats.name(0), "capture cam0");
  EXPECT_EQ(beats.name(1), "fusion");
  EXPECT_EQ(beats.beats(0), 0U);
  beats.Beat(0);
  beats.Beat(0);
  EXPECT_EQ(beats.beats(0), 2U);
  EXPECT_EQ(beats.beats(1), 0U);
}

TEST(HeartbeatsTest, NoStagesMeansAllMoved) {
  Heartbeats beats;
  std::string stalled = "left over";
  EXPECT_TRUE(beats.AllMoved(&stalled));
  EXPECT_EQ(stalled, "");
}

TEST(HeartbeatsTest, EachCheckComparesWithThePreviousOne) {
  Heartbeats beats;
  const int a = beats.Register("a");
  const int b = beats.Register("b");
  std::string stalled;
  // First check: measured from registration, nobody beat yet.
  EXPECT_FALSE(beats.AllMoved(&stalled));
  EXPECT_EQ(stalled, "a, b");

  beats.Beat(a);
  beats.Beat(b);
  EXPECT_TRUE(beats.AllMoved(&stalled));
  EXPECT_EQ(stalled, "");

  // Beats before the previous check do not count again.
  EXPECT_FALSE(beats.AllMoved(&stalled));
  EXPECT_EQ(stalled, "a, b");

  beats.Beat(b);
  beats.Beat(b);
  EXPECT_FALSE(beats.AllMoved(&stalled));
  EXPECT_EQ(stalled, "a");

  beats.Beat(a);
  EXPECT_FALSE(beats.AllMoved(nullptr));  // Names are optional.
  beats.Beat(a);
  beats.Beat(b);
  EXPECT_TRUE(beats.AllMoved(nullptr));
}

// A stage registered with an allowance (tracking: no safety output, cycles of
// seconds on a loaded machine) counts as stalled only once it has not beaten
// for that long, measured from the last check that saw it move.
TEST(HeartbeatsTest, AStageWithAnAllowanceMayStayStillThatLong) {
  Heartbeats beats;
  const int a = beats.Register("a");
  const int slow = beats.Register("slow", std::chrono::seconds(5));
  const int brief = beats.Register("brief", milliseconds(200));
  std::string stalled;
  beats.Beat(a);
  EXPECT_TRUE(beats.AllMoved(&stalled));
  EXPECT_EQ(stalled, "");  // Within their allowances since registration.
  std::this_thread::sleep_for(milliseconds(250));
  beats.Beat(a);
  EXPECT_FALSE(beats.AllMoved(&stalled));
  EXPECT_EQ(stalled, "brief");
  beats.Beat(a);
  beats.Beat(brief);
  EXPECT_TRUE(beats.AllMoved(&stalled));
  beats.Beat(a);
  EXPECT_TRUE(beats.AllMoved(&stalled));  // brief moved at the last check.
  // A stage without allowance is stalled at the first check it did not beat.
  EXPECT_FALSE(beats.AllMoved(&stalled));
  EXPECT_EQ(stalled, "a");
  (void)slow;
}

TEST(HeartbeatsTest, MatchesOracleOnRandomBeatPatterns) {
  std::mt19937_64 rng(0x5eed'0001);
  Heartbeats beats;
  constexpr int kStages = 12;
  for (int i = 0; i < kStages; ++i) beats.Register(StageName("stage", i));
  std::uniform_int_distribution<int> beats_per_round(0, 3);
  std::bernoulli_distribution all_beat(0.3);
  std::string stalled;
  for (int round = 0; round < 2000; ++round) {
    const bool force_all = all_beat(rng);
    std::string expected;
    for (int i = 0; i < kStages; ++i) {
      const int n = force_all ? 1 + beats_per_round(rng) : beats_per_round(rng);
      for (int k = 0; k < n; ++k) beats.Beat(i);
      if (n == 0) {
        if (!expected.empty()) expected += ", ";
        expected += beats.name(i);
      }
    }
    ASSERT_EQ(beats.AllMoved(&stalled), expected.empty()) << "round " << round;
    ASSERT_EQ(stalled, expected) << "round " << round;
  }
}

TEST(HeartbeatsTest, ConcurrentBeatsAreAllCounted) {
  Heartbeats beats;
  constexpr int kStages = 3;
  constexpr int kThreads = 4;
  constexpr int kBeats = 50000;
  for (int i = 0; i < kStages; ++i) beats.Register(StageName("s", i));
  std::atomic<bool> done{false};
  // A checker runs alongside, as the watchdog does (exercised under TSan).
  std::thread checker([&] {
    std::string stalled;
    while (!done.load()) beats.AllMoved(&stalled);
  });
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&beats, t] {
      for (int k = 0; k < kBeats; ++k) beats.Beat((t + k) % kStages);
    });
  }
  for (std::thread& t : threads) t.join();
  done.store(true);
  checker.join();
  std::uint64_t total = 0;
  for (int i = 0; i < kStages; ++i) total += beats.beats(i);
  EXPECT_EQ(total, static_cast<std::uint64_t>(kThreads) * kBeats);
  for (int i = 0; i < kStages; ++i) EXPECT_GE(beats.beats(i), 1U);
}

TEST(HeartbeatsDeathTest, CapacityIsFixed) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  Heartbeats beats;
  for (int i = 0; i < Heartbeats::kCapacity; ++i) {
    EXPECT_EQ(beats.Register(StageName("s", i)), i);
  }
  EXPECT_DEATH(beats.Register("one too many"), "HG_CHECK failed");
}

TEST(HeartbeatsDeathTest, BeatOfUnregisteredStageAborts) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  Heartbeats beats;
  beats.Register("only");
  EXPECT_DEATH(beats.Beat(1), "HG_CHECK failed");
  EXPECT_DEATH(beats.Beat(-1), "HG_CHECK failed");
}

// ---------------------------------------------------------------------------
// A stand-in for systemd: the notification socket and the watchdog variables.

class FakeSystemd {
 public:
  /// Binds a datagram socket in a fresh temporary directory and points
  /// NOTIFY_SOCKET at it; sets WATCHDOG_USEC / WATCHDOG_PID when asked.
  explicit FakeSystemd(std::optional<microseconds> watchdog, pid_t watchdog_pid = getpid()) {
    char dir[] = "/tmp/hg_service_test_XXXXXX";
    if (mkdtemp(dir) == nullptr) throw std::runtime_error("mkdtemp failed");
    dir_ = dir;
    path_ = dir_ + "/notify";
    fd_ = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    if (fd_ < 0) throw std::runtime_error("socket failed");
    sockaddr_un address{};
    address.sun_family = AF_UNIX;
    std::strncpy(address.sun_path, path_.c_str(), sizeof(address.sun_path) - 1);
    if (bind(fd_, reinterpret_cast<const sockaddr*>(&address), sizeof(address)) != 0) {
      throw std::runtime_error("bind failed: " + path_);
    }
    setenv("NOTIFY_SOCKET", path_.c_str(), 1);
    if (watchdog) {
      setenv("WATCHDOG_USEC", std::to_string(watchdog->count()).c_str(), 1);
      setenv("WATCHDOG_PID", std::to_string(watchdog_pid).c_str(), 1);
    } else {
      unsetenv("WATCHDOG_USEC");
      unsetenv("WATCHDOG_PID");
    }
  }

  ~FakeSystemd() {
    unsetenv("NOTIFY_SOCKET");
    unsetenv("WATCHDOG_USEC");
    unsetenv("WATCHDOG_PID");
    close(fd_);
    unlink(path_.c_str());
    rmdir(dir_.c_str());
  }

  FakeSystemd(const FakeSystemd&) = delete;
  FakeSystemd& operator=(const FakeSystemd&) = delete;

  /// The next datagram, or nothing if none arrives within `timeout`.
  std::optional<std::string> Receive(milliseconds timeout) {
    pollfd p{fd_, POLLIN, 0};
    if (poll(&p, 1, static_cast<int>(timeout.count())) <= 0) return std::nullopt;
    char buffer[4096];
    const ssize_t n = recv(fd_, buffer, sizeof(buffer), 0);
    if (n < 0) return std::nullopt;
    return std::string(buffer, static_cast<std::size_t>(n));
  }

  /// Receives until a message satisfies `match` (returned) or `timeout`
  /// passes (nullopt). Every message received is appended to `seen`.
  std::optional<std::string> WaitFor(const std::function<bool(const std::string&)>& match,
                                     milliseconds timeout, std::vector<std::string>* seen) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (true) {
      const auto left =
          std::chrono::duration_cast<milliseconds>(end - std::chrono::steady_clock::now());
      if (left.count() <= 0) return std::nullopt;
      std::optional<std::string> m = Receive(left);
      if (!m) return std::nullopt;
      seen->push_back(*m);
      if (match(*m)) return m;
    }
  }

 private:
  std::string dir_;
  std::string path_;
  int fd_ = -1;
};

bool IsPing(const std::string& m) { return m == "WATCHDOG=1"; }
bool IsStatus(const std::string& m) { return m.rfind("STATUS=", 0) == 0; }

/// A stage thread: beats every couple of milliseconds, each iteration passing
/// through a gate. Freeze() closes the gate, so the thread hangs as a stuck
/// stage would, in a blocking call.
class StageThread {
 public:
  StageThread(Heartbeats& beats, int id)
      : thread_([this, &beats, id] {
          while (!quit_.load()) {
            { std::lock_guard<std::mutex> pass(gate_); }
            beats.Beat(id);
            std::this_thread::sleep_for(milliseconds(2));
          }
        }) {}
  ~StageThread() {
    Unfreeze();
    quit_.store(true);
    thread_.join();
  }
  StageThread(const StageThread&) = delete;
  StageThread& operator=(const StageThread&) = delete;

  void Freeze() {
    gate_.lock();
    frozen_ = true;
  }
  void Unfreeze() {
    if (!frozen_) return;
    frozen_ = false;
    gate_.unlock();
  }

 private:
  std::mutex gate_;
  bool frozen_ = false;  // Test thread only.
  std::atomic<bool> quit_{false};
  std::thread thread_;
};

// ---------------------------------------------------------------------------
// ServiceNotifier

TEST(ServiceNotifierTest, WithoutNotifySocketEverythingIsANoOp) {
  unsetenv("NOTIFY_SOCKET");
  setenv("WATCHDOG_USEC", "200000", 1);
  setenv("WATCHDOG_PID", std::to_string(getpid()).c_str(), 1);
  ServiceNotifier notifier;
  EXPECT_FALSE(notifier.enabled());
  EXPECT_FALSE(notifier.WatchdogInterval().has_value());
  EXPECT_FALSE(notifier.Ready());
  EXPECT_FALSE(notifier.Status("ok"));
  EXPECT_FALSE(notifier.WatchdogPing());
  EXPECT_FALSE(notifier.Stopping());
  unsetenv("WATCHDOG_USEC");
  unsetenv("WATCHDOG_PID");
}

TEST(ServiceNotifierTest, SendsTheProtocolMessages) {
  FakeSystemd systemd(microseconds(200000));
  ServiceNotifier notifier;
  ASSERT_TRUE(notifier.enabled());
  ASSERT_TRUE(notifier.WatchdogInterval().has_value());
  EXPECT_EQ(*notifier.WatchdogInterval(), microseconds(200000));
  EXPECT_TRUE(notifier.Ready());
  EXPECT_TRUE(notifier.WatchdogPing());
  EXPECT_TRUE(notifier.Status("degraded: cam1 stale\nsecond line"));
  EXPECT_TRUE(notifier.Stopping());
  EXPECT_EQ(systemd.Receive(kEventually), "READY=1");
  EXPECT_EQ(systemd.Receive(kEventually), "WATCHDOG=1");
  EXPECT_EQ(systemd.Receive(kEventually), "STATUS=degraded: cam1 stale second line");
  EXPECT_EQ(systemd.Receive(kEventually), "STOPPING=1");
}

TEST(ServiceNotifierTest, WatchdogMeantForAnotherProcessIsIgnored) {
  FakeSystemd systemd(microseconds(200000), getpid() + 1);
  ServiceNotifier notifier;
  EXPECT_TRUE(notifier.enabled());
  EXPECT_FALSE(notifier.WatchdogInterval().has_value());
}

TEST(ServiceNotifierTest, NoWatchdogWhenSystemdSetsNone) {
  FakeSystemd systemd(std::nullopt);
  ServiceNotifier notifier;
  EXPECT_TRUE(notifier.enabled());
  EXPECT_FALSE(notifier.WatchdogInterval().has_value());
}

// ---------------------------------------------------------------------------
// ServiceWatchdog

TEST(ServiceWatchdogTest, PingsOnlyWhileEveryStageMoves) {
  FakeSystemd systemd(microseconds(200000));
  Heartbeats beats;
  const int capture = beats.Register("capture cam0");
  const int fusion = beats.Register("fusion");
  auto capture_thread = std::make_unique<StageThread>(beats, capture);
  StageThread fusion_thread(beats, fusion);

  ServiceNotifier notifier;
  ServiceWatchdog watchdog(beats, notifier, milliseconds(5000));
  EXPECT_EQ(watchdog.period(), microseconds(100000));  // WatchdogSec / 2, not the fallback.
  ASSERT_TRUE(notifier.Ready());
  watchdog.Start();
  watchdog.SetStatus("ok cycle 1");

  std::vector<std::string> seen;
  ASSERT_EQ(systemd.Receive(kEventually), "READY=1");
  ASSERT_TRUE(systemd.WaitFor([](const std::string& m) { return m == "STATUS=ok cycle 1"; },
                              kEventually, &seen));
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(systemd.WaitFor(IsPing, kEventually, &seen));

  // A stuck capture thread: the watchdog names it (a transient hiccup of the
  // healthy stage may show up in an earlier status; the report follows the
  // set of stalled stages, so one naming the capture stage alone arrives).
  capture_thread->Freeze();
  seen.clear();
  const auto report = systemd.WaitFor(
      [](const std::string& m) {
        return IsStatus(m) && m.find("capture cam0") != std::string::npos &&
               m.find("fusion") == std::string::npos;
      },
      kEventually, &seen);
  ASSERT_TRUE(report) << "no STATUS= naming the stalled stage";
  EXPECT_NE(report->find("STALLED"), std::string::npos) << *report;
  EXPECT_TRUE(watchdog.stalled());

  // While the stage is stuck: no ping for five check periods, and the health
  // text stays held back so systemctl keeps showing the stall.
  watchdog.SetStatus("ok cycle 2");
  const std::uint64_t healthy_before = watchdog.healthy_checks();
  seen.clear();
  EXPECT_FALSE(systemd.WaitFor(IsPing, milliseconds(500), &seen));
  for (const std::string& m : seen) EXPECT_NE(m, "STATUS=ok cycle 2");
  EXPECT_EQ(watchdog.healthy_checks(), healthy_before);

  // The stage comes back before systemd acted: pinging resumes, and the held
  // health text replaces the stall report first.
  capture_thread->Unfreeze();
  seen.clear();
  ASSERT_TRUE(systemd.WaitFor(IsPing, kEventually, &seen));
  ASSERT_FALSE(seen.empty());
  bool restored = false;
  for (const std::string& m : seen) restored = restored || m == "STATUS=ok cycle 2";
  EXPECT_TRUE(restored);
  EXPECT_FALSE(watchdog.stalled());
  ASSERT_TRUE(systemd.WaitFor(IsPing, kEventually, &seen));

  watchdog.Stop();
  watchdog.Stop();  // Idempotent.
  // Stopped: no more pings even though the stages keep beating.
  seen.clear();
  EXPECT_FALSE(systemd.WaitFor(IsPing, milliseconds(300), &seen));
}

// A 2 m cell with one simulated camera (no people), for the real pipeline.
struct OneCamera {
  std::shared_ptr<sim::Scene> scene;
  pipeline::PipelineOptions options;
  int timeout_ms = 200;
  [[nodiscard]] std::vector<pipeline::PipelineCamera> Cameras() const {
    std::vector<pipeline::PipelineCamera> cameras;
    cameras.push_back(
        {scene->cameras[0].model,
         std::make_unique<capture::SimSource>(scene, 0, 30.0, capture::SimClock::Now()),
         timeout_ms});
    return cameras;
  }
};

OneCamera OneSimCamera(int timeout_ms) {
  OneCamera cell;
  cell.scene = std::make_shared<sim::Scene>();
  cell.scene->bounds.min = Eigen::Vector3d(0, 0, 0);
  cell.scene->bounds.max = Eigen::Vector3d(2, 2, 2);
  sim::SceneCamera camera;
  camera.model = scene::LookAtCamera({-0.5, -0.5, 2.2}, {1, 1, 0.8}, 160, 120, 130);
  camera.model.name = "cam0";
  cell.scene->cameras.push_back(camera);
  cell.options.bounds = cell.scene->bounds;
  cell.options.depth = 5;
  cell.options.publish_depth = 5;
  cell.timeout_ms = timeout_ms;
  return cell;
}

// The real pipeline's stages: one simulated camera and the fusion thread beat
// the heartbeats; a consumer that blocks freezes the fusion stage (as a hung
// publisher would) and the pings stop until it returns.
TEST(ServiceWatchdogTest, AFrozenPipelineStageStopsThePings) {
  FakeSystemd systemd(microseconds(200000));
  const OneCamera cell = OneSimCamera(200);
  const pipeline::PipelineOptions& options = cell.options;
  std::vector<pipeline::PipelineCamera> cameras = cell.Cameras();
  std::atomic<bool> freeze{false};
  std::atomic<bool> frozen{false};  // The fusion thread is inside the freeze.
  Heartbeats beats;
  pipeline::Pipeline pipeline(
      options, std::move(cameras), {},
      [&freeze, &frozen](const std::shared_ptr<const pipeline::OccupancySnapshot>&) {
        while (freeze.load()) {
          frozen.store(true);
          std::this_thread::sleep_for(milliseconds(5));
        }
        frozen.store(false);
      },
      &beats);
  ASSERT_EQ(beats.size(), 3);
  EXPECT_EQ(beats.name(0), "capture cam0");
  EXPECT_EQ(beats.name(1), "silhouette cam0");
  EXPECT_EQ(beats.name(2), "fusion");

  ServiceNotifier notifier;
  ServiceWatchdog watchdog(beats, notifier);
  pipeline.Start();
  watchdog.Start();
  std::vector<std::string> seen;
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(systemd.WaitFor(IsPing, kEventually, &seen));

  freeze.store(true);
  const auto frozen_by = std::chrono::steady_clock::now() + kEventually;
  while (!frozen.load() && std::chrono::steady_clock::now() < frozen_by) {
    std::this_thread::sleep_for(milliseconds(1));
  }
  ASSERT_TRUE(frozen.load()) << "the fusion thread never reached the consumer";
  // From here on the fusion stage does not beat. What was sent so far may hold
  // a stall report from a moment the machine held the fusion thread up, with
  // pings after it: the stall counts as reported only when no ping follows
  // its report; otherwise the report is still to come.
  auto names_fusion = [](const std::string& m) {
    return IsStatus(m) && m.find("fusion") != std::string::npos;
  };
  std::vector<std::string> sent;
  while (const auto m = systemd.Receive(milliseconds(0))) sent.push_back(*m);
  const auto last_report = std::find_if(sent.rbegin(), sent.rend(), names_fusion);
  const bool reported =
      last_report != sent.rend() && std::find_if(sent.rbegin(), last_report, IsPing) == last_report;
  if (!reported) {
    ASSERT_TRUE(systemd.WaitFor(names_fusion, kEventually, &seen))
        << "no STATUS= naming the frozen fusion stage";
  }
  seen.clear();
  EXPECT_FALSE(systemd.WaitFor(IsPing, milliseconds(600), &seen));

  freeze.store(false);
  ASSERT_TRUE(systemd.WaitFor(IsPing, kEventually, &seen));
  watchdog.Stop();
  pipeline.Stop();
}

// At a low rate (1 Hz) the fusion thread beats while it waits for the next
// cycle, not once per cycle: a beat per second is as slow as the watchdog's
// checks under WatchdogSec=2, and jitter left checks without a beat (systemd
// would restart a healthy daemon).
TEST(ServiceWatchdogTest, FusionAtOneHertzBeatsWhileItWaits) {
  OneCamera cell = OneSimCamera(2000);
  cell.options.rate_hz = 1.0;
  Heartbeats beats;
  pipeline::Pipeline pipeline(cell.options, cell.Cameras(), {}, nullptr, &beats);
  ASSERT_EQ(beats.name(2), "fusion");
  pipeline.Start();
  // Ten windows of 250 ms: a beat per cycle would reach at most three of them.
  int windows_with_beats = 0;
  std::uint64_t last = beats.beats(2);
  for (int w = 0; w < 10; ++w) {
    std::this_thread::sleep_for(milliseconds(250));
    const std::uint64_t now = beats.beats(2);
    windows_with_beats += now != last ? 1 : 0;
    last = now;
  }
  pipeline.Stop();
  EXPECT_GE(windows_with_beats, 8);
}

TEST(ServiceWatchdogTest, WithoutSystemdItStillDetectsStalls) {
  unsetenv("NOTIFY_SOCKET");
  unsetenv("WATCHDOG_USEC");
  unsetenv("WATCHDOG_PID");
  Heartbeats beats;
  const int id = beats.Register("worker");
  StageThread stage(beats, id);
  ServiceNotifier notifier;
  ServiceWatchdog watchdog(beats, notifier, milliseconds(20));
  EXPECT_EQ(watchdog.period(), microseconds(20000));
  watchdog.Start();

  auto wait_until = [](const std::function<bool()>& condition) {
    const auto end = std::chrono::steady_clock::now() + kEventually;
    while (!condition() && std::chrono::steady_clock::now() < end) {
      std::this_thread::sleep_for(milliseconds(5));
    }
    return condition();
  };
  ASSERT_TRUE(wait_until([&] { return watchdog.healthy_checks() >= 2; }));
  stage.Freeze();
  ASSERT_TRUE(wait_until([&] { return watchdog.stalled(); }));
  const std::uint64_t healthy = watchdog.healthy_checks();
  std::this_thread::sleep_for(milliseconds(100));  // Five periods, all stalled.
  EXPECT_EQ(watchdog.healthy_checks(), healthy);
  EXPECT_TRUE(watchdog.stalled());
  stage.Unfreeze();
  ASSERT_TRUE(wait_until([&] { return !watchdog.stalled(); }));
  watchdog.Stop();
}

TEST(ServiceWatchdogTest, StopWithoutStartIsFine) {
  Heartbeats beats;
  ServiceNotifier notifier;
  ServiceWatchdog watchdog(beats, notifier);
  watchdog.Stop();
}

}  // namespace
}  // namespace hg::app
