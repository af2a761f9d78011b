// End to end through real GigE Vision: fake GigE cameras in this process
// (Aravis' ArvGvFakeCamera on 127.0.0.2 .. 127.0.0.4) serve the simulator's
// colour frames of a cell, over GVCP and GVSP, to hullguardd's aravis
// sources; the daemon's background model, octree and DDS publisher do the
// rest, and this test reads Occupancy and Status as a robot controller would.
// A camera is killed and restarted while the daemon runs. Run through
// tests/publish/in_netns.sh: a private network namespace with only loopback,
// so no discovery broadcast or stream leaves the machine.
//   gige_e2e_test (HG_HULLGUARDD: the daemon binary)
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "capture/aravis_source.h"
#include "capture/camera_health.h"
#include "hullguard.h"
#include "publish/dds.h"
#include "publish/dds_publisher.h"
#include "publish/hullguardd_run.h"
#include "sim/body.h"
#include "sim/colour_renderer.h"
#include "sim/scene.h"
#include "support/fake_gige_camera.h"
#include "support/sim_bodies.h"

namespace hg {
namespace {

namespace fs = std::filesystem;
namespace dds = publish::dds;
using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;
using namespace std::chrono_literals;

constexpr int kWidth = 320;
constexpr int kHeight = 240;
constexpr double kFrameRateHz = 10.0;
constexpr int kLearnFrames = 10;       // background.learn_frames of the daemon's config.
constexpr int kCameraTimeoutMs = 800;  // timing.camera_timeout_ms: the frame watchdog too.
// systemd/hullguardd.service: TimeoutStopSec=5, after which systemd kills.
constexpr auto kSystemdStopTimeout = 5s;

// The cell: three corner cameras over a 3 x 3 x 2.5 m volume, 320 x 240,
// each asking for another pixel format, so that the RGB, Bayer and Mono
// paths all carry the reconstruction.
struct CameraSpec {
  const char* name;
  const char* position;
  const char* address;
  const char* pixel_format;
};
constexpr CameraSpec kCameras[] = {
    {"cam0", "[-0.4, -0.4, 2.4]", "127.0.0.2", "RGB8"},
    {"cam1", "[3.4, 3.4, 2.4]", "127.0.0.3", "BayerRG8"},
    {"cam2", "[3.4, -0.4, 2.4]", "127.0.0.4", "Mono8"},
};
constexpr int kNumCameras = 3;
constexpr const char* kCameraBlock =
    "width: 320, height: 240, K: [260, 0, 159.5, 0, 260, 119.5, 0, 0, 1], "
    "look_at: [1.5, 1.5, 0.8]";

std::string SceneYaml() {
  std::ostringstream s;
  s << "scene: {name: gige_cell, bounds: {min: [0, 0, 0], max: [3, 3, 2.5]}, rate_hz: 10}\n"
    << "cameras:\n";
  for (const CameraSpec& c : kCameras) {
    s << "  - {name: " << c.name << ", position: " << c.position << ", " << kCameraBlock << "}\n";
  }
  // Two people standing still for the whole run: occupancy can be compared
  // across time, and the ground truth holds whatever a frame's time stamp.
  s << "people:\n"
    << "  - {name: alice, height: 1.7, start: [1.0, 1.2], script: [{stand: {duration: 600}}]}\n"
    << "  - {name: bob, height: 1.85, start: [2.0, 1.7], "
       "script: [{stand: {duration: 600, heading_deg: 90}}]}\n";
  return s.str();
}

// The daemon's config: the scene's calibration, aravis sources by address.
// motion.max_speed_mps 0: the people stand still, and the cameras' free-running
// phases would otherwise grow each silhouette by a different skew dilation
// every cycle, so occupancy could not be compared across cycles.
std::string ConfigYaml() {
  std::ostringstream s;
  s << "cell: {bounds: {min: [0, 0, 0], max: [3, 3, 2.5]}}\n"
    << "octree: {depth: 7, publish_depth: 6}\n"
    << "timing: {rate_hz: 10, deadline_ms: 80, camera_timeout_ms: " << kCameraTimeoutMs << "}\n"
    << "motion: {max_speed_mps: 0}\n"
    << "background: {learn_frames: " << kLearnFrames << "}\n"
    << "dds: {domain_id: 0, topic_prefix: hullguard, enabled: true}\n"
    << "cameras:\n";
  for (const CameraSpec& c : kCameras) {
    s << "  - {name: " << c.name << ", position: " << c.position << ", " << kCameraBlock << ",\n"
      << "     source: {type: aravis, device: \"" << c.address
      << "\", pixel_format: " << c.pixel_format << ", frame_rate_hz: " << kFrameRateHz
      << ", exposure_us: 2000}}\n";
  }
  return s.str();
}

using testing::ReadFile;

// Pre-rendered frames of every camera, the empty cell and the cell with its
// people, each a loop of sensor-noise variants, served by the fake cameras:
// more of them than the frames a repeat is looked for among
// (CameraHealthMonitor::kRecentFrames), so that no camera looks frozen.
class CellFrames {
 public:
  static constexpr int kVariants = capture::CameraHealthMonitor::kRecentFrames + 8;

  explicit CellFrames(const sim::Scene& scene) : frames_(scene.cameras.size()) {
    sim::Scene empty = scene;
    empty.people.clear();
    std::vector<sim::BodyState> people;
    for (const sim::Person& p : scene.people) people.push_back(sim::EvaluatePerson(p, 0.0));
    for (std::size_t c = 0; c < scene.cameras.size(); ++c) {
      const sim::ColourRenderer with_people(scene, static_cast<int>(c));
      const sim::ColourRenderer without(empty, static_cast<int>(c));
      for (int i = 0; i < kVariants; ++i) {
        const double t = i / kFrameRateHz;
        common::ImageRgb8 image;
        without.Render({}, t, static_cast<std::uint64_t>(i), &image);
        frames_[c].empty.push_back(image);
        with_people.Render(people, t, static_cast<std::uint64_t>(kVariants + i), &image);
        frames_[c].people.push_back(image);
      }
    }
  }

  /// From now on every camera shows the people.
  void ShowPeople() { people_.store(true); }

  /// The frame source of camera `c` for a FakeGigeCamera.
  testing::FakeGigeCamera::FrameFn Source(int c) {
    return [this, c](std::uint64_t index) -> const common::ImageRgb8& {
      const Loop& loop = frames_[c];
      return (people_.load() ? loop.people : loop.empty)[index % kVariants];
    };
  }

 private:
  struct Loop {
    std::vector<common::ImageRgb8> empty, people;
  };
  std::vector<Loop> frames_;
  std::atomic<bool> people_{false};
};

struct CameraSample {
  std::uint8_t state = 0;
  std::uint64_t frames = 0, completed = 0, failed = 0, underruns = 0, resends = 0;
};

struct StatusSample {
  std::uint64_t sequence = 0;
  Clock::time_point received;
  bool degraded = false;
  std::vector<CameraSample> cameras;

  [[nodiscard]] bool AllOk() const {
    return std::all_of(cameras.begin(), cameras.end(),
                       [](const CameraSample& c) { return c.state == 1; });
  }
};

struct OccupancySample {
  std::uint64_t sequence = 0;
  std::int64_t stamp_ns = 0;
  Eigen::Vector3d lo, hi;
  int depth = 0;
  std::vector<hullguard_GridRun> occupied, occluded;
};

/// A controller's view of both topics; every sample received is kept.
class Controller {
 public:
  Controller()
      : participant_(0),
        occupancy_topic_(participant_, &hullguard_Occupancy_desc,
                         publish::OccupancyTopicName("hullguard")),
        status_topic_(participant_, &hullguard_Status_desc, publish::StatusTopicName("hullguard")),
        occupancy_(participant_, occupancy_topic_, publish::OccupancyReaderQos(1s).get()),
        status_(participant_, status_topic_, publish::StatusReaderQos(1s).get()),
        waitset_(participant_) {
    for (const dds::Reader* r : {&occupancy_, &status_}) {
      dds::Check(dds_set_status_mask(r->handle(), DDS_DATA_AVAILABLE_STATUS), "status mask");
      waitset_.Attach(*r, 0);
    }
  }

  /// Takes samples as they arrive until `done` holds (true) or `limit` passes
  /// (false).
  bool Until(const std::function<bool()>& done, Clock::duration limit) {
    const Clock::time_point end = Clock::now() + limit;
    for (;;) {
      Take();
      if (done()) return true;
      if (Clock::now() >= end) return false;
      dds_attach_t tokens[2];
      waitset_.Wait(tokens, 2, 50ms);
    }
  }

  /// The first status sample received at or after `t`, or nullptr.
  const StatusSample* StatusAfter(Clock::time_point t) const {
    for (const StatusSample& s : status) {
      if (s.received >= t) return &s;
    }
    return nullptr;
  }
  /// The status sample of cycle `sequence`, or nullptr (not received).
  const StatusSample* StatusOf(std::uint64_t sequence) const {
    const auto it = status_by_sequence_.find(sequence);
    return it == status_by_sequence_.end() ? nullptr : &status[it->second];
  }
  /// Occupancy samples after cycle `after` whose status satisfies `keep`.
  std::vector<const OccupancySample*> OccupancyWhere(
      std::uint64_t after, const std::function<bool(const StatusSample&)>& keep) const {
    std::vector<const OccupancySample*> out;
    for (const OccupancySample& o : occupancy) {
      const StatusSample* st = StatusOf(o.sequence);
      if (o.sequence > after && st != nullptr && keep(*st)) out.push_back(&o);
    }
    return out;
  }

  std::vector<OccupancySample> occupancy;
  std::vector<StatusSample> status;

 private:
  void Take() {
    void* samples[8] = {};
    dds_sample_info_t infos[8];
    dds_return_t n = dds_take(occupancy_.handle(), samples, infos, 8, 8);
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto& s = *static_cast<const hullguard_Occupancy*>(samples[i]);
      OccupancySample o;
      o.sequence = s.sequence;
      o.stamp_ns = s.stamp_ns;
      o.lo = Eigen::Vector3d(s.bounds_min[0], s.bounds_min[1], s.bounds_min[2]);
      o.hi = Eigen::Vector3d(s.bounds_max[0], s.bounds_max[1], s.bounds_max[2]);
      o.depth = s.depth;
      o.occupied.assign(s.occupied._buffer, s.occupied._buffer + s.occupied._length);
      o.occluded.assign(s.occluded._buffer, s.occluded._buffer + s.occluded._length);
      occupancy.push_back(std::move(o));
    }
    if (n > 0) dds_return_loan(occupancy_.handle(), samples, n);
    n = dds_take(status_.handle(), samples, infos, 8, 8);
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto& s = *static_cast<const hullguard_Status*>(samples[i]);
      StatusSample st{s.sequence, Clock::now(), s.degraded, {}};
      for (std::uint32_t c = 0; c < s.cameras._length; ++c) {
        const hullguard_CameraStatus& cs = s.cameras._buffer[c];
        st.cameras.push_back(
            {cs.state, cs.frames, cs.completed, cs.failed, cs.underruns, cs.resends});
      }
      status_by_sequence_[st.sequence] = status.size();
      status.push_back(std::move(st));
    }
    if (n > 0) dds_return_loan(status_.handle(), samples, n);
  }

  dds::Participant participant_;
  dds::Topic occupancy_topic_, status_topic_;
  dds::Reader occupancy_, status_;
  dds::WaitSet waitset_;
  std::map<std::uint64_t, std::size_t> status_by_sequence_;
};

// Published cells of a sample that are not free (occupied or occluded), as a
// dense flag grid of 2^depth cells per axis.
std::vector<std::uint8_t> NotFree(const OccupancySample& s) {
  const std::size_t n = std::size_t{1} << s.depth;
  std::vector<std::uint8_t> cells(n * n * n, 0);
  for (const auto* runs : {&s.occupied, &s.occluded}) {
    for (const hullguard_GridRun& r : *runs) {
      for (int i = 0; i < r.length; ++i) cells[r.x + i + n * (r.y + n * r.z)] = 1;
    }
  }
  return cells;
}

// Whether flagged cell i of a dense grid of 2^depth cells per axis has a
// face neighbour inside the grid that is not flagged.
bool OnSurface(const std::vector<std::uint8_t>& flags, int depth, std::size_t i) {
  const auto n = static_cast<long>(std::size_t{1} << depth);
  const auto index = static_cast<long>(i);
  const long x = index % n, y = (index / n) % n, z = index / (n * n);
  const long step[3] = {1, n, n * n};
  const long at[3] = {x, y, z};
  for (int a = 0; a < 3; ++a) {
    if (at[a] > 0 && flags[index - step[a]] == 0) return true;
    if (at[a] + 1 < n && flags[index + step[a]] == 0) return true;
  }
  return false;
}

std::size_t Count(const std::vector<std::uint8_t>& cells) {
  return static_cast<std::size_t>(std::count(cells.begin(), cells.end(), 1));
}

// Ground-truth points of the people (standing still, so the same at every
// frame time) in cells the sample certifies free.
int PointsReportedFree(const sim::Scene& scene, const OccupancySample& s) {
  return testing::PointsInUnlistedCells(testing::PointsInPeople(scene, 0.0, 40, s.sequence), s.lo,
                                        s.hi, s.depth, {&s.occupied, &s.occluded});
}

class GigeE2E : public ::testing::Test {
 protected:
  void SetUp() override {
    for (const CameraSpec& c : kCameras) {
      std::string error;
      if (!testing::AddLoopbackAddress(c.address, &error)) GTEST_SKIP() << error;
    }
    dir_ = fs::temp_directory_path() /
           ("hg_gige_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override {
    if (!dir_.empty()) fs::remove_all(dir_);
  }
  fs::path dir_;
};

// The whole life of a camera behind the daemon: the background is learned
// from the empty cell, the people are covered, a killed camera turns the
// status degraded within its timeout while occupancy only grows, a restarted
// one is reconnected by the same daemon process, and a daemon whose camera
// just died still stops within systemd's stop timeout.
TEST_F(GigeE2E, CamerasServeTheDaemonThroughLossAndReconnection) {
  const sim::Scene scene = sim::ParseScene(SceneYaml(), "gige_cell.yaml", dir_.string());
  CellFrames frames(scene);
  std::vector<std::unique_ptr<testing::FakeGigeCamera>> cameras(kNumCameras);
  auto start_camera = [&](int c) {
    cameras[c] = std::make_unique<testing::FakeGigeCamera>(
        kCameras[c].address, std::string("HGE2E").append(std::to_string(c)), kWidth, kHeight,
        frames.Source(c));
    ASSERT_TRUE(cameras[c]->running()) << "cannot serve a camera on " << kCameras[c].address;
  };
  for (int c = 0; c < kNumCameras; ++c) start_camera(c);

  const std::string config = (dir_ / "gige.yaml").string();
  std::ofstream(config) << ConfigYaml();
  Controller controller;
  testing::HullguarddRun daemon(HG_HULLGUARDD, config, 240.0,
                                dir_);  // Bounded: no daemon left behind.
  const pid_t pid = daemon.pid();
  auto log = [&daemon] { return "daemon log:\n" + daemon.Log(); };

  // 1. The empty cell until every camera has delivered enough frames for the
  // background model (and the camera health reference) to be learned.
  ASSERT_TRUE(controller.Until(
      [&] {
        const StatusSample* s = controller.status.empty() ? nullptr : &controller.status.back();
        return s != nullptr && s->AllOk() &&
               std::all_of(s->cameras.begin(), s->cameras.end(), [](const CameraSample& c) {
                 return c.frames >= static_cast<std::uint64_t>(2 * kLearnFrames);
               });
      },
      60s))
      << log();
  frames.ShowPeople();
  const Clock::time_point people_shown = Clock::now();
  // Frames counted at the first cycle after the switch may still show the
  // empty cell (captured or in flight before it); three more each do not.
  ASSERT_TRUE(
      controller.Until([&] { return controller.StatusAfter(people_shown) != nullptr; }, 10s));
  const std::vector<CameraSample> at_switch = controller.StatusAfter(people_shown)->cameras;
  std::uint64_t people_from = 0;  // Cycles after this one see the people in every camera.
  ASSERT_TRUE(controller.Until(
      [&] {
        const StatusSample& s = controller.status.back();
        for (int c = 0; c < kNumCameras; ++c) {
          if (s.cameras[c].frames < at_switch[c].frames + 3) return false;
        }
        people_from = s.sequence;
        return true;
      },
      20s))
      << log();

  // 2. Healthy: every camera ok, the people inside not-free cells. Twice as
  // many cycles as the cameras' noise variants, so that what every variant
  // of each camera carves is in some healthy cycle (with 15, a degraded
  // cycle could meet a variant none of them had, and a cell only it carves).
  auto all_ok = [](const StatusSample& s) { return s.AllOk(); };
  const std::size_t healthy_cycles = 2 * static_cast<std::size_t>(CellFrames::kVariants);
  ASSERT_TRUE(controller.Until(
      [&] { return controller.OccupancyWhere(people_from, all_ok).size() >= healthy_cycles; }, 30s))
      << log();
  const std::vector<const OccupancySample*> healthy =
      controller.OccupancyWhere(people_from, all_ok);
  bool ok_seen = false;
  for (const StatusSample& s : controller.status) {
    ok_seen = ok_seen || (s.sequence > people_from && s.AllOk() && !s.degraded);
  }
  EXPECT_TRUE(ok_seen) << "no status with every camera ok and not degraded";
  // Cells no healthy cycle certified free: what the three cameras could not
  // carve away (the people, their shadows, what hides behind them).
  std::vector<std::uint8_t> reference = NotFree(*healthy.front());
  int free_points = 0;
  for (const OccupancySample* s : healthy) {
    free_points += PointsReportedFree(scene, *s);
    const std::vector<std::uint8_t> cells = NotFree(*s);
    for (std::size_t i = 0; i < cells.size(); ++i) reference[i] &= cells[i];
  }
  EXPECT_EQ(free_points, 0) << "healthy: people's points in free cells";
  const std::size_t reference_cells = Count(reference);
  EXPECT_GT(reference_cells, 0U);
  // GigE transport counters in the status: every camera streamed complete
  // frames, at least as many as the pipeline counted.
  const StatusSample before_kill = controller.status.back();
  for (int c = 0; c < kNumCameras; ++c) {
    const CameraSample& cs = before_kill.cameras[c];
    EXPECT_GT(cs.completed, 0U) << kCameras[c].name;
    EXPECT_GE(cs.completed, cs.frames) << kCameras[c].name;
  }

  // 3. cam2 dies. Within its timeout (and a margin for a loaded machine) the
  // status is degraded with cam2 stale or failed; the occupancy only grows.
  constexpr int kLost = 2;
  cameras[kLost].reset();
  const Clock::time_point killed = Clock::now();
  auto lost = [](const StatusSample& s) {
    return s.degraded && (s.cameras[kLost].state == 2 || s.cameras[kLost].state == 3) &&
           s.cameras[0].state == 1 && s.cameras[1].state == 1;
  };
  StatusSample noticed;  // A copy: the controller's vector grows.
  ASSERT_TRUE(controller.Until(
      [&] {
        for (const StatusSample& s : controller.status) {
          if (s.received >= killed && lost(s)) {
            noticed = s;
            return true;
          }
        }
        return false;
      },
      30s))
      << log();
  const auto latency = std::chrono::duration_cast<milliseconds>(noticed.received - killed);
  std::printf("camera loss noticed after %lld ms (timeout %d ms)\n",
              static_cast<long long>(latency.count()), kCameraTimeoutMs);
  EXPECT_LT(latency, milliseconds(kCameraTimeoutMs) + 2000ms) << log();
  const std::uint64_t lost_from = noticed.sequence - 1;
  ASSERT_TRUE(controller.Until(
      [&] { return controller.OccupancyWhere(lost_from, lost).size() >= 15; }, 30s))
      << log();
  const std::vector<const OccupancySample*> degraded = controller.OccupancyWhere(lost_from, lost);
  std::size_t min_degraded_cells = SIZE_MAX;
  free_points = 0;
  for (const OccupancySample* s : degraded) {
    free_points += PointsReportedFree(scene, *s);
    const std::vector<std::uint8_t> cells = NotFree(*s);
    // The fake cameras loop through sensor-noise variants, and the free-running
    // cameras' phases drift, so a degraded cycle can pair cam0's and cam1's
    // variants in a way no healthy cycle did: a noisy pixel at a silhouette's
    // edge may then carve a cell on the hull's surface that no healthy cycle
    // carved (seen: 2 such cells in 2 cycles 8 apart, the variants' period).
    // Such a cell borders space a healthy cycle certified free. A freed cell
    // inside the healthy not-free set would be cam2's loss freeing space.
    std::size_t freed_inside = 0, freed_surface = 0;
    for (std::size_t i = 0; i < cells.size(); ++i) {
      if (!reference[i] || cells[i]) continue;
      (OnSurface(reference, s->depth, i) ? freed_surface : freed_inside) += 1;
    }
    EXPECT_EQ(freed_inside, 0U) << "cycle " << s->sequence << ": cells inside what no healthy "
                                << "cycle certified free became free without cam2";
    EXPECT_LE(freed_surface * 1000, reference_cells)
        << "cycle " << s->sequence << ": " << freed_surface << " cells on the surface of what "
        << "no healthy cycle certified free became free without cam2";
    min_degraded_cells = std::min(min_degraded_cells, Count(cells));
  }
  EXPECT_EQ(free_points, 0) << "degraded: people's points in free cells";
  // What only cam2 carved is not free any more.
  EXPECT_GT(min_degraded_cells, reference_cells);

  // 4. cam2 comes back: the same daemon reconnects it; no restart.
  start_camera(kLost);
  const Clock::time_point restarted = Clock::now();
  StatusSample recovered;
  ASSERT_TRUE(controller.Until(
      [&] {
        for (const StatusSample& s : controller.status) {
          if (s.received >= restarted && s.AllOk() && !s.degraded) {
            recovered = s;
            return true;
          }
        }
        return false;
      },
      40s))
      << log();
  std::printf(
      "camera reconnected %lld ms after its restart\n",
      static_cast<long long>(
          std::chrono::duration_cast<milliseconds>(recovered.received - restarted).count()));
  EXPECT_TRUE(daemon.Running()) << log();
  EXPECT_EQ(daemon.pid(), pid);
  // Counters continue (the same source object, not a new daemon).
  EXPECT_GT(recovered.cameras[kLost].completed, before_kill.cameras[kLost].completed);
  EXPECT_GT(recovered.cameras[kLost].frames, before_kill.cameras[kLost].frames);
  EXPECT_NE(daemon.Log().find(std::string("aravis[") + kCameras[kLost].address + "]: reconnected"),
            std::string::npos)
      << log();
  const std::uint64_t back_from = recovered.sequence;
  ASSERT_TRUE(controller.Until(
      [&] { return controller.OccupancyWhere(back_from, all_ok).size() >= 5; }, 30s))
      << log();
  free_points = 0;
  std::size_t max_recovered_cells = 0;
  for (const OccupancySample* s : controller.OccupancyWhere(back_from, all_ok)) {
    free_points += PointsReportedFree(scene, *s);
    max_recovered_cells = std::max(max_recovered_cells, Count(NotFree(*s)));
  }
  EXPECT_EQ(free_points, 0) << "recovered: people's points in free cells";
  std::printf(
      "not-free cells: %zu in every one of %zu healthy cycles, >= %zu in %zu degraded, <= %zu "
      "after reconnection\n",
      reference_cells, healthy.size(), min_degraded_cells, degraded.size(), max_recovered_cells);
  // The reconnected camera carves again.
  EXPECT_LT(max_recovered_cells, min_degraded_cells);
  // One daemon's stream throughout: sequence numbers only increase.
  for (std::size_t i = 1; i < controller.status.size(); ++i) {
    ASSERT_GT(controller.status[i].sequence, controller.status[i - 1].sequence);
  }
  for (std::size_t i = 1; i < controller.occupancy.size(); ++i) {
    ASSERT_GT(controller.occupancy[i].sequence, controller.occupancy[i - 1].sequence);
  }

  // 5. A camera dies and the daemon is stopped at once, before it has even
  // noticed: it still exits cleanly within systemd's stop timeout (releasing
  // a dead camera takes Aravis about 12 s).
  cameras[1].reset();
  Clock::duration took{};
  const int code = daemon.Terminate(3 * kSystemdStopTimeout, &took);
  const auto took_ms = std::chrono::duration_cast<milliseconds>(took);
  std::printf("daemon stopped %lld ms after SIGTERM with a dead camera\n",
              static_cast<long long>(took_ms.count()));
  EXPECT_EQ(code, 0) << log();
  EXPECT_LT(took, kSystemdStopTimeout) << log();
}

// The source alone: destroying an AravisSource whose camera died returns
// within its release grace, whether the loss was noticed or not, and so does
// one whose camera never answered.
TEST_F(GigeE2E, SourceWithADeadCameraIsDestroyedQuickly) {
  common::ImageRgb8 grey(64, 48);
  std::fill(grey.pixels.begin(), grey.pixels.end(), 128);
  const testing::FakeGigeCamera::FrameFn same = [&grey](std::uint64_t) -> const common::ImageRgb8& {
    return grey;
  };
  capture::AravisOptions options;
  options.device = kCameras[0].address;
  options.pixel_format = capture::AravisOptions::Pixel::kMono8;
  options.frame_rate_hz = 20.0;
  options.width = 64;
  options.height = 48;
  options.frame_timeout = 500ms;
  // Release grace after Stop(), plus a margin for a loaded machine; releasing
  // a dead camera in Aravis takes about 12 s.
  const auto limit = capture::AravisSource::kReleaseGrace + 1500ms;
  auto first_frame = [](capture::AravisSource* source) {
    capture::Frame frame;
    const Clock::time_point end = Clock::now() + 20s;
    while (Clock::now() < end) {
      if (source->Next(&frame, 50ms)) return true;
    }
    return false;
  };
  for (const bool noticed : {false, true}) {
    SCOPED_TRACE(noticed ? "loss noticed" : "loss not noticed yet");
    auto camera =
        std::make_unique<testing::FakeGigeCamera>(kCameras[0].address, "HGQUIT", 64, 48, same);
    ASSERT_TRUE(camera->running());
    auto source = std::make_unique<capture::AravisSource>(options);
    ASSERT_TRUE(first_frame(source.get()));
    camera.reset();
    if (noticed) {
      // The watchdog hands the dead connection to the release thread, which
      // is then busy with Aravis' command timeouts.
      capture::Frame frame;
      const Clock::time_point end = Clock::now() + 10s;
      while (source->stats().connected && Clock::now() < end) source->Next(&frame, 50ms);
      ASSERT_FALSE(source->stats().connected);
    }
    const Clock::time_point before = Clock::now();
    source.reset();
    const auto took = std::chrono::duration_cast<milliseconds>(Clock::now() - before);
    std::printf("source destroyed in %lld ms (%s)\n", static_cast<long long>(took.count()),
                noticed ? "loss noticed" : "loss not noticed");
    EXPECT_LT(took, limit);
  }
  {
    SCOPED_TRACE("no camera at the address");
    auto source = std::make_unique<capture::AravisSource>(options);
    capture::Frame frame;
    EXPECT_FALSE(source->Next(&frame, 300ms));
    const Clock::time_point before = Clock::now();
    source.reset();
    const auto took = std::chrono::duration_cast<milliseconds>(Clock::now() - before);
    std::printf("source destroyed in %lld ms (no camera)\n", static_cast<long long>(took.count()));
    EXPECT_LT(took, limit);
  }
}

}  // namespace
}  // namespace hg
