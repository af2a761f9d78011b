// The simulator facade: cameras in parallel equal cameras one by one, capture
// offsets, ground truth, and every shipped scene renders its people.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <optional>
#include <vector>

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include "scene/demo_cell.h"

#include "sim/simulator.h"

namespace hg::sim {
namespace {

Scene SmallScene() {
  Scene scene;
  scene.name = "small";
  scene.bounds.min = Eigen::Vector3d(0, 0, 0);
  scene.bounds.max = Eigen::Vector3d(3, 3, 2.5);
  const Eigen::Vector3d target(1.5, 1.5, 0.8);
  const std::vector<Eigen::Vector3d> eyes = {{-0.4, -0.4, 2.4}, {3.4, 3.4, 2.4}, {3.4, -0.4, 2.4}};
  for (std::size_t i = 0; i < eyes.size(); ++i) {
    SceneCamera camera;
    camera.model = scene::LookAtCamera(eyes[i], target, 240, 180, 200);
    geometry::CameraModel& m = camera.model;
    m.name = std::string("cam").append(std::to_string(i));
    if (i == 1) m.distortion = {-0.1, 0.02, 0.001, -0.001, 0.0};
    if (i == 2) camera.time_offset_s = 0.04;
    scene.cameras.push_back(camera);
  }
  scene.obstacles.push_back(
      {"table",
       BoxSolid{Eigen::Vector3d(2.3, 0.7, 0.72), Eigen::Vector3d(0.4, 0.35, 0.03),
                Eigen::Matrix3d::Identity()},
       Rgb(0.5F, 0.4F, 0.3F)});
  for (int p = 0; p < 2; ++p) {
    Person person;
    person.name = std::string("p").append(std::to_string(p));
    person.start_W = Eigen::Vector3d(0.7 + p, 0.8, 0.0);
    Action walk;
    walk.kind = ActionKind::kWalk;
    walk.path_W = {Eigen::Vector3d(0.7 + p, 2.3, 0.0)};
    walk.speed_mps = 1.2;
    walk.duration_s = 1.5 / 1.2;
    person.actions.push_back(walk);
    scene.people.push_back(person);
  }
  return scene;
}

TEST(SimulatorTest, ParallelCamerasEqualSequentialAndOffsetsApply) {
  const Scene scene = SmallScene();
  Simulator one(scene, 1);
  Simulator two(scene, 2);
  std::vector<common::ImageU8> a, b;
  for (const double t : {0.0, 0.3, 0.9}) {
    one.RenderMasks(t, &a);
    two.RenderMasks(t, &b);
    ASSERT_EQ(a.size(), 3U);
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(a[c].pixels, b[c].pixels) << "camera " << c << " t " << t;
      // Each camera saw the people at its own capture time.
      const MaskRenderer renderer(scene.cameras[c].model, scene.obstacles, {}, true);
      std::vector<BodyState> people;
      for (const Person& p : scene.people) {
        people.push_back(EvaluatePerson(p, t + scene.cameras[c].time_offset_s));
      }
      common::ImageU8 direct;
      renderer.Render(people, &direct);
      EXPECT_EQ(direct.pixels, a[c].pixels) << "camera " << c << " t " << t;
      long long fg = 0;
      for (const auto v : a[c].pixels) fg += v != 0;
      EXPECT_GT(fg, 200) << "camera " << c << " sees the people";
    }
  }
  // The offset camera differs from what it would have seen without the offset.
  Scene no_offset = scene;
  no_offset.cameras[2].time_offset_s = 0.0;
  Simulator synced(no_offset, 1);
  synced.RenderMasks(0.3, &b);
  one.RenderMasks(0.3, &a);
  EXPECT_NE(a[2].pixels, b[2].pixels);
  EXPECT_EQ(a[0].pixels, b[0].pixels);
}

TEST(SimulatorTest, TruthIsThePoseAtTheFrameTime) {
  const Scene scene = SmallScene();
  const Simulator simulator(scene, 1);
  const FrameTruth truth = simulator.Truth(7, 0.7);
  EXPECT_EQ(truth.frame, 7);
  EXPECT_EQ(truth.time_s, 0.7);
  ASSERT_EQ(truth.people.size(), 2U);
  const BodyState expected = EvaluatePerson(scene.people[1], 0.7);
  EXPECT_EQ(truth.people[1].name, "p1");
  EXPECT_EQ(truth.people[1].state.centre_W, expected.centre_W);
  EXPECT_EQ(truth.people[1].state.parts[0].a_W, expected.parts[0].a_W);
}

TEST(SimulatorTest, ColourFramesAreDeterministicAcrossThreadCounts) {
  const Scene scene = SmallScene();
  Simulator one(scene, 1);
  Simulator two(scene, 2);
  std::vector<common::ImageRgb8> a, b;
  one.RenderColour(0.5, 3, &a);
  two.RenderColour(0.5, 3, &b);
  ASSERT_EQ(a.size(), 3U);
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(a[c].width, 240);
    EXPECT_EQ(a[c].pixels, b[c].pixels) << "camera " << c;
  }
}

// Every shipped scene renders every one of its people: at two times, the
// centre of each person's torso projects onto foreground in some camera's
// mask (seen at that camera's capture time). A person left out of the masks
// would fail this for its scene.
TEST(SimulatorTest, EveryShippedSceneRendersItsPeople) {
  namespace fs = std::filesystem;
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(fs::path(HG_SOURCE_DIR) / "config" / "scenes")) {
    if (entry.path().extension() == ".yaml") files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  ASSERT_GE(files.size(), 5U);
  std::vector<common::ImageU8> masks;
  for (const fs::path& file : files) {
    const Scene scene = LoadScene(file.string());
    EXPECT_FALSE(scene.people.empty()) << file;
    Simulator simulator(scene, 2);
    for (const double t_s : {1.0, 4.0}) {
      simulator.RenderMasks(t_s, &masks);
      for (const Person& person : scene.people) {
        int seen_by = 0;  // Cameras whose mask covers the torso centre.
        for (int c = 0; c < simulator.num_cameras(); ++c) {
          const SceneCamera& camera = scene.cameras[c];
          const BodyState state = EvaluatePerson(person, t_s + camera.time_offset_s);
          const BodyCapsule& torso = state.parts[static_cast<int>(BodyPart::kTorso)];
          const std::optional<Eigen::Vector2d> uv =
              camera.model.Project(0.5 * (torso.a_W + torso.b_W));
          if (!uv) continue;
          const auto u = static_cast<int>(std::lround(uv->x()));
          const auto v = static_cast<int>(std::lround(uv->y()));
          const common::ImageU8& mask = masks[c];
          if (u < 0 || v < 0 || u >= mask.width || v >= mask.height) continue;
          if (mask.At(u, v) != 0) ++seen_by;
        }
        EXPECT_GT(seen_by, 0) << file.filename() << ": " << person.name << " at t = " << t_s
                              << " s";
      }
    }
  }
}

}  // namespace
}  // namespace hg::sim
