// The tracks topic end to end: DdsPublisher::PublishTracks to a reader, and
// hullguardd tracking a simulated walking person, checked against the scene's
// ground truth by a DDS reader as a controller would. Run inside a private
// network namespace holding only loopback (tests/publish/in_netns.sh).
//   tracks_e2e_test HULLGUARDD SOURCE_DIR HULLGUARD
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "hullguard.h"
#include "publish/dds.h"
#include "publish/dds_publisher.h"
#include "publish/hullguardd_run.h"
#include "sim/body.h"
#include "sim/scene.h"
#include "support/run_tool.h"

namespace hg {
namespace {

// Samples are written only while fresh (PublisherConfig::max_age): stamps of now.
std::int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

namespace fs = std::filesystem;
namespace dds = publish::dds;
using Clock = std::chrono::steady_clock;
using Eigen::Vector3d;
using namespace std::chrono_literals;

std::string g_daemon;
std::string g_source_dir;
std::string g_hullguard;

using testing::ReadFile;

struct ReceivedTracks {
  std::uint64_t sequence = 0;
  std::int64_t stamp_ns = 0;
  bool degraded = false;
  std::vector<hullguard_Track> tracks;
};

/// A reader of the tracks topic and, for the sequence numbers, of occupancy.
class Listener {
 public:
  explicit Listener(int domain, const std::string& prefix = "hullguard")
      : participant_(static_cast<dds_domainid_t>(domain)),
        tracks_topic_(participant_, &hullguard_Tracks_desc, publish::TracksTopicName(prefix)),
        occupancy_topic_(participant_, &hullguard_Occupancy_desc,
                         publish::OccupancyTopicName(prefix)),
        tracks_(participant_, tracks_topic_,
                testing::KeepingLast(publish::TracksReaderQos(1s)).get()),
        occupancy_(participant_, occupancy_topic_,
                   testing::KeepingLast(publish::OccupancyReaderQos(1s)).get()) {}

  /// Polls both readers for `duration` or until `enough` tracks samples.
  void Collect(std::chrono::milliseconds duration, std::size_t enough = SIZE_MAX) {
    for (const auto end = Clock::now() + duration;
         Clock::now() < end && tracks_samples.size() < enough;) {
      TakeTracks();
      TakeOccupancy();
      std::this_thread::sleep_for(5ms);
    }
  }

  std::vector<ReceivedTracks> tracks_samples;
  std::map<std::uint64_t, std::int64_t> occupancy_stamps;  // Sequence -> stamp_ns.

 private:
  void TakeTracks() {
    void* samples[8] = {};
    dds_sample_info_t infos[8];
    const dds_return_t n = dds_take(tracks_.handle(), samples, infos, 8, 8);
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto& s = *static_cast<const hullguard_Tracks*>(samples[i]);
      tracks_samples.push_back({s.sequence,
                                s.stamp_ns,
                                s.degraded,
                                {s.tracked._buffer, s.tracked._buffer + s.tracked._length}});
    }
    if (n > 0) dds_return_loan(tracks_.handle(), samples, n);
  }
  void TakeOccupancy() {
    void* samples[8] = {};
    dds_sample_info_t infos[8];
    const dds_return_t n = dds_take(occupancy_.handle(), samples, infos, 8, 8);
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto& s = *static_cast<const hullguard_Occupancy*>(samples[i]);
      occupancy_stamps[s.sequence] = s.stamp_ns;
    }
    if (n > 0) dds_return_loan(occupancy_.handle(), samples, n);
  }

  dds::Participant participant_;
  dds::Topic tracks_topic_, occupancy_topic_;
  dds::Reader tracks_, occupancy_;
};

Vector3d Vec(const float (&v)[3]) { return {v[0], v[1], v[2]}; }

// What PublishTracks writes is what a reader gets: every field, the spread
// as the square root of the covariance diagonal, tracks in the given order.
TEST(TracksPublisherTest, PublishedTracksArriveUnchanged) {
  publish::PublisherConfig config;
  config.domain_id = static_cast<int>(getpid() % 200) + 1;
  config.topic_prefix = "tracks_unit";
  // One stamp is republished until discovery is done: no age limit.
  config.max_age = std::chrono::nanoseconds(0);
  publish::DdsPublisher publisher(config, 30.0);
  EXPECT_EQ(publisher.tracks_topic(), "tracks_unit/tracks");
  Listener listener(config.domain_id, config.topic_prefix);

  std::vector<tracking::Track> tracks(2);
  tracks[0].id = 3;
  tracks[0].centre_W = {1.25, 2.5, 0.875};
  tracks[0].half_axes_m = {0.3, 0.25, 0.85};
  tracks[0].velocity_W_mps = {1.0, -0.5, 0.0};
  tracks[0].centre_covariance_m2 = Eigen::Vector3d(0.0004, 0.0009, 0.0001).asDiagonal();
  tracks[0].centre_covariance_m2(0, 1) = 0.0002;
  tracks[0].age_s = 4.5;
  tracks[1].id = 7;
  tracks[1].centre_W = {3.0, 0.75, 0.4};
  tracks[1].half_axes_m = {0.5, 0.5, 0.4};
  tracks[1].occluded = true;
  tracks[1].occluded_fraction = 0.75;
  tracks[1].time_since_support_s = 2.25;

  // Discovery takes a moment: publish until a sample arrives.
  const std::int64_t stamp_ns = NowNs();
  for (int i = 0; i < 200 && listener.tracks_samples.empty(); ++i) {
    publisher.PublishTracks(41, stamp_ns, true, tracks);
    listener.Collect(25ms, 1);
  }
  ASSERT_FALSE(listener.tracks_samples.empty());
  EXPECT_EQ(publisher.tracks_write_failures(), 0u);
  const ReceivedTracks& r = listener.tracks_samples.front();
  EXPECT_EQ(r.sequence, 41u);
  EXPECT_EQ(r.stamp_ns, stamp_ns);
  EXPECT_TRUE(r.degraded);
  ASSERT_EQ(r.tracks.size(), 2u);
  const hullguard_Track& a = r.tracks[0];
  EXPECT_EQ(a.id, 3u);
  EXPECT_EQ(Vec(a.centre), Vector3d(1.25, 2.5, 0.875));
  EXPECT_EQ(Vec(a.half_axes), Vector3d(0.3, 0.25, 0.85).cast<float>().cast<double>());
  EXPECT_EQ(Vec(a.velocity), Vector3d(1.0, -0.5, 0.0));
  EXPECT_NEAR(a.spread[0], 0.02, 1e-6);
  EXPECT_NEAR(a.spread[1], 0.03, 1e-6);
  EXPECT_NEAR(a.spread[2], 0.01, 1e-6);
  EXPECT_FALSE(a.occluded);
  EXPECT_FLOAT_EQ(a.age_s, 4.5F);
  EXPECT_EQ(a.time_since_support_s, 0.0F);
  const hullguard_Track& b = r.tracks[1];
  EXPECT_EQ(b.id, 7u);
  EXPECT_TRUE(b.occluded);
  EXPECT_FLOAT_EQ(b.occluded_fraction, 0.75F);
  EXPECT_FLOAT_EQ(b.time_since_support_s, 2.25F);
  EXPECT_EQ(Vec(b.spread), Vector3d::Zero());

  // An empty cycle is a sample too (nobody tracked is news).
  const std::size_t before = listener.tracks_samples.size();
  for (int i = 0; i < 100 && listener.tracks_samples.size() == before; ++i) {
    publisher.PublishTracks(42, NowNs(), false, {});
    listener.Collect(25ms, before + 1);
  }
  ASSERT_GT(listener.tracks_samples.size(), before);
  EXPECT_EQ(listener.tracks_samples.back().sequence, 42u);
  EXPECT_TRUE(listener.tracks_samples.back().tracks.empty());

  // While another publisher writes the same topics (a second daemon with a
  // copied config), every tracks sample says degraded, as the status does.
  publish::DdsPublisher other(config, 30.0);
  int others = 0;
  for (int i = 0; i < 200 && others == 0; ++i) {
    std::this_thread::sleep_for(25ms);
    others = publisher.CheckOtherPublishers();
  }
  ASSERT_EQ(others, 1);
  const std::size_t with_other = listener.tracks_samples.size();
  for (int i = 0; i < 100 && listener.tracks_samples.size() == with_other; ++i) {
    publisher.PublishTracks(43, NowNs(), false, {});
    listener.Collect(25ms, with_other + 1);
  }
  ASSERT_GT(listener.tracks_samples.size(), with_other);
  EXPECT_EQ(listener.tracks_samples.back().sequence, 43u);
  EXPECT_TRUE(listener.tracks_samples.back().degraded);
}

// `hullguard echo --topic tracks` prints the tracks, and its --snapshot
// picture draws them (magenta outlines) over the occupancy they came from.
TEST(TracksEchoTest, PrintsAndDrawsTracks) {
  publish::PublisherConfig config;
  config.domain_id = static_cast<int>(getpid() % 200) + 11;
  config.topic_prefix = "tracks_echo";
  publish::DdsPublisher publisher(config, 20.0);
  const fs::path picture =
      fs::temp_directory_path() / ("hg_tracks_echo_" + std::to_string(getpid()) + ".png");
  std::atomic<bool> done{false};
  testing::ProcessResult echo;
  std::thread listener([&] {
    echo = testing::RunTool(g_hullguard, "echo --domain " + std::to_string(config.domain_id) +
                                             " --prefix tracks_echo --topic tracks --count 5 "
                                             "--timeout 30 --snapshot " +
                                             picture.string());
    done = true;
  });
  pipeline::OccupancySnapshot snap;
  snap.bounds = {Vector3d::Zero(), Vector3d(4, 4, 4)};
  snap.depth = 5;
  snap.occupied = {{10, 10, 0, 3}, {10, 11, 0, 3}, {10, 10, 1, 3}};
  std::vector<tracking::Track> tracks(1);
  tracks[0].id = 9;
  tracks[0].centre_W = {1.5, 1.35, 0.9};
  tracks[0].half_axes_m = {0.3, 0.25, 0.85};
  tracks[0].velocity_W_mps = {1.0, 0.0, 0.0};
  for (std::uint64_t seq = 1; !done && seq < 2000; ++seq) {
    snap.sequence = seq;
    snap.stamp_ns = NowNs();
    publisher.Publish(snap);
    publisher.PublishTracks(seq, snap.stamp_ns, false, tracks);
    std::this_thread::sleep_for(50ms);
  }
  listener.join();
  EXPECT_EQ(echo.code, 0) << echo.err;
  EXPECT_EQ(echo.out.find("occupancy seq="), std::string::npos) << echo.out;
  EXPECT_NE(echo.out.find("tracks seq="), std::string::npos) << echo.out;
  EXPECT_NE(echo.out.find(" count=1 [#9 c=(1.50 1.35 0.90) r=(0.30 0.25 0.85) v=(1.00 0.00 0.00)"),
            std::string::npos)
      << echo.out;
  const cv::Mat image = cv::imread(picture.string());
  fs::remove(picture);
  ASSERT_FALSE(image.empty()) << echo.err;
  int magenta = 0;
  for (int y = 0; y < image.rows; ++y) {
    for (int x = 0; x < image.cols; ++x) {
      const cv::Vec3b& p = image.at<cv::Vec3b>(y, x);
      magenta += p[0] == 200 && p[1] == 0 && p[2] == 200;
    }
  }
  EXPECT_GT(magenta, 200);  // Three outlines and labels.
}

// The demo cell at a third of Full HD (so that rendering four cameras stays
// cheap on a loaded machine), its table and rack, one person walking a loop
// clear of both (0.9 m from the rack, whose shadows can start extra tracks),
// then standing.
const char* const kScene = R"(scene:
  name: tracks_e2e
  bounds: {min: [0, 0, 0], max: [4, 4, 4]}
  rate_hz: 30
cameras:
  - {name: cam0, width: 640, height: 360, position: [-0.3, -0.3, 3.6], look_at: [2, 2, 1], K: &k [361.1929021124099, 0, 319.5, 0, 361.1929021124099, 179.5, 0, 0, 1]}
  - {name: cam1, width: 640, height: 360, position: [4.3, 4.3, 3.6], look_at: [2, 2, 1], K: *k}
  - {name: cam2, width: 640, height: 360, position: [4.3, -0.3, 3.6], look_at: [2, 2, 1], K: *k}
  - {name: cam3, width: 640, height: 360, position: [-0.3, 4.3, 3.6], look_at: [2, 2, 1], K: *k}
obstacles:
  - {name: table_top, box: {min: [2.6, 0.6, 0.72], max: [3.6, 1.4, 0.78]}}
  - {name: table_leg_0, box: {min: [2.65, 0.65, 0], max: [2.7, 0.7, 0.72]}}
  - {name: table_leg_1, box: {min: [3.5, 0.65, 0], max: [3.55, 0.7, 0.72]}}
  - {name: table_leg_2, box: {min: [2.65, 1.3, 0], max: [2.7, 1.35, 0.72]}}
  - {name: table_leg_3, box: {min: [3.5, 1.3, 0], max: [3.55, 1.35, 0.72]}}
  - {name: rack, box: {min: [0.2, 3.3, 0], max: [1.4, 3.8, 1.9]}}
people:
  - name: walker
    height: 1.75
    start: [1.0, 1.0]
    script:
      - walk: {speed: 1.0, path: [[2.1, 1.0], [2.1, 2.4], [1.0, 2.4], [1.0, 1.0]]}
      - stand: {duration: 60}
)";

std::string Camera(int i) {
  static const char* const kPositions[] = {"[-0.3, -0.3, 3.6]", "[4.3, 4.3, 3.6]",
                                           "[4.3, -0.3, 3.6]", "[-0.3, 4.3, 3.6]"};
  return "  - {name: cam" + std::to_string(i) +
         ", width: 640, height: 360, position: " + kPositions[i] +
         ", look_at: [2, 2, 1], K: [361.1929021124099, 0, 319.5, 0, 361.1929021124099, 179.5, "
         "0, 0, 1], source: {type: sim, scene: scene.yaml}}\n";
}

class TracksE2E : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("hg_tracks_e2e_" + std::to_string(getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

// hullguardd tracks the walking person: one track, whose id stays the same,
// follows the ground truth within 0.3 m (horizontally) in most cycles; every
// Tracks sample carries the sequence number and stamp of an Occupancy sample.
TEST_F(TracksE2E, ATrackWithAStableIdFollowsTheWalkingPerson) {
  std::ofstream(dir_ / "scene.yaml") << kScene;
  std::string config =
      "cell:\n  bounds: {min: [0, 0, 0], max: [4, 4, 4]}\n"
      "octree: {depth: 7, publish_depth: 7}\n"
      "timing: {rate_hz: 30, deadline_ms: 25}\n"
      "cameras:\n";
  for (int i = 0; i < 4; ++i) config += Camera(i);
  config += "obstacles:\n  - file: " + g_source_dir + "/config/demo_cell/obstacles.obj\n";
  config += "tracking: {enabled: true}\n";
  const std::string config_path = (dir_ / "tracks.yaml").string();
  std::ofstream(config_path) << config;
  const sim::Scene scene = sim::LoadScene((dir_ / "scene.yaml").string());
  ASSERT_EQ(scene.people.size(), 1u);

  Listener listener(0);
  testing::HullguarddRun daemon(g_daemon, config_path, 10.0, dir_);
  const std::int64_t epoch = daemon.SceneEpoch();
  listener.Collect(9000ms);
  EXPECT_EQ(daemon.Wait(), 0) << daemon.Log();
  const std::string log = daemon.Log();
  ASSERT_GE(listener.tracks_samples.size(), 60u) << log;

  // Sequence numbers: rising, and those of occupancy samples with the same stamp.
  std::size_t matched = 0;
  for (std::size_t i = 0; i < listener.tracks_samples.size(); ++i) {
    const ReceivedTracks& s = listener.tracks_samples[i];
    if (i > 0) {
      EXPECT_GT(s.sequence, listener.tracks_samples[i - 1].sequence);
    }
    const auto occupancy = listener.occupancy_stamps.find(s.sequence);
    if (occupancy == listener.occupancy_stamps.end()) continue;  // Best effort: may be lost.
    ++matched;
    EXPECT_EQ(occupancy->second, s.stamp_ns) << "sequence " << s.sequence;
  }
  EXPECT_GE(matched, listener.tracks_samples.size() * 9 / 10);

  // Per id, the cycles in which that track is within 0.3 m (horizontally) of
  // the person: one id must follow the person through most of the run.
  std::map<std::uint32_t, int> near_by_id;
  int cycles = 0, one_track = 0, at_most_two = 0;
  double worst_m = 0.0;  // Of the nearest track.
  for (const ReceivedTracks& s : listener.tracks_samples) {
    const double t_s = static_cast<double>(s.stamp_ns - epoch) * 1e-9;
    if (t_s < 1.0) continue;  // Birth and the filter settling.
    ++cycles;
    one_track += s.tracks.size() == 1;
    at_most_two += s.tracks.size() <= 2;
    const sim::BodyState body = sim::EvaluatePerson(scene.people[0], t_s);
    double best = INFINITY;
    for (const hullguard_Track& t : s.tracks) {
      const double d = (Vec(t.centre) - body.centre_W).head<2>().norm();
      best = std::min(best, d);
      if (d <= 0.3) ++near_by_id[t.id];
    }
    if (std::isfinite(best)) worst_m = std::max(worst_m, best);
  }
  ASSERT_GE(cycles, 40) << log;
  std::uint32_t follower = 0;
  int followed = 0;
  for (const auto& [id, n] : near_by_id) {
    if (n > followed) {
      follower = id;
      followed = n;
    }
  }
  std::printf(
      "%d cycles: track #%u within 0.3 m in %d, one track in %d, at most two in %d; nearest "
      "track at most %.2f m away\n",
      cycles, follower, followed, one_track, at_most_two, worst_m);
  EXPECT_GE(followed, cycles * 8 / 10) << "no track follows the person with one id\n" << log;
  // Extra tracks (visual-hull ghosts, the hull's tips and shadows near
  // obstacles, part of the person) are counted above but not asserted: how
  // many come depends on the tracker's birth rules and on timing (the cameras'
  // capture skew at start-up), not on the daemon's wiring tested here.

  // The health line reports tracking.
  EXPECT_TRUE(std::regex_search(log, std::regex(" tracks [0-9]+ tracking [0-9.]+ ms"))) << log;
  EXPECT_NE(log.find("hullguardd: tracking on "), std::string::npos) << log;
}

}  // namespace
}  // namespace hg

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  if (argc != 4) {
    std::fprintf(stderr, "usage: tracks_e2e_test HULLGUARDD SOURCE_DIR HULLGUARD\n");
    return 2;
  }
  hg::g_daemon = argv[1];
  hg::g_source_dir = argv[2];
  hg::g_hullguard = argv[3];
  return RUN_ALL_TESTS();
}
