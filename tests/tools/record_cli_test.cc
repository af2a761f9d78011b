// End-to-end tests of recording: `hullguard record` on simulated cameras, the
// recording replayed by `hullguard replay` (the same digest twice), a frame
// that cannot be written reported in the summary and the exit code, the
// daemon's black box dumping on SIGUSR1 and when the status turns degraded,
// and `hullguard replay` checking synth recordings against their ground truth.
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "capture/recording.h"
#include "geometry/camera_yaml.h"
#include "silhouette/mask_io.h"
#include "sim/ground_truth.h"
#include "support/run_tool.h"
#include "support/small_cell_config.h"

extern char** environ;

namespace hg {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

const std::string kScene = std::string(HG_SOURCE_DIR) + "/tests/data/small_cell.yaml";

std::string Config(const std::string& source, const std::string& extra = "") {
  return testing::SmallCellConfig(source, extra);
}

std::string ReadFile(const fs::path& path) {
  std::stringstream text;
  text << std::ifstream(path).rdbuf();
  return text.str();
}

class RecordCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           std::string("hg_record_")
               .append(std::to_string(::getpid()))
               .append("_")
               .append(::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    std::ofstream(Path("sim.yaml")) << Config("{type: sim, scene: " + kScene + "}");
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  static testing::ProcessResult Hullguard(const std::string& args) {
    return testing::RunTool(HG_HULLGUARD_BIN, args);
  }
  // `hullguard replay --digest` of a recording; the digest, empty on failure.
  std::string ReplayDigest(const std::string& recording) {
    const std::string config = Path("replay_" + fs::path(recording).filename().string() + ".yaml");
    std::ofstream(config) << Config("{type: replay, directory: " + recording + "}");
    const auto r =
        Hullguard("replay --config " + config + " --recording " + recording + " --digest");
    EXPECT_EQ(r.code, 0) << r.out << r.err;
    EXPECT_NE(r.out.find(" cycles at 30 Hz over "), std::string::npos) << r.out;
    // Recorded cameras have no ground truth.
    EXPECT_EQ(r.out.find("ground truth"), std::string::npos) << r.out;
    std::smatch m;
    const std::regex digest("digest ([0-9a-f]{16})");
    return std::regex_search(r.out, m, digest) ? std::string(m[1]) : std::string();
  }
  fs::path dir_;
};

// Checks a recording of the three cameras: every frame's stamp after the
// previous one, frame numbers rising, the calibration next to it; the
// cameras' capture offsets (0, 6 and 12 ms in the scene) show in the stamps.
void CheckRecording(const std::string& dir, std::size_t min_frames) {
  std::vector<capture::RecordingCamera> cams;
  for (const char* name : {"cam0", "cam1", "cam2"}) {
    cams.push_back(capture::ReadRecordingCamera(dir, name));
    const capture::RecordingCamera& rec = cams.back();
    EXPECT_EQ(rec.kind, capture::FrameKind::kMask);
    EXPECT_EQ(rec.width, 320);
    EXPECT_GE(rec.frames.size(), min_frames) << name;
    for (std::size_t i = 1; i < rec.frames.size(); ++i) {
      EXPECT_GT(rec.frames[i].stamp_ns, rec.frames[i - 1].stamp_ns) << name << " frame " << i;
      EXPECT_GT(rec.frames[i].file, rec.frames[i - 1].file);
    }
  }
  // The sim source captures at epoch + offset + k * 33333333 ns.
  constexpr std::int64_t kPeriod = 33'333'333;
  for (int c = 1; c < 3; ++c) {
    if (cams[c].frames.empty() || cams[0].frames.empty()) continue;
    const std::int64_t d = cams[c].frames[0].stamp_ns - cams[0].frames[0].stamp_ns;
    EXPECT_EQ(((d % kPeriod) + kPeriod) % kPeriod, 6'000'000 * c) << "cam" << c;
  }
  const auto models = geometry::LoadCamerasFile((fs::path(dir) / "cameras.yaml").string());
  ASSERT_EQ(models.size(), 3U);
  EXPECT_EQ(models[2].name, "cam2");
  EXPECT_NEAR(models[2].K(0, 0), 180.59645105620495, 1e-12);
}

TEST_F(RecordCliTest, RecordsSimCamerasAndReplaysDeterministically) {
  const auto r =
      Hullguard("record --config " + Path("sim.yaml") + " --out " + Path("rec") + " --seconds 2");
  ASSERT_EQ(r.code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("cam2: "), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("last write error"), std::string::npos) << r.out;
  EXPECT_TRUE(fs::exists(dir_ / "rec" / "config.yaml"));
  CheckRecording(Path("rec"), 3);
  const std::string first = ReplayDigest(Path("rec"));
  EXPECT_FALSE(first.empty());
  EXPECT_EQ(ReplayDigest(Path("rec")), first);
  // Its cycles do not match frames of a ground truth.
  const auto truth = Hullguard("replay --config " + Path("replay_rec.yaml") + " --recording " +
                               Path("rec") + " --truth " + Path("sim.yaml"));
  EXPECT_EQ(truth.code, 2) << truth.out << truth.err;
  EXPECT_NE(truth.err.find("is not a synth recording"), std::string::npos) << truth.err;

  // The daemon plays it in real time (`source: replay`, looped so that it
  // lasts): every camera is live at a health report (one a second; a loaded
  // machine may make any single one of them miss a deadline).
  std::ofstream(Path("daemon.yaml"))
      << Config("{type: replay, directory: " + Path("rec") + ", loop: true}");
  const auto daemon = testing::RunToolInNetns(
      HG_HULLGUARDD_BIN, "--config " + Path("daemon.yaml") + " --duration 4.5");
  if (daemon.code == testing::kNoNetns) GTEST_SKIP() << "no network namespace: " << daemon.err;
  EXPECT_EQ(daemon.code, 0) << daemon.err;
  EXPECT_TRUE(std::regex_search(
      daemon.err, std::regex("cycle [0-9]+ ok .* cam0 ok [0-9]+ fps( margin [0-9.]+ cm)? cam1 ok "
                             "[0-9]+ fps( margin [0-9.]+ cm)? cam2 ok")))
      << daemon.err;

  // A folder that holds a recording is not overwritten.
  const auto again =
      Hullguard("record --config " + Path("sim.yaml") + " --out " + Path("rec") + " --seconds 0.2");
  EXPECT_EQ(again.code, 2);
  EXPECT_NE(again.err.find("already holds a recording"), std::string::npos) << again.err;
}

// A camera that delivered nothing while it was recorded (lost before the
// recording, or the black box's dump, began) is in the recording without
// frames: the recording still replays, lock-step and in the daemon, with that
// camera seeing nothing (`failed`, every cycle degraded). Looping it is refused.
TEST_F(RecordCliTest, CameraWithoutFramesReplaysAsOneThatNeverDelivers) {
  std::string text = Config("{type: sim, scene: " + kScene + "}");
  const std::string cam2 = "source: {type: sim, scene: " + kScene + "}}\n";
  const std::size_t at = text.rfind(cam2);
  ASSERT_NE(at, std::string::npos);
  text.replace(at, cam2.size(), "source: {type: sim, scene: " + kScene + ", stop_after_s: 0}}\n");
  std::ofstream(Path("dead_cam2.yaml")) << text;
  // 3 s: the daemon's first health line, a second after its start, must
  // come while the recording still plays, on a loaded machine too.
  const auto rec = Hullguard("record --config " + Path("dead_cam2.yaml") + " --out " + Path("rec") +
                             " --seconds 3");
  // `record` says so (exit 1), and keeps what the others delivered.
  EXPECT_EQ(rec.code, 1) << rec.out << rec.err;
  EXPECT_NE(rec.err.find("a camera delivered no frame"), std::string::npos) << rec.err;
  ASSERT_TRUE(capture::ReadRecordingCamera(Path("rec"), "cam2").frames.empty());
  ASSERT_FALSE(capture::ReadRecordingCamera(Path("rec"), "cam0").frames.empty());

  std::ofstream(Path("replay.yaml")) << Config("{type: replay, directory: " + Path("rec") + "}");
  const auto replay =
      Hullguard("replay --config " + Path("replay.yaml") + " --recording " + Path("rec"));
  ASSERT_EQ(replay.code, 0) << replay.out << replay.err;
  EXPECT_NE(replay.out.find("camera 'cam2' has no frames in the recording"), std::string::npos)
      << replay.out;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(replay.out, m,
                                std::regex("replay: ([0-9]+) cycles .* ([0-9]+) cycles degraded")))
      << replay.out;
  EXPECT_GE(std::stoi(m[1]), 80) << replay.out;
  EXPECT_EQ(m[1], m[2]) << replay.out;
  const std::string cycles = m[1];
  // The camera's own line says what it was: without a frame in every cycle.
  ASSERT_TRUE(std::regex_search(replay.out, m, std::regex("\n  cam2: starting ([0-9]+) cycles\n")))
      << replay.out;
  EXPECT_EQ(m[1], cycles) << replay.out;

  const auto daemon = testing::RunToolInNetns(
      HG_HULLGUARDD_BIN, "--config " + Path("replay.yaml") + " --duration 2.5");
  if (daemon.code == testing::kNoNetns) GTEST_SKIP() << "no network namespace: " << daemon.err;
  EXPECT_EQ(daemon.code, 0) << daemon.err;
  EXPECT_TRUE(std::regex_search(
      daemon.err, std::regex("cycle [0-9]+ DEGRADED .* cam0 ok .* cam2 failed 0 fps")))
      << daemon.err;

  std::ofstream(Path("loop.yaml"))
      << Config("{type: replay, directory: " + Path("rec") + ", loop: true}");
  const auto loop = testing::RunTool(HG_HULLGUARDD_BIN, "--check-config " + Path("loop.yaml"));
  EXPECT_EQ(loop.code, 2) << loop.out << loop.err;
  EXPECT_NE(loop.err.find("has no frames of camera 'cam2' to loop"), std::string::npos) << loop.err;
}

// A recording with a silence of days in it (every camera's next frame two
// days on) replays at once: the cycles of the silence, every camera stale,
// are counted (as degraded), not run one by one for hours.
TEST_F(RecordCliTest, ReplayCountsASilenceOfDaysWithoutRunningIt) {
  const auto r =
      Hullguard("record --config " + Path("sim.yaml") + " --out " + Path("rec") + " --seconds 0.5");
  ASSERT_EQ(r.code, 0) << r.out << r.err;
  constexpr std::int64_t kTwoDaysNs = std::int64_t{2} * 24 * 3600 * 1'000'000'000;
  for (const char* camera : {"cam0", "cam1", "cam2"}) {
    const fs::path index = dir_ / "rec" / "frames" / camera / "index.csv";
    std::string text = ReadFile(index.string());
    ASSERT_FALSE(text.empty());
    const std::size_t line = text.rfind('\n', text.size() - 2) + 1;
    std::vector<std::string> field;
    std::stringstream row(text.substr(line, text.size() - line - 1));
    for (std::string cell; std::getline(row, cell, ',');) field.push_back(cell);
    ASSERT_EQ(field.size(), 5U) << text.substr(line);
    std::ofstream(index, std::ios::app)
        << std::stoll(field[0]) + 1 << ',' << std::stoll(field[1]) + kTwoDaysNs << ",,"
        << std::stoll(field[3]) + 1 << ',' << field[4] << '\n';
  }
  std::ofstream(Path("replay_rec.yaml"))
      << Config("{type: replay, directory: " + Path("rec") + "}");
  const auto start = std::chrono::steady_clock::now();
  const auto replay =
      Hullguard("replay --config " + Path("replay_rec.yaml") + " --recording " + Path("rec"));
  EXPECT_EQ(replay.code, 0) << replay.out << replay.err;
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(60));
  std::smatch m;
  ASSERT_TRUE(std::regex_search(
      replay.out, m,
      std::regex("replay: ([0-9]+) cycles .* ([0-9]+) cycles degraded \\(([0-9]+) of them in "
                 "silences of every camera, counted, not run\\)")))
      << replay.out;
  const long long cycles = std::stoll(m[1]);
  const long long degraded = std::stoll(m[2]);
  const long long skipped = std::stoll(m[3]);
  EXPECT_GT(cycles, 2LL * 24 * 3600 * 30) << "two days at 30 Hz";
  EXPECT_GT(skipped, cycles - 100);
  EXPECT_GE(degraded, skipped);
}

// Simulated colour cameras recorded: the people come in after the empty
// period (nothing learns a background while recording, so nothing may hold
// them back longer, as the daemon's models do).
TEST_F(RecordCliTest, SimColourCamerasShowTheirPeopleAfterTheEmptyPeriod) {
  // learn_frames 5: the people come in after 2 * 5 / 30 + 1 s.
  std::ofstream(Path("colour.yaml")) << Config("{type: sim, scene: " + kScene + ", colour: true}",
                                               "background: {learn_frames: 5}\n");
  const auto r = Hullguard("record --config " + Path("colour.yaml") + " --out " + Path("rec") +
                           " --seconds 2.5");
  ASSERT_EQ(r.code, 0) << r.out << r.err;
  const capture::RecordingCamera rec = capture::ReadRecordingCamera(Path("rec"), "cam0");
  ASSERT_EQ(rec.kind, capture::FrameKind::kRgb);
  ASSERT_GE(rec.frames.size(), 2U);
  capture::Frame first, last;
  std::vector<unsigned char> bytes;
  std::string path;
  ASSERT_TRUE(capture::LoadRecordedFrame(rec, 0, &first, &bytes, &path)) << path;
  ASSERT_TRUE(capture::LoadRecordedFrame(rec, rec.frames.size() - 1, &last, &bytes, &path)) << path;
  ASSERT_EQ(first.rgb.pixels.size(), last.rgb.pixels.size());
  const double span_s =
      static_cast<double>(rec.frames.back().stamp_ns - rec.frames[0].stamp_ns) * 1e-9;
  ASSERT_GT(span_s, 1.6) << "too short a recording to pass the empty period";
  int largest = 0;  // People are painted 100 grey levels off the empty cell; noise is below 20.
  for (std::size_t i = 0; i < first.rgb.pixels.size(); ++i) {
    largest = std::max(largest, std::abs(last.rgb.pixels[i] - first.rgb.pixels[i]));
  }
  EXPECT_GT(largest, 50) << "no people in the last frame, " << span_s << " s in";
}

// A camera bumped during a recording: cam0's frames from 1.5 s on are those
// of the same cell recorded with cam0 aimed 15 cm aside at 4 m (about 5
// pixels, under the 8-pixel edge grid), its calibration unchanged. The
// replay finds its view shifted and the camera moved, and says so in its
// line.
TEST_F(RecordCliTest, ReplayTellsOfACameraBumpedDuringTheRecording) {
  const std::string extra = "background: {learn_frames: 5}\n";
  std::ofstream(Path("colour.yaml"))
      << Config("{type: sim, scene: " + kScene + ", colour: true}", extra);
  std::string scene = ReadFile(kScene);
  const std::string aim = "look_at: [2, 2, 1]";
  ASSERT_NE(scene.find(aim), std::string::npos);
  scene.replace(scene.find(aim), aim.size(), "look_at: [2.15, 2, 1]");  // cam0's line.
  std::ofstream(Path("bumped_scene.yaml")) << scene;
  std::string bumped =
      Config("{type: sim, scene: " + Path("bumped_scene.yaml") + ", colour: true}", extra);
  bumped.replace(bumped.find(aim), aim.size(), "look_at: [2.15, 2, 1]");
  std::ofstream(Path("bumped.yaml")) << bumped;
  for (const char* name : {"colour", "bumped"}) {
    const auto r = Hullguard(std::string("record --config ") + Path(std::string(name) + ".yaml") +
                             " --out " + Path(std::string("rec_") + name) + " --seconds 3");
    ASSERT_EQ(r.code, 0) << r.out << r.err;
  }
  const capture::RecordingCamera installed =
      capture::ReadRecordingCamera(Path("rec_colour"), "cam0");
  const capture::RecordingCamera moved = capture::ReadRecordingCamera(Path("rec_bumped"), "cam0");
  int spliced = 0;
  for (std::size_t i = 45; i < installed.frames.size() && i < moved.frames.size(); ++i) {
    // `file` is the frame's path within the recording.
    fs::copy_file(fs::path(Path("rec_bumped")) / moved.frames[i].file,
                  fs::path(Path("rec_colour")) / installed.frames[i].file,
                  fs::copy_options::overwrite_existing);
    ++spliced;
  }
  ASSERT_GE(spliced, 30) << "too short a recording";
  std::ofstream(Path("replay.yaml"))
      << Config("{type: replay, directory: " + Path("rec_colour") + "}", extra);
  const auto replay =
      Hullguard("replay --config " + Path("replay.yaml") + " --recording " + Path("rec_colour"));
  ASSERT_EQ(replay.code, 0) << replay.out << replay.err;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(
      replay.out, m,
      std::regex("\n  cam0: [^\n]*moved from cycle ([0-9]+); view shifted in ([0-9]+) cycles; "
                 "largest misalignment ([0-9.]+) px\n")))
      << replay.out;
  EXPECT_GE(std::stod(m[3]), 3.0) << replay.out;
  EXPECT_EQ(replay.out.find("  cam1:"), std::string::npos) << replay.out;
  EXPECT_EQ(replay.out.find("  cam2:"), std::string::npos) << replay.out;
}

// A frame that cannot be written (a folder stands where cam0's third frame
// goes) is reported per camera and turns the exit code to 1; the other frames
// are kept.
TEST_F(RecordCliTest, FrameThatCannotBeWrittenIsReported) {
  fs::create_directories(dir_ / "rec" / "frames" / "cam0" / "000002.png");
  const auto r =
      Hullguard("record --config " + Path("sim.yaml") + " --out " + Path("rec") + " --seconds 1");
  EXPECT_EQ(r.code, 1) << r.out << r.err;
  EXPECT_NE(r.out.find("lost (queue full 0, write errors 1)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("last write error: "), std::string::npos) << r.out;
  EXPECT_NE(r.err.find("1 frames could not be kept"), std::string::npos) << r.err;
  const capture::RecordingCamera cam0 = capture::ReadRecordingCamera(Path("rec"), "cam0");
  EXPECT_EQ(cam0.lost, 1U);
  for (const capture::RecordedFrame& f : cam0.frames) EXPECT_NE(f.file, "frames/cam0/000002.png");
  EXPECT_EQ(capture::ReadRecordingCamera(Path("rec"), "cam1").lost, 0U);
}

// The black box's rings are sized at load: too long a history for the memory
// allowed is refused with the file, the line and the numbers.
TEST_F(RecordCliTest, BlackBoxLargerThanItsMemoryIsRefusedAtLoad) {
  std::ofstream(Path("big.yaml")) << Config("{type: sim, scene: " + kScene + "}",
                                            "blackbox:\n  max_memory_mb: 100\n  seconds: 60\n");
  const auto r = testing::RunTool(HG_HULLGUARDD_BIN, "--check-config " + Path("big.yaml"));
  EXPECT_EQ(r.code, 2) << r.out << r.err;
  // 3 cameras x 1801 slots x 57600 bytes = 297 MiB of rings.
  EXPECT_NE(r.err.find(Path("big.yaml") + ":11: blackbox.seconds: 60 s of every camera need 297 "
                                          "MiB of rings, three times that while two dumps copy "
                                          "them, "
                                          "more than blackbox.max_memory_mb = 100 (largest: cam0 "
                                          "320x180 mask at 30 Hz, 99 MiB)"),
            std::string::npos)
      << r.err;
  std::ofstream(Path("small.yaml")) << Config("{type: sim, scene: " + kScene + "}",
                                              "blackbox: {seconds: 5, max_memory_mb: 100}\n");
  EXPECT_EQ(testing::RunTool(HG_HULLGUARDD_BIN, "--check-config " + Path("small.yaml")).code, 0);
}

/// hullguardd in the background, its stderr in a file.
class Daemon {
 public:
  Daemon(const std::string& config, double duration_s, const std::string& log) : log_(log) {
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 2, log_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
    std::vector<std::string> args = {HG_HULLGUARDD_BIN, "--config", config, "--duration",
                                     std::to_string(duration_s)};
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    EXPECT_EQ(posix_spawn(&pid_, HG_HULLGUARDD_BIN, &actions, nullptr, argv.data(), environ), 0);
    posix_spawn_file_actions_destroy(&actions);
  }
  ~Daemon() {
    if (pid_ > 0) {
      kill(pid_, SIGTERM);
      Wait();
    }
  }
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  void Signal(int signal) const { kill(pid_, signal); }
  int Wait() {
    int status = 0;
    if (pid_ > 0 && waitpid(pid_, &status, 0) == pid_) pid_ = -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
  /// Waits (up to 30 s) for a log line matching `pattern`; its first group.
  std::string WaitFor(const std::string& pattern) const {
    const std::regex re(pattern);
    for (const auto give_up = std::chrono::steady_clock::now() + 30s;
         std::chrono::steady_clock::now() < give_up; std::this_thread::sleep_for(50ms)) {
      std::smatch m;
      const std::string log = ReadFile(log_);
      if (std::regex_search(log, m, re)) return m.size() > 1 ? std::string(m[1]) : m.str();
    }
    ADD_FAILURE() << "no line matching '" << pattern << "' in the daemon's log:\n"
                  << ReadFile(log_);
    return {};
  }

 private:
  std::string log_;
  pid_t pid_ = -1;
};

// The daemon keeps 1 s of every camera: SIGUSR1 dumps it; cam2 stopping
// (fault injection) turns the status degraded and dumps again. Both dumps are
// recordings that replay.
TEST_F(RecordCliTest, DaemonBlackBoxDumpsOnSigusr1AndWhenDegraded) {
  const std::string box = Path("blackbox");
  std::ofstream(Path("daemon.yaml"))
      << Config("{type: sim, scene: " + kScene + "}",
                "blackbox: {seconds: 1, dir: " + box + ", on_degraded: true, max_memory_mb: 64}\n");
  // cam2 stops 3 s after start.
  std::string text = ReadFile(Path("daemon.yaml"));
  const std::string cam2 = "source: {type: sim, scene: " + kScene + "}}\n";
  const std::size_t at = text.rfind(cam2);
  ASSERT_NE(at, std::string::npos);
  text.replace(at, cam2.size(), "source: {type: sim, scene: " + kScene + ", stop_after_s: 3}}\n");
  std::ofstream(Path("daemon.yaml")) << text;

  Daemon daemon(Path("daemon.yaml"), 6.0, Path("hullguardd.log"));
  daemon.WaitFor("hullguardd: cycle [0-9]+ ok");
  daemon.Signal(SIGUSR1);
  const std::string dumped = " wrote [0-9]+ frames \\([0-9.]+ s, [0-9]+ torn\\) to (\\S+)";
  const std::string manual = daemon.WaitFor("black box \\(SIGUSR1\\):" + dumped);
  EXPECT_EQ(daemon.Wait(), 0);
  ASSERT_FALSE(manual.empty());
  EXPECT_EQ(fs::path(manual).parent_path(), fs::path(box));
  // 1 s at 30 Hz: 31 slots a camera.
  CheckRecording(manual, 5);
  for (const char* name : {"cam0", "cam1", "cam2"}) {
    EXPECT_LE(capture::ReadRecordingCamera(manual, name).frames.size(), 31U);
  }
  EXPECT_FALSE(ReplayDigest(manual).empty());

  // A degraded dump (a deadline miss on a busy machine may add others) in
  // which cam2's last frame is older than cam0's by more than its timeout.
  const std::string log = ReadFile(Path("hullguardd.log"));
  const std::regex degraded("black box \\(degraded\\):" + dumped);
  int dumps = 0;
  bool cam2_lags = false;
  for (auto it = std::sregex_iterator(log.begin(), log.end(), degraded);
       it != std::sregex_iterator(); ++it) {
    ++dumps;
    const std::string dir = (*it)[1];
    const auto last = [&](const char* name) {
      const auto rec = capture::ReadRecordingCamera(dir, name);
      return rec.frames.empty() ? std::int64_t{0} : rec.frames.back().stamp_ns;
    };
    cam2_lags = cam2_lags || last("cam2") + 150'000'000 < last("cam0");
  }
  EXPECT_GE(dumps, 1) << log;
  EXPECT_TRUE(cam2_lags) << log;
}

// What `hullguard replay` prints after its summary for a synth recording
// with a ground truth; -1 each when the line is missing.
struct TruthLine {
  long long points = -1;
  int frame_sets = -1;
  long long free = -1;
};

TruthLine ParseTruthLine(const std::string& out) {
  std::smatch m;
  const std::regex line(
      "\nground truth: ([0-9]+) points inside people over ([0-9]+) frame sets, ([0-9]+) in cells "
      "published free\n");
  if (!std::regex_search(out, m, line)) return {};
  return {std::stoll(m[1]), std::stoi(m[2]), std::stoll(m[3])};
}

const std::string kDemoScene = std::string(HG_SOURCE_DIR) + "/config/scenes/demo_cell.yaml";
const std::string kDemoConfig = std::string(HG_SOURCE_DIR) + "/config/demo.yaml";

// A synth recording of the demo cell replays with every sampled point inside
// a person in an occupied or occluded cell; so does the small recording of the
// regression test, whose cameras capture 6 and 12 ms apart.
TEST_F(RecordCliTest, ReplayChecksSynthRecordingsAgainstTheirGroundTruth) {
  const auto synth =
      Hullguard("synth --scene " + kDemoScene + " --frames 3 --masks --out " + Path("demo"));
  ASSERT_EQ(synth.code, 0) << synth.out << synth.err;
  const auto r = Hullguard("replay --config " + kDemoConfig + " --recording " + Path("demo"));
  EXPECT_EQ(r.code, 0) << r.out << r.err;
  TruthLine truth = ParseTruthLine(r.out);
  EXPECT_EQ(truth.frame_sets, 3) << r.out;
  // Two people, 200 points each a frame; no capture offsets, so none is dropped.
  EXPECT_EQ(truth.points, 3 * 2 * 200) << r.out;
  EXPECT_EQ(truth.free, 0) << r.out;

  // --frames checks the frame sets replayed, with the same points.
  const auto two =
      Hullguard("replay --config " + kDemoConfig + " --recording " + Path("demo") + " --frames 2");
  EXPECT_EQ(two.code, 0) << two.out << two.err;
  EXPECT_EQ(ParseTruthLine(two.out).frame_sets, 2) << two.out;

  const std::string data = std::string(HG_SOURCE_DIR) + "/tests/data";
  const auto small = Hullguard("replay --config " + data + "/small_cell_config.yaml --recording " +
                               data + "/small_cell_recording");
  EXPECT_EQ(small.code, 0) << small.out << small.err;
  truth = ParseTruthLine(small.out);
  EXPECT_EQ(truth.frame_sets, 12) << small.out;
  // Points near the surface of a moving part are dropped (capture offsets).
  EXPECT_GT(truth.points, 12 * 20) << small.out;
  EXPECT_LT(truth.points, 12 * 200) << small.out;
  EXPECT_EQ(truth.free, 0) << small.out;
}

// `hullguard replay` plays a recording with the config's cameras only when
// the recording's calibration is theirs: cameras swapped in the recording,
// or no cameras.yaml, exit 2 with the file and the camera named. Frame sets
// missing for every camera are a gap in time: the cameras time out
// (degraded, nothing inside a person free), as they would in the daemon.
TEST_F(RecordCliTest, ReplayChecksTheCalibrationAndTimesOutAGapInTheRecording) {
  const fs::path data = fs::path(HG_SOURCE_DIR) / "tests/data";
  const std::string config = (data / "small_cell_config.yaml").string();
  const fs::path rec = dir_ / "rec";
  fs::copy(data / "small_cell_recording", rec, fs::copy_options::recursive);
  const std::string replay = "replay --config " + config + " --recording " + rec.string();

  const std::string cameras = ReadFile(rec / "cameras.yaml");
  std::string swapped = std::regex_replace(cameras, std::regex("name: cam0"), "name: camX");
  swapped = std::regex_replace(swapped, std::regex("name: cam1"), "name: cam0");
  swapped = std::regex_replace(swapped, std::regex("name: camX"), "name: cam1");
  ASSERT_NE(swapped, cameras);
  std::ofstream(rec / "cameras.yaml") << swapped;
  auto r = Hullguard(replay);
  EXPECT_EQ(r.code, 2) << r.out << r.err;
  EXPECT_NE(r.err.find((rec / "cameras.yaml").string() + ": the recording does not match"),
            std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("cameras[0] 'cam0' (recorded 'cam0'): "), std::string::npos) << r.err;
  EXPECT_EQ(r.out.find("digest"), std::string::npos) << r.out;

  fs::remove(rec / "cameras.yaml");
  r = Hullguard(replay);
  EXPECT_EQ(r.code, 2) << r.out << r.err;
  EXPECT_NE(r.err.find("has no cameras.yaml"), std::string::npos) << r.err;

  std::ofstream(rec / "cameras.yaml") << cameras;
  r = Hullguard(replay);
  ASSERT_EQ(r.code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find(", 0 cycles degraded"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(" 0 frames missing or unreadable"), std::string::npos) << r.out;

  // A frame of another size than its camera's is unreadable, and counted so
  // (a synth recording does not state its frames' size).
  const fs::path frame = rec / "masks" / "cam1" / "000002.png";
  fs::rename(frame, dir_ / "kept.png");
  silhouette::WriteGreyImage(frame.string(), common::ImageU8(321, 180));
  r = Hullguard(replay);
  EXPECT_EQ(r.code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find(" 1 frames missing or unreadable"), std::string::npos) << r.out;
  fs::rename(dir_ / "kept.png", frame);

  // Frame sets 3 to 10 (267 ms, over the 200 ms camera timeout) gone.
  for (const char* camera : {"cam0", "cam1", "cam2"}) {
    for (int i = 3; i <= 10; ++i) {
      char name[16];
      std::snprintf(name, sizeof(name), "%06d.png", i);
      ASSERT_TRUE(fs::remove(rec / "masks" / camera / name));
    }
  }
  r = Hullguard(replay);
  EXPECT_EQ(r.code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("24 frames missing or unreadable"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find(", 0 cycles degraded"), std::string::npos) << r.out;
  EXPECT_EQ(ParseTruthLine(r.out).free, 0) << r.out;
}

// A camera capturing 150 ms after the others while the person, standing for
// a second, starts to walk: the check takes as deep only points that stayed
// inside the body over every camera's capture time, from the speeds over
// all of it (it took them from the frames next to the one checked, where
// the person still stood, and reported points the walk had left as
// published free: 5 here, a false alarm).
TEST_F(RecordCliTest, ReplayCheckAllowsForAPersonStartingWithinTheCaptureOffsets) {
  std::string scene = ReadFile(kScene);
  for (const auto& [from, to] :
       {std::pair<std::string, std::string>{"capture_offsets_ms: {cam1: 6.0, cam2: 12.0}",
                                            "capture_offsets_ms: {cam2: 150.0}"},
        {"      - walk: {speed: 1.5,",
         "      - stand: {duration: 1.0}\n      - walk: {speed: 1.5,"}}) {
    const std::size_t at = scene.find(from);
    ASSERT_NE(at, std::string::npos) << from;
    scene.replace(at, from.size(), to);
  }
  std::ofstream(Path("starting.yaml")) << scene;
  const auto synth = Hullguard("synth --scene " + Path("starting.yaml") +
                               " --frames 75 --masks --out " + Path("rec"));
  ASSERT_EQ(synth.code, 0) << synth.out << synth.err;
  std::ofstream(Path("replay.yaml"))
      << Config("{type: replay, directory: " + Path("rec") + "}", "motion: {max_speed_mps: 6}\n");
  const auto r =
      Hullguard("replay --config " + Path("replay.yaml") + " --recording " + Path("rec"));
  EXPECT_EQ(r.code, 0) << r.out << r.err;
  const TruthLine line = ParseTruthLine(r.out);
  EXPECT_GT(line.points, 1000) << r.out;
  EXPECT_EQ(line.free, 0) << r.out << r.err;
}

// A ground truth that puts a person where the cameras certify the space free
// (alice moved 2 m across the cell, in every frame) fails the replay, with
// the points named; --truth and --no-truth pick the file or skip the check.
TEST_F(RecordCliTest, ReplayFailsWhenAPointInsideAPersonIsPublishedFree) {
  const auto synth =
      Hullguard("synth --scene " + kDemoScene + " --frames 3 --masks --out " + Path("demo"));
  ASSERT_EQ(synth.code, 0) << synth.out << synth.err;
  const std::string file = Path("demo/ground_truth.yaml");
  const sim::GroundTruth truth = sim::ReadGroundTruth(file);
  sim::WriteGroundTruth(Path("original.yaml"), truth);
  sim::GroundTruth moved = truth;
  const Eigen::Vector3d shift(1.2, 1.6, 0.0);
  for (sim::FrameTruth& frame : moved.frames) {
    ASSERT_EQ(frame.people.size(), 2U);
    ASSERT_EQ(frame.people[0].name, "alice");
    sim::BodyState& body = frame.people[0].state;
    for (sim::BodyCapsule& c : body.parts) {
      c.a_W += shift;
      c.b_W += shift;
    }
    body.centre_W += shift;
  }
  sim::WriteGroundTruth(file, moved);

  const std::string replay = "replay --config " + kDemoConfig + " --recording " + Path("demo");
  const auto r = Hullguard(replay);
  EXPECT_EQ(r.code, 1) << r.out << r.err;
  const TruthLine line = ParseTruthLine(r.out);
  EXPECT_EQ(line.points, 3 * 2 * 200) << r.out;
  // Most of alice's 600 points lie in free space; bob's are all covered.
  EXPECT_GT(line.free, 300) << r.out;
  EXPECT_LE(line.free, 600) << r.out;
  EXPECT_NE(r.err.find(" points inside people lie in cells published free"), std::string::npos)
      << r.err;
  EXPECT_TRUE(std::regex_search(r.err, std::regex("\n  frame 0, alice \\([a-z_]+\\): point \\(")))
      << r.err;

  const auto original = Hullguard(replay + " --truth " + Path("original.yaml"));
  EXPECT_EQ(original.code, 0) << original.out << original.err;
  EXPECT_EQ(ParseTruthLine(original.out).free, 0) << original.out;

  const auto skipped = Hullguard(replay + " --no-truth");
  EXPECT_EQ(skipped.code, 0) << skipped.out << skipped.err;
  EXPECT_NE(skipped.out.find("ground truth: not checked (--no-truth)"), std::string::npos)
      << skipped.out;
  EXPECT_NE(Hullguard(replay + " --no-truth --truth " + file).code, 0);
}

}  // namespace
}  // namespace hg
