// Camera faults on simulated colour frames of the demo cell: people walking
// are no fault; a camera turned by a degree is "moved" and stays so, and so is
// one turned, rolled or zoomed by less than the edge grid's step (found by
// registration, on RGB frames and raw Bayer mosaics); frozen, black and
// saturated images are recognised.
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

// The demo cell with its camera 0 scaled down by `scale`, optionally turned
// about the camera's own vertical axis by `yaw_deg` and about its optical axis
// by `roll_deg` (the centre stays where it is), and zoomed by `zoom`.
sim::Scene DemoCell(double yaw_deg, double roll_deg = 0.0, double zoom = 1.0, int scale = kScale) {
  sim::Scene scene = sim::LoadScene(std::string(HG_SOURCE_DIR) + "/config/scenes/demo_cell.yaml");
  scene.cameras.resize(1);
  geometry::CameraModel& m = scene.cameras[0].model;
  m.width /= scale;
  m.height /= scale;
  m.K.topRows(2) /= scale;
  m.K(0, 0) *= zoom;
  m.K(1, 1) *= zoom;
  const Eigen::Matrix3d turn =
      (Eigen::AngleAxisd(roll_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()) *
       Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY()))
          .toRotationMatrix();
  m.R_CW = turn * m.R_CW;
  m.t_CW = turn * m.t_CW;
  return scene;
}

class Camera {
 public:
  explicit Camera(double yaw_deg, double roll_deg = 0.0, double zoom = 1.0, int scale = kScale)
      : scene_(DemoCell(yaw_deg, roll_deg, zoom, scale)), renderer_(scene_, 0) {}
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
  EXPECT_LE(first_moved, 60 + options.moved_checks + 1);
  // Moved stays until a reset, even if the view happens to look right again.
  EXPECT_EQ(monitor.Check(installed.At(90)), CameraFault::kMoved);
  monitor.Reset();
  EXPECT_EQ(monitor.Check(installed.At(91)), CameraFault::kNone);
}

// The raw BayerRG8 mosaic of a colour frame, as a Bayer camera's (kMono).
Frame Mosaic(const Frame& colour) {
  Frame out;
  out.kind = FrameKind::kMono;
  out.index = colour.index;
  out.grey = common::ImageU8(colour.rgb.width, colour.rgb.height);
  for (int v = 0; v < out.grey.height; ++v) {
    for (int u = 0; u < out.grey.width; ++u) {
      out.grey.At(u, v) = colour.rgb.Pixel(u, v)[(u & 1) + (v & 1)];
    }
  }
  return out;
}

// Moves smaller than the edge grid's step (8 px), at 640 x 360 with the Full
// HD options: the edges stay at their samples, so only registration finds
// them. A turn of 0.4 degrees is about 3.6 px here, a roll of 1 degree up to
// 5 px at the patches, a zoom of 2 % up to 7 px; a turn of 0.05 degrees
// (0.45 px) is measured, and is no move.
class RegistrationTest : public ::testing::TestWithParam<bool> {
 protected:
  // Frame i of `camera`, as the raw mosaic for the Bayer case.
  Frame At(Camera& camera, int i) { return GetParam() ? Mosaic(camera.At(i)) : camera.At(i); }
};

TEST_P(RegistrationTest, MovesSmallerThanTheGridAreFound) {
  struct Move {
    const char* what;
    double yaw_deg, roll_deg, zoom;
  };
  const CameraHealthOptions options;  // The Full HD grid, in smaller images.
  Camera installed(0.0);
  // Frames of the installed camera, with people walking, and with the light
  // turned down by a fifth: no fault, and a misalignment well under a pixel.
  CameraHealthMonitor still(options);
  double largest = 0.0;
  int measured = 0;
  for (int i = 0; i < 150; ++i) {
    Frame frame = At(installed, i);
    if (i >= 100) {
      for (std::uint8_t& p : frame.rgb.pixels) p = static_cast<std::uint8_t>(p * 4 / 5);
      for (std::uint8_t& p : frame.grey.pixels) p = static_cast<std::uint8_t>(p * 4 / 5);
    }
    ASSERT_EQ(still.Check(frame), CameraFault::kNone) << "frame " << i;
    if (still.misalignment_px() >= 0.0) {
      largest = std::max(largest, still.misalignment_px());
      ++measured;
    }
  }
  EXPECT_GE(still.reference_patches(), 20);
  EXPECT_GE(measured, 40) << "most registrations should tell";
  EXPECT_LT(largest, 0.5);
  for (const Move& move :
       {Move{"turn 0.4 deg", 0.4, 0.0, 1.0}, Move{"roll 1 deg", 0.0, 1.0, 1.0},
        Move{"zoom 2 %", 0.0, 0.0, 1.02}, Move{"turn 0.05 deg", 0.05, 0.0, 1.0}}) {
    SCOPED_TRACE(move.what);
    const bool small = move.yaw_deg == 0.05;  // 0.45 px: under max_shift_px, not a move.
    Camera bumped(move.yaw_deg, move.roll_deg, move.zoom);
    CameraHealthMonitor monitor(options);
    for (int i = 0; i < 30; ++i) ASSERT_EQ(monitor.Check(At(installed, i)), CameraFault::kNone);
    int first_moved = -1;
    double least_kept = 1.0;
    for (int i = 30; i < 90 && first_moved < 0; ++i) {
      if (monitor.Check(At(bumped, i)) == CameraFault::kMoved) first_moved = i;
      least_kept = std::min(least_kept, monitor.edges_kept());
    }
    if (small) {
      EXPECT_LT(first_moved, 0);
      EXPECT_GT(monitor.misalignment_px(), 0.2);
      EXPECT_LT(monitor.misalignment_px(), 1.0);
      continue;
    }
    ASSERT_GE(first_moved, 0) << "misalignment " << monitor.misalignment_px() << " px";
    EXPECT_LE(first_moved, 30 + options.shift_check_every * (options.moved_checks + 1));
    EXPECT_GT(least_kept, options.min_edges_kept) << "the edge grid alone would have seen it";
    EXPECT_GT(monitor.misalignment_px(), options.max_shift_px);
  }
}

INSTANTIATE_TEST_SUITE_P(Frames, RegistrationTest, ::testing::Values(false, true),
                         [](const ::testing::TestParamInfo<bool>& param) {
                           return param.param ? "BayerMosaic" : "Rgb";
                         });

// A knock that turns the view farther than registration looks (3 degrees:
// about 27 px here): the edges are lost at once, the view is found nowhere,
// and its frames are not used from the first one on.
TEST(CameraHealthTest, ALargeMoveStopsTheFramesAtOnce) {
  Camera installed(0.0), knocked(3.0);
  CameraHealthMonitor monitor;
  for (int i = 0; i < 30; ++i) ASSERT_EQ(monitor.Check(installed.At(i)), CameraFault::kNone);
  for (int i = 30; i < 60; ++i) {
    const CameraFault fault = monitor.Check(knocked.At(i));
    EXPECT_TRUE(monitor.shifted() || fault == CameraFault::kMoved) << "frame " << i;
  }
}

// A small turn between two registrations (which come every third frame) is
// seen on its first frame by the glance at a few patches on the frames
// between: that frame is not used, whichever frame of the three the turn
// falls on.
TEST(CameraHealthTest, AMoveBetweenRegistrationsIsCaughtOnItsFirstFrame) {
  Camera installed(0.0), turned(0.2);  // About 1.6 px.
  // No edges (a threshold no gradient reaches): only registration and the
  // glances watch, so the edge grid cannot trigger a registration.
  CameraHealthOptions options;
  options.edge_threshold = 1000;
  for (int phase = 0; phase < options.shift_check_every; ++phase) {
    SCOPED_TRACE(phase);
    CameraHealthMonitor monitor(options);
    const int turn_at = 30 + phase;
    for (int i = 0; i < turn_at; ++i) ASSERT_EQ(monitor.Check(installed.At(i)), CameraFault::kNone);
    for (int i = turn_at; i < turn_at + 10; ++i) {
      const CameraFault fault = monitor.Check(turned.At(i));
      EXPECT_TRUE(monitor.shifted() || fault == CameraFault::kMoved) << "frame " << i;
    }
  }
}

// A camera turned while its edge reference is still being averaged (frame
// 5 of 10): registration's reference is the first frame, so it is found.
TEST(CameraHealthTest, AMoveWhileTheReferenceIsTakenIsFound) {
  Camera installed(0.0), turned(0.4);
  CameraHealthMonitor monitor;
  const CameraHealthOptions options;
  for (int i = 0; i < 5; ++i) ASSERT_EQ(monitor.Check(installed.At(i)), CameraFault::kNone);
  int first_moved = -1;
  for (int i = 5; i < 60 && first_moved < 0; ++i) {
    if (monitor.Check(turned.At(i)) == CameraFault::kMoved) first_moved = i;
    if (i > 5 + options.shift_check_every) {
      EXPECT_TRUE(monitor.shifted()) << "frame " << i;
    }
  }
  EXPECT_GE(first_moved, 0);
  EXPECT_LE(first_moved, 5 + options.shift_check_every * (options.moved_checks + 1));
}

// A view dimmed to a quarter, or covered for the most part (someone at the
// lens), loses its edges but is no move: registration finds it in place, or,
// covered, cannot tell and holds its frames back until it sees the view
// again. Neither latches "moved".
TEST(CameraHealthTest, ADimmedOrCoveredViewIsNoMove) {
  Camera installed(0.0);
  CameraHealthMonitor monitor;
  int i = 0;
  for (; i < 30; ++i) ASSERT_EQ(monitor.Check(installed.At(i)), CameraFault::kNone);
  for (; i < 60; ++i) {
    Frame frame = installed.At(i);
    for (std::uint8_t& p : frame.rgb.pixels) p = static_cast<std::uint8_t>(p / 4 + 10);
    EXPECT_EQ(monitor.Check(frame), CameraFault::kNone) << "dimmed, frame " << i;
    EXPECT_FALSE(monitor.shifted()) << "dimmed, frame " << i;
    EXPECT_LT(monitor.edges_kept(), CameraHealthOptions{}.min_edges_kept) << "frame " << i;
  }
  for (; i < 90; ++i) {
    Frame frame = installed.At(i);
    for (int v = 0; v < frame.rgb.height; ++v) {
      for (int u = 0; u < frame.rgb.width * 8 / 10; ++u) {
        std::uint8_t* p = frame.rgb.Pixel(u, v);
        p[0] = p[1] = p[2] = static_cast<std::uint8_t>(90 + (u + v) % 3);
      }
    }
    EXPECT_NE(monitor.Check(frame), CameraFault::kMoved) << "covered, frame " << i;
  }
  for (; i < 100; ++i) ASSERT_NE(monitor.Check(installed.At(i)), CameraFault::kMoved);
  EXPECT_FALSE(monitor.shifted()) << "uncovered, the view is in place";
  EXPECT_EQ(monitor.fault(), CameraFault::kNone);
}

// A rack of period 4 px over 40 % of the view: its patches match themselves
// a period away, where a search could settle and read a move of the camera
// that did not happen. They are passed over when the reference is taken.
TEST(CameraHealthTest, ARepetitiveTextureIsNoMove) {
  Camera installed(0.0);
  auto with_rack = [](Frame frame) {
    std::mt19937 rng(static_cast<std::uint32_t>(frame.index));
    std::normal_distribution<double> noise(0.0, 2.0);
    for (int v = 0; v < frame.rgb.height; ++v) {
      for (int u = 0; u < frame.rgb.width * 4 / 10; ++u) {
        const bool upright = u % 4 < 2;
        const bool shelf = v % 12 < 2;
        const double g = (upright ? 160 : 70) + (shelf ? 60 : 0) +
                         20 * std::sin(u * 0.013 + v * 0.021) + noise(rng);
        std::uint8_t* p = frame.rgb.Pixel(u, v);
        p[0] = p[1] = p[2] = static_cast<std::uint8_t>(std::clamp(g, 0.0, 255.0));
      }
    }
    return frame;
  };
  CameraHealthMonitor monitor;
  for (int i = 0; i < 100; ++i) {
    ASSERT_EQ(monitor.Check(with_rack(installed.At(i))), CameraFault::kNone) << "frame " << i;
    ASSERT_FALSE(monitor.shifted()) << "frame " << i << ": " << monitor.misalignment_px() << " px";
  }
  EXPECT_GE(monitor.reference_patches(), ViewRegistration::kFewPatches);
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
