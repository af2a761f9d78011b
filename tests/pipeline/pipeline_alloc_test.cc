// After warm-up, a fusion cycle and the silhouette step of every frame
// allocate nothing (global operator new counted on every thread), on mask
// frames and on colour frames through the background model.
#include <memory>
#include <vector>

#include <gtest/gtest.h>

#include "common/image.h"
#include "pipeline/pipeline.h"
#include "scene/demo_cell.h"
#include "sim/body.h"
#include "sim/colour_renderer.h"
#include "sim/mask_renderer.h"
#include "sim/scene.h"
#include "support/allocation_counter.h"
#include "support/luma_image.h"

namespace hg::pipeline {
namespace {

sim::Scene SmallScene() {
  sim::Scene scene;
  scene.name = "alloc";
  scene.bounds.min = Eigen::Vector3d(0, 0, 0);
  scene.bounds.max = Eigen::Vector3d(3, 3, 2.5);
  const Eigen::Vector3d target(1.5, 1.5, 0.8);
  const std::vector<Eigen::Vector3d> eyes = {{-0.4, -0.4, 2.4}, {3.4, 3.4, 2.4}, {3.4, -0.4, 2.4}};
  for (std::size_t i = 0; i < eyes.size(); ++i) {
    sim::SceneCamera camera;
    camera.model = scene::LookAtCamera(eyes[i], target, 320, 240, 260);
    camera.model.name = "cam" + std::to_string(i);
    if (i == 1) camera.model.distortion = {-0.08, 0.01, 0, 0, 0};  // Undistortion runs too.
    scene.cameras.push_back(camera);
  }
  sim::Person walker;
  walker.name = "walker";
  walker.start_W = Eigen::Vector3d(0.8, 1.2, 0.0);
  sim::Action walk;
  walk.kind = sim::ActionKind::kWalk;
  walk.speed_mps = 1.2;
  walk.path_W = {{2.2, 1.2, 0.0}, {2.2, 2.0, 0.0}, {0.8, 2.0, 0.0}, {0.8, 1.2, 0.0}};
  walk.duration_s = 10.0;
  walker.actions = {walk};
  scene.people.push_back(walker);
  return scene;
}

enum class Frames { kMask, kColour, kGrey };

void RunAndCount(Frames kind) {
  const bool colour = kind != Frames::kMask;  // Through the background model.
  const sim::Scene scene = SmallScene();
  PipelineOptions options;
  options.bounds = scene.bounds;
  options.depth = 6;
  options.publish_depth = 5;
  options.background.learn_frames = 5;
  std::vector<PipelineCamera> cameras;
  for (const sim::SceneCamera& c : scene.cameras) cameras.push_back({c.model, nullptr, 150});
  Pipeline pipeline(options, std::move(cameras), {}, nullptr);
  std::vector<sim::MaskRenderer> masks;
  std::vector<sim::ColourRenderer> colours;
  for (int c = 0; c < static_cast<int>(scene.cameras.size()); ++c) {
    masks.emplace_back(scene.cameras[c].model, scene.obstacles, scene.foreground_objects,
                       scene.mask_occlusion);
    colours.emplace_back(scene, c);
  }
  // Frames rendered before counting (the renderers are not the pipeline).
  // Warm-up is the first frames only (the background model learns; the
  // pipeline's buffers take their sizes), then the whole sequence is counted,
  // with its larger occupancies, while the consumers hold as many snapshots
  // as they can (the pool is made with room for them and for the most runs a
  // cycle can list). (The octree's node store is reserved when it is made,
  // OctreeAllocationTest.)
  constexpr int kFrames = 30;
  std::vector<std::vector<capture::Frame>> frames(kFrames);
  for (int i = 0; i < kFrames; ++i) {
    const double t = i / 30.0;
    std::vector<sim::BodyState> people;
    if (!colour || i >= options.background.learn_frames) {
      for (const sim::Person& p : scene.people) people.push_back(sim::EvaluatePerson(p, t));
    }
    for (std::size_t c = 0; c < scene.cameras.size(); ++c) {
      capture::Frame f;
      f.stamp_ns = 1'000'000'000LL + i * 1'000'000'000LL / 30;
      f.index = static_cast<std::uint64_t>(i);
      if (colour) {
        f.kind = capture::FrameKind::kRgb;
        colours[c].Render(people, t, f.index, &f.rgb);
        if (kind == Frames::kGrey) {  // Mono8: the texture test on the path too.
          f.kind = capture::FrameKind::kMono;
          testing::LumaOf(f.rgb, &f.grey);
        }
      } else {
        f.kind = capture::FrameKind::kMask;
        masks[c].Render(people, &f.grey);
      }
      frames[i].push_back(std::move(f));
    }
  }
  auto cycle = [&](int i) {
    for (std::size_t c = 0; c < frames[i].size(); ++c) {
      pipeline.Feed(static_cast<int>(c), frames[i][c]);
    }
    return pipeline.Step(frames[i][0].stamp_ns);
  };
  std::size_t listed = 0;
  constexpr int kWarmUp = 8;  // The learning frames and a few with the walker.
  for (int i = 0; i < kWarmUp; ++i) cycle(i);
  // The consumers' holdings: all of the pool but the newest and the one filled.
  std::vector<std::shared_ptr<const OccupancySnapshot>> held(Pipeline::kSnapshotPool - 2);
  held.reserve(held.size());
  std::size_t next_held = 0;
  long feed = 0, step = 0;
  for (int i = 0; i < kFrames; ++i) {
    {
      testing::AllocationCounter counter;
      for (std::size_t c = 0; c < frames[i].size(); ++c) {
        pipeline.Feed(static_cast<int>(c), frames[i][c]);
      }
      feed += counter.count();
    }
    testing::AllocationCounter counter;
    held[next_held] = pipeline.Step(frames[i][0].stamp_ns);
    step += counter.count();
    listed += OccupancySnapshot::Cells(held[next_held]->occupied);
    next_held = (next_held + 1) % held.size();
  }
  const char* name = kind == Frames::kMask ? "mask" : kind == Frames::kColour ? "colour" : "Mono8";
  EXPECT_EQ(feed, 0) << name << " frames, silhouette steps";
  EXPECT_EQ(step, 0) << name << " frames, fusion cycles";
  EXPECT_GT(listed, 0U) << "the walker was not seen: the cycles did nothing";
}

TEST(PipelineAllocationTest, NoAllocationPerCycleOnMaskFrames) { RunAndCount(Frames::kMask); }

TEST(PipelineAllocationTest, NoAllocationPerCycleOnColourFrames) { RunAndCount(Frames::kColour); }

TEST(PipelineAllocationTest, NoAllocationPerCycleOnMono8Frames) { RunAndCount(Frames::kGrey); }

}  // namespace
}  // namespace hg::pipeline
