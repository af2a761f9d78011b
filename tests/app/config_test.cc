#include "app/config.h"

#include <chrono>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include "app/config_doc.h"
#include "app/pipeline_setup.h"
#include "app/tracking_stage.h"
#include "capture/recording.h"
#include "common/config_error.h"
#include "common/version.h"
#include "geometry/camera_yaml.h"
#include "sim/body.h"
#include "sim/scene.h"
#include "support/run_tool.h"

namespace hg::app {
namespace {

namespace fs = std::filesystem;

const std::string kSourceDir = HG_SOURCE_DIR;
const std::string kConfigDir = kSourceDir + "/config";

/// A valid file with one camera of each kind and every section set to a
/// non-default value. Line numbers matter to the tests below.
const char* const kFull = R"(cell:
  bounds: {min: [-1, -2, 0], max: [3, 4, 2.5]}
octree: {depth: 8, boundary_coarsening: 2, knowledge_filter_m3: 0.002, publish_depth: 6}
timing: {rate_hz: 20, deadline_ms: 40, camera_timeout_ms: 150, align_to_frames: false, align_margin_ms: 3}
threads: {octree: 4, silhouette_workers: 3, realtime_priority: 12}
cameras:
  - name: cam0
    width: 1920
    height: 1080
    K: [1083.5787063372297, 0, 959.5, 0, 1083.5787063372297, 539.5, 0, 0, 1]
    position: [-0.3, -0.3, 3.6]
    look_at: [2, 2, 1]
    source: {type: sim, scene: scenes/demo_cell.yaml}
  - name: rec
    width: 320
    height: 180
    K: [180.59645105620496, 0, 159.5, 0, 180.59645105620496, 89.5, 0, 0, 1]
    R: [0.70710678118654757, 0.70710678118654757, -0, 0.44150314702736099, -0.44150314702736099, -0.78112095243302315, -0.55233592239228524, 0.55233592239228524, -0.62437973835649652]
    t: [-2.8284271247461903, 0.78112095243302271, 4.7885123010878994]
    source: {type: replay, directory: ../tests/data/small_cell_recording, camera: cam2, realtime: false}
    timeout_ms: 500
  - name: gige
    width: 1280
    height: 1024
    P: [900, 0, 639.5, 0, 0, 900, 511.5, 0, 0, 0, 1, 2]
    source:
      type: aravis
      device: "192.168.10.21"
      pixel_format: BayerRG8
      exposure_us: 4000
      gain_db: 3.5
      frame_rate_hz: 25
      trigger: software
      packet_size: 9000
      socket_buffer_bytes: 8388608
  - name: usb
    width: 640
    height: 480
    K: [500, 0, 319.5, 0, 500, 239.5, 0, 0, 1]
    distortion: [-0.1, 0.01, 0, 0, 0]
    position: [4, 4, 2]
    look_at: [2, 2, 1]
    source: {type: v4l2, device: /dev/video2, format: MJPEG, frame_rate_hz: 15, exposure: 120}
background: {learn_frames: 50, threshold: 30, adapt_rate: 0.05, shadows_are_foreground: false, max_threshold: 40, keep_dir: state/bg}
obstacles:
  - file: demo_cell/obstacles.obj
dds: {domain_id: 7, topic_prefix: cell7, enabled: false}
logging: {level: debug, journald: true}
motion: {max_speed_mps: 1.6, min_camera_distance_m: 1.5}
)";

Config Parse(const std::string& text) { return ParseConfig(text, "t.yaml", kConfigDir); }

/// The message of the ConfigError that parsing `text` throws ("" if none).
std::string ErrorOf(const std::string& text) {
  try {
    (void)Parse(text);
  } catch (const common::ConfigError& e) {
    return e.what();
  }
  return "";
}

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) out.push_back(line);
  return out;
}

/// `text` with the first occurrence of `from` replaced by `to`.
std::string Replace(std::string text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

const char* const kMinimal = R"(cell:
  bounds: {min: [0, 0, 0], max: [4, 4, 4]}
cameras:
  - name: a
    width: 64
    height: 48
    K: [50, 0, 31.5, 0, 50, 23.5, 0, 0, 1]
    R: [1, 0, 0, 0, 1, 0, 0, 0, 1]
    t: [0, 0, 1]
    source: {type: aravis, device: cam-a}
)";

TEST(ConfigTest, DefaultsOfAMinimalFile) {
  const Config c = Parse(kMinimal);
  EXPECT_EQ(c.source_file, "t.yaml");
  EXPECT_EQ(c.octree.depth, 10);
  EXPECT_EQ(c.octree.boundary_coarsening, 3);
  EXPECT_EQ(c.octree.knowledge_filter_m3, 0.0);
  EXPECT_EQ(c.octree.publish_depth, 7);
  EXPECT_EQ(c.motion.max_speed_mps, 5.0);
  EXPECT_EQ(c.motion.min_camera_distance_m, 1.0);
  EXPECT_EQ(c.timing.rate_hz, 30.0);
  EXPECT_EQ(c.timing.deadline_ms, 25.0);
  EXPECT_EQ(c.timing.camera_timeout_ms, 200);
  EXPECT_TRUE(c.timing.align_to_frames);
  EXPECT_EQ(c.timing.align_margin_ms, 2.0);
  EXPECT_EQ(c.threads.octree, 2);
  EXPECT_EQ(c.threads.silhouette_workers, 0);
  EXPECT_EQ(c.background.learn_frames, 30);
  EXPECT_EQ(c.background.threshold, 15);
  EXPECT_EQ(c.background.adapt_rate, 0.01);
  EXPECT_TRUE(c.background.shadows_are_foreground);
  EXPECT_TRUE(c.obstacles.empty());
  EXPECT_EQ(c.dds.domain_id, 0);
  EXPECT_EQ(c.dds.topic_prefix, "hullguard");
  EXPECT_TRUE(c.dds.enabled);
  EXPECT_EQ(c.logging.level, LogLevel::kInfo);
  EXPECT_FALSE(c.logging.journald);
  ASSERT_EQ(c.cameras.size(), 1u);
  EXPECT_EQ(c.cameras[0].timeout_ms, 200);  // Taken from timing.
  const auto& aravis = std::get<AravisSourceConfig>(c.cameras[0].source);
  EXPECT_EQ(aravis.device, "cam-a");
  EXPECT_EQ(aravis.pixel_format, PixelFormat::kMono8);
  EXPECT_EQ(aravis.trigger, Trigger::kFreeRun);
  EXPECT_FALSE(aravis.exposure_us.has_value());
  EXPECT_FALSE(aravis.packet_size.has_value());
}

TEST(ConfigTest, EverySectionReadsBack) {
  const Config c = Parse(kFull);
  EXPECT_EQ(c.cell.bounds.min, Eigen::Vector3d(-1, -2, 0));
  EXPECT_EQ(c.cell.bounds.max, Eigen::Vector3d(3, 4, 2.5));
  EXPECT_EQ(c.octree.depth, 8);
  EXPECT_EQ(c.octree.boundary_coarsening, 2);
  EXPECT_EQ(c.octree.knowledge_filter_m3, 0.002);
  EXPECT_EQ(MakePipelineOptions(c).knowledge_filter_m3, 0.002);
  EXPECT_EQ(MakePipelineOptions(c).silhouette_workers, 3);
  EXPECT_EQ(c.timing.rate_hz, 20.0);
  EXPECT_EQ(c.timing.deadline_ms, 40.0);
  EXPECT_EQ(c.timing.camera_timeout_ms, 150);
  EXPECT_FALSE(c.timing.align_to_frames);
  EXPECT_EQ(c.timing.align_margin_ms, 3.0);
  EXPECT_FALSE(MakePipelineOptions(c).align_to_frames);
  EXPECT_EQ(MakePipelineOptions(c).align_margin_ms, 3.0);
  EXPECT_EQ(c.threads.octree, 4);
  EXPECT_EQ(c.threads.silhouette_workers, 3);
  EXPECT_EQ(c.threads.realtime_priority, 12);
  EXPECT_EQ(MakePipelineOptions(c).fusion_realtime_priority, 12);
  EXPECT_EQ(c.background.learn_frames, 50);
  EXPECT_EQ(c.background.threshold, 30);
  EXPECT_EQ(c.background.adapt_rate, 0.05);
  EXPECT_FALSE(c.background.shadows_are_foreground);
  // Relative to the config's folder; the pipeline keeps the backgrounds there.
  EXPECT_EQ(c.background.keep_dir, kConfigDir + "/state/bg");
  EXPECT_EQ(MakePipelineOptions(c).background_dir, kConfigDir + "/state/bg");
  EXPECT_EQ(Parse(kMinimal).background.keep_dir, "");
  ASSERT_EQ(c.obstacles.size(), 1u);
  EXPECT_EQ(c.obstacles[0].file, kConfigDir + "/demo_cell/obstacles.obj");
  EXPECT_EQ(c.dds.domain_id, 7);
  EXPECT_EQ(c.dds.topic_prefix, "cell7");
  EXPECT_FALSE(c.dds.enabled);
  EXPECT_EQ(c.logging.level, LogLevel::kDebug);
  EXPECT_TRUE(c.logging.journald);

  ASSERT_EQ(c.cameras.size(), 4u);
  const CameraConfig& sim_cam = c.cameras[0];
  EXPECT_EQ(sim_cam.model.name, "cam0");
  EXPECT_EQ(sim_cam.model.width, 1920);
  EXPECT_NEAR((sim_cam.model.CentreW() - Eigen::Vector3d(-0.3, -0.3, 3.6)).norm(), 0.0, 1e-9);
  EXPECT_EQ(sim_cam.timeout_ms, 150);
  const auto& sim = std::get<SimSourceConfig>(sim_cam.source);
  EXPECT_EQ(sim.scene, kConfigDir + "/scenes/demo_cell.yaml");
  EXPECT_EQ(sim.camera, "cam0");  // Defaults to the camera's own name.

  const CameraConfig& rec = c.cameras[1];
  EXPECT_EQ(rec.timeout_ms, 500);
  const auto& replay = std::get<ReplaySourceConfig>(rec.source);
  EXPECT_TRUE(fs::equivalent(replay.directory, kSourceDir + "/tests/data/small_cell_recording"))
      << replay.directory;
  EXPECT_EQ(replay.camera, "cam2");
  EXPECT_FALSE(replay.realtime);
  EXPECT_EQ(TypeOf(rec.source), SourceType::kReplay);

  const CameraConfig& gige = c.cameras[2];
  EXPECT_DOUBLE_EQ(gige.model.K(0, 0), 900.0);
  const auto& aravis = std::get<AravisSourceConfig>(gige.source);
  EXPECT_EQ(aravis.device, "192.168.10.21");
  EXPECT_EQ(aravis.pixel_format, PixelFormat::kBayerRG8);
  EXPECT_EQ(aravis.exposure_us, 4000.0);
  EXPECT_EQ(aravis.gain_db, 3.5);
  EXPECT_EQ(aravis.frame_rate_hz, 25.0);
  EXPECT_EQ(aravis.trigger, Trigger::kSoftware);
  EXPECT_EQ(aravis.packet_size, 9000);
  EXPECT_EQ(aravis.socket_buffer_bytes, 8388608);

  const CameraConfig& usb = c.cameras[3];
  EXPECT_EQ(usb.model.distortion[0], -0.1);
  const auto& v4l2 = std::get<V4l2SourceConfig>(usb.source);
  EXPECT_EQ(v4l2.device, "/dev/video2");
  EXPECT_EQ(v4l2.format, V4l2Format::kMjpeg);
  EXPECT_EQ(v4l2.frame_rate_hz, 15.0);
  EXPECT_EQ(v4l2.exposure, 120);

  EXPECT_EQ(c.octree.publish_depth, 6);
  EXPECT_EQ(c.motion.max_speed_mps, 1.6);
  EXPECT_EQ(c.motion.min_camera_distance_m, 1.5);
  // Accepted, but it has no effect any more: said, with its line; and
  // shadows as background, which can hide a person, said too.
  ASSERT_EQ(c.notices.size(), 2u);
  EXPECT_NE(c.notices[0].find("t.yaml:"), std::string::npos) << c.notices[0];
  EXPECT_NE(c.notices[0].find("motion.min_camera_distance_m: ignored"), std::string::npos)
      << c.notices[0];
  EXPECT_NE(c.notices[1].find("t.yaml:44: background.shadows_are_foreground: false: a part of a "
                              "person that is darker"),
            std::string::npos)
      << c.notices[1];
  EXPECT_EQ(Summary(c), "4 cameras (1 sim, 1 replay, 1 aravis, 1 v4l2), depth 8, 20 Hz");
}

TEST(ConfigTest, DemoConfigLoads) {
  const Config c = LoadConfig(kConfigDir + "/demo.yaml");
  ASSERT_EQ(c.cameras.size(), 4u);
  EXPECT_EQ(c.octree.depth, 7);
  EXPECT_EQ(c.cell.bounds.max, Eigen::Vector3d(4, 4, 4));
  for (const CameraConfig& cam : c.cameras) {
    ASSERT_EQ(TypeOf(cam.source), SourceType::kSim);
    EXPECT_EQ(std::get<SimSourceConfig>(cam.source).camera, cam.model.name);
  }
  EXPECT_EQ(Summary(c), "4 cameras (4 sim), depth 7, 30 Hz");
}

// Every shipped daemon config loads; the colour variants of the paper cell
// differ from it only in what their cameras deliver.
TEST(ConfigTest, EveryShippedConfigLoads) {
  int loaded = 0;
  for (const auto& entry : fs::directory_iterator(kConfigDir)) {
    if (entry.path().extension() != ".yaml") continue;
    SCOPED_TRACE(entry.path().string());
    EXPECT_TRUE(LoadConfig(entry.path().string()).notices.empty());
    ++loaded;
  }
  EXPECT_GE(loaded, 4);
  const Config masks = LoadConfig(kConfigDir + "/paper_cell.yaml");
  for (const char* name : {"paper_cell_bayer.yaml", "paper_cell_colour.yaml"}) {
    const Config c = LoadConfig(kConfigDir + "/" + name);
    ASSERT_EQ(c.cameras.size(), masks.cameras.size()) << name;
    EXPECT_EQ(c.octree.depth, masks.octree.depth) << name;
    EXPECT_EQ(c.timing.deadline_ms, masks.timing.deadline_ms) << name;
    for (const CameraConfig& cam : c.cameras) {
      const auto& sim = std::get<SimSourceConfig>(cam.source);
      EXPECT_TRUE(std::string(name) == "paper_cell_bayer.yaml" ? sim.bayer
                                                               : sim.colour && !sim.bayer)
          << name << " " << cam.model.name;
    }
  }
}

// The fastest any point of a person in `scene` moves, over each script and
// a second after.
double FastestPartSpeed(const sim::Scene& scene) {
  double fastest = 0.0;
  for (const sim::Person& person : scene.people) {
    fastest = std::max(fastest, sim::FastestPartSpeed(person, 0.0, sim::ScriptEndS(person) + 1.0));
  }
  return fastest;
}

// The skew compensation holds only for people no faster than max_speed_mps,
// swinging feet and arms included (a foot in swing moves at up to three times
// the walking speed): every shipped config with simulated cameras gives a
// speed no lower than that of its scene's fastest limb.
TEST(ConfigTest, ShippedConfigsBoundTheSpeedOfTheirPeople) {
  int checked = 0;
  for (const auto& entry : fs::directory_iterator(kConfigDir)) {
    if (entry.path().extension() != ".yaml") continue;
    SCOPED_TRACE(entry.path().string());
    const Config c = LoadConfig(entry.path().string());
    std::set<std::string> scenes;
    for (const CameraConfig& cam : c.cameras) {
      if (const auto* sim = std::get_if<SimSourceConfig>(&cam.source)) scenes.insert(sim->scene);
    }
    for (const std::string& scene : scenes) {
      const double fastest = FastestPartSpeed(sim::LoadScene(scene));
      std::printf("%s: %s fastest part %.2f m/s, max_speed_mps %.2f\n",
                  entry.path().filename().c_str(), scene.c_str(), fastest, c.motion.max_speed_mps);
      EXPECT_LE(fastest, c.motion.max_speed_mps) << scene;
      ++checked;
    }
  }
  EXPECT_GE(checked, 4);
}

// hullguardd warns when a sim scene's people outrun motion.max_speed_mps.
TEST(ConfigTest, SimSpeedNoticesNameTheKeyAndTheScene) {
  const Config shipped = LoadConfig(kConfigDir + "/demo.yaml");
  EXPECT_TRUE(SimSpeedNotices(shipped).empty());
  std::string text = ReadFile(kConfigDir + "/demo.yaml");
  ASSERT_EQ(text.find("motion:"), std::string::npos);
  if (!text.empty() && text.back() != '\n') text += '\n';
  const int line = 2 + static_cast<int>(std::count(text.begin(), text.end(), '\n'));
  text += "motion:\n  max_speed_mps: 3.0\n";
  const Config slow = ParseConfig(text, "slow.yaml", kConfigDir);
  const std::vector<std::string> notices = SimSpeedNotices(slow);
  ASSERT_EQ(notices.size(), 1u);
  EXPECT_EQ(
      notices[0].rfind("slow.yaml:" + std::to_string(line) + ": motion.max_speed_mps: 3.00 m/s", 0),
      0u)
      << notices[0];
  EXPECT_NE(notices[0].find("demo_cell.yaml"), std::string::npos) << notices[0];
}

// The coarse passes stop at the level whose cells are no larger than the
// tracking voxel, so that an aborted cycle can still start tracks.
TEST(ConfigTest, OctreeKeyLevelIsTheTrackingVoxel) {
  Config c = LoadConfig(kConfigDir + "/paper_cell.yaml");
  ASSERT_EQ(c.cell.bounds.max, Eigen::Vector3d(4, 4, 3));
  c.tracking.voxel_m = 0.05;  // Level 7: 4 m / 128 = 3.1 cm; level 6 is 6.25 cm.
  EXPECT_EQ(MakePipelineOptions(c).key_level, 7);
  c.tracking.voxel_m = 0.0625;
  EXPECT_EQ(MakePipelineOptions(c).key_level, 6);
  c.tracking.voxel_m = 0.001;  // Finer than the octree: its depth.
  EXPECT_EQ(MakePipelineOptions(c).key_level, c.octree.depth);
  c.tracking.enabled = false;
  EXPECT_EQ(MakePipelineOptions(c).key_level, 0);
}

TEST(ConfigTest, DocExampleLoads) {
  const Config c = Parse(ConfigExampleYaml());
  EXPECT_EQ(c.cameras.size(), 2u);
}

struct Mistake {
  const char* from;     ///< Text of kFull replaced...
  const char* to;       ///< ...by this.
  int line;             ///< Line the error must name.
  const char* path;     ///< Key path it must name.
  const char* problem;  ///< Part of the problem text.
};

// Each mistake on its own, applied to the valid kFull.
const Mistake kMistakes[] = {
    {"max: [3, 4, 2.5]", "max: [3, -4, 2.5]", 2, "cell.bounds.max", "must exceed min"},
    {"max: [3, 4, 2.5]", "max: [3, 4]", 2, "cell.bounds.max", "3 numbers"},
    {"depth: 8", "depth: 17", 3, "octree.depth", "must be in 3 .. 16"},
    {"depth: 8", "depth: 8.5", 3, "octree.depth", "expected an integer"},
    {"knowledge_filter_m3: 0.002", "knowledge_filter_m3: -1", 3, "octree.knowledge_filter_m3",
     ">= 0"},
    {"octree: {", "octree: {colour: red, ", 3, "octree", "unknown key 'colour'"},
    {"deadline_ms: 40", "deadline_ms: 60", 4, "timing.deadline_ms", "1000 / rate_hz"},
    {"rate_hz: 20", "rate_hz: fast", 4, "timing.rate_hz", "expected a number"},
    {"camera_timeout_ms: 150", "camera_timeout_ms: 0", 4, "timing.camera_timeout_ms", ">= 1"},
    {"align_margin_ms: 3", "align_margin_ms: -1", 4, "timing.align_margin_ms", ">= 0"},
    {"align_to_frames: false", "align_to_frames: maybe", 4, "timing.align_to_frames", "expected"},
    {"align_to_frames: false", "align_to_frames: yes", 4, "timing.align_to_frames",
     "expected true or false (got 'yes')"},
    {"octree: 4", "octree: \"4\"", 5, "threads.octree",
     "expected an integer (got the quoted string \"4\")"},
    {"octree: 4", "octree: 0", 5, "threads.octree", "must be in 1 .. 64"},
    {"width: 1920", "width: wide", 8, "cameras[0].width", "positive integer"},
    {"K: [1083.5787063372297, 0, 959.5, 0, 1083.5787063372297, 539.5, 0, 0, 1]", "K: [1, 2, 3]", 10,
     "cameras[0].K", "expected 9 numbers"},
    {"type: sim", "type: usb", 13, "cameras[0].source.type",
     "unknown source type 'usb' (expected sim, replay, aravis or v4l2)"},
    {"scene: scenes/demo_cell.yaml", "scene: scenes/nope.yaml", 13, "cameras[0].source.scene",
     "no such file"},
    {"scene: scenes/demo_cell.yaml", "scene: scenes", 13, "cameras[0].source.scene",
     "a folder, not a file"},
    {"scene: scenes/demo_cell.yaml}", "scene: scenes/demo_cell.yaml, camera: cam9}", 13,
     "cameras[0].source.camera", "has no camera 'cam9'"},
    {"scene: scenes/demo_cell.yaml}", "scene: scenes/demo_cell.yaml, device: x}", 13,
     "cameras[0].source", "unknown key 'device'"},
    {"name: rec", "name: cam0", 14, "cameras[1].name", "duplicate camera name 'cam0'"},
    {"directory: ../tests/data/small_cell_recording", "directory: missing_dir", 20,
     "cameras[1].source.directory", "no such directory"},
    {"realtime: false", "realtime: maybe", 20, "cameras[1].source.realtime", "true or false"},
    {"timeout_ms: 500", "timeout_ms: -5", 21, "cameras[1].timeout_ms", ">= 1"},
    {"timeout_ms: 500", "timeout: 500", 21, "cameras[1]", "unknown key 'timeout'"},
    {"pixel_format: BayerRG8", "pixel_format: YUV422", 29, "cameras[2].source.pixel_format",
     "unknown value 'YUV422'"},
    {"gain_db: 3.5", "gain_db: 99", 31, "cameras[2].source.gain_db", "must be in 0 .. 60"},
    {"trigger: software", "trigger: sometimes", 33, "cameras[2].source.trigger",
     "free_run, software or hardware"},
    {"packet_size: 9000", "packet_size: 100", 34, "cameras[2].source.packet_size", "576"},
    {"      device: \"192.168.10.21\"\n", "", 26, "cameras[2].source", "missing key 'device'"},
    {"device: /dev/video2", "device: video2", 43, "cameras[3].source.device", "/dev/video0"},
    {"format: MJPEG", "format: H264", 43, "cameras[3].source.format", "GREY, YUYV or MJPEG"},
    {"distortion: [-0.1, 0.01, 0, 0, 0]", "distortion: [-0.1, x, 0, 0, 0]", 40,
     "cameras[3].distortion[1]", "not a number"},
    {"threshold: 30", "threshold: 256", 44, "background.threshold", "must be in 1 .. 255"},
    {"adapt_rate: 0.05", "adapt_rate: 1.5", 44, "background.adapt_rate", "must be in 0 .. 0.25"},
    {"file: demo_cell/obstacles.obj", "file: demo_cell/cameras.yaml", 46, "obstacles[0].file",
     ".obj or .stl"},
    {"file: demo_cell/obstacles.obj", "file: demo_cell/none.obj", 46, "obstacles[0].file",
     "no such file"},
    {"domain_id: 7", "domain_id: 233", 47, "dds.domain_id", "must be in 0 .. 232"},
    {"level: debug", "level: loud", 48, "logging.level", "unknown value 'loud'"},
    {"logging:", "loging:", 48, "", "unknown key 'loging'"},
    {"max_threshold: 40", "max_threshold: 20", 44, "background.max_threshold",
     "must be >= background.threshold = 30"},
    {"max_threshold: 40", "max_threshold: 40, texture_threshold: 41", 44,
     "background.texture_threshold", "must be <= background.max_threshold = 40"},
    {"max_threshold: 40", "max_threshold: 40, fill_holes: sometimes", 44, "background.fill_holes",
     "true or false"},
    {"publish_depth: 6", "publish_depth: 9", 3, "octree.publish_depth", "<= octree.depth = 8"},
    {"octree: {", "octree: {coarse_first_depth: 8, ", 3, "octree.coarse_first_depth",
     "a level below octree.depth = 8"},
    {"boundary_coarsening: 2", "boundary_coarsening: 6", 3, "octree.boundary_coarsening",
     "<= octree.depth - 3 = 5"},
    {"max: [3, 4, 2.5]", "max: [3, 4, 1e300]", 2, "cell.bounds.max", "within +-1e6 m"},
    {"topic_prefix: cell7", "topic_prefix: \"cell 7\"", 47, "dds.topic_prefix",
     "not a DDS topic name prefix"},
    {"topic_prefix: cell7", "topic_prefix: 7cell", 47, "dds.topic_prefix", "not starting"},
    {"name: gige", "name: gige/left", 22, "cameras[2].name",
     "'gige/left' cannot name the camera's files and folders"},
    {"K: [180.59645105620496, 0, 159.5, 0, 180.59645105620496, 89.5, 0, 0, 1]\n    R:",
     "K: [1e-9, 0, 159.5, 0, 1e-9, 89.5, 0, 0, 1]\n    R:", 17, "cameras[1].K",
     "focal lengths must be within [1, 1e6] px"},
    {"t: [-2.8284271247461903, 0.78112095243302271, 4.7885123010878994]",
     "t: [-2.8284271247461903, 0.78112095243302271, 1e300]", 19, "cameras[1].t", "more than 1e6 m"},
    {"distortion: [-0.1, 0.01, 0, 0, 0]", "distortion: [-0.1, 1e30, 0, 0, 0]", 40,
     "cameras[3].distortion", "within [-1000, 1000]"},
    {"max_speed_mps: 1.6", "max_speed_mps: -1", 49, "motion.max_speed_mps", "must be in 0 .. 20"},
    {"min_camera_distance_m: 1.5", "min_camera_dist: 1.5", 49, "motion",
     "unknown key 'min_camera_dist'"},
    // The sim camera's block must be the scene's camera (the renderer draws the
    // scene's, the pipeline projects with the block).
    {"width: 1920", "width: 1280", 8, "cameras[0].width",
     "is 1280 but camera 'cam0' of scene 'scenes/demo_cell.yaml' has 1920"},
    {"height: 1080", "height: 1088", 9, "cameras[0].height", "has 1080"},
    {"959.5, 0, 1083", "959.50001, 0, 1083", 10, "cameras[0].K",
     "differs from camera 'cam0' of scene 'scenes/demo_cell.yaml': K[2] 959.50001 here, 959.5 in "
     "the scene"},
    {"position: [-0.3, -0.3, 3.6]", "position: [-0.3, -0.3, 3.5]", 11, "cameras[0].position",
     "the pose differs from camera 'cam0'"},
    {"look_at: [2, 2, 1]\n", "look_at: [2, 2, 1]\n    distortion: [0.1, 0, 0, 0, 0]\n", 13,
     "cameras[0].distortion", "distortion[0] 0.1 here, 0 in the scene"},
    {"scene: scenes/demo_cell.yaml", "scene: /dev/null", 13, "cameras[0].source.scene",
     "not a regular file (a pipe, socket or device): '/dev/null'"},
    {"scene: scenes/demo_cell.yaml}", "scene: scenes/demo_cell.yaml, <<: {camera: cam1}}", 13,
     "cameras[0].source", "merge keys ('<<') are not read: write the keys out"},
    {"min: [-1, -2, 0]", "min: [-2e6, -2, 0]", 2, "cell.bounds.min", "within +-1e6 m"},
    // The background model takes no more: the config said OK, the start failed.
    {"adapt_rate: 0.05", "adapt_rate: 0.5", 44, "background.adapt_rate", "must be in 0 .. 0.25"},
    // A camera block too broken to have a name: its recording is not searched
    // for a camera '' (a second, misleading error).
    {"4.7885123010878994]\n    source: {type: replay, directory: "
     "../tests/data/small_cell_recording, "
     "camera: cam2,",
     "x]\n    source: {type: replay, directory: ../tests/data/small_cell_recording,", 19,
     "cameras[1].t[2]", "not a number"},
};

TEST(ConfigTest, EachMistakeNamesFileLineAndKey) {
  ASSERT_EQ(ErrorOf(kFull), "");
  for (const Mistake& m : kMistakes) {
    const std::string error = ErrorOf(Replace(kFull, m.from, m.to));
    SCOPED_TRACE(std::string(m.from) + " -> " + m.to);
    EXPECT_EQ(Lines(error).size(), 1u) << error;
    const std::string head = "t.yaml:" + std::to_string(m.line) + ": " +
                             (std::string(m.path).empty() ? "" : std::string(m.path) + ": ");
    EXPECT_EQ(error.rfind(head, 0), 0u) << error;
    EXPECT_NE(error.find(m.problem), std::string::npos) << error;
  }
}

TEST(ConfigTest, AllMistakesOfAFileAreReported) {
  std::string text = kFull;
  for (int i : {0, 2, 6, 12, 16, 22, 29, 34}) {
    text = Replace(text, kMistakes[i].from, kMistakes[i].to);
  }
  const std::vector<std::string> lines = Lines(ErrorOf(text));
  ASSERT_EQ(lines.size(), 8u) << ErrorOf(text);
  int previous_line = 0;
  for (int i : {0, 2, 6, 12, 16, 22, 29, 34}) {
    const Mistake& m = kMistakes[i];
    const std::string head = "t.yaml:" + std::to_string(m.line) + ": " + m.path + ": ";
    bool found = false;
    for (const std::string& line : lines) {
      found = found || (line.rfind(head, 0) == 0 && line.find(m.problem) != std::string::npos);
    }
    EXPECT_TRUE(found) << head << m.problem << "\nin:\n" << ErrorOf(text);
    EXPECT_GE(m.line, previous_line);  // Reported in file order.
    previous_line = m.line;
  }
}

TEST(ConfigTest, MoreCamerasThanOneOctreeFusesAreRefused) {
  auto config = [](int n) {
    std::string text = "cell:\n  bounds: {min: [0, 0, 0], max: [4, 4, 3]}\ncameras:\n";
    for (int i = 0; i < n; ++i) {
      text += "  - {name: c" + std::to_string(i) +
              ", width: 640, height: 480, K: [500, 0, 319.5, 0, 500, 239.5, 0, 0, 1], position: "
              "[0, 0, 3], look_at: [2, 2, 1], source: {type: v4l2, device: /dev/video" +
              std::to_string(i) + "}}\n";
    }
    return text;
  };
  EXPECT_EQ(ErrorOf(config(16)), "");
  const std::string error = ErrorOf(config(17));
  EXPECT_EQ(error.rfind("t.yaml:3: cameras: 17 cameras, at most 16", 0), 0u) << error;
}

TEST(ConfigTest, StructuralMistakes) {
  EXPECT_EQ(ErrorOf(""), "t.yaml: expected a map with the config sections (cell, cameras, ...)");
  EXPECT_NE(ErrorOf("# A comment first.\ncell: {bounds: {min: [0, 0, 0], max: [1, 1, 1]}}\n")
                .find("t.yaml:2: missing section 'cameras'"),
            std::string::npos);
  EXPECT_NE(ErrorOf(Replace(kMinimal, "cameras:\n", "cameras: []\nx:\n"))
                .find("t.yaml:3: cameras: expected a non-empty list"),
            std::string::npos);
  EXPECT_NE(ErrorOf(Replace(kMinimal, "    source: {type: aravis, device: cam-a}\n", ""))
                .find("t.yaml:4: cameras[0]: missing key 'source'"),
            std::string::npos);
  EXPECT_NE(ErrorOf(Replace(kMinimal, "type: aravis, ", ""))
                .find("t.yaml:10: cameras[0].source: "
                      "missing key 'type'"),
            std::string::npos);
  EXPECT_NE(ErrorOf(Replace(kMinimal, "{min: [0, 0, 0], max: [4, 4, 4]}", "[0, 4]"))
                .find("t.yaml:2: cell.bounds: expected a map"),
            std::string::npos);
  EXPECT_NE(ErrorOf(Replace(kMinimal, "    t: [0, 0, 1]\n", ""))
                .find("t.yaml:4: cameras[0]: missing key 't'"),
            std::string::npos);
  EXPECT_NE(ErrorOf("cell: [\n").find("t.yaml:"), std::string::npos);  // Malformed YAML.
}

TEST(ConfigTest, ReferenceDocIsUpToDate) {
  const std::string path = kSourceDir + "/docs/configuration.md";
  EXPECT_TRUE(ReadFile(path) == ConfigReferenceMarkdown())
      << path << " is stale; regenerate it with\n"
      << "  build/daemon/hullguardd --print-config-docs > docs/configuration.md";
}

TEST(ConfigTest, ReferenceDocNamesEveryKey) {
  const std::string md = ConfigReferenceMarkdown();
  for (const char* key :
       {"`octree.depth`", "`timing.deadline_ms`", "`cameras[].source.type`",
        "`cameras[].source.socket_buffer_bytes`", "`cameras[].timeout_ms`", "`cameras[].look_at`",
        "`background.adapt_rate`", "`obstacles[].file`", "`dds.domain_id`", "`logging.journald`"}) {
    EXPECT_NE(md.find(key), std::string::npos) << key;
  }
  EXPECT_NE(md.find("| `octree.depth` | integer | 10 | 3 .. 16 |"), std::string::npos);
  EXPECT_NE(md.find("| `logging.level` | enum | info | trace, debug, info, warn or error |"),
            std::string::npos);
}

// `--version` names the version and the commit built, and exits 0.
TEST(HullguarddTest, VersionNamesTheBuild) {
  const testing::ProcessResult r = testing::RunTool(HG_HULLGUARDD_BIN, "--version");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(r.out.rfind(std::string("hullguardd ") + common::Version() + " (", 0), 0u) << r.out;
  EXPECT_NE(r.out.find(std::string(common::Commit()) + ")"), std::string::npos) << r.out;
  EXPECT_STRNE(common::Version(), "");
  EXPECT_STRNE(common::Commit(), "");
}

TEST(HullguarddTest, CheckConfig) {
  const testing::ProcessResult ok =
      testing::RunTool(HG_HULLGUARDD_BIN, "--check-config " + kConfigDir + "/demo.yaml");
  EXPECT_EQ(ok.code, 0) << ok.err;
  EXPECT_EQ(ok.out, "config OK: 4 cameras (4 sim), depth 7, 30 Hz\n");

  const fs::path bad = fs::temp_directory_path() / "hg_config_test_bad.yaml";
  {
    std::ofstream out(bad);
    out << Replace(Replace(kMinimal, "width: 64", "width: 0"), "max: [4, 4, 4]", "max: [4, 4, -1]");
  }
  const testing::ProcessResult fail =
      testing::RunTool(HG_HULLGUARDD_BIN, "--check-config " + bad.string());
  fs::remove(bad);
  EXPECT_EQ(fail.code, 2);
  EXPECT_EQ(fail.out, "");
  EXPECT_NE(fail.err.find(bad.string() + ":2: cell.bounds.max: "), std::string::npos) << fail.err;
  EXPECT_NE(fail.err.find(bad.string() + ":5: cameras[0].width: "), std::string::npos) << fail.err;

  // The demo runs the pipeline on live simulated cameras and stops cleanly.
  // It publishes over DDS: in a namespace of its own, loopback only.
  const testing::ProcessResult run = testing::RunToolInNetns(
      HG_HULLGUARDD_BIN, "--config " + kConfigDir + "/demo.yaml --duration 2.5");
  if (run.code == testing::kNoNetns) GTEST_SKIP() << "no network namespace: " << run.err;
  EXPECT_EQ(run.code, 0) << run.err;
  EXPECT_NE(run.err.find("hullguardd: cycle "), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("cam3 ok"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("hullguardd: stopped"), std::string::npos) << run.err;

  const testing::ProcessResult docs = testing::RunTool(HG_HULLGUARDD_BIN, "--print-config-docs");
  EXPECT_EQ(docs.code, 0);
  EXPECT_EQ(docs.out, ConfigReferenceMarkdown());
}

// logging.level drops the lines below it: at error, a healthy run prints
// nothing; at info (above) it prints start-up and a health line a second.
TEST(HullguarddTest, LogLevelDropsLinesBelowIt) {
  std::string text = Replace(ReadFile(kConfigDir + "/demo.yaml"), "level: info", "level: error");
  // The copy lives elsewhere: its relative paths made absolute.
  for (const std::string from : {"scene: scenes/", "file: demo_cell/"}) {
    const std::string to =
        from.substr(0, from.find(' ') + 1) + kConfigDir + "/" + from.substr(from.find(' ') + 1);
    for (std::size_t at = text.find(from); at != std::string::npos; at = text.find(from, at)) {
      text.replace(at, from.size(), to);
      at += to.size();
    }
  }
  const fs::path path = fs::temp_directory_path() / "hg_config_test_log_error.yaml";
  {
    std::ofstream out(path);
    out << text;
  }
  // In a namespace of its own: another test's daemon on the same DDS domain
  // would be a second publisher of its topics, an error line.
  const testing::ProcessResult run =
      testing::RunToolInNetns(HG_HULLGUARDD_BIN, "--config " + path.string() + " --duration 1.5");
  fs::remove(path);
  if (run.code == testing::kNoNetns) GTEST_SKIP() << "no network namespace: " << run.err;
  EXPECT_EQ(run.code, 0) << run.err;
  EXPECT_EQ(run.err, "");
}

/// A fresh folder for one test's files, removed with them.
class TempDir {
 public:
  TempDir()
      : path_(fs::temp_directory_path() /
              std::string("hg_config_test_")
                  .append(std::to_string(::getpid()))
                  .append("_")
                  .append(::testing::UnitTest::GetInstance()->current_test_info()->name())) {
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() { fs::remove_all(path_); }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  /// Writes `text` to the file `name` in the folder; returns its path.
  std::string Write(const std::string& name, const std::string& text) const {
    const std::string path = (path_ / name).string();
    std::ofstream(path) << text;
    return path;
  }
  [[nodiscard]] std::string Path(const std::string& name) const { return (path_ / name).string(); }
  [[nodiscard]] std::string str() const { return path_.string(); }

 private:
  fs::path path_;
};

/// A scene with one small camera in the K, R, t form.
const char* const kSmallScene = R"(scene:
  name: small
  bounds: {min: [0, 0, 0], max: [4, 4, 4]}
  rate_hz: 30
cameras:
  - name: a
    width: 64
    height: 48
    K: [50, 0, 31.5, 0, 50, 23.5, 0, 0, 1]
    distortion: [0.01, 0, 0, 0, 0]
    R: [1, 0, 0, 0, 1, 0, 0, 0, 1]
    t: [0, 0, 1]
)";

/// A config rendering camera `a` of kSmallScene (as scene.yaml next to it).
const char* const kSimConfig = R"(cell:
  bounds: {min: [0, 0, 0], max: [4, 4, 4]}
cameras:
  - name: a
    width: 64
    height: 48
    K: [50, 0, 31.5, 0, 50, 23.5, 0, 0, 1]
    distortion: [0.01, 0, 0, 0, 0]
    R: [1, 0, 0, 0, 1, 0, 0, 0, 1]
    t: [0, 0, 1]
    source: {type: sim, scene: scene.yaml}
)";

/// The message of the ConfigError that parsing `text` as c.yaml in `dir` throws ("" if none).
std::string ErrorIn(const TempDir& dir, const std::string& text) {
  try {
    (void)ParseConfig(text, "c.yaml", dir.str());
  } catch (const common::ConfigError& e) {
    return e.what();
  }
  return "";
}

// The scene of a sim source is loaded whole at validation; its own error (its
// file and line) is reported at the config's source.scene key, and
// --check-config fails on it.
TEST(ConfigSceneTest, ASceneThatDoesNotLoadIsReportedAtTheSceneKey) {
  const TempDir dir;
  dir.Write("scene.yaml", Replace(kSmallScene, "rate_hz: 30", "rate_hz: fast"));
  const std::string error = ErrorIn(dir, kSimConfig);
  ASSERT_EQ(Lines(error).size(), 1u) << error;
  EXPECT_EQ(error.rfind("c.yaml:11: cameras[0].source.scene: bad scene: " + dir.Path("scene.yaml") +
                            ":4: scene.rate_hz: ",
                        0),
            0u)
      << error;

  // Two cameras of one bad scene: one load, one error, at the first reference.
  const std::string entry =
      std::string(kSimConfig).substr(std::string(kSimConfig).find("  - name: a"));
  const std::string two = kSimConfig + Replace(entry, "name: a", "name: b");
  EXPECT_EQ(Lines(ErrorIn(dir, two)).size(), 1u) << ErrorIn(dir, two);

  // Also when the black box sizes its rings from the scene's rate (that read
  // used to throw a yaml-cpp conversion error out of the loader: an abort).
  const std::string config = dir.Write(
      "c.yaml", std::string(kSimConfig) + "blackbox: {seconds: 1, dir: " + dir.Path("box") +
                    ", max_memory_mb: 64}\n");
  for (const char* flag : {"--check-config ", "--config "}) {
    const testing::ProcessResult r = testing::RunTool(HG_HULLGUARDD_BIN, flag + config);
    EXPECT_EQ(r.code, 2) << flag << r.err;
    EXPECT_EQ(r.out, "");
    EXPECT_EQ(Lines(r.err).size(), 1u) << r.err;
    EXPECT_NE(r.err.find(config + ":11: cameras[0].source.scene: bad scene: "), std::string::npos)
        << r.err;
  }
}

// A replay source's recording is opened at validation: a recording without
// the camera, with a broken manifest or without the camera's frames is
// reported at the source's `directory` key (with the recording's own file and
// line), and --check-config exits 2; the shipped test recording passes.
TEST(ConfigReplayTest, TheRecordingIsOpenedAtValidation) {
  const TempDir dir;
  const std::string data = kSourceDir + "/tests/data";
  fs::copy(data + "/small_cell_recording", dir.Path("rec"), fs::copy_options::recursive);
  // Every reference to the recording (the cameras' and the obstacle mesh's) to the copy.
  std::string config = ReadFile(data + "/small_cell_config.yaml");
  for (std::size_t at; (at = config.find("small_cell_recording")) != std::string::npos;) {
    config.replace(at, std::string("small_cell_recording").size(), "rec");
  }
  EXPECT_EQ(ErrorIn(dir, config), "");

  // The first camera asks for one the recording lacks.
  const std::string no_camera =
      Replace(config, "directory: rec}}", "directory: rec, camera: camX}}");
  std::string error = ErrorIn(dir, no_camera);
  ASSERT_EQ(Lines(error).size(), 1u) << error;
  EXPECT_NE(error.find("c.yaml:10: cameras[0].source.directory: bad recording: "),
            std::string::npos)
      << error;
  EXPECT_NE(error.find("manifest.yaml:10: cameras: the recording has no camera 'camX'"),
            std::string::npos)
      << error;

  // The first camera replays what another camera of the recording saw: its
  // silhouettes would be carved with the wrong pose (people certified free).
  const std::string swapped = Replace(config, "directory: rec}}", "directory: rec, camera: cam1}}");
  error = ErrorIn(dir, swapped);
  ASSERT_EQ(Lines(error).size(), 1u) << error;
  EXPECT_NE(error.find("c.yaml:8: cameras[0].position: the pose differs from camera 'cam1' of "
                       "recording '"),
            std::string::npos)
      << error;
  EXPECT_NE(error.find(" in the recording"), std::string::npos) << error;
  // Another focal length.
  error = ErrorIn(dir, Replace(config, "K: &k [180.59645105620495,", "K: &k [181,"));
  EXPECT_NE(error.find("c.yaml:9: cameras[0].K: differs from camera 'cam0' of recording '"),
            std::string::npos)
      << error;

  // A loop must keep two frames or more; playing from memory is just a flag.
  EXPECT_EQ(ErrorIn(dir, Replace(config, "directory: rec}}",
                                 "directory: rec, loop: true, preload: true}}")),
            "");
  // Unless the frames need more than half the machine's memory: a million
  // frames of 320 x 180 are 55 GiB.
  {
    const std::string manifest = dir.Path("rec/manifest.yaml");
    const std::string kept = ReadFile(manifest);
    std::ofstream(manifest) << Replace(kept, "frames: 12", "frames: 1000000");
    error = ErrorIn(dir, Replace(config, "directory: rec}}", "directory: rec, preload: true}}"));
    const double memory_mib = static_cast<double>(sysconf(_SC_PHYS_PAGES)) *
                              static_cast<double>(sysconf(_SC_PAGE_SIZE)) / (1024.0 * 1024.0);
    if (1e6 * 320 * 180 / (1024.0 * 1024.0) > 0.5 * memory_mib) {
      EXPECT_NE(error.find("c.yaml:10: cameras[0].source.preload: 1000000 frames of camera 'cam0' "
                           "need 54932 MiB preloaded, more than half of this machine's memory ("),
                std::string::npos)
          << error;
    } else {
      EXPECT_EQ(error, "");
    }
    std::ofstream(manifest) << kept;
  }
  const std::string late_loop =
      Replace(config, "directory: rec}}", "directory: rec, loop: true, loop_start_s: 1000}}");
  error = ErrorIn(dir, late_loop);
  ASSERT_EQ(Lines(error).size(), 1u) << error;
  EXPECT_NE(error.find("c.yaml:10: cameras[0].source.directory: loop_start_s 1000 leaves 0 "
                       "frame(s) of camera 'cam0' to loop, at least 2 needed"),
            std::string::npos)
      << error;

  // A camera's frames are gone.
  fs::remove_all(dir.Path("rec/masks/cam1"));
  error = ErrorIn(dir, config);
  ASSERT_EQ(Lines(error).size(), 1u) << error;
  EXPECT_NE(error.find("c.yaml:12: cameras[1].source.directory: first frame of camera 'cam1' "
                       "cannot be read: "),
            std::string::npos)
      << error;

  // Without the calibration the frames were taken with, nothing can be checked.
  fs::rename(dir.Path("rec/cameras.yaml"), dir.Path("rec/cameras.yaml.away"));
  error = ErrorIn(dir, config);
  EXPECT_NE(error.find("c.yaml:10: cameras[0].source.directory: recording '"), std::string::npos)
      << error;
  EXPECT_NE(error.find("' has no cameras.yaml"), std::string::npos) << error;
  fs::rename(dir.Path("rec/cameras.yaml.away"), dir.Path("rec/cameras.yaml"));

  // The manifest does not parse: every camera says so, and the daemon exits 2.
  std::ofstream(dir.Path("rec/manifest.yaml")) << "garbage: [\n";
  error = ErrorIn(dir, config);
  EXPECT_EQ(Lines(error).size(), 3u) << error;
  EXPECT_NE(error.find("manifest.yaml:2: malformed YAML"), std::string::npos) << error;
  const std::string path = dir.Write("c.yaml", config);
  const testing::ProcessResult r = testing::RunTool(HG_HULLGUARDD_BIN, "--check-config " + path);
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_EQ(Lines(r.err).size(), 3u) << r.err;
}

// A scene that breaks after validation: what the daemon reads from it at
// start-up fails with a ConfigError (exit 2), not a yaml-cpp exception.
TEST(ConfigSceneTest, ASceneBrokenAfterLoadingFailsWithAConfigError) {
  const TempDir dir;
  dir.Write("scene.yaml", kSmallScene);
  const Config config = ParseConfig(kSimConfig, "c.yaml", dir.str());
  EXPECT_EQ(BlackBoxCameras(config).at(0).rate_hz, 30.0);
  dir.Write("scene.yaml", Replace(kSmallScene, "rate_hz: 30", "rate_hz: fast"));
  EXPECT_THROW((void)BlackBoxCameras(config), common::ConfigError);
  EXPECT_THROW((void)MakeCameras(config, capture::SimClock::Now()), common::ConfigError);
}

// A sim camera that delivers raw Bayer mosaics is made as one (its frames are
// not grey: the pipeline leaves the texture test off for it); one of masks or
// RGB is not.
TEST(ConfigSceneTest, ASimCameraOfBayerMosaicsIsMadeAsOne) {
  const TempDir dir;
  dir.Write("scene.yaml", kSmallScene);
  for (const auto& [source, mosaic] :
       std::vector<std::pair<std::string, bool>>{{"scene: scene.yaml, bayer: true", true},
                                                 {"scene: scene.yaml, colour: true", false},
                                                 {"scene: scene.yaml", false}}) {
    const Config config =
        ParseConfig(Replace(kSimConfig, "scene: scene.yaml", source), "c.yaml", dir.str());
    const std::vector<pipeline::PipelineCamera> cameras =
        MakeCameras(config, capture::SimClock::Now());
    ASSERT_EQ(cameras.size(), 1U);
    EXPECT_EQ(cameras[0].bayer_mosaic, mosaic) << source;
  }
}

// The camera block of a sim camera must be the scene's camera of that name:
// the size exactly, K, distortion, R and t to 1e-9 relative, in any form.
TEST(ConfigSceneTest, TheCameraBlockMustBeTheScenesCamera) {
  const TempDir dir;
  dir.Write("scene.yaml", kSmallScene);
  ASSERT_EQ(ErrorIn(dir, kSimConfig), "");
  // The same camera as P = K [R | t].
  const std::string as_p = Replace(kSimConfig,
                                   "    K: [50, 0, 31.5, 0, 50, 23.5, 0, 0, 1]\n"
                                   "    distortion: [0.01, 0, 0, 0, 0]\n"
                                   "    R: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n"
                                   "    t: [0, 0, 1]\n",
                                   "    P: [50, 0, 31.5, 31.5, 0, 50, 23.5, 23.5, 0, 0, 1, 1]\n"
                                   "    distortion: [0.01, 0, 0, 0, 0]\n");
  EXPECT_EQ(ErrorIn(dir, as_p), "");

  const Mistake mistakes[] = {
      {"width: 64", "width: 66", 5, "cameras[0].width",
       "is 66 but camera 'a' of scene 'scene.yaml' has 64: every frame would be the wrong size"},
      {"height: 48", "height: 47", 6, "cameras[0].height", "is 47 but"},
      {"50, 0, 31.5,", "50, 0, 31.50001,", 7, "cameras[0].K",
       "differs from camera 'a' of scene 'scene.yaml': K[2] 31.50001 here, 31.5 in the scene"},
      {"distortion: [0.01, 0", "distortion: [0.02, 0", 8, "cameras[0].distortion",
       "distortion[0] 0.02 here, 0.01 in the scene"},
      {"    distortion: [0.01, 0, 0, 0, 0]\n", "", 4, "cameras[0].distortion",
       "distortion[0] 0 here, 0.01 in the scene"},
      {"R: [1, 0, 0, 0, 1, 0, 0, 0, 1]", "R: [0, -1, 0, 1, 0, 0, 0, 0, 1]", 9, "cameras[0].R",
       "R[0] 0 here, 1 in the scene"},
      {"t: [0, 0, 1]", "t: [0, 0, 1.000001]", 10, "cameras[0].t",
       "t[2] 1.000001 here, 1 in the scene"},
      {"name: a", "name: b", 11, "cameras[0].source.camera",
       "scene 'scene.yaml' has no camera 'b' (it has a)"},
  };
  for (const Mistake& m : mistakes) {
    const std::string error = ErrorIn(dir, Replace(kSimConfig, m.from, m.to));
    SCOPED_TRACE(std::string(m.from) + " -> " + m.to);
    EXPECT_EQ(Lines(error).size(), 1u) << error;
    EXPECT_EQ(error.rfind("c.yaml:" + std::to_string(m.line) + ": " + m.path + ": ", 0), 0u)
        << error;
    EXPECT_NE(error.find(m.problem), std::string::npos) << error;
  }
  // Within the tolerance: the same camera.
  EXPECT_EQ(ErrorIn(dir, Replace(kSimConfig, "t: [0, 0, 1]", "t: [0, 0, 1.0000000000001]")), "");
  // K, R and t from P: a difference is reported at P.
  const std::string error = ErrorIn(dir, Replace(as_p, "23.5, 0, 0, 1, 1]", "23.5, 0, 0, 1, 2]"));
  EXPECT_EQ(Lines(error).size(), 1u) << error;
  EXPECT_EQ(error.rfind("c.yaml:7: cameras[0].P: the pose differs from camera 'a'", 0), 0u)
      << error;

  // The daemon refuses it too, before any camera is opened.
  const std::string config = dir.Write("c.yaml", Replace(kSimConfig, "width: 64", "width: 66"));
  const testing::ProcessResult r = testing::RunTool(HG_HULLGUARDD_BIN, "--config " + config);
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find(config + ":5: cameras[0].width: is 66 but"), std::string::npos) << r.err;
}

// Obstacle meshes are loaded at validation: a file that is no mesh, or a
// malformed one, is reported at the obstacle's key.
TEST(ConfigTest, ObstacleMeshesAreLoaded) {
  const TempDir dir;
  const struct {
    const char* name;
    const char* text;
    const char* problem;
  } meshes[] = {
      {"garbage.obj", "this is no mesh\nat all\n", "has no triangles"},
      {"vertices.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n", "has no triangles"},
      {"number.obj", "v 0 0 0\nv 1 x 0\nv 0 1 0\nf 1 2 3\n", "bad mesh: "},
      {"index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "bad mesh: "},
      {"garbage.stl", "solid x\n  facet nonsense\n", "bad mesh: "},
  };
  for (const auto& mesh : meshes) {
    SCOPED_TRACE(mesh.name);
    const std::string path = dir.Write(mesh.name, mesh.text);
    const std::string error = ErrorOf(Replace(kFull, "demo_cell/obstacles.obj", path));
    EXPECT_EQ(Lines(error).size(), 1u) << error;
    EXPECT_EQ(error.rfind("t.yaml:46: obstacles[0].file: ", 0), 0u) << error;
    EXPECT_NE(error.find(mesh.problem), std::string::npos) << error;
  }
  const std::string path = dir.Write("ok.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  EXPECT_EQ(ErrorOf(Replace(kFull, "demo_cell/obstacles.obj", path)), "");
}

// Every problem of a camera block is reported, not only the first; the
// stand-alone parser (`hullguard carve --cameras`) still stops at the first.
TEST(ConfigTest, EveryProblemOfACameraBlockIsReported) {
  const std::string text =
      Replace(Replace(Replace(kMinimal, "height: 48", "height: 0"), "0, 0, 1]", "0, 0, 1, 7]"),
              "R: [1, 0, 0, 0, 1, 0, 0, 0, 1]", "R: [1, 0, 0, 0, 1, 0, 0, 0, 2]");
  const std::vector<std::string> lines = Lines(ErrorOf(text));
  ASSERT_EQ(lines.size(), 3u) << ErrorOf(text);
  EXPECT_EQ(lines[0].rfind("t.yaml:6: cameras[0].height: expected a positive integer", 0), 0u);
  EXPECT_EQ(lines[1], "t.yaml:7: cameras[0].K: expected 9 numbers, got 10");
  EXPECT_EQ(lines[2].rfind("t.yaml:8: cameras[0].R: R is not a rotation", 0), 0u) << lines[2];

  const YAML::Node block = YAML::Load(
      "{name: a, width: 64, height: 0, K: [50, 0, 31.5, 0, 50, 23.5, 0, 0, 1, 7], "
      "R: [1, 0, 0, 0, 1, 0, 0, 0, 2], t: [0, 0, 1]}");
  try {
    (void)geometry::ParseCamera(block, "cams.yaml");
    ADD_FAILURE() << "no error";
  } catch (const common::ConfigError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("cams.yaml:1: height: expected a positive integer", 0),
              0u)
        << e.what();
  }
  std::vector<std::string> errors;
  EXPECT_FALSE(geometry::ParseCameraReportingAll(block, "cams.yaml", &errors).has_value());
  EXPECT_EQ(errors.size(), 3u);
}

// MakeCameras reads every scene and recording before it makes any source
// (making a V4L2 source opens its device, an Aravis one starts connecting):
// a bad recording after a V4L2 camera fails without touching the device.
TEST(ConfigTest, CamerasAreMadeOnlyOnceEverythingHasLoaded) {
  const TempDir dir;
  Config config;
  config.source_file = "c.yaml";
  CameraConfig usb;
  usb.model.name = "usb";
  usb.model.width = 64;
  usb.model.height = 48;
  V4l2SourceConfig device;
  device.device = dir.Path("no_such_video");
  usb.source = device;
  CameraConfig rec = usb;
  rec.model.name = "rec";
  ReplaySourceConfig recording;
  recording.directory = dir.str();
  recording.camera = "rec";
  rec.source = recording;
  config.cameras = {usb, rec};
  // Made in config order, the V4L2 source would fail first, as a device
  // that cannot be opened (std::runtime_error), not a ConfigError.
  EXPECT_THROW((void)MakeCameras(config, capture::SimClock::Now()), common::ConfigError);
}

// Looping replay cameras share one loop period, the longest of theirs: a
// camera whose recording lacks its last frame (5 frames against 4) plays
// each repetition at the same times as the other, not one frame interval
// earlier per repetition (the drift put a person's silhouettes apart).
TEST(ConfigTest, LoopingReplayCamerasShareTheLongestLoopPeriod) {
  const TempDir dir;
  std::vector<geometry::CameraModel> models(2);
  for (int c = 0; c < 2; ++c) {
    models[c].name = c == 0 ? "a" : "b";
    models[c].width = 8;
    models[c].height = 6;
    models[c].K << 10, 0, 3.5, 0, 10, 2.5, 0, 0, 1;
    models[c].t_CW = Eigen::Vector3d(0, 0, 3);
  }
  {
    capture::RecordingWriter writer(dir.str(), models, "test");
    for (std::uint64_t i = 0; i < 5; ++i) {
      for (int c = 0; c < 2; ++c) {
        if (c == 1 && i == 4) continue;  // b's last frame is missing.
        capture::Frame f;
        f.kind = capture::FrameKind::kMono;
        f.grey = common::ImageU8(8, 6, 0);
        f.stamp_ns = 9'000'000'000 + static_cast<std::int64_t>(i) * 50'000'000;
        f.index = i;
        ASSERT_TRUE(writer.Write(c, i, f));
      }
    }
  }
  Config config;
  config.source_file = "c.yaml";
  for (int c = 0; c < 2; ++c) {
    CameraConfig camera;
    camera.model = models[c];
    ReplaySourceConfig replay;
    replay.directory = dir.str();
    replay.camera = models[c].name;
    replay.loop = true;
    replay.loop_start_s = 0.1;
    camera.source = replay;
    config.cameras.push_back(camera);
  }
  const capture::SimClock clock = capture::SimClock::Now();
  std::vector<pipeline::PipelineCamera> cameras = MakeCameras(config, clock);
  ASSERT_EQ(cameras.size(), 2u);
  // Camera b, frames of its second and third repetitions: the recording's
  // time plus whole periods of a's length (150 ms from frame 2 to a's 5th
  // frame and one interval on), not b's own (100 ms).
  int checked = 0;
  capture::Frame f;
  for (const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(900);
       std::chrono::steady_clock::now() < until;) {
    if (!cameras[1].source->Next(&f, std::chrono::milliseconds(50)) || f.index < 4) continue;
    EXPECT_EQ(f.stamp_ns, clock.epoch_ns + static_cast<std::int64_t>(f.index % 4) * 50'000'000 +
                              static_cast<std::int64_t>(f.index / 4) * 150'000'000)
        << "frame " << f.index;
    ++checked;
  }
  EXPECT_GE(checked, 3);
}

// A command line that cannot be parsed, like a config that cannot be read,
// exits with 2 (which systemd does not restart) and says why in one line.
TEST(HullguarddTest, CommandLineErrorsExitWithTwo) {
  const testing::ProcessResult missing =
      testing::RunTool(HG_HULLGUARDD_BIN, "--config /nonexistent/hullguard.yaml");
  EXPECT_EQ(missing.code, 2);
  EXPECT_EQ(missing.err, "/nonexistent/hullguard.yaml: cannot open config: no such file\n");
  const testing::ProcessResult check =
      testing::RunTool(HG_HULLGUARDD_BIN, "--check-config /nonexistent/hullguard.yaml");
  EXPECT_EQ(check.code, 2);
  EXPECT_EQ(check.err, "/nonexistent/hullguard.yaml: cannot open config: no such file\n");
  const testing::ProcessResult folder = testing::RunTool(HG_HULLGUARDD_BIN, "--config /");
  EXPECT_EQ(folder.code, 2);
  EXPECT_EQ(Lines(folder.err).size(), 1u) << folder.err;
  for (const char* args :
       {"--bogus", "--config", "--duration -1 --config x.yaml", "--duration soon --config x.yaml",
        "--config a.yaml --check-config b.yaml", "stray"}) {
    const testing::ProcessResult r = testing::RunTool(HG_HULLGUARDD_BIN, args);
    EXPECT_EQ(r.code, 2) << args << ": " << r.err;
    EXPECT_EQ(r.out, "") << args;
    EXPECT_EQ(Lines(r.err).size(), 1u) << args << ": " << r.err;
    EXPECT_EQ(r.err.rfind("hullguardd: ", 0), 0u) << args << ": " << r.err;
  }
  const testing::ProcessResult help = testing::RunTool(HG_HULLGUARDD_BIN, "--help");
  EXPECT_EQ(help.code, 0);
  EXPECT_NE(help.out.find("--check-config"), std::string::npos) << help.out;
}

TEST(ConfigTrackingTest, DefaultsAreTheTrackersOwn) {
  const Config c = Parse(kMinimal);
  EXPECT_TRUE(c.tracking.enabled);
  EXPECT_EQ(c.tracking.voxel_m, 0.05);
  EXPECT_EQ(c.tracking.particles, 300);
  EXPECT_EQ(c.tracking.max_tracks, 16);
  EXPECT_EQ(c.tracking.rho_unknown, 1.0);
  EXPECT_EQ(c.tracking.sigma_occluded, 0.1);
  EXPECT_EQ(c.tracking.tau_known, -5.0);
  EXPECT_EQ(c.tracking.epsilon_free, -0.1);
  EXPECT_EQ(c.tracking.below_floor_weight, -0.1);
  EXPECT_EQ(c.tracking.collision_radius_m, 0.2);
  EXPECT_EQ(c.tracking.birth_min_volume_m3, 0.06);
  EXPECT_EQ(c.tracking.death_timeout_s, 1.0);
  EXPECT_EQ(c.tracking.occluded_death_timeout_s, 30.0);
  EXPECT_EQ(c.tracking.reacquire_radius_m, 0.5);
  EXPECT_EQ(c.tracking.reacquire_speed_mps, 1.5);
  // Every default maps onto the tracker's own default (but the first step,
  // which is one fusion period).
  const tracking::TrackerOptions o = MakeTrackerOptions(c.tracking, 30.0);
  const tracking::TrackerOptions d;
  EXPECT_EQ(o.voxel_m, d.voxel_m);
  EXPECT_EQ(o.filter.num_particles, d.filter.num_particles);
  EXPECT_EQ(o.max_tracks, d.max_tracks);
  EXPECT_EQ(o.likelihood.unknown, d.likelihood.unknown);
  EXPECT_EQ(o.likelihood.occluded, d.likelihood.occluded);
  EXPECT_EQ(o.likelihood.known, d.likelihood.known);
  EXPECT_EQ(o.likelihood.free, d.likelihood.free);
  EXPECT_EQ(o.likelihood.below_floor, d.likelihood.below_floor);
  EXPECT_EQ(o.filter.collision_radius_m, d.filter.collision_radius_m);
  EXPECT_EQ(o.filter.support_reach_m, d.filter.support_reach_m);
  EXPECT_EQ(o.filter.posture_noise_m_per_sqrt_s, d.filter.posture_noise_m_per_sqrt_s);
  EXPECT_EQ(o.birth_min_volume_m3, d.birth_min_volume_m3);
  EXPECT_EQ(o.death_timeout_s, d.death_timeout_s);
  EXPECT_EQ(o.occluded_death_timeout_s, d.occluded_death_timeout_s);
  EXPECT_EQ(o.reacquire_radius_m, d.reacquire_radius_m);
  EXPECT_EQ(o.reacquire_speed_mps, d.reacquire_speed_mps);
  EXPECT_DOUBLE_EQ(o.first_dt_s, 1.0 / 30.0);
  EXPECT_TRUE(tracking::CheckOptions(o).empty());
}

/// kMinimal with a tracking section setting every key; its keys are on lines 12 to 28.
const std::string kTracking = std::string(kMinimal) + R"(tracking:
  enabled: false
  voxel_m: 0.05
  particles: 120
  max_tracks: 4
  rho_unknown: 2
  sigma_occluded: 0.2
  tau_known: -4
  epsilon_free: -0.2
  below_floor_weight: 0
  collision_radius_m: 0.15
  birth_min_volume_m3: 0.05
  death_timeout_s: 2
  occluded_death_timeout_s: 20
  reacquire_radius_m: 0.7
  reacquire_speed_mps: 1
  support_reach_m: 0.3
  posture_noise_m_per_sqrt_s: 0.2
)";

TEST(ConfigTrackingTest, EveryKeyReadsBackAndMaps) {
  const Config c = Parse(kTracking);
  EXPECT_FALSE(c.tracking.enabled);
  const tracking::TrackerOptions o = MakeTrackerOptions(c.tracking, 20.0);
  EXPECT_EQ(o.voxel_m, 0.05);
  EXPECT_EQ(o.filter.num_particles, 120);
  EXPECT_EQ(o.max_tracks, 4);
  EXPECT_EQ(o.likelihood.unknown, 2.0);
  EXPECT_EQ(o.likelihood.occluded, 0.2);
  EXPECT_EQ(o.likelihood.known, -4.0);
  EXPECT_EQ(o.likelihood.free, -0.2);
  EXPECT_EQ(o.likelihood.below_floor, 0.0);
  EXPECT_EQ(o.filter.collision_radius_m, 0.15);
  EXPECT_EQ(o.birth_min_volume_m3, 0.05);
  EXPECT_EQ(o.death_timeout_s, 2.0);
  EXPECT_EQ(o.occluded_death_timeout_s, 20.0);
  EXPECT_EQ(o.reacquire_radius_m, 0.7);
  EXPECT_EQ(o.reacquire_speed_mps, 1.0);
  EXPECT_EQ(o.filter.support_reach_m, 0.3);
  EXPECT_EQ(o.filter.posture_noise_m_per_sqrt_s, 0.2);
  EXPECT_DOUBLE_EQ(o.first_dt_s, 0.05);
}

TEST(ConfigTrackingTest, EachMistakeNamesFileLineAndKey) {
  ASSERT_EQ(ErrorOf(kTracking), "");
  const Mistake mistakes[] = {
      {"enabled: false", "enabled: sometimes", 12, "tracking.enabled", "true or false"},
      {"voxel_m: 0.05", "voxel_m: 0", 13, "tracking.voxel_m", "must be in 0.01 .. 0.25"},
      {"voxel_m: 0.05", "voxel_m: 0.5", 13, "tracking.voxel_m", "must be in 0.01 .. 0.25"},
      {"particles: 120", "particles: 0", 14, "tracking.particles", "must be in 10 .. 100000"},
      {"particles: 120", "particles: 5", 14, "tracking.particles", "must be in 10 .. 100000"},
      {"particles: 120", "particles: many", 14, "tracking.particles", "expected an integer"},
      {"max_tracks: 4", "max_tracks: 2000", 15, "tracking.max_tracks", "must be in 1 .. 1024"},
      {"rho_unknown: 2", "rho_unknown: 0", 16, "tracking.rho_unknown", "must be > 0"},
      {"tau_known: -4", "tau_known: big", 18, "tracking.tau_known", "expected a number"},
      // The tracker's own check (tracking::CheckOptions), at the line of the key.
      {"collision_radius_m: 0.15", "collision_radius_m: 0.3", 21, "tracking.collision_radius_m",
       "not larger than any half-axis"},
      {"death_timeout_s: 2", "death_timeout_s: 0", 23, "tracking.death_timeout_s", "must be > 0"},
      {"reacquire_speed_mps: 1", "reacquire_speed_mps: -1", 26, "tracking.reacquire_speed_mps",
       "must be >= 0"},
      {"reacquire_speed_mps: 1", "reacquire_speed: 1", 26, "tracking",
       "unknown key 'reacquire_speed'"},
      {"posture_noise_m_per_sqrt_s: 0.2", "posture_noise_m_per_sqrt_s: -0.1", 28,
       "tracking.posture_noise_m_per_sqrt_s", "must be >= 0"},
  };
  for (const Mistake& m : mistakes) {
    const std::string error = ErrorOf(Replace(kTracking, m.from, m.to));
    SCOPED_TRACE(std::string(m.from) + " -> " + m.to);
    EXPECT_EQ(Lines(error).size(), 1u) << error;
    const std::string head = "t.yaml:" + std::to_string(m.line) + ": " + m.path + ": ";
    EXPECT_EQ(error.rfind(head, 0), 0u) << error;
    EXPECT_NE(error.find(m.problem), std::string::npos) << error;
  }
}

TEST(ConfigTrackingTest, GridTooLargeForTheCellIsRejectedWhenEnabled) {
  // 40 x 40 x 4 m at 2 cm: 800 million voxels.
  const std::string big = Replace(Replace(kTracking, "max: [4, 4, 4]", "max: [40, 40, 4]"),
                                  "voxel_m: 0.05", "voxel_m: 0.02");
  EXPECT_EQ(ErrorOf(big), "");  // Tracking is off: no grid is built.
  const std::string error = ErrorOf(Replace(big, "enabled: false", "enabled: true"));
  EXPECT_EQ(Lines(error).size(), 1u) << error;
  EXPECT_EQ(error.rfind("t.yaml:13: tracking.voxel_m: ", 0), 0u) << error;
  EXPECT_NE(error.find("at most 5e+07"), std::string::npos) << error;
  // Without a tracking section the defaults (4 cm) are checked; no line to name.
  const std::string default_error =
      ErrorOf(Replace(kMinimal, "max: [4, 4, 4]", "max: [100, 100, 10]"));
  EXPECT_EQ(default_error.rfind("t.yaml: tracking.voxel_m: ", 0), 0u) << default_error;
}

TEST(ConfigTrackingTest, ReferenceDocListsTheSection) {
  const std::string md = ConfigReferenceMarkdown();
  EXPECT_NE(md.find("| `tracking` | map |"), std::string::npos);
  EXPECT_NE(md.find("| `tracking.enabled` | bool | true | - |"), std::string::npos);
  EXPECT_NE(md.find("| `tracking.voxel_m` | number | 0.05 | 0.01 .. 0.25 |"), std::string::npos);
  EXPECT_NE(md.find("| `tracking.particles` | integer | 300 | 10 .. 100000 |"), std::string::npos);
  for (const char* key :
       {"`tracking.rho_unknown`", "`tracking.sigma_occluded`", "`tracking.tau_known`",
        "`tracking.epsilon_free`", "`tracking.collision_radius_m`", "`tracking.death_timeout_s`"}) {
    EXPECT_NE(md.find(key), std::string::npos) << key;
  }
}

// A knowledge filter that could drop a small child is accepted (it is the
// integrator's choice) but said, with its line.
TEST(ConfigTest, AKnowledgeFilterAboveAChildsVolumeIsNoticed) {
  const Config c = Parse(Replace(kFull, "knowledge_filter_m3: 0.002", "knowledge_filter_m3: 0.05"));
  ASSERT_EQ(c.notices.size(), 3u);  // And the shadows and motion.min_camera_distance_m.
  EXPECT_NE(c.notices[0].find("t.yaml:3: octree.knowledge_filter_m3: 0.05 m^3 is more than a small "
                              "child's volume (about 0.02 m^3)"),
            std::string::npos)
      << c.notices[0];
  EXPECT_EQ(Parse(Replace(kFull, "knowledge_filter_m3: 0.002", "knowledge_filter_m3: 0.02"))
                .notices.size(),
            2u);
}

// A camera inside an obstacle mesh (its mount modelled with it) runs failed
// (blocked), seeing nothing: --check-config says so, with the camera's line,
// before a deployment.
TEST(ConfigTest, ACameraInsideAnObstacleIsNoticed) {
  const TempDir dir;
  // A 10 cm cube around camera a's centre (0, 0, -1); camera b is clear of it.
  const std::string mesh = dir.Write("mount.obj",
                                     "v -0.05 -0.05 -1.05\nv 0.05 -0.05 -1.05\nv 0.05 0.05 -1.05\n"
                                     "v -0.05 0.05 -1.05\nv -0.05 -0.05 -0.95\nv 0.05 -0.05 -0.95\n"
                                     "v 0.05 0.05 -0.95\nv -0.05 0.05 -0.95\n"
                                     "f 1 2 3\nf 1 3 4\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\n"
                                     "f 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n");
  // Camera b: a's entry 2 m further back.
  const std::string a_entry =
      std::string(kMinimal).substr(std::string(kMinimal).find("  - name: a"));
  const std::string two_cameras =
      std::string(kMinimal) +
      Replace(Replace(Replace(a_entry, "name: a", "name: b"), "t: [0, 0, 1]", "t: [0, 0, 3]"),
              "cam-a", "cam-b");
  EXPECT_TRUE(BlockedCameraNotices(Parse(two_cameras)).empty());
  const std::vector<std::string> notices =
      BlockedCameraNotices(Parse(two_cameras + "obstacles:\n  - file: " + mesh + "\n"));
  ASSERT_EQ(notices.size(), 1u);
  EXPECT_NE(notices[0].find("t.yaml:4: cameras[0]: camera 'a' is blocked: an obstacle reaches "
                            "within 1 mm in front of its centre or covers its whole view within "
                            "10 cm"),
            std::string::npos)
      << notices[0];
  // Moved out of the mesh, the camera is clear.
  EXPECT_TRUE(BlockedCameraNotices(Parse(Replace(two_cameras, "t: [0, 0, 1]", "t: [0, 0, 1.2]") +
                                         "obstacles:\n  - file: " + mesh + "\n"))
                  .empty());
  // hullguardd --check-config says it, and passes the config.
  const std::string config_path =
      dir.Write("blocked.yaml", Replace(two_cameras, "cell:", "dds: {enabled: false}\ncell:") +
                                    "obstacles:\n  - file: " + mesh + "\n");
  const testing::ProcessResult check =
      testing::RunTool(HG_HULLGUARDD_BIN, "--check-config " + config_path);
  EXPECT_EQ(check.code, 0) << check.err;
  EXPECT_NE(check.err.find("blocked.yaml:5: cameras[0]: camera 'a' is blocked"), std::string::npos)
      << check.err;
}

}  // namespace
}  // namespace hg::app
