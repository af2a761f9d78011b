// Camera faults on simulated colour frames of the demo cell: people walking
// are no fault; a camera turned by a degree is "moved" and stays so; frozen,
// black and saturated images are recognised.
#include "capture/camera_health.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include <Eigen/Geometry>

#include "sim/colour_renderer.h"
#include "sim/scene.h"

namespace hg::capture {
namespace {

constexpr int kScale = 3;  // Full HD / 3 = 640 x 360.

// The demo cell with its camera 0 scaled down, optionally turned about the
// camera's own vertical axis by `yaw_deg` (the centre stays where it is).
sim::Scene DemoCell(double yaw_deg) {
  sim::Scene scene = sim::LoadScene(std::string(HG_SOURCE_DIR) + "/config/scenes/demo_cell.yaml");
  scene.cameras.resize(1);
  geometry::CameraModel& m = scene.cameras[0].model;
  m.width /= kScale;
  m.height /= kScale;
  m.K.topRows(2) /= kScale;
  const Eigen::Matrix3d turn =
      Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
  m.R_CW = turn * m.R_CW;
  m.t_CW = turn * m.t_CW;
  return scene;
}

class Camera {
 public:
  explicit Camera(double yaw_deg) : scene_(DemoCell(yaw_deg)), renderer_(scene_, 0) {}
  const Frame& At(int index) {
    const double t = 10.0 + index / 30.0;
    std::vector<sim::BodyState> people;
    for (const sim::Person& p : scene_.people) people.push_back(sim::EvaluatePerson(p, t));
    frame_.kind = FrameKind::kRgb;
    renderer_.Render(people, t, static_cast<std::uint64_t>(index), &frame_.rgb);
    frame_.index = static_cast<std::uint64_t>(index);
    return frame_;
  }

 private:
  sim::Scene scene_;
  sim::ColourRenderer renderer_;
  Frame frame_;
};

TEST(CameraHealthTest, PeopleWalkingAreNoFaultAndATurnedCameraIsMoved) {
  Camera installed(0.0), bumped(1.0);
  CameraHealthOptions options;
  options.sample_step_px = 8 / kScale;  // The Full HD grid, in these smaller images.
  CameraHealthMonitor monitor(options);
  double least_kept = 1.0;
  for (int i = 0; i < 60; ++i) {
    ASSERT_EQ(monitor.Check(installed.At(i)), CameraFault::kNone) << "frame " << i;
    if (i >= 10) least_kept = std::min(least_kept, monitor.edges_kept());
  }
  EXPECT_GT(least_kept, 0.7) << "walking people should hide few of the reference edges";
  int first_moved = -1;
  for (int i = 60; i < 90; ++i) {
    if (monitor.Check(bumped.At(i)) == CameraFault::kMoved && first_moved < 0) first_moved = i;
  }
  ASSERT_GE(first_moved, 0) << "edges kept " << monitor.edges_kept();
  EXPECT_LE(first_moved, 60 + options.moved_frames + 1);
  // Moved stays until a reset, even if the view happens to look right again.
  EXPECT_EQ(monitor.Check(installed.At(90)), CameraFault::kMoved);
  monitor.Reset();
  EXPECT_EQ(monitor.Check(installed.At(91)), CameraFault::kNone);
}

TEST(CameraHealthTest, FrozenBlackAndSaturatedImages) {
  Camera camera(0.0);
  CameraHealthMonitor monitor;
  for (int i = 0; i < 12; ++i) ASSERT_EQ(monitor.Check(camera.At(i)), CameraFault::kNone);
  const Frame still = camera.At(12);
  CameraFault fault = CameraFault::kNone;
  int frames = 0;
  while (fault == CameraFault::kNone && frames < 40) {
    fault = monitor.Check(still);
    ++frames;
  }
  EXPECT_EQ(fault, CameraFault::kFrozen);
  EXPECT_EQ(frames, CameraHealthOptions{}.frozen_frames + 1);
  EXPECT_EQ(monitor.Check(camera.At(13)), CameraFault::kNone) << "a new image ends it";

  // A driver cycling through three stale buffers: each frame repeats one of
  // the last few, so from the fourth on they bring nothing new, and the run of
  // repeats ends frozen as a single repeated frame does.
  CameraHealthMonitor cycling;
  const Frame stale[3] = {camera.At(20), camera.At(21), camera.At(22)};
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(cycling.Check(stale[i]), CameraFault::kNone);
    EXPECT_FALSE(cycling.repeated()) << i;
  }
  fault = CameraFault::kNone;
  frames = 0;
  while (fault == CameraFault::kNone && frames < 40) {
    fault = cycling.Check(stale[frames % 3]);
    EXPECT_TRUE(cycling.repeated()) << frames;
    ++frames;
  }
  EXPECT_EQ(fault, CameraFault::kFrozen);
  EXPECT_EQ(frames, CameraHealthOptions{}.frozen_frames);
  // Frames of a live camera never repeat.
  for (int i = 23; i < 40; ++i) {
    cycling.Check(camera.At(i));
    EXPECT_FALSE(cycling.repeated()) << i;
  }
  EXPECT_EQ(cycling.fault(), CameraFault::kNone);

  // As many stale buffers as a GigE source (8) or a V4L2 one at most (32)
  // holds: with a look-back of four frames, a cycle of five or more went
  // unnoticed, and the empty cell of the stale buffers freed the person.
  for (const int buffers : {5, 8, 32}) {
    SCOPED_TRACE(buffers);
    CameraHealthMonitor many;
    std::vector<Frame> ring;
    for (int i = 0; i < buffers; ++i) ring.push_back(camera.At(100 + i));
    for (const Frame& f : ring) EXPECT_EQ(many.Check(f), CameraFault::kNone);
    fault = CameraFault::kNone;
    frames = 0;
    while (fault == CameraFault::kNone && frames < 60) {
      fault = many.Check(ring[static_cast<std::size_t>(frames % buffers)]);
      EXPECT_TRUE(many.repeated()) << frames;
      ++frames;
    }
    EXPECT_EQ(fault, CameraFault::kFrozen);
  }

  Frame black = camera.At(14);
  std::fill(black.rgb.pixels.begin(), black.rgb.pixels.end(), 3);
  EXPECT_EQ(monitor.Check(black), CameraFault::kBlack);
  Frame white = camera.At(15);
  std::fill(white.rgb.pixels.begin(), white.rgb.pixels.end(), 252);
  EXPECT_EQ(monitor.Check(white), CameraFault::kSaturated);
  EXPECT_EQ(monitor.Check(camera.At(16)), CameraFault::kNone);

  // A blank view (a plain wall) has no edges to find a move by: the
  // pipeline warns of it once the reference is taken. The cell has plenty.
  CameraHealthMonitor blank;
  std::mt19937 rng(3);
  for (int i = 0; i < CameraHealthOptions{}.reference_frames; ++i) {
    EXPECT_FALSE(blank.has_reference());
    Frame wall;
    wall.kind = FrameKind::kMono;
    wall.grey = common::ImageU8(320, 180, 0);
    for (auto& p : wall.grey.pixels) p = static_cast<std::uint8_t>(120 + rng() % 5);
    blank.Check(wall);
  }
  EXPECT_TRUE(blank.has_reference());
  EXPECT_LT(blank.reference_edges(), CameraHealthMonitor::kFewEdges);
  EXPECT_TRUE(monitor.has_reference());
  EXPECT_GT(monitor.reference_edges(), 10 * CameraHealthMonitor::kFewEdges);

  // Grey (Mono8) images are checked the same way.
  Frame mono;
  mono.kind = FrameKind::kMono;
  mono.grey = common::ImageU8(64, 48, 0);
  CameraHealthMonitor grey;
  EXPECT_EQ(grey.Check(mono), CameraFault::kBlack);
}

}  // namespace
}  // namespace hg::capture
