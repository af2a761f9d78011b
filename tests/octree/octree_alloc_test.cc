// After warm-up, a frame (quadtree builds and the octree update) allocates nothing.
// Its own test binary: it replaces the global operator new to count calls.
#include <atomic>
#include <cstdlib>
#include <new>

#include <gtest/gtest.h>

#include "octree/octree.h"
#include "silhouette/quadtree.h"
#include "support/allocation_counter.h"
#include "support/random_scene.h"

namespace hg::octree {
namespace {

TEST(OctreeAllocationTest, NoAllocationPerFrameAfterWarmUp) {
  testing::RandomSceneOptions opt;
  opt.num_cameras = 4;
  opt.num_objects = 3;
  opt.num_obstacles = 2;
  testing::RandomScene scene = testing::MakeRandomScene(12, opt);
  // A looping sequence: 12 frames of moving objects, played three times.
  std::vector<std::vector<common::ImageU8>> frames;
  for (int f = 0; f < 12; ++f) {
    const Eigen::Vector3d step(0.04 * std::cos(f * 0.5), 0.03 * std::sin(f * 0.5), 0.0);
    for (auto& obj : scene.objects) obj = scene::Translated(obj, step);
    frames.push_back(testing::RenderMasks(scene.cameras, scene.objects));
  }
  std::vector<silhouette::SilhouetteQuadtree> trees;
  std::vector<const silhouette::SilhouetteQuadtree*> ptrs;
  for (const auto& c : scene.cameras) trees.emplace_back(c.width, c.height);
  for (const auto& t : trees) ptrs.push_back(&t);
  for (const int coarse_first : {0, 3}) {
    OctreeConfig config{scene.bounds, 7, 2};
    config.coarse_first_depth = coarse_first;
    Octree tree(config, testing::MakeViews(scene.cameras, scene.obstacles));
    long allocations_last_pass = -1;
    std::int64_t visited = 0;
    for (int pass = 0; pass < 3; ++pass) {
      long allocations = 0;
      for (const auto& masks : frames) {
        const hg::testing::AllocationCounter counter;
        for (std::size_t c = 0; c < trees.size(); ++c) trees[c].Build(masks[c].View(), 127);
        const UpdateStats stats = tree.Update(ptrs);
        allocations += counter.count();
        visited += stats.nodes_visited;
      }
      if (pass == 2) allocations_last_pass = allocations;
    }
    EXPECT_GT(visited, 10000) << coarse_first;  // The frames did real work.
    EXPECT_EQ(allocations_last_pass, 0) << coarse_first;
  }
}

}  // namespace
}  // namespace hg::octree
