// End-to-end tests of `hullguard synth` and `hullguard bench`: a real scene
// file, the real binary, the files it writes read back.
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <variant>

#include <gtest/gtest.h>

#include "geometry/camera_yaml.h"
#include "geometry/mesh.h"
#include "silhouette/mask_io.h"
#include "sim/ground_truth.h"
#include "sim/simulator.h"
#include "support/run_tool.h"

namespace hg {
namespace {

namespace fs = std::filesystem;

// Two small cameras (one with lens distortion), a table, one walking person
// and one who crouches.
constexpr char kScene[] =
    R"(scene: {name: tiny, bounds: {min: [0, 0, 0], max: [3, 3, 2.5]}, rate_hz: 10}
cameras:
  - {name: a, width: 320, height: 240, K: [240, 0, 159.5, 0, 240, 119.5, 0, 0, 1],
     distortion: [-0.08, 0.01, 0, 0, 0], position: [-0.4, -0.4, 2.4], look_at: [1.5, 1.5, 0.8]}
  - {name: b, width: 320, height: 240, K: [240, 0, 159.5, 0, 240, 119.5, 0, 0, 1],
     position: [3.4, 3.4, 2.4], look_at: [1.5, 1.5, 0.8]}
capture_offsets_ms: {b: 5}
obstacles:
  - {name: table, box: {min: [2.0, 0.3, 0.70], max: [2.8, 1.0, 0.75]}}
people:
  - name: walker
    start: [0.8, 0.8]
    script:
      - walk: {path: [[2.0, 2.2]], speed: 1.0}
  - name: croucher
    start: [0.7, 2.3]
    script:
      - crouch: {duration: 5}
)";

class SynthCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           std::string("hg_synth_")
               .append(std::to_string(::getpid()))
               .append("_")
               .append(::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
    std::ofstream(Path("tiny.yaml")) << kScene;
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  static testing::ProcessResult Hullguard(const std::string& args) {
    return testing::RunTool(HG_HULLGUARD_BIN, args);
  }
  fs::path dir_;
};

TEST_F(SynthCliTest, WritesMasksColourCamerasAndGroundTruthThatMatchTheLibrary) {
  const auto r = Hullguard("synth --scene " + Path("tiny.yaml") + " --frames 4 --start 0.5 --out " +
                           Path("out") + " --colour --masks");
  ASSERT_EQ(r.code, 0) << r.err;
  const fs::path out = dir_ / "out";
  for (const char* f :
       {"manifest.yaml", "scene.yaml", "cameras.yaml", "obstacles.obj", "ground_truth.yaml"}) {
    EXPECT_TRUE(fs::exists(out / f)) << f;
  }
  const sim::Scene scene = sim::LoadScene(Path("tiny.yaml"));
  const auto cameras = geometry::LoadCamerasFile((out / "cameras.yaml").string());
  ASSERT_EQ(cameras.size(), 2U);
  EXPECT_EQ(cameras[0].K, scene.cameras[0].model.K);
  EXPECT_EQ(cameras[0].distortion, scene.cameras[0].model.distortion);
  EXPECT_GE(geometry::LoadObj((out / "obstacles.obj").string()).triangles.size(), 12U);

  // The files hold exactly what the library renders in-process.
  sim::Simulator simulator(scene, 1);
  const sim::GroundTruth truth = sim::ReadGroundTruth((out / "ground_truth.yaml").string());
  ASSERT_EQ(truth.frames.size(), 4U);
  EXPECT_EQ(truth.scene, "tiny");
  std::vector<common::ImageU8> masks;
  std::vector<common::ImageRgb8> colour;
  for (int frame = 0; frame < 4; ++frame) {
    const double t = 0.5 + frame / 10.0;
    const sim::FrameTruth expected = simulator.Truth(frame, t);
    ASSERT_EQ(truth.frames[frame].people.size(), 2U);
    EXPECT_EQ(truth.frames[frame].time_s, t);
    for (std::size_t p = 0; p < 2; ++p) {
      EXPECT_EQ(truth.frames[frame].people[p].name, expected.people[p].name);
      for (int part = 0; part < sim::kNumBodyParts; ++part) {
        EXPECT_EQ(truth.frames[frame].people[p].state.parts[part].a_W,
                  expected.people[p].state.parts[part].a_W);
      }
    }
    simulator.RenderMasks(t, &masks);
    simulator.RenderColour(t, static_cast<std::uint64_t>(frame), &colour);
    char name[16];
    std::snprintf(name, sizeof(name), "%06d.png", frame);
    for (int c = 0; c < 2; ++c) {
      const std::string cam = scene.cameras[c].model.name;
      const common::ImageU8 mask = silhouette::ReadGreyImage((out / "masks" / cam / name).string());
      EXPECT_EQ(mask.pixels, masks[c].pixels) << cam << " frame " << frame;
      const common::ImageRgb8 rgb =
          silhouette::ReadRgbImage((out / "colour" / cam / name).string());
      EXPECT_EQ(rgb.pixels, colour[c].pixels) << cam << " frame " << frame;
      long long fg = 0;
      for (auto v : mask.pixels) fg += v != 0;
      EXPECT_GT(fg, 100) << "the people are in view of " << cam;
    }
  }
}

TEST_F(SynthCliTest, ColourAloneWritesNoMasks) {
  const auto r =
      Hullguard("synth --scene " + Path("tiny.yaml") + " --frames 1 --colour --out " + Path("c"));
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir_ / "c" / "colour" / "a" / "000000.png"));
  EXPECT_FALSE(fs::exists(dir_ / "c" / "masks"));
}

TEST_F(SynthCliTest, BadSceneNamesFileLineAndKey) {
  std::ofstream(Path("bad.yaml"))
      << "scene: {name: x, bounds: {min: [0, 0, 0], max: [1, 1, 1]}}\n"
         "cameras:\n"
         "  - {name: a, width: 64, height: 48, K: [50, 0, 31.5, 0, 50, "
         "23.5, 0, 0, 1], R: [1, 0, 0, 0, 1, 0, 0, 0, 1], t: [0, 0, 2]}\n"
         "people:\n"
         "  - name: p\n"
         "    heigth: 1.8\n";
  const auto r = Hullguard("synth --scene " + Path("bad.yaml") + " --frames 1 --out " + Path("o"));
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("bad.yaml:6"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("heigth"), std::string::npos) << r.err;
  const auto missing = Hullguard("synth --scene " + Path("nope.yaml") + " --out " + Path("o"));
  EXPECT_EQ(missing.code, 2);
  EXPECT_NE(missing.err.find("nope.yaml"), std::string::npos) << missing.err;
}

// OUT/scene.yaml loads on its own: the meshes the scene names by relative
// paths (paper_cell: meshes/robot.obj) are copied beside it.
TEST_F(SynthCliTest, OutputSceneLoadsWithItsMeshes) {
  const std::string scene_file = std::string(HG_SOURCE_DIR) + "/config/scenes/paper_cell.yaml";
  const auto r = Hullguard("synth --scene " + scene_file + " --frames 1 --out " + Path("paper"));
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir_ / "paper" / "meshes" / "robot.obj"));
  const sim::Scene original = sim::LoadScene(scene_file);
  sim::Scene copy;
  ASSERT_NO_THROW(copy = sim::LoadScene((dir_ / "paper" / "scene.yaml").string()));
  ASSERT_EQ(copy.obstacles.size(), original.obstacles.size());
  for (std::size_t i = 0; i < copy.obstacles.size(); ++i) {
    const auto* mesh = std::get_if<sim::MeshSolid>(&copy.obstacles[i].geometry);
    if (mesh == nullptr) continue;
    EXPECT_EQ(mesh->mesh.vertices,
              std::get<sim::MeshSolid>(original.obstacles[i].geometry).mesh.vertices);
  }
}

// A relative mesh path that leaves the scene's folder cannot be copied beside
// scene.yaml: bad input, before anything is written.
TEST_F(SynthCliTest, MeshOutsideTheSceneFolderIsRefused) {
  geometry::WriteObj(Path("box.obj"), geometry::TriangleMesh::Box(Eigen::Vector3d(1, 1, 0),
                                                                  Eigen::Vector3d(2, 2, 1)));
  fs::create_directories(dir_ / "scenes");
  std::string scene = kScene;
  scene.replace(scene.find("people:"), 0, "  - {name: box, mesh: {file: ../box.obj}}\n");
  std::ofstream(Path("scenes/up.yaml")) << scene;
  const auto r =
      Hullguard("synth --scene " + Path("scenes/up.yaml") + " --frames 1 --out " + Path("up"));
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("../box.obj"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "up"));
}

// A relative mesh path at a name synth writes itself (its combined
// obstacles.obj, or under masks/) would be overwritten or removed: refused,
// before anything is written.
TEST_F(SynthCliTest, MeshAtANameSynthWritesIsRefused) {
  geometry::WriteObj(Path("obstacles.obj"), geometry::TriangleMesh::Box(Eigen::Vector3d(1, 1, 0),
                                                                        Eigen::Vector3d(2, 2, 1)));
  std::string scene = kScene;
  scene.replace(scene.find("people:"), 0, "  - {name: box, mesh: {file: obstacles.obj}}\n");
  std::ofstream(Path("clash.yaml")) << scene;
  const auto r =
      Hullguard("synth --scene " + Path("clash.yaml") + " --frames 1 --out " + Path("clash"));
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("mesh file 'obstacles.obj' has a name synth writes its own output under"),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "clash"));
}

// A camera name is a folder name in the output: one that would leave it is
// refused with the scene's file and line.
TEST_F(SynthCliTest, CameraNamesThatCannotNameAFolderAreRefused) {
  std::string scene = kScene;
  scene.replace(scene.find("{name: b,"), 9, "{name: ../../b,");
  std::ofstream(Path("escape.yaml")) << scene;
  const auto r =
      Hullguard("synth --scene " + Path("escape.yaml") + " --frames 1 --out " + Path("esc"));
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("escape.yaml:5: cameras[1].name: '../../b' cannot name the camera's files"),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "esc"));
  EXPECT_FALSE(fs::exists(dir_.parent_path().parent_path() / "b"));
}

// Writing over an earlier synth output leaves none of its frames behind.
TEST_F(SynthCliTest, RerunIntoAnEarlierOutputLeavesNoStaleFrames) {
  const std::string scene = " --scene " + Path("tiny.yaml") + " --out " + Path("out");
  const auto first = Hullguard("synth" + scene + " --frames 3 --colour --masks");
  ASSERT_EQ(first.code, 0) << first.err;
  ASSERT_TRUE(fs::exists(dir_ / "out" / "masks" / "a" / "000002.png"));
  const auto second = Hullguard("synth" + scene + " --frames 1");
  ASSERT_EQ(second.code, 0) << second.err;
  EXPECT_TRUE(fs::exists(dir_ / "out" / "masks" / "a" / "000000.png"));
  EXPECT_FALSE(fs::exists(dir_ / "out" / "masks" / "a" / "000001.png"));
  EXPECT_FALSE(fs::exists(dir_ / "out" / "masks" / "b" / "000002.png"));
  EXPECT_FALSE(fs::exists(dir_ / "out" / "colour"));
  EXPECT_EQ(sim::ReadGroundTruth((dir_ / "out" / "ground_truth.yaml").string()).frames.size(), 1U);
}

// Any other non-empty folder is refused with one line naming it, and left as
// it was; an empty one is used.
TEST_F(SynthCliTest, NonEmptyFolderThatIsNoSynthOutputIsRefused) {
  fs::create_directories(dir_ / "mine");
  std::ofstream(Path("mine/notes.txt")) << "keep me\n";
  const auto r =
      Hullguard("synth --scene " + Path("tiny.yaml") + " --frames 1 --out " + Path("mine"));
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find(Path("mine")), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << "one line: " << r.err;
  EXPECT_TRUE(fs::exists(dir_ / "mine" / "notes.txt"));
  EXPECT_FALSE(fs::exists(dir_ / "mine" / "manifest.yaml"));
  EXPECT_FALSE(fs::exists(dir_ / "mine" / "masks"));

  fs::create_directories(dir_ / "empty");
  const auto empty =
      Hullguard("synth --scene " + Path("tiny.yaml") + " --frames 1 --out " + Path("empty"));
  ASSERT_EQ(empty.code, 0) << empty.err;
  EXPECT_TRUE(fs::exists(dir_ / "empty" / "masks" / "a" / "000000.png"));
}

std::string JsonField(const std::string& json, const std::string& key) {
  const auto at = json.find("\"" + key + "\": ");
  if (at == std::string::npos) return "";
  const auto start = at + key.size() + 4;
  return json.substr(start, json.find_first_of(",}", start) - start);
}

TEST_F(SynthCliTest, BenchReportsStagesAndTheDenseBaselineAndNoTruthPointFree) {
  const auto r =
      Hullguard("bench --scene " + Path("tiny.yaml") +
                " --frames 5 --start 0.5 --depth 6 --threads 2 --baseline dense:64 --json");
  ASSERT_EQ(r.code, 0) << r.err << r.out;
  for (const char* key : {"median_ms", "p99_ms", "max_ms", "nodes", "leaves", "aborts",
                          "octree_first_frame_ms", "ratio_to_octree_median"}) {
    EXPECT_NE(r.out.find(std::string("\"") + key + "\""), std::string::npos) << key;
  }
  EXPECT_EQ(JsonField(r.out, "truth_points_free"), "0");
  EXPECT_GT(std::stoll(JsonField(r.out, "truth_points")), 1000);
  EXPECT_GT(std::stoll(JsonField(r.out, "leaves")), 8);
  EXPECT_EQ(JsonField(r.out, "frames"), "5");
  EXPECT_EQ(JsonField(r.out, "aborts"), "0");

  // A deadline that has passed before the update starts aborts every frame,
  // and the result stays conservative.
  const auto aborted = Hullguard("bench --scene " + Path("tiny.yaml") +
                                 " --frames 3 --depth 6 --deadline-ms 0.000001 --json");
  ASSERT_EQ(aborted.code, 0) << aborted.err;
  EXPECT_EQ(JsonField(aborted.out, "aborts"), "3");
  EXPECT_EQ(JsonField(aborted.out, "truth_points_free"), "0");
  EXPECT_NE(aborted.out.find("\"refined_level\": {\"median\": 0, \"min\": 0}"), std::string::npos)
      << aborted.out;
  // A deadline counted from the update's start, not the frame's: a generous
  // one aborts nothing, and every update is refined to the depth.
  const auto coarse = Hullguard("bench --scene " + Path("tiny.yaml") +
                                " --frames 3 --depth 6 --coarse-first 3 --key-level 4"
                                " --deadline-ms 10000 --json");
  ASSERT_EQ(coarse.code, 0) << coarse.err;
  EXPECT_EQ(JsonField(coarse.out, "aborts"), "0");
  EXPECT_NE(coarse.out.find("\"refined_level\": {\"median\": 6, \"min\": 6}"), std::string::npos)
      << coarse.out;
  // The passes, 3 (coarse), 4 (key), 6, each completed by both incremental updates.
  const std::size_t passes = coarse.out.find("\"passes\": [{\"level\": 3, \"frames\": 2, ");
  ASSERT_NE(passes, std::string::npos) << coarse.out;
  const std::string rest = coarse.out.substr(passes, coarse.out.find(']', passes) - passes);
  EXPECT_NE(rest.find("{\"level\": 4, \"frames\": 2, "), std::string::npos) << rest;
  EXPECT_NE(rest.find("{\"level\": 6, \"frames\": 2, "), std::string::npos) << rest;
  EXPECT_EQ(rest.find("\"level\": 5"), std::string::npos) << rest;
  EXPECT_EQ(JsonField(coarse.out, "leaves_written_per_frame_median"), "") << coarse.out;

  // --leaf-changes counts what each incremental update wrote: some leaves as
  // the people move, never more than the tree holds.
  const auto changes = Hullguard("bench --scene " + Path("tiny.yaml") +
                                 " --frames 3 --start 0.5 --depth 6 --leaf-changes --json");
  ASSERT_EQ(changes.code, 0) << changes.err;
  const long long written = std::stoll(JsonField(changes.out, "leaves_written_per_frame_median"));
  EXPECT_GT(written, 0) << changes.out;
  EXPECT_LE(written, std::stoll(JsonField(changes.out, "leaves"))) << changes.out;

  // Whatever the scene is called, --json prints valid JSON.
  std::string quoted = kScene;
  quoted.replace(quoted.find("name: tiny"), 10, R"(name: "my \"cell\" \\ v2")");
  std::ofstream(Path("quoted.yaml")) << quoted;
  const auto q = Hullguard("bench --scene " + Path("quoted.yaml") +
                           " --frames 2 --depth 5 --threads 1 --truth-points 10 --json");
  ASSERT_EQ(q.code, 0) << q.err;
  EXPECT_EQ(q.out.rfind(R"({"scene": "my \"cell\" \\ v2", "cameras": 2,)", 0), 0u) << q.out;
  // A scene without cameras has nothing to benchmark: a clear error, no crash.
  std::string no_cameras = kScene;
  const std::size_t from = no_cameras.find("cameras:"), to = no_cameras.find("capture_offsets_ms");
  no_cameras.erase(from, to - from);
  no_cameras.replace(no_cameras.find("capture_offsets_ms: {b: 5}\n"), 27, "");
  std::ofstream(Path("blind.yaml")) << no_cameras;
  const auto blind = Hullguard("bench --scene " + Path("blind.yaml") + " --frames 2");
  EXPECT_EQ(blind.code, 2) << blind.out << blind.err;
  EXPECT_NE(blind.err.find("the scene has no cameras: nothing to benchmark"), std::string::npos)
      << blind.err;

  const auto bad = Hullguard("bench --scene " + Path("tiny.yaml") + " --baseline voxels:3");
  EXPECT_EQ(bad.code, 2);
  EXPECT_NE(bad.err.find("--baseline"), std::string::npos) << bad.err;
}

// End to end on the shipped paper cell (8 Full HD cameras, obstacles, capture
// offsets, distortion where the scene has it): no point inside a person is free.
TEST_F(SynthCliTest, PaperCellBenchAtDepthSevenKeepsEveryPersonPointOccupied) {
  const auto r = Hullguard(std::string("bench --scene ") + HG_SOURCE_DIR +
                           "/config/scenes/paper_cell.yaml --frames 6 --start 4 --depth 7 "
                           "--threads 2 --truth-points 3000 --json");
  ASSERT_EQ(r.code, 0) << r.err << r.out;
  EXPECT_EQ(JsonField(r.out, "cameras"), "8");
  EXPECT_EQ(JsonField(r.out, "truth_points_free"), "0");
  EXPECT_GT(std::stoll(JsonField(r.out, "truth_points")), 6 * 3 * 2000);
}

}  // namespace
}  // namespace hg
