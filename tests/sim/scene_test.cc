#include "sim/scene.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <string>
#include <system_error>
#include <variant>
#include <vector>

#include <unistd.h>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "common/config_error.h"
#include "geometry/camera_yaml.h"
#include "geometry/mesh.h"
#include "sim/body.h"
#include "sim/solids.h"

namespace hg::sim {
namespace {

namespace fs = std::filesystem;
using common::ConfigError;

constexpr double kPi = 3.14159265358979323846;

/// The directories TestDir made, removed when the test program exits.
struct TestDirs {
  std::vector<fs::path> made;
  ~TestDirs() {
    std::error_code ignored;
    for (const fs::path& dir : made) fs::remove_all(dir, ignored);
  }
};
TestDirs g_test_dirs;

/// A fresh directory for the running test; the process id keeps parallel runs apart.
fs::path TestDir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const fs::path dir =
      fs::path(::testing::TempDir()) / ("hg_scene_test_" + std::to_string(::getpid()) + "_" +
                                        info->test_suite_name() + "_" + info->name());
  fs::remove_all(dir);
  fs::create_directories(dir);
  g_test_dirs.made.push_back(dir);
  return dir;
}

void WriteText(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream(path) << text;
}

/// Replaces the one occurrence of `from` in `text`.
std::string Replace(std::string text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  EXPECT_EQ(text.find(from, at + 1), std::string::npos) << from;
  return at == std::string::npos ? text : text.replace(at, from.size(), to);
}

// ---------------------------------------------------------------------------
// Every key of the format, with values that are easy to check.

const char* const kFullScene = R"(
scene:
  name: full_example
  bounds: {min: [-1, -2, 0], max: [5, 4, 3.5]}
  rate_hz: 25
cameras:
  - name: cam_a
    width: 640
    height: 480
    K: [500, 0, 319.5, 0, 500, 239.5, 0, 0, 1]
    distortion: [0.01, 0, 0, 0, 0]
    R: [1, 0, 0, 0, -1, 0, 0, 0, -1]
    t: [-2, 1, 3]
  - name: cam_b
    width: 800
    height: 600
    K: [600, 0, 399.5, 0, 600, 299.5, 0, 0, 1]
    position: [-1, -2, 3]
    look_at: [2, 1, 1]
    up: [0, 0, 1]
capture_offsets_ms: {cam_a: -2.0, cam_b: 12.5}
obstacles:
  - {name: table_top, box: {min: [1, 1, 0.7], max: [2, 1.6, 0.75]}, colour: [0.55, 0.4, 0.25]}
  - {name: column, box: {centre: [3, 3, 1], size: [0.4, 0.2, 2], yaw_deg: 30}}
  - {name: pole, cylinder: {base: [0, 3, 0], radius: 0.1, height: 2.0}}
  - {name: strut, cylinder: {a: [0, 0, 0], b: [1, 0, 1], radius: 0.05}}
  - {name: pipe, capsule: {a: [0, 0, 2.5], b: [4, 0, 2.5], radius: 0.05}}
  - name: arm
    mesh: {file: meshes/arm.obj, translate: [1, 2, 0], yaw_deg: 90, scale: 2.0}
    colour: [1, 0.5, 0]
foreground_objects:
  - {name: crate, box: {min: [4, 3, 0], max: [4.5, 3.5, 0.5]}, colour: [0.6, 0.45, 0.3]}
  - {name: wedge, mesh: {file: meshes/wedge.STL}}
people:
  - name: alice
    height: 1.6
    shirt: [0.8, 0.2, 0.2]
    trousers: [0.1, 0.1, 0.3]
    skin: [0.9, 0.7, 0.6]
    start: [1, 1]
    heading_deg: 90
    script:
      - walk: {path: [[1, 3], [2, 3, 0.5], [2, 2]], speed: 2.0}
      - stand: {duration: 1.5, heading_deg: -90}
      - at: 10
        crouch: {duration: 2}
      - crawl: {path: [[2, 0.5, 0]]}
      - reach: {target: [2.5, 0.5, 1.0], hand: left, duration: 1.25}
      - reach: {target: [2.5, 0.0, 1.0], duration: 0.5}
      - walk: {path: [[3, 0.5]]}
  - name: bob
    start: [3, 3, 0.2]
imaging:
  noise_sigma: 1.5
  light: [1, 2, 3]
  ambient: 0.25
  shadows: false
  shadow_softness: 0.3
  light_change: {amplitude: 0.1, period_s: 15}
  seed: 42
masks: {occlusion: false}
)";

const char* const kWedgeStl =
    "solid wedge\n"
    "facet normal 0 0 -1\nouter loop\nvertex 4 0 0\nvertex 4 1 0\nvertex 5 0 0\nendloop\n"
    "endfacet\n"
    "facet normal 0 0 1\nouter loop\nvertex 4 0 0\nvertex 5 0 0\nvertex 4 0 1\nendloop\n"
    "endfacet\n"
    "endsolid wedge\n";

/// Writes kFullScene and its meshes into `dir`; returns the scene path.
fs::path WriteFullScene(const fs::path& dir) {
  fs::create_directories(dir / "meshes");
  geometry::WriteObj((dir / "meshes" / "arm.obj").string(),
                     geometry::TriangleMesh::Box({0, 0, 0}, {0.5, 0.25, 1}));
  WriteText(dir / "meshes" / "wedge.STL", kWedgeStl);
  WriteText(dir / "full.yaml", kFullScene);
  return dir / "full.yaml";
}

TEST(SceneTest, FullExampleHasEveryValue) {
  const fs::path path = WriteFullScene(TestDir());
  const Scene scene = LoadScene(path.string());
  EXPECT_EQ(scene.name, "full_example");
  EXPECT_EQ(scene.source_file, path.string());
  EXPECT_EQ(scene.bounds.min, Eigen::Vector3d(-1, -2, 0));
  EXPECT_EQ(scene.bounds.max, Eigen::Vector3d(5, 4, 3.5));
  EXPECT_EQ(scene.rate_hz, 25.0);

  // Cameras, in both pose forms, with their offsets.
  ASSERT_EQ(scene.cameras.size(), 2u);
  EXPECT_EQ(scene.cameras[0].model.name, "cam_a");
  EXPECT_EQ(scene.cameras[0].model.distortion[0], 0.01);
  EXPECT_EQ(scene.cameras[0].model.t_CW, Eigen::Vector3d(-2, 1, 3));
  EXPECT_DOUBLE_EQ(scene.cameras[0].time_offset_s, -0.002);
  EXPECT_EQ(scene.cameras[1].model.width, 800);
  EXPECT_DOUBLE_EQ(scene.cameras[1].time_offset_s, 0.0125);
  EXPECT_LT((scene.cameras[1].model.CentreW() - Eigen::Vector3d(-1, -2, 3)).norm(), 1e-12);
  const std::optional<Eigen::Vector2d> aim = scene.cameras[1].model.Project({2, 1, 1});
  ASSERT_TRUE(aim.has_value());
  EXPECT_NEAR(aim->x(), 399.5, 1e-9);
  EXPECT_NEAR(aim->y(), 299.5, 1e-9);
  const std::vector<geometry::CameraModel> models = scene.CameraModels();
  ASSERT_EQ(models.size(), 2u);
  EXPECT_EQ(models[1].name, "cam_b");
  EXPECT_EQ(models[1].R_CW, scene.cameras[1].model.R_CW);

  // Obstacles of every kind.
  ASSERT_EQ(scene.obstacles.size(), 6u);
  EXPECT_EQ(scene.obstacles[0].name, "table_top");
  EXPECT_EQ(scene.obstacles[0].colour, Rgb(0.55F, 0.4F, 0.25F));
  const auto& table = std::get<BoxSolid>(scene.obstacles[0].geometry);
  EXPECT_LT((table.centre_W - Eigen::Vector3d(1.5, 1.3, 0.725)).norm(), 1e-12);
  EXPECT_LT((table.half_extents_m - Eigen::Vector3d(0.5, 0.3, 0.025)).norm(), 1e-12);
  EXPECT_EQ(table.R_WB, Eigen::Matrix3d::Identity());

  EXPECT_EQ(scene.obstacles[1].colour, Rgb(0.6F, 0.6F, 0.6F));  // The default.
  const auto& column = std::get<BoxSolid>(scene.obstacles[1].geometry);
  EXPECT_EQ(column.centre_W, Eigen::Vector3d(3, 3, 1));
  EXPECT_LT((column.half_extents_m - Eigen::Vector3d(0.2, 0.1, 1)).norm(), 1e-12);
  const Eigen::Matrix3d yaw30 =
      Eigen::AngleAxisd(kPi / 6, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  EXPECT_LT((column.R_WB - yaw30).norm(), 1e-12);

  const auto& pole = std::get<CylinderSolid>(scene.obstacles[2].geometry);
  EXPECT_EQ(pole.a_W, Eigen::Vector3d(0, 3, 0));
  EXPECT_EQ(pole.b_W, Eigen::Vector3d(0, 3, 2));
  EXPECT_EQ(pole.radius_m, 0.1);
  const auto& strut = std::get<CylinderSolid>(scene.obstacles[3].geometry);
  EXPECT_EQ(strut.b_W, Eigen::Vector3d(1, 0, 1));
  EXPECT_EQ(strut.radius_m, 0.05);
  const auto& pipe = std::get<CapsuleSolid>(scene.obstacles[4].geometry);
  EXPECT_EQ(pipe.a_W, Eigen::Vector3d(0, 0, 2.5));
  EXPECT_EQ(pipe.b_W, Eigen::Vector3d(4, 0, 2.5));
  EXPECT_EQ(pipe.radius_m, 0.05);

  // The mesh is scaled, turned about z, then moved: local (0.5, 0, 0) -> (1, 0, 0)
  // -> (0, 1, 0) -> (1, 3, 0).
  EXPECT_EQ(scene.obstacles[5].colour, Rgb(1.0F, 0.5F, 0.0F));
  const auto& arm = std::get<MeshSolid>(scene.obstacles[5].geometry);
  ASSERT_EQ(arm.mesh.vertices.size(), 8u);
  ASSERT_EQ(arm.mesh.triangles.size(), 12u);
  EXPECT_LT((arm.mesh.vertices[1] - Eigen::Vector3d(1, 3, 0)).norm(), 1e-12);
  EXPECT_LT((arm.mesh.vertices[7] - Eigen::Vector3d(0.5, 3, 2)).norm(), 1e-12);

  ASSERT_EQ(scene.foreground_objects.size(), 2u);
  EXPECT_EQ(scene.foreground_objects[0].name, "crate");
  const auto& wedge = std::get<MeshSolid>(scene.foreground_objects[1].geometry);
  EXPECT_EQ(wedge.mesh.triangles.size(), 2u);
  EXPECT_EQ(wedge.mesh.vertices.size(), 4u);

  const std::vector<geometry::TriangleMesh> meshes = scene.ObstacleMeshes();
  ASSERT_EQ(meshes.size(), scene.obstacles.size());
  EXPECT_EQ(meshes[5].triangles.size(), 12u);  // Meshes are returned as they are.
  for (const geometry::TriangleMesh& mesh : meshes) {
    EXPECT_FALSE(mesh.triangles.empty());
  }

  // People, every action filled in.
  ASSERT_EQ(scene.people.size(), 2u);
  const Person& alice = scene.people[0];
  EXPECT_EQ(alice.name, "alice");
  EXPECT_EQ(alice.height_m, 1.6);
  EXPECT_EQ(alice.shirt, Rgb(0.8F, 0.2F, 0.2F));
  EXPECT_EQ(alice.trousers, Rgb(0.1F, 0.1F, 0.3F));
  EXPECT_EQ(alice.skin, Rgb(0.9F, 0.7F, 0.6F));
  EXPECT_EQ(alice.start_W, Eigen::Vector3d(1, 1, 0));
  EXPECT_DOUBLE_EQ(alice.start_heading_rad, kPi / 2);
  ASSERT_EQ(alice.actions.size(), 7u);

  const Action& walk = alice.actions[0];
  EXPECT_EQ(walk.kind, ActionKind::kWalk);
  EXPECT_EQ(walk.start_s, 0.0);
  ASSERT_EQ(walk.path_W.size(), 3u);
  EXPECT_EQ(walk.path_W[0], Eigen::Vector3d(1, 3, 0));  // Ground z of the start.
  EXPECT_EQ(walk.path_W[1], Eigen::Vector3d(2, 3, 0.5));
  EXPECT_EQ(walk.path_W[2], Eigen::Vector3d(2, 2, 0.5));  // Ground z of the previous waypoint.
  EXPECT_EQ(walk.speed_mps, 2.0);
  // From the start (1, 1, 0): 2 + sqrt(1.25) + 1 metres at 2 m/s.
  const double walk_s = (3.0 + std::sqrt(1.25)) / 2.0;
  EXPECT_DOUBLE_EQ(walk.duration_s, walk_s);
  EXPECT_TRUE(std::isnan(walk.heading_rad));

  const Action& stand = alice.actions[1];
  EXPECT_EQ(stand.kind, ActionKind::kStand);
  EXPECT_DOUBLE_EQ(stand.start_s, walk_s);
  EXPECT_EQ(stand.duration_s, 1.5);
  EXPECT_DOUBLE_EQ(stand.heading_rad, -kPi / 2);

  const Action& crouch = alice.actions[2];
  EXPECT_EQ(crouch.kind, ActionKind::kCrouch);
  EXPECT_EQ(crouch.start_s, 10.0);  // `at`.
  EXPECT_EQ(crouch.duration_s, 2.0);
  EXPECT_TRUE(std::isnan(crouch.heading_rad));

  const Action& crawl = alice.actions[3];
  EXPECT_EQ(crawl.kind, ActionKind::kCrawl);
  EXPECT_EQ(crawl.start_s, 12.0);
  EXPECT_EQ(crawl.speed_mps, 0.4);  // The crawl default.
  ASSERT_EQ(crawl.path_W.size(), 1u);
  EXPECT_EQ(crawl.path_W[0], Eigen::Vector3d(2, 0.5, 0));
  const double crawl_s = std::sqrt(1.5 * 1.5 + 0.5 * 0.5) / 0.4;
  EXPECT_DOUBLE_EQ(crawl.duration_s, crawl_s);

  const Action& reach = alice.actions[4];
  EXPECT_EQ(reach.kind, ActionKind::kReach);
  EXPECT_DOUBLE_EQ(reach.start_s, 12.0 + crawl_s);
  EXPECT_EQ(reach.target_W, Eigen::Vector3d(2.5, 0.5, 1.0));
  EXPECT_TRUE(reach.left_hand);
  EXPECT_EQ(reach.duration_s, 1.25);
  EXPECT_FALSE(alice.actions[5].left_hand);  // Right hand by default.

  const Action& last = alice.actions[6];
  EXPECT_EQ(last.speed_mps, 1.2);  // The walking default.
  EXPECT_EQ(last.path_W[0], Eigen::Vector3d(3, 0.5, 0));
  EXPECT_DOUBLE_EQ(last.duration_s, 1.0 / 1.2);
  EXPECT_DOUBLE_EQ(last.start_s, 12.0 + crawl_s + 1.75);

  const Person& bob = scene.people[1];
  EXPECT_EQ(bob.start_W, Eigen::Vector3d(3, 3, 0.2));
  EXPECT_EQ(bob.height_m, 1.75);
  EXPECT_EQ(bob.shirt, Person().shirt);
  EXPECT_EQ(bob.start_heading_rad, 0.0);
  EXPECT_TRUE(bob.actions.empty());

  EXPECT_EQ(scene.imaging.noise_sigma, 1.5);
  EXPECT_EQ(scene.imaging.light_W, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(scene.imaging.ambient, 0.25);
  EXPECT_FALSE(scene.imaging.shadows);
  EXPECT_EQ(scene.imaging.shadow_softness_m, 0.3);
  EXPECT_EQ(scene.imaging.light_change_amplitude, 0.1);
  EXPECT_EQ(scene.imaging.light_change_period_s, 15.0);
  EXPECT_EQ(scene.imaging.seed, 42u);
  EXPECT_FALSE(scene.mask_occlusion);
}

TEST(SceneTest, MinimalSceneTakesTheDefaults) {
  const Scene scene = ParseScene("scene: {name: bare, bounds: {min: [0, 0, 0], max: [1, 1, 1]}}\n",
                                 "bare.yaml", "");
  EXPECT_EQ(scene.name, "bare");
  EXPECT_TRUE(scene.source_file.empty());
  EXPECT_EQ(scene.rate_hz, 30.0);
  EXPECT_TRUE(scene.cameras.empty());
  EXPECT_TRUE(scene.obstacles.empty());
  EXPECT_TRUE(scene.people.empty());
  const ImagingSettings defaults;
  EXPECT_EQ(scene.imaging.noise_sigma, defaults.noise_sigma);
  EXPECT_EQ(scene.imaging.light_W, defaults.light_W);
  EXPECT_EQ(scene.imaging.light_change_amplitude, 0.0);
  EXPECT_EQ(scene.imaging.seed, defaults.seed);
  EXPECT_TRUE(scene.mask_occlusion);
}

// ---------------------------------------------------------------------------
// Mesh paths.

TEST(SceneMeshPathTest, RelativeToTheSceneFile) {
  const fs::path dir = TestDir();
  fs::create_directories(dir / "cell" / "meshes");
  geometry::WriteObj((dir / "cell" / "meshes" / "box.obj").string(),
                     geometry::TriangleMesh::Box({0, 0, 0}, {1, 1, 1}));
  const std::string text =
      "scene: {name: m, bounds: {min: [0, 0, 0], max: [4, 4, 3]}}\n"
      "obstacles:\n"
      "  - {name: box, mesh: {file: meshes/box.obj}}\n";
  WriteText(dir / "cell" / "scene.yaml", text);

  // Loaded from its file: resolved against the file's directory, whatever the
  // working directory.
  const Scene loaded = LoadScene((dir / "cell" / "scene.yaml").string());
  EXPECT_EQ(std::get<MeshSolid>(loaded.obstacles[0].geometry).mesh.triangles.size(), 12u);

  // Parsed from text: resolved against base_dir.
  const Scene parsed = ParseScene(text, "text.yaml", (dir / "cell").string());
  EXPECT_EQ(std::get<MeshSolid>(parsed.obstacles[0].geometry).mesh.vertices.size(), 8u);

  // Absolute paths are used as they are.
  const std::string absolute = (dir / "cell" / "meshes" / "box.obj").string();
  const Scene abs = ParseScene(Replace(text, "meshes/box.obj", absolute), "abs.yaml", "/nowhere");
  EXPECT_EQ(std::get<MeshSolid>(abs.obstacles[0].geometry).mesh.triangles.size(), 12u);

  // From another directory the relative path does not resolve; the message
  // names the scene file, line and key, and the path that was tried.
  try {
    (void)ParseScene(text, "other.yaml", dir.string());
    ADD_FAILURE() << "no error";
  } catch (const ConfigError& e) {
    const std::string message = e.what();
    EXPECT_EQ(message.rfind("other.yaml:3: obstacles[0].mesh.file: cannot load mesh: ", 0), 0u)
        << message;
    EXPECT_NE(message.find((dir / "meshes" / "box.obj").string() + ": cannot open"),
              std::string::npos)
        << message;
  }
}

TEST(SceneMeshPathTest, MissingSceneFile) {
  const std::string path = (TestDir() / "nope.yaml").string();
  try {
    (void)LoadScene(path);
    ADD_FAILURE() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_EQ(std::string(e.what()), path + ": cannot open: no such file");
  }
}

// ---------------------------------------------------------------------------
// Errors: each names the file, the line and the key path.

// A valid scene; the comments give the 1-based line numbers the tests rely on.
const char* const kBase =
    "scene:\n"                                                         // 1
    "  name: t\n"                                                      // 2
    "  bounds: {min: [0, 0, 0], max: [4, 4, 3]}\n"                     // 3
    "cameras:\n"                                                       // 4
    "  - name: c0\n"                                                   // 5
    "    width: 640\n"                                                 // 6
    "    height: 480\n"                                                // 7
    "    K: [500, 0, 319.5, 0, 500, 239.5, 0, 0, 1]\n"                 // 8
    "    position: [-0.5, -0.5, 2.5]\n"                                // 9
    "    look_at: [2, 2, 1]\n"                                         // 10
    "obstacles:\n"                                                     // 11
    "  - {name: table, box: {min: [1, 1, 0.7], max: [2, 2, 0.75]}}\n"  // 12
    "  - name: column\n"                                               // 13
    "    cylinder: {base: [3, 3, 0], radius: 0.1, height: 2}\n"        // 14
    "people:\n"                                                        // 15
    "  - name: alice\n"                                                // 16
    "    start: [0.5, 0.5]\n"                                          // 17
    "    script:\n"                                                    // 18
    "      - walk: {path: [[0.5, 3.5]], speed: 1.0}\n"                 // 19
    "      - stand: {duration: 2}\n"                                   // 20
    "  - name: bob\n"                                                  // 21
    "    start: [3.5, 0.5]\n"                                          // 22
    "    height: 1.8\n"                                                // 23
    "    script:\n"                                                    // 24
    "      - crouch: {duration: 1}\n"                                  // 25
    "      - reach: {target: [3, 1, 1], duration: 1}\n"                // 26
    "      - walk:\n"                                                  // 27
    "          path: [[3.5, 2.5]]\n"                                   // 28
    "          speed: 1.2\n"                                           // 29
    "imaging: {noise_sigma: 1.0}\n";                                   // 30

/// Parses `text` as "scenes/x.yaml" and expects "scenes/x.yaml:LINE: MESSAGE..."
/// where the message starts with `start` (the key path and the problem).
void ExpectError(const std::string& text, int line, const std::string& start) {
  try {
    (void)ParseScene(text, "scenes/x.yaml", "");
    ADD_FAILURE() << "no error for:\n" << text;
  } catch (const ConfigError& e) {
    const std::string expected = "scenes/x.yaml:" + std::to_string(line) + ": " + start;
    EXPECT_EQ(std::string(e.what()).rfind(expected, 0), 0u)
        << "expected '" << expected << "...', got: " << e.what();
  }
}

// Numbers that overflow what they feed are refused where they stand: a
// script of endless duration (its loops never ended: the daemon hung at
// start-up, deaf to SIGTERM), coordinates beyond the cell's largest, angles
// whose radians are infinite, a second YAML document (dropped unread).
TEST(SceneErrorTest, OverflowingNumbersAreRefused) {
  ExpectError(Replace(kBase, "stand: {duration: 2}", "stand: {duration: 1e308}"), 20,
              "people[0].script[1]: ends at ");
  ExpectError(Replace(kBase, "path: [[0.5, 3.5]]", "path: [[1e200, 3.5]]"), 19,
              "people[0].script[0].walk.path[0][0]: must be in [-1e+06, 1e+06]");
  ExpectError(Replace(kBase, "height: 1.8\n", "height: 1.8\n    heading_deg: 1e308\n"), 24,
              "people[1].heading_deg: must be in [-360000, 360000]");
  ExpectError(std::string(kBase) + "---\nscene: {name: u}\n", 32,
              "a second YAML document ('---'): a file holds one");
  ExpectError(Replace(kBase, "imaging: {noise_sigma: 1.0}", "imaging: {<<: {noise_sigma: 1.0}}"),
              30, "imaging: merge keys ('<<') are not read: write the keys out");
  // A tag is no instruction the readers follow: `!!str 1.0` was read as 1.0.
  ExpectError(Replace(kBase, "imaging: {noise_sigma: 1.0}", "imaging: {noise_sigma: !!str 1.0}"),
              30, "a YAML tag ('!!str'): tags are not read, write the plain value");
  // An alias is the node it names: a tree of aliases is checked node by node.
  ExpectError(std::string(kBase) + "x: &a [1, 1]\ny: &b [*a, *a, *a, *a]\nz: [*b, *b, !w 1]\n", 33,
              "a YAML tag ('!w')");
  // A NUL byte went into the key, and the message naming it was cut there.
  ExpectError(Replace(kBase, "imaging: {noise_sigma", std::string("imag\0ing: {noise_sigma", 22)),
              30, "a NUL byte: not a YAML text file (binary, or saved as UTF-16?)");
}

TEST(SceneErrorTest, BaseSceneLoads) {
  const Scene scene = ParseScene(kBase, "scenes/x.yaml", "");
  EXPECT_EQ(scene.people.size(), 2u);
  EXPECT_EQ(scene.people[1].actions.size(), 3u);
}

TEST(SceneErrorTest, MalformedYamlGivesTheParserLine) {
  ExpectError(Replace(kBase, "height: 1.8", "height: 1.8: 2"), 23, "malformed YAML");
  ExpectError(Replace(kBase, "speed: 1.0}", "speed: 1.0"), 20, "malformed YAML");
}

TEST(SceneErrorTest, UnknownKeysAtEveryLevel) {
  ExpectError(std::string(kBase) + "extra: 1\n", 31, "unknown key 'extra' (known: scene, ");
  ExpectError(Replace(kBase, "  name: t\n", "  name: t\n  colour: red\n"), 3,
              "scene: unknown key 'colour'");
  ExpectError(Replace(kBase, "speed: 1.0}", "sped: 1.0}"), 19,
              "people[0].script[0].walk: unknown key 'sped' (known: path, speed)");
  ExpectError(Replace(kBase, "    height: 1.8\n", "    hieght: 1.8\n"), 23,
              "people[1]: unknown key 'hieght'");
  ExpectError(Replace(kBase, "radius: 0.1,", "radius: 0.1, colour: [1, 1, 1],"), 14,
              "obstacles[1].cylinder: unknown key 'colour'");
  ExpectError(Replace(kBase, "      - stand: {duration: 2}\n", "      - sit: {duration: 2}\n"), 20,
              "people[0].script[1]: unknown key 'sit'");
  ExpectError(Replace(kBase, "{noise_sigma: 1.0}", "{noise: 1.0}"), 30,
              "imaging: unknown key 'noise'");
  ExpectError(Replace(kBase, "    look_at: [2, 2, 1]\n", "    look_at: [2, 2, 1]\n    fov: 60\n"),
              11, "cameras[0]: unknown key 'fov'");
  ExpectError(Replace(kBase, "    height: 1.8\n", "    height: 1.8\n    height: 1.7\n"), 24,
              "people[1]: duplicate key 'height'");
}

TEST(SceneErrorTest, MissingKeys) {
  ExpectError(Replace(kBase, "  name: t\n", ""), 1, "scene: missing key 'name'");
  ExpectError(Replace(kBase, "  bounds: {min: [0, 0, 0], max: [4, 4, 3]}\n", ""), 1,
              "scene: missing key 'bounds'");
  ExpectError(Replace(kBase, "max: [4, 4, 3]}", "}"), 3, "scene.bounds: missing key 'max'");
  ExpectError(Replace(kBase, "  - name: bob\n", "  - nick: bob\n"), 21,
              "people[1]: unknown key 'nick'");
  ExpectError(Replace(kBase, "  - name: bob\n    start: [3.5, 0.5]\n", "  - start: [3.5, 0.5]\n"),
              21, "people[1]: missing key 'name'");
  ExpectError(Replace(kBase, "    start: [0.5, 0.5]\n", ""), 16, "people[0]: missing key 'start'");
  ExpectError(Replace(kBase, "          path: [[3.5, 2.5]]\n", ""), 27,
              "people[1].script[2].walk: missing key 'path'");
  ExpectError(Replace(kBase, "{duration: 2}", "{heading_deg: 2}"), 20,
              "people[0].script[1].stand: missing key 'duration'");
  ExpectError(Replace(kBase, "{target: [3, 1, 1], duration: 1}", "{duration: 1}"), 26,
              "people[1].script[1].reach: missing key 'target'");
  ExpectError("", 1, "expected a map with the key 'scene'");
  ExpectError("cameras: []\n", 1, "missing key 'scene'");
}

TEST(SceneErrorTest, WrongTypes) {
  ExpectError(Replace(kBase, "height: 1.8", "height: tall"), 23,
              "people[1].height: expected a number");
  ExpectError(Replace(kBase, "  name: t\n", "  name: [t]\n"), 2,
              "scene.name: expected a non-empty string");
  ExpectError(Replace(kBase, "{noise_sigma: 1.0}", "{shadows: maybe}"), 30,
              "imaging.shadows: expected true or false");
  ExpectError(Replace(kBase, "{noise_sigma: 1.0}", "{seed: -3}"), 30,
              "imaging.seed: expected a non-negative integer");
  ExpectError(Replace(kBase,
                      "    script:\n      - crouch: {duration: 1}\n"
                      "      - reach: {target: [3, 1, 1], duration: 1}\n"
                      "      - walk:\n          path: [[3.5, 2.5]]\n          speed: 1.2\n",
                      "    script: crouch\n"),
              24, "people[1].script: expected a list");
  ExpectError(Replace(kBase, "start: [0.5, 0.5]", "start: 0.5"), 17,
              "people[0].start: expected a list of 2 or 3 numbers");
  ExpectError(Replace(kBase, "start: [0.5, 0.5]", "start: [0.5, 0.5, 0, 1]"), 17,
              "people[0].start: expected 2 or 3 numbers, got 4");
  ExpectError(Replace(kBase, "min: [1, 1, 0.7]", "min: [1, one, 0.7]"), 12,
              "obstacles[0].box.min[1]: expected a number");
  ExpectError(Replace(kBase, "obstacles:\n", "obstacles:\n  - table\n"), 12,
              "obstacles[0]: expected a map (keys: name, colour, box, ");
  ExpectError(Replace(kBase, "[[3.5, 2.5]]", "[3.5, 2.5]"), 28,
              "people[1].script[2].walk.path[0]: expected a list of 2 or 3 numbers");
}

TEST(SceneErrorTest, NonFiniteNumbers) {
  ExpectError(Replace(kBase, "start: [0.5, 0.5]", "start: [0.5, .nan]"), 17,
              "people[0].start[1]: not finite");
  ExpectError(Replace(kBase, "max: [2, 2, 0.75]", "max: [2, .inf, 0.75]"), 12,
              "obstacles[0].box.max[1]: not finite");
  ExpectError(Replace(kBase, "speed: 1.2", "speed: .inf"), 29,
              "people[1].script[2].walk.speed: not finite");
}

TEST(SceneErrorTest, ValueRanges) {
  // The example of the format documentation.
  ExpectError(Replace(kBase, "speed: 1.2", "speed: 0"), 29,
              "people[1].script[2].walk.speed: must be in [0.01, 10]");
  ExpectError(Replace(kBase, "speed: 1.0}", "speed: -1.0}"), 19,
              "people[0].script[0].walk.speed: must be in [0.01, 10]");
  // Near zero, the walk would last for ever.
  ExpectError(Replace(kBase, "speed: 1.0}", "speed: 1e-320}"), 19,
              "people[0].script[0].walk.speed: must be in [0.01, 10]");
  ExpectError(Replace(kBase, "    height: 1.8\n", "    height: 1.8\n    shirt: [0.5, 1.2, 0]\n"),
              24, "people[1].shirt[1]: must be in [0, 1]");
  ExpectError(Replace(kBase, "height: 1.8", "height: 2.5"), 23,
              "people[1].height: must be in [1, 2.2]");
  ExpectError(Replace(kBase, "radius: 0.1", "radius: 0"), 14,
              "obstacles[1].cylinder.radius: must be > 0");
  ExpectError(Replace(kBase, "height: 2}", "height: -2}"), 14,
              "obstacles[1].cylinder.height: must be > 0");
  ExpectError(Replace(kBase, "radius: 0.1", "radius: 1e300"), 14,
              "obstacles[1].cylinder.radius: must be at most 1e6");
  ExpectError(Replace(kBase, "{min: [1, 1, 0.7], max: [2, 2, 0.75]}",
                      "{centre: [1, 1, 0.7], size: [1, 1, 0]}"),
              12, "obstacles[0].box.size[2]: must be > 0");
  ExpectError(Replace(kBase, "max: [2, 2, 0.75]", "max: [2, 2, 0.7]"), 12,
              "obstacles[0].box.max: must be greater than min on every axis");
  ExpectError(Replace(kBase, "max: [4, 4, 3]", "max: [4, -4, 3]"), 3,
              "scene.bounds.max: must be greater than min on every axis");
  ExpectError(Replace(kBase, "{duration: 2}", "{duration: 0}"), 20,
              "people[0].script[1].stand.duration: must be > 0");
  ExpectError(Replace(kBase, "{noise_sigma: 1.0}", "{ambient: 1.5}"), 30,
              "imaging.ambient: must be in [0, 1]");
  ExpectError(Replace(kBase, "{noise_sigma: 1.0}", "{noise_sigma: -1}"), 30,
              "imaging.noise_sigma: must be >= 0");
  ExpectError(Replace(kBase, "{noise_sigma: 1.0}", "{light_change: {amplitude: 1.0}}"), 30,
              "imaging.light_change.amplitude: must be < 1");
  ExpectError(Replace(kBase, "target: [3, 1, 1],", "target: [3, 1, 1], hand: middle,"), 26,
              "people[1].script[1].reach.hand: expected 'left' or 'right'");
  ExpectError(Replace(kBase, "  name: t\n", "  name: t\n  rate_hz: 0\n"), 3,
              "scene.rate_hz: must be > 0");
  ExpectError(Replace(kBase, "  name: t\n", "  name: t\n  rate_hz: 1e-30\n"), 3,
              "scene.rate_hz: must be within [0.1, 1000] Hz");
  ExpectError(Replace(kBase, "max: [4, 4, 3]", "max: [4, 4, 1e300]"), 3,
              "scene.bounds.max[2]: must be in [-1e+06, 1e+06]");
  ExpectError(Replace(kBase, "K: [500, 0, 319.5, 0, 500,", "K: [1e-30, 0, 319.5, 0, 500,"), 8,
              "cameras[0].K: focal lengths must be within [1, 1e6] px");
}

TEST(SceneErrorTest, PathsAndTiming) {
  ExpectError(Replace(kBase, "[[0.5, 3.5]]", "[]"), 19,
              "people[0].script[0].walk.path: needs at least 1 waypoint");
  ExpectError(Replace(kBase, "[[0.5, 3.5]]", "[[0.5, 0.5], [0.5, 0.5, 0]]"), 19,
              "people[0].script[0].walk.path: has zero length");
  // The walk ends at 3 s; the stand may start then or later, not before.
  ExpectError(Replace(kBase, "      - stand: {duration: 2}\n",
                      "      - stand: {duration: 2}\n        at: 2.5\n"),
              21, "people[0].script[1].at: must not be before the end of the previous action");
  EXPECT_EQ(ParseScene(Replace(kBase, "      - stand: {duration: 2}\n",
                               "      - stand: {duration: 2}\n        at: 3\n"),
                       "scenes/x.yaml", "")
                .people[0]
                .actions[1]
                .start_s,
            3.0);
  ExpectError(Replace(kBase, "      - crouch: {duration: 1}\n",
                      "      - {at: -1, crouch: {duration: 1}}\n"),
              25, "people[1].script[0].at: must be >= 0");
  ExpectError(Replace(kBase, "      - crouch: {duration: 1}\n",
                      "      - {crouch: {duration: 1}, stand: {duration: 1}}\n"),
              25, "people[1].script[0]: give only one of walk, stand, crouch, crawl, reach");
  ExpectError(Replace(kBase, "      - crouch: {duration: 1}\n", "      - {at: 1}\n"), 25,
              "people[1].script[0]: needs one of walk, stand, crouch, crawl, reach");
}

TEST(SceneErrorTest, NamesAndShapes) {
  ExpectError(Replace(kBase, "  - name: bob\n", "  - name: alice\n"), 21,
              "people[1].name: duplicate person name 'alice' (first at line 16)");
  ExpectError(Replace(kBase, "  - name: column\n", "  - name: table\n"), 13,
              "obstacles[1].name: duplicate object name 'table' (first at line 12)");
  ExpectError(std::string(kBase) +
                  "foreground_objects:\n"
                  "  - {name: column, capsule: {a: [0, 0, 0], b: [0, 0, 1], radius: 0.1}}\n",
              32, "foreground_objects[0].name: duplicate object name 'column' (first at line 13)");
  ExpectError(Replace(kBase, "radius: 0.1, height: 2}\n",
                      "radius: 0.1, height: 2}\n    box: {min: [0, 0, 0], max: [1, 1, 1]}\n"),
              15, "obstacles[1]: give only one of box, cylinder, capsule, mesh");
  ExpectError(Replace(kBase, "    cylinder: {base: [3, 3, 0], radius: 0.1, height: 2}\n", ""), 13,
              "obstacles[1]: needs one of box, cylinder, capsule, mesh");
  ExpectError(Replace(kBase, "{base: [3, 3, 0], radius: 0.1, height: 2}",
                      "{base: [3, 3, 0], radius: 0.1, height: 2, b: [3, 3, 1]}"),
              14, "obstacles[1].cylinder: give either base+height (vertical) or a+b, not both");
  ExpectError(Replace(kBase, "{base: [3, 3, 0], radius: 0.1, height: 2}",
                      "{a: [3, 3, 0], b: [3, 3, 0], radius: 0.1}"),
              14, "obstacles[1].cylinder.b: must differ from a");
  ExpectError(Replace(kBase, "max: [2, 2, 0.75]}", "max: [2, 2, 0.75], yaw_deg: 10}"), 12,
              "obstacles[0].box: give either min+max or centre+size (+yaw_deg), not both");
}

TEST(SceneErrorTest, CamerasAndOffsets) {
  ExpectError(std::string(kBase) + "capture_offsets_ms: {c0: 1.0, c9: 2.0}\n", 31,
              "capture_offsets_ms.c9: unknown camera 'c9' (cameras: c0)");
  ExpectError(std::string(kBase) + "capture_offsets_ms: {c0: fast}\n", 31,
              "capture_offsets_ms.c0: expected a number");
  // A synth recording's manifest takes offsets within a second.
  ExpectError(std::string(kBase) + "capture_offsets_ms: {c0: 1e300}\n", 31,
              "capture_offsets_ms.c0: must be in [-1000, 1000]");
  // Camera entries report through the camera block's own parser.
  ExpectError(
      Replace(kBase, "    look_at: [2, 2, 1]\n", "    look_at: [2, 2, 1]\n    t: [0, 0, 1]\n"), 11,
      "cameras[0]: give either R+t or position+look_at");
  ExpectError(Replace(kBase, "0, 0, 1]\n    position", "0, 1]\n    position"), 8,
              "cameras[0].K: expected 9 numbers, got 8");
  ExpectError(Replace(kBase, "cameras:\n  - name: c0", "cameras:\n  - 5\n  - name: c0"), 5,
              "cameras[0]: expected a map");
  ExpectError(Replace(kBase,
                      "cameras:\n  - name: c0\n    width: 640\n    height: 480\n"
                      "    K: [500, 0, 319.5, 0, 500, 239.5, 0, 0, 1]\n"
                      "    position: [-0.5, -0.5, 2.5]\n    look_at: [2, 2, 1]\n",
                      "cameras: []\n"),
              4, "cameras: expected a non-empty list of cameras");
  std::string seventeen = "cameras:\n";
  for (int i = 0; i < 17; ++i) {
    seventeen += "  - {name: c" + std::to_string(i) +
                 ", width: 64, height: 48, K: [50, 0, 31.5, 0, 50, 23.5, 0, 0, 1], position: "
                 "[-0.5, -0.5, 2.5], look_at: [2, 2, 1]}\n";
  }
  ExpectError(Replace(kBase,
                      "cameras:\n  - name: c0\n    width: 640\n    height: 480\n"
                      "    K: [500, 0, 319.5, 0, 500, 239.5, 0, 0, 1]\n"
                      "    position: [-0.5, -0.5, 2.5]\n    look_at: [2, 2, 1]\n",
                      seventeen),
              4, "cameras: 17 cameras, at most 16");
}

TEST(SceneErrorTest, MeshFiles) {
  const fs::path dir = TestDir();
  WriteText(dir / "bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
  WriteText(dir / "empty.obj", "# nothing\n");
  WriteText(dir / "mesh.ply", "ply\n");
  auto scene_with = [](const std::string& mesh) {
    return std::string(kBase) + "foreground_objects:\n  - name: thing\n    mesh: " + mesh + "\n";
  };
  auto expect = [&](const std::string& mesh, const std::string& start, const std::string& also) {
    try {
      (void)ParseScene(scene_with(mesh), "scenes/x.yaml", dir.string());
      ADD_FAILURE() << "no error for " << mesh;
    } catch (const ConfigError& e) {
      const std::string message = e.what();
      EXPECT_EQ(message.rfind("scenes/x.yaml:33: " + start, 0), 0u) << message;
      EXPECT_NE(message.find(also), std::string::npos) << message;
    }
  };
  expect("{file: missing.stl}", "foreground_objects[0].mesh.file: cannot load mesh: ",
         (dir / "missing.stl").string() + ": cannot open");
  expect("{file: bad.obj}", "foreground_objects[0].mesh.file: cannot load mesh: ",
         (dir / "bad.obj").string() + ":4: f: index 9 out of range");
  expect("{file: mesh.ply}",
         "foreground_objects[0].mesh.file: cannot load mesh: ", "unknown mesh format '.ply'");
  expect("{file: empty.obj}", "foreground_objects[0].mesh.file: mesh has no triangles",
         "empty.obj");
  WriteText(dir / "ok.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  expect("{file: ok.obj, scale: 0}", "foreground_objects[0].mesh.scale: must be > 0", "");
  expect("{file: ok.obj, translate: [1, 2]}",
         "foreground_objects[0].mesh.translate: expected 3 numbers, got 2", "");
  expect("{translate: [1, 2, 3]}", "foreground_objects[0].mesh: missing key 'file'", "");
}

// ---------------------------------------------------------------------------
// The shipped scenes.

std::vector<fs::path> ShippedScenes() {
  std::vector<fs::path> paths;
  for (const auto& entry : fs::directory_iterator(fs::path(HG_SOURCE_DIR) / "config" / "scenes")) {
    if (entry.path().extension() == ".yaml") paths.push_back(entry.path());
  }
  std::sort(paths.begin(), paths.end());
  return paths;
}

/// Axis-aligned bounds of a solid, computed here from the parameters.
common::Box3 SolidBounds(const SolidGeometry& geometry) {
  common::Box3 box;
  if (const auto* b = std::get_if<BoxSolid>(&geometry)) {
    const Eigen::Vector3d extent = b->R_WB.cwiseAbs() * b->half_extents_m;
    box.min = b->centre_W - extent;
    box.max = b->centre_W + extent;
  } else if (const auto* c = std::get_if<CylinderSolid>(&geometry)) {
    box.min = c->a_W.cwiseMin(c->b_W).array() - c->radius_m;
    box.max = c->a_W.cwiseMax(c->b_W).array() + c->radius_m;
  } else if (const auto* s = std::get_if<CapsuleSolid>(&geometry)) {
    box.min = s->a_W.cwiseMin(s->b_W).array() - s->radius_m;
    box.max = s->a_W.cwiseMax(s->b_W).array() + s->radius_m;
  } else {
    const auto& mesh = std::get<MeshSolid>(geometry).mesh;
    box.min = box.max = mesh.vertices.at(0);
    for (const Eigen::Vector3d& p : mesh.vertices) {
      box.min = box.min.cwiseMin(p);
      box.max = box.max.cwiseMax(p);
    }
  }
  return box;
}

bool Overlap(const common::Box3& a, const common::Box3& b) {
  return (a.min.array() < b.max.array()).all() && (b.min.array() < a.max.array()).all();
}

/// Room a person takes at feet position p_W, as a box: upright people a
/// column of half-width 0.3 m, crouching people a wider, lower one, crawling
/// people a low one of half-width 0.45 m (the body lies along the way). The
/// column starts 2 cm above the ground so that standing on a table is allowed.
common::Box3 Envelope(const Person& person, ActionKind kind, const Eigen::Vector3d& p_W) {
  double half_width = 0.3;
  double top = person.height_m;
  if (kind == ActionKind::kCrouch) {
    half_width = 0.35;
    top = 0.75 * person.height_m;
  } else if (kind == ActionKind::kCrawl) {
    half_width = 0.45;
    top = 0.5 * person.height_m;
  }
  common::Box3 box;
  box.min = p_W + Eigen::Vector3d(-half_width, -half_width, 0.02);
  box.max = p_W + Eigen::Vector3d(half_width, half_width, top);
  return box;
}

TEST(ShippedScenesTest, AllLoadAndEveryCameraSeesTheCellCentre) {
  const std::vector<fs::path> paths = ShippedScenes();
  std::vector<std::string> names;
  for (const fs::path& path : paths) names.push_back(path.filename().string());
  for (const char* expected :
       {"crawl_under_table.yaml", "demo_cell.yaml", "paper_cell.yaml", "passing_behind_rack.yaml",
        "table_on_and_under.yaml", "walk_behind_rack.yaml"}) {
    EXPECT_NE(std::find(names.begin(), names.end(), expected), names.end()) << expected;
  }
  for (const fs::path& path : paths) {
    SCOPED_TRACE(path.string());
    const Scene scene = LoadScene(path.string());
    EXPECT_EQ(scene.name, path.stem().string());
    EXPECT_GE(scene.cameras.size(), 4u);
    EXPECT_LE(scene.cameras.size(), 8u);
    EXPECT_FALSE(scene.people.empty());
    const Eigen::Vector3d centre = 0.5 * (scene.bounds.min + scene.bounds.max);
    for (const SceneCamera& camera : scene.cameras) {
      SCOPED_TRACE(camera.model.name);
      EXPECT_EQ(camera.model.width, 1920);
      EXPECT_EQ(camera.model.height, 1080);
      const std::optional<Eigen::Vector2d> uv = camera.model.Project(centre);
      ASSERT_TRUE(uv.has_value());
      EXPECT_GE(uv->x(), 0.0);
      EXPECT_LE(uv->x(), camera.model.width - 1.0);
      EXPECT_GE(uv->y(), 0.0);
      EXPECT_LE(uv->y(), camera.model.height - 1.0);
      // Cameras sit outside the obstacles, looking at the cell.
      for (const Solid& obstacle : scene.obstacles) {
        EXPECT_FALSE(SolidBounds(obstacle.geometry).Contains(camera.model.CentreW()));
      }
    }
    EXPECT_EQ(scene.ObstacleMeshes().size(), scene.obstacles.size());
  }
}

// People move as people do: no part faster than 6 m/s (a walker's swinging
// foot reaches three times the walking speed), and nothing jumps. A heading
// blended the short way round while the path turned through the opposite
// heading once flung a walker's limbs at 400 m/s; an arm turned straight
// from hanging to reaching overhead whipped the hand at 9 m/s.
TEST(ShippedScenesTest, NoPartOfAPersonMovesFasterThanSixMetresPerSecond) {
  for (const fs::path& path : ShippedScenes()) {
    SCOPED_TRACE(path.string());
    const Scene scene = LoadScene(path.string());
    for (const Person& person : scene.people) {
      EXPECT_LE(FastestPartSpeed(person, 0.0, ScriptEndS(person) + 1.0), 6.0) << person.name;
    }
  }
}

TEST(ShippedScenesTest, PeopleStayInTheCellAndClearOfObjects) {
  for (const fs::path& path : ShippedScenes()) {
    SCOPED_TRACE(path.string());
    const Scene scene = LoadScene(path.string());
    std::vector<const Solid*> solids;
    for (const Solid& s : scene.obstacles) solids.push_back(&s);
    for (const Solid& s : scene.foreground_objects) solids.push_back(&s);
    for (const Person& person : scene.people) {
      SCOPED_TRACE(person.name);
      // Checks one feet position; returns false on the first problem so that
      // a bad path reports once.
      auto check = [&](ActionKind kind, const Eigen::Vector3d& p_W, double t_s) {
        // People may enter and leave the cell: their feet stay within
        // kDoorway of the bounds.
        constexpr double kDoorway = 1.0;
        const bool inside = p_W.x() >= scene.bounds.min.x() - kDoorway &&
                            p_W.x() <= scene.bounds.max.x() + kDoorway &&
                            p_W.y() >= scene.bounds.min.y() - kDoorway &&
                            p_W.y() <= scene.bounds.max.y() + kDoorway;
        EXPECT_TRUE(inside) << "feet far outside the bounds at t = " << t_s << " s";
        if (!inside) return false;
        const common::Box3 room = Envelope(person, kind, p_W);
        for (const Solid* solid : solids) {
          if (Overlap(room, SolidBounds(solid->geometry))) {
            ADD_FAILURE() << ActionName(kind) << " at (" << p_W.transpose() << ") t = " << t_s
                          << " s runs into " << solid->name;
            return false;
          }
        }
        return true;
      };
      Eigen::Vector3d p_W = person.start_W;
      bool ok = check(ActionKind::kStand, p_W, 0.0);
      for (const Action& action : person.actions) {
        if (!ok) break;
        ok = check(ActionKind::kStand, p_W, action.start_s);  // Waiting for the action.
        if (action.kind == ActionKind::kWalk || action.kind == ActionKind::kCrawl) {
          double t_s = action.start_s;
          for (const Eigen::Vector3d& waypoint : action.path_W) {
            const double length = (waypoint - p_W).norm();
            const int steps = std::max(1, static_cast<int>(std::ceil(length / 0.05)));
            for (int i = 1; i <= steps && ok; ++i) {
              const double f = static_cast<double>(i) / steps;
              ok = check(action.kind, p_W + f * (waypoint - p_W),
                         t_s + f * length / action.speed_mps);
            }
            t_s += length / action.speed_mps;
            p_W = waypoint;
          }
          EXPECT_NEAR(t_s, action.start_s + action.duration_s, 1e-9);
        } else {
          ok = ok && check(action.kind, p_W, action.start_s);
        }
        if (action.kind == ActionKind::kReach) {
          // The hand goes to free space, within reach of the shoulders.
          const Eigen::Vector3d shoulders_W = p_W + Eigen::Vector3d(0, 0, 0.8 * person.height_m);
          EXPECT_LT((action.target_W - shoulders_W).norm(), 0.6 * person.height_m)
              << action.start_s;
          for (const Solid* solid : solids) {
            common::Box3 grown = SolidBounds(solid->geometry);
            grown.min.array() -= 0.05;
            grown.max.array() += 0.05;
            EXPECT_FALSE(grown.Contains(action.target_W))
                << "reach at " << action.start_s << " s into " << solid->name;
          }
        }
      }
    }
  }
}

/// Distance from p_W to the solid (0 inside); meshes by their bounding box,
/// which can only make the distance smaller.
double DistanceToSolid(const SolidGeometry& geometry, const Eigen::Vector3d& p_W) {
  auto to_box = [](const Eigen::Vector3d& centre, const Eigen::Vector3d& half,
                   const Eigen::Matrix3d& R_WB, const Eigen::Vector3d& p) {
    const Eigen::Vector3d q = R_WB.transpose() * (p - centre);
    return (q.cwiseAbs() - half).cwiseMax(0.0).norm();
  };
  if (const auto* b = std::get_if<BoxSolid>(&geometry)) {
    return to_box(b->centre_W, b->half_extents_m, b->R_WB, p_W);
  }
  if (const auto* c = std::get_if<CylinderSolid>(&geometry)) {
    const Eigen::Vector3d axis = c->b_W - c->a_W;
    const double length = axis.norm();
    const double along = (p_W - c->a_W).dot(axis) / length;
    const double radial = ((p_W - c->a_W) - along * axis / length).norm();
    return std::hypot(std::max(0.0, radial - c->radius_m), std::max({0.0, -along, along - length}));
  }
  if (const auto* s = std::get_if<CapsuleSolid>(&geometry)) {
    const Eigen::Vector3d ab = s->b_W - s->a_W;
    const double f = ab.squaredNorm() > 0.0
                         ? std::clamp((p_W - s->a_W).dot(ab) / ab.squaredNorm(), 0.0, 1.0)
                         : 0.0;
    return std::max(0.0, (s->a_W + f * ab - p_W).norm() - s->radius_m);
  }
  const common::Box3 box = SolidBounds(geometry);
  return to_box(0.5 * (box.min + box.max), 0.5 * (box.max - box.min), Eigen::Matrix3d::Identity(),
                p_W);
}

/// Points along a body capsule's axis, 2 cm apart or closer.
std::vector<Eigen::Vector3d> AxisSamples(const BodyCapsule& capsule) {
  const int n = std::max(2, static_cast<int>(std::ceil((capsule.b_W - capsule.a_W).norm() / 0.02)));
  std::vector<Eigen::Vector3d> out;
  for (int i = 0; i <= n; ++i) {
    out.push_back(capsule.a_W + (static_cast<double>(i) / n) * (capsule.b_W - capsule.a_W));
  }
  return out;
}

// The same with the posed bodies of the body model: no part of a person goes
// more than 1 cm into an object (feet touch the table they stand on) or into
// another person, at any time of the script.
TEST(ShippedScenesTest, BodiesClearObjectsAndEachOther) {
  constexpr double kTolerance = 0.01;
  constexpr double kStep = 0.1;
  for (const fs::path& path : ShippedScenes()) {
    SCOPED_TRACE(path.string());
    const Scene scene = LoadScene(path.string());
    std::vector<const Solid*> solids;
    for (const Solid& s : scene.obstacles) solids.push_back(&s);
    for (const Solid& s : scene.foreground_objects) solids.push_back(&s);
    double end_s = 0.0;
    for (const Person& person : scene.people) {
      if (!person.actions.empty()) {
        end_s = std::max(end_s, person.actions.back().start_s + person.actions.back().duration_s);
      }
    }
    std::vector<bool> reported(scene.people.size(), false);
    bool pair_reported = false;
    for (double t_s = 0.0; t_s <= end_s + 1.0; t_s += kStep) {
      std::vector<BodyState> bodies;
      for (const Person& person : scene.people) bodies.push_back(EvaluatePerson(person, t_s));
      for (std::size_t i = 0; i < bodies.size(); ++i) {
        for (const BodyCapsule& part : bodies[i].parts) {
          for (const Eigen::Vector3d& p_W : AxisSamples(part)) {
            for (const Solid* solid : solids) {
              const double gap = DistanceToSolid(solid->geometry, p_W) - part.radius_m;
              if (gap < -kTolerance && !reported[i]) {
                reported[i] = true;
                ADD_FAILURE() << scene.people[i].name << "'s " << BodyPartName(part.part) << " is "
                              << -gap << " m inside " << solid->name << " at t = " << t_s << " s";
              }
            }
          }
        }
        for (std::size_t j = i + 1; j < bodies.size() && !pair_reported; ++j) {
          for (const BodyCapsule& a : bodies[i].parts) {
            for (const BodyCapsule& b : bodies[j].parts) {
              for (const Eigen::Vector3d& p : AxisSamples(a)) {
                for (const Eigen::Vector3d& q : AxisSamples(b)) {
                  if ((p - q).norm() - a.radius_m - b.radius_m < -kTolerance && !pair_reported) {
                    pair_reported = true;
                    ADD_FAILURE() << scene.people[i].name << " and " << scene.people[j].name
                                  << " overlap at t = " << t_s << " s";
                  }
                }
              }
            }
          }
        }
      }
    }
  }
}

// The example of docs/scenes.md loads (its mesh path resolves in config/scenes).
TEST(ShippedScenesTest, DocumentationExampleLoads) {
  std::ifstream in(std::string(HG_SOURCE_DIR) + "/docs/scenes.md");
  const std::string doc((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::size_t begin = doc.find("```yaml\n");
  ASSERT_NE(begin, std::string::npos);
  const std::size_t end = doc.find("```", begin + 8);
  ASSERT_NE(end, std::string::npos);
  const Scene scene = ParseScene(doc.substr(begin + 8, end - begin - 8), "docs/scenes.md",
                                 std::string(HG_SOURCE_DIR) + "/config/scenes");
  EXPECT_EQ(scene.cameras.size(), 2u);
  EXPECT_EQ(scene.obstacles.size(), 6u);
  EXPECT_EQ(scene.people.at(0).actions.size(), 5u);
  EXPECT_EQ(scene.people.at(0).actions[3].start_s, 10.0);
}

TEST(ShippedScenesTest, DemoCellMatchesTheBuiltInCell) {
  const Scene scene = LoadScene(std::string(HG_SOURCE_DIR) + "/config/scenes/demo_cell.yaml");
  const std::vector<geometry::CameraModel> reference =
      geometry::LoadCamerasFile(std::string(HG_SOURCE_DIR) + "/config/demo_cell/cameras.yaml");
  ASSERT_EQ(scene.cameras.size(), 4u);
  for (std::size_t i = 0; i < 4; ++i) {
    SCOPED_TRACE(i);
    const geometry::CameraModel& camera = scene.cameras[i].model;
    EXPECT_EQ(camera.name, reference[i].name);
    EXPECT_EQ(camera.width, reference[i].width);
    EXPECT_EQ(camera.K, reference[i].K);
    EXPECT_LT((camera.R_CW - reference[i].R_CW).norm(), 1e-12);
    EXPECT_LT((camera.t_CW - reference[i].t_CW).norm(), 1e-12);
  }
  // The table (top and legs) and the rack, as in config/demo_cell/obstacles.obj.
  const geometry::TriangleMesh reference_obstacles =
      geometry::LoadObj(std::string(HG_SOURCE_DIR) + "/config/demo_cell/obstacles.obj");
  common::Box3 expected;
  expected.min = expected.max = reference_obstacles.vertices.at(0);
  for (const Eigen::Vector3d& p : reference_obstacles.vertices) {
    expected.min = expected.min.cwiseMin(p);
    expected.max = expected.max.cwiseMax(p);
  }
  ASSERT_EQ(scene.obstacles.size(), 6u);
  common::Box3 all = SolidBounds(scene.obstacles[0].geometry);
  for (const Solid& obstacle : scene.obstacles) {
    const common::Box3 b = SolidBounds(obstacle.geometry);
    all.min = all.min.cwiseMin(b.min);
    all.max = all.max.cwiseMax(b.max);
  }
  EXPECT_LT((all.min - expected.min).norm(), 1e-12);
  EXPECT_LT((all.max - expected.max).norm(), 1e-12);
  // About a minute of motion each.
  ASSERT_EQ(scene.people.size(), 2u);
  for (const Person& person : scene.people) {
    const Action& last = person.actions.back();
    EXPECT_GT(last.start_s + last.duration_s, 55.0) << person.name;
  }
}

TEST(ShippedScenesTest, PaperCellHasItsParts) {
  const Scene scene = LoadScene(std::string(HG_SOURCE_DIR) + "/config/scenes/paper_cell.yaml");
  EXPECT_EQ(scene.cameras.size(), 8u);
  EXPECT_EQ(scene.people.size(), 3u);
  ASSERT_EQ(scene.foreground_objects.size(), 1u);
  EXPECT_EQ(scene.foreground_objects[0].name, "crate");
  EXPECT_GT(scene.imaging.light_change_amplitude, 0.0);
  int offsets = 0;
  for (const SceneCamera& camera : scene.cameras) {
    EXPECT_LE(std::abs(camera.time_offset_s), 0.02);
    offsets += camera.time_offset_s != 0.0 ? 1 : 0;
  }
  EXPECT_GE(offsets, 2);
  const auto robot = std::find_if(scene.obstacles.begin(), scene.obstacles.end(),
                                  [](const Solid& s) { return s.name == "robot"; });
  ASSERT_NE(robot, scene.obstacles.end());
  const common::Box3 b = SolidBounds(robot->geometry);
  EXPECT_LT((b.min - Eigen::Vector3d(0.82, 1.02, 0)).norm(), 1e-6);
  EXPECT_LT((b.max - Eigen::Vector3d(1.58, 1.38, 1.0)).norm(), 1e-6);
  for (const Person& person : scene.people) {
    const Action& last = person.actions.back();
    EXPECT_GT(last.start_s + last.duration_s, 55.0) << person.name;
  }
}

}  // namespace
}  // namespace hg::sim
