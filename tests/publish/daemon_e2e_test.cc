// End to end over DDS: hullguardd runs on simulated cameras and this test
// subscribes as a robot controller would. Run inside a private network
// namespace holding only loopback (tests/publish/in_netns.sh).
//   daemon_e2e_test HULLGUARDD SOURCE_DIR
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "hullguard.h"
#include "publish/dds.h"
#include "publish/dds_publisher.h"
#include "publish/hullguardd_run.h"
#include "sim/scene.h"
#include "support/run_tool.h"
#include "support/sim_bodies.h"

namespace hg {
namespace {

namespace fs = std::filesystem;
namespace dds = publish::dds;
using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

std::string g_daemon;
std::string g_source_dir;

using testing::ReadFile;

std::string Replace(std::string text, const std::string& from, const std::string& to) {
  for (std::size_t at = text.find(from); at != std::string::npos;
       at = text.find(from, at + to.size())) {
    text.replace(at, from.size(), to);
  }
  return text;
}

struct OccupancySample {
  std::uint64_t sequence = 0;
  std::int64_t stamp_ns = 0;
  std::int64_t received_ns = 0;
  bool complete = false;
  Eigen::Vector3d lo, hi;
  int depth = 0;
  std::vector<hullguard_GridRun> occupied, occluded;
};

struct StatusSample {
  std::uint64_t sequence = 0;
  Clock::time_point received;
  bool degraded = false;
  std::vector<std::uint8_t> camera_states;
  std::vector<float> frame_ages_ms;
  std::vector<float> fps;
};

std::int64_t RealtimeNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

/// A controller's view: both topics, collected for a while.
class Controller {
 public:
  Controller()
      : participant_(0),
        occupancy_topic_(participant_, &hullguard_Occupancy_desc,
                         publish::OccupancyTopicName("hullguard")),
        status_topic_(participant_, &hullguard_Status_desc, publish::StatusTopicName("hullguard")),
        occupancy_(participant_, occupancy_topic_,
                   testing::KeepingLast(publish::OccupancyReaderQos(1s)).get()),
        status_(participant_, status_topic_,
                testing::KeepingLast(publish::StatusReaderQos(1s)).get()) {}

  /// Polls both readers for `duration` (or until `enough` occupancy samples).
  void Collect(std::chrono::milliseconds duration, std::size_t enough = SIZE_MAX) {
    for (const auto end = Clock::now() + duration;
         Clock::now() < end && occupancy_samples.size() < enough;) {
      TakeOccupancy();
      TakeStatus();
      std::this_thread::sleep_for(5ms);
    }
  }

  std::vector<OccupancySample> occupancy_samples;
  std::vector<StatusSample> status_samples;

 private:
  void TakeOccupancy() {
    void* samples[8] = {};
    dds_sample_info_t infos[8];
    const dds_return_t n = dds_take(occupancy_.handle(), samples, infos, 8, 8);
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto& s = *static_cast<const hullguard_Occupancy*>(samples[i]);
      OccupancySample o;
      o.sequence = s.sequence;
      o.stamp_ns = s.stamp_ns;
      o.received_ns = RealtimeNs();
      o.complete = s.complete;
      o.lo = Eigen::Vector3d(s.bounds_min[0], s.bounds_min[1], s.bounds_min[2]);
      o.hi = Eigen::Vector3d(s.bounds_max[0], s.bounds_max[1], s.bounds_max[2]);
      o.depth = s.depth;
      o.occupied.assign(s.occupied._buffer, s.occupied._buffer + s.occupied._length);
      o.occluded.assign(s.occluded._buffer, s.occluded._buffer + s.occluded._length);
      occupancy_samples.push_back(std::move(o));
    }
    if (n > 0) dds_return_loan(occupancy_.handle(), samples, n);
  }
  void TakeStatus() {
    void* samples[8] = {};
    dds_sample_info_t infos[8];
    const dds_return_t n = dds_take(status_.handle(), samples, infos, 8, 8);
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto& s = *static_cast<const hullguard_Status*>(samples[i]);
      StatusSample st{s.sequence, Clock::now(), s.degraded, {}, {}, {}};
      for (std::uint32_t c = 0; c < s.cameras._length; ++c) {
        st.camera_states.push_back(s.cameras._buffer[c].state);
        st.frame_ages_ms.push_back(s.cameras._buffer[c].frame_age_ms);
        st.fps.push_back(s.cameras._buffer[c].fps);
      }
      status_samples.push_back(std::move(st));
    }
    if (n > 0) dds_return_loan(status_.handle(), samples, n);
  }

  dds::Participant participant_;
  dds::Topic occupancy_topic_, status_topic_;
  dds::Reader occupancy_, status_;
};

std::size_t Cells(const std::vector<hullguard_GridRun>& runs) {
  std::size_t n = 0;
  for (const hullguard_GridRun& r : runs) n += r.length;
  return n;
}

/// Ground-truth points of the scene at the sample's stamp in cells the
/// sample lists neither occupied nor occluded.
int PointsReportedFree(const sim::Scene& scene, std::int64_t epoch_ns, const OccupancySample& s,
                       std::uint64_t seed) {
  const double t = static_cast<double>(s.stamp_ns - epoch_ns) * 1e-9;
  return testing::PointsInUnlistedCells(testing::PointsInPeople(scene, t, 40, seed), s.lo, s.hi,
                                        s.depth, {&s.occupied, &s.occluded});
}

class DaemonE2E : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("hg_e2e_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

// People walking in the demo cell: every sampled point of every person, at the
// instant each received sample is stamped with, lies in a listed cell.
TEST_F(DaemonE2E, ReceivedOccupancyCoversEveryPersonPoint) {
  const std::string config = g_source_dir + "/config/demo.yaml";
  const sim::Scene scene = sim::LoadScene(g_source_dir + "/config/scenes/demo_cell.yaml");
  Controller controller;
  testing::HullguarddRun daemon(g_daemon, config, 9.0, dir_);
  const std::int64_t epoch = daemon.SceneEpoch();
  controller.Collect(8000ms, 60);
  ASSERT_GE(controller.occupancy_samples.size(), 20U) << daemon.Log();
  int free = 0;
  std::size_t occupied = 0;
  for (std::size_t i = 0; i < controller.occupancy_samples.size(); ++i) {
    const OccupancySample& s = controller.occupancy_samples[i];
    free += PointsReportedFree(scene, epoch, s, i);
    occupied += Cells(s.occupied);
  }
  EXPECT_EQ(free, 0);
  EXPECT_GT(occupied, 0U);
  EXPECT_FALSE(controller.status_samples.empty());
}

// One camera stops delivering 4 s in (a pulled cable). Within its timeout the
// status turns degraded and names the camera stale, and the occupied volume of
// the static scene only grows.
TEST_F(DaemonE2E, StoppedCameraTurnsDegradedAndOccupancyOnlyGrows) {
  std::string text = ReadFile(g_source_dir + "/config/demo.yaml");
  text = Replace(text, "scene: scenes/demo_cell.yaml",
                 "scene: " + g_source_dir + "/tests/data/demo_cell_standing.yaml");
  // Depth 6 keeps the updates well inside the deadline on a loaded machine, so
  // complete cycles are there to compare with.
  text = Replace(text, "  depth: 7", "  depth: 6");
  // The exact octree: with boundary coarsening, a coarse occluded leaf at the
  // edge of a view is split where a silhouette reaches into it, and the parts
  // another camera sees as background turn free. A lagging camera's dilated
  // mask does that, so the non-free volume may dip by such cells while the
  // camera turns stale (docs/operations.md); here it must not.
  text = Replace(text, "boundary_coarsening: 3", "boundary_coarsening: 0");
  // Nobody moves: no silhouette needs growing for the cameras' capture skew,
  // so every healthy cycle lists the same cells.
  text += "\nmotion:\n  max_speed_mps: 0\n";
  text = Replace(text, "file: demo_cell/obstacles.obj",
                 "file: " + g_source_dir + "/config/demo_cell/obstacles.obj");
  // The last camera's source gets the fault.
  const std::size_t last = text.rfind("demo_cell_standing.yaml}");
  ASSERT_NE(last, std::string::npos);
  text.replace(last, std::string("demo_cell_standing.yaml}").size(),
               "demo_cell_standing.yaml, stop_after_s: 4}");
  const std::string config = (dir_ / "standing.yaml").string();
  std::ofstream(config) << text;
  const sim::Scene scene = sim::LoadScene(g_source_dir + "/tests/data/demo_cell_standing.yaml");

  Controller controller;
  testing::HullguarddRun daemon(g_daemon, config, 7.0, dir_);
  const std::int64_t epoch = daemon.SceneEpoch();
  controller.Collect(6500ms);
  ASSERT_FALSE(controller.occupancy_samples.empty()) << daemon.Log();

  // Before the stop (with a margin for the camera's last frames), cycles whose
  // status was healthy; after it, every cycle once the timeout has certainly
  // passed.
  std::set<std::uint64_t> healthy_cycles;  // Every camera ok (an update may have aborted).
  for (const StatusSample& st : controller.status_samples) {
    if (std::all_of(st.camera_states.begin(), st.camera_states.end(),
                    [](std::uint8_t state) { return state == 1; })) {
      healthy_cycles.insert(st.sequence);
    }
  }
  const std::int64_t stop_ns = epoch + 4'000'000'000LL;
  // The baseline is the last healthy cycle 0.3 s before the stop (the healthy
  // cycles once the people stand list the same cells); from then on, through
  // the timeout, the turn to stale and after it, every sample must list each
  // of its cells.
  int free = 0;
  const OccupancySample* baseline = nullptr;
  std::size_t before = 0, after = 0;
  for (std::size_t i = 0; i < controller.occupancy_samples.size(); ++i) {
    const OccupancySample& s = controller.occupancy_samples[i];
    free += PointsReportedFree(scene, epoch, s, i);
    if (s.stamp_ns < stop_ns - 300'000'000LL && healthy_cycles.count(s.sequence) != 0 &&
        s.complete) {
      ++before;
      baseline = &s;
    }
  }
  EXPECT_EQ(free, 0);
  ASSERT_GT(before, 5U) << daemon.Log();
  auto listed_cells = [](const OccupancySample& s) {
    return testing::ListedCells(s.depth, {&s.occupied, &s.occluded});
  };
  const std::vector<std::uint8_t> base = listed_cells(*baseline);
  std::size_t checked = 0, dropped = 0;
  for (const OccupancySample& s : controller.occupancy_samples) {
    if (s.stamp_ns < stop_ns - 300'000'000LL) continue;
    ASSERT_EQ(s.depth, baseline->depth);
    const std::vector<std::uint8_t> now = listed_cells(s);
    for (std::size_t c = 0; c < base.size(); ++c) dropped += base[c] && !now[c] ? 1 : 0;
    ++checked;
    after += s.stamp_ns > stop_ns + 500'000'000LL ? 1 : 0;
  }
  ASSERT_GT(after, 5U) << daemon.Log();
  EXPECT_EQ(dropped, 0U) << "losing a camera must never free space (" << checked << " samples)";

  // Status: ok before, degraded with camera 3 stale (state 2) after.
  bool healthy_seen = false, degraded_seen = false;
  for (const StatusSample& st : controller.status_samples) {
    if (!st.degraded) healthy_seen = true;
    if (st.degraded && st.camera_states.size() == 4 && st.camera_states[3] == 2) {
      degraded_seen = true;
    }
  }
  EXPECT_TRUE(healthy_seen);
  EXPECT_TRUE(degraded_seen) << daemon.Log();
  // Stale within its timeout (200 ms): every cycle whose newest frame of the
  // camera is older than that reports it stale, and none reports it ok with
  // an older frame. (The cycles' own times depend on the machine's load; the
  // rule holds at each of them.)
  constexpr float kTimeoutMs = 200.0F;
  std::size_t past_timeout = 0, called_ok = 0, not_degraded = 0;
  for (const StatusSample& st : controller.status_samples) {
    ASSERT_EQ(st.frame_ages_ms.size(), 4U);
    if (st.frame_ages_ms[3] > kTimeoutMs + 0.01F) {
      ++past_timeout;
      called_ok += st.camera_states[3] == 1 ? 1 : 0;
      not_degraded += st.degraded ? 0 : 1;
    }
  }
  EXPECT_GT(past_timeout, 5U) << "the stopped camera's frames never aged past the timeout";
  EXPECT_EQ(called_ok, 0U) << "of " << past_timeout
                           << " cycles with camera 3's frames past its timeout, called it ok";
  EXPECT_EQ(not_degraded, 0U) << "of " << past_timeout
                              << " cycles with camera 3's frames past its timeout, not degraded";
  // Its rate over the last second: 0 once its newest frame is more than a
  // second old (with a reporting cycle to spare), not the old rate until the
  // next window.
  std::size_t long_silent = 0, rate_shown = 0;
  for (const StatusSample& st : controller.status_samples) {
    if (st.frame_ages_ms[3] > 1100.0F) {
      ++long_silent;
      rate_shown += st.fps[3] > 0.0F ? 1 : 0;
    }
  }
  EXPECT_GT(long_silent, 5U);
  EXPECT_EQ(rate_shown, 0U) << "of " << long_silent
                            << " cycles with camera 3 silent for over a second, showed a rate";
  // The daemon's log names the stale camera within the timeout (200 ms) plus
  // a reporting period.
  EXPECT_NE(daemon.Log().find("cam3 stale"), std::string::npos) << daemon.Log();
}

// This test plays systemd for Type=notify: READY=1 comes only once every
// camera has delivered (the status line sent with it names no camera still
// starting), WATCHDOG=1 follows while every stage runs, and SIGTERM ends the
// daemon cleanly within a second, with STOPPING=1 first.
TEST_F(DaemonE2E, NotifiesReadyWatchdogAndStoppingAsAService) {
  const std::string socket_path = (dir_ / "notify").string();
  const int fd = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  ASSERT_GE(fd, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  ASSERT_LT(socket_path.size(), sizeof(addr.sun_path));
  std::strncpy(addr.sun_path, socket_path.c_str(), sizeof(addr.sun_path) - 1);
  ASSERT_EQ(bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)), 0);
  setenv("NOTIFY_SOCKET", socket_path.c_str(), 1);
  setenv("WATCHDOG_USEC", "1000000", 1);  // Pings every 0.5 s.
  testing::HullguarddRun daemon(g_daemon, g_source_dir + "/config/demo.yaml", 60.0, dir_);
  unsetenv("NOTIFY_SOCKET");
  unsetenv("WATCHDOG_USEC");

  std::vector<std::string> messages;  // One line each, in arrival order.
  auto receive_until = [&](Clock::duration limit, auto done) {
    for (const auto end = Clock::now() + limit; Clock::now() < end && !done();) {
      pollfd p{fd, POLLIN, 0};
      if (poll(&p, 1, 50) <= 0) continue;
      char buf[4096];
      const ssize_t n = recv(fd, buf, sizeof(buf), 0);
      if (n <= 0) continue;
      std::istringstream lines(std::string(buf, static_cast<std::size_t>(n)));
      for (std::string line; std::getline(lines, line);) messages.push_back(line);
    }
  };
  auto index_of = [&](const std::string& line, std::size_t from = 0) {
    const auto it =
        std::find(messages.begin() + static_cast<std::ptrdiff_t>(from), messages.end(), line);
    return static_cast<std::size_t>(it - messages.begin());
  };
  // READY, then a ping after it.
  receive_until(30s, [&] {
    const std::size_t ready = index_of("READY=1");
    return ready < messages.size() && index_of("WATCHDOG=1", ready) < messages.size();
  });
  const std::size_t ready = index_of("READY=1");
  ASSERT_LT(ready, messages.size()) << "no READY=1\n" << daemon.Log();
  ASSERT_LT(index_of("WATCHDOG=1", ready), messages.size()) << "no WATCHDOG=1 after READY=1";
  const auto status =
      std::find_if(messages.begin() + static_cast<std::ptrdiff_t>(ready), messages.end(),
                   [](const std::string& m) { return m.rfind("STATUS=", 0) == 0; });
  ASSERT_NE(status, messages.end()) << "no STATUS= with READY=1";
  // Every camera has delivered (one may be stale for a moment on a loaded
  // machine, but none is still starting), and each is named.
  EXPECT_EQ(status->find("starting"), std::string::npos) << *status;
  for (const char* camera : {"cam0 ", "cam1 ", "cam2 ", "cam3 "}) {
    EXPECT_NE(status->find(camera), std::string::npos) << *status;
  }

  Clock::duration took{};
  EXPECT_EQ(daemon.Terminate(1s, &took), 0) << daemon.Log();
  EXPECT_LT(took, 1s);
  std::printf("SIGTERM to exit: %.0f ms\n",
              std::chrono::duration<double, std::milli>(took).count());
  receive_until(500ms, [&] { return index_of("STOPPING=1") < messages.size(); });
  EXPECT_LT(index_of("STOPPING=1"), messages.size());
  close(fd);
}

// SIGTERM ends the daemon cleanly (exit 0, "stopped") within a second also
// while it starts up (a signal then used to kill it half-built) and at a
// cycle rate of 1 Hz (its fusion thread used to sleep out the period, and
// then ran one more cycle with its cameras stopped).
// Whether process `pid` catches SIGTERM (/proc: SigCgt). Before main()
// nothing can catch it.
bool CatchesSigterm(pid_t pid) {
  std::ifstream status("/proc/" + std::to_string(pid) + "/status");
  for (std::string line; std::getline(status, line);) {
    if (line.rfind("SigCgt:", 0) == 0) {
      return ((std::stoull(line.substr(7), nullptr, 16) >> (SIGTERM - 1)) & 1u) != 0;
    }
  }
  return false;
}

TEST_F(DaemonE2E, SigtermDuringStartUpAndAtALowRateEndsCleanlyWithinASecond) {
  {
    fs::create_directories(dir_ / "early");
    testing::HullguarddRun daemon(g_daemon, g_source_dir + "/config/demo.yaml", 60.0,
                                  dir_ / "early");
    // As soon as it catches SIGTERM (/proc: SigCgt), well before its start-up
    // (config, obstacle maps, tracking voxels, cameras) is done. Before main()
    // nothing can catch it, so this waits for that.
    auto catches_sigterm = [&] { return CatchesSigterm(daemon.pid()); };
    for (const auto end = Clock::now() + 10s; Clock::now() < end && !catches_sigterm();) {
      std::this_thread::sleep_for(1ms);
    }
    ASSERT_TRUE(catches_sigterm()) << daemon.Log();
    EXPECT_EQ(daemon.Log().find("running"), std::string::npos) << "started up already";
    Clock::duration took{};
    EXPECT_EQ(daemon.Terminate(1s, &took), 0) << daemon.Log();
    EXPECT_LT(took, 1s);
    EXPECT_NE(daemon.Log().find("stopped"), std::string::npos) << daemon.Log();
  }
  std::string text = ReadFile(g_source_dir + "/config/demo.yaml");
  text = Replace(text, "  rate_hz: 30", "  rate_hz: 1");
  const std::string config = (dir_ / "slow.yaml").string();
  std::ofstream(config) << text;
  // The scene and obstacle paths are relative to the config's folder.
  fs::copy(g_source_dir + "/config/scenes", dir_ / "scenes", fs::copy_options::recursive);
  fs::copy(g_source_dir + "/config/demo_cell", dir_ / "demo_cell", fs::copy_options::recursive);
  for (const double after_s : {2.3, 2.8}) {
    fs::create_directories(dir_ / "slow");
    testing::HullguarddRun daemon(g_daemon, config, 60.0, dir_ / "slow");
    std::this_thread::sleep_for(1500ms);
    // Neither a hangup (it does not reload) nor a closed pipe ends it.
    kill(daemon.pid(), SIGHUP);
    kill(daemon.pid(), SIGPIPE);
    // Said once its main loop runs (a loaded machine may still be starting it up).
    for (const auto end = Clock::now() + 10s;
         Clock::now() < end && daemon.Log().find("SIGHUP ignored") == std::string::npos;) {
      std::this_thread::sleep_for(10ms);
    }
    EXPECT_NE(daemon.Log().find("SIGHUP ignored"), std::string::npos) << daemon.Log();
    std::this_thread::sleep_for(std::chrono::duration<double>(after_s - 1.5));
    EXPECT_TRUE(daemon.Running()) << daemon.Log();
    Clock::duration took{};
    EXPECT_EQ(daemon.Terminate(1s, &took), 0) << daemon.Log();
    EXPECT_LT(took, 1s) << "after " << after_s << " s";
    std::printf("1 Hz, SIGTERM after %.1f s: exit in %.0f ms\n", after_s,
                std::chrono::duration<double, std::milli>(took).count());
  }
  // A start-up step that takes seconds without a look at the stop (here the
  // tracking voxels of a fine grid: 11 million, about 2 s on this machine)
  // does not hold SIGTERM up: it took 1.7 s past the signal, systemd's
  // TimeoutStopSec=5 would have killed a slower one.
  text = ReadFile(g_source_dir + "/config/demo.yaml") + "tracking:\n  voxel_m: 0.018\n";
  const std::string fine = (dir_ / "fine_tracking.yaml").string();
  std::ofstream(fine) << text;
  fs::create_directories(dir_ / "fine");
  testing::HullguarddRun daemon(g_daemon, fine, 60.0, dir_ / "fine");
  auto catches_sigterm = [&] { return CatchesSigterm(daemon.pid()); };
  for (const auto end = Clock::now() + 10s; Clock::now() < end && !catches_sigterm();) {
    std::this_thread::sleep_for(1ms);
  }
  ASSERT_TRUE(catches_sigterm()) << daemon.Log();
  std::this_thread::sleep_for(800ms);  // Into the tracking grid's build.
  const bool started = daemon.Log().find("tracking on") != std::string::npos;
  Clock::duration took{};
  EXPECT_EQ(daemon.Terminate(1s, &took), 0) << daemon.Log();
  EXPECT_LT(took, 1s) << daemon.Log();
  EXPECT_NE(daemon.Log().find("stopped during start-up"), std::string::npos) << daemon.Log();
  std::printf("fine tracking grid, SIGTERM during start-up (%s): exit in %.0f ms\n",
              started ? "grid built already" : "building the grid",
              std::chrono::duration<double, std::milli>(took).count());
}

TEST_F(DaemonE2E, BadConfigExitsTwoNamingKeyAndLine) {
  std::string text = ReadFile(g_source_dir + "/config/demo.yaml");
  text = Replace(text, "  deadline_ms: 25", "  deadline_ms: 25\n  jitter_ms: 3");
  const std::string config = (dir_ / "bad.yaml").string();
  std::ofstream(config) << text;
  const testing::ProcessResult r = testing::RunTool(g_daemon, "--config " + config);
  EXPECT_EQ(r.code, 2);
  const std::size_t line = std::count(text.begin(), text.begin() + text.find("jitter_ms"), '\n');
  EXPECT_NE(r.err.find(config + ":" + std::to_string(line + 1) + ": timing"), std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("unknown key 'jitter_ms'"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace hg

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  if (argc != 3) {
    std::fprintf(stderr, "usage: daemon_e2e_test HULLGUARDD SOURCE_DIR\n");
    return 2;
  }
  hg::g_daemon = argv[1];
  hg::g_source_dir = argv[2];
  return RUN_ALL_TESTS();
}
