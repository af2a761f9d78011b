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

// A random scene of four cameras.
testing::RandomScene FourCameraScene(std::uint64_t seed, int objects, int obstacles) {
  testing::RandomSceneOptions opt;
  opt.num_cameras = 4;
  opt.num_objects = objects;
  opt.num_obstacles = obstacles;
  return testing::MakeRandomScene(seed, opt);
}

// One quadtree per camera, and the pointers Octree::Update() takes.
struct Quadtrees {
  explicit Quadtrees(const std::vector<geometry::CameraModel>& cameras) {
    for (const auto& c : cameras) trees.emplace_back(c.width, c.height);
    for (const auto& t : trees) ptrs.push_back(&t);
  }
  std::vector<silhouette::SilhouetteQuadtree> trees;
  std::vector<const silhouette::SilhouetteQuadtree*> ptrs;
};

TEST(OctreeAllocationTest, NoAllocationPerFrameAfterWarmUp) {
  testing::RandomScene scene = FourCameraScene(12, 3, 2);
  // A looping sequence: 12 frames of moving objects, played three times.
  std::vector<std::vector<common::ImageU8>> frames;
  for (int f = 0; f < 12; ++f) {
    const Eigen::Vector3d step(0.04 * std::cos(f * 0.5), 0.03 * std::sin(f * 0.5), 0.0);
    for (auto& obj : scene.objects) obj = scene::Translated(obj, step);
    frames.push_back(testing::RenderMasks(scene.cameras, scene.objects));
  }
  Quadtrees q(scene.cameras);
  std::vector<silhouette::SilhouetteQuadtree>& trees = q.trees;
  const std::vector<const silhouette::SilhouetteQuadtree*>& ptrs = q.ptrs;
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

// Objects that walk into parts of the cell where the tree never had nodes
// (new roots among them) still cost no allocation: nodes come from the store
// reserved at construction. Only the first update is warm-up.
TEST(OctreeAllocationTest, NoAllocationWhereObjectsHaveNeverBeen) {
  testing::RandomScene scene = FourCameraScene(21, 2, 1);
  Quadtrees q(scene.cameras);
  // A sweep across the cell: a tenth of its width per frame.
  const Eigen::Vector3d extent = scene.bounds.max - scene.bounds.min;
  const Eigen::Vector3d step(0.1 * extent.x(), 0.05 * extent.y(), 0.0);
  std::vector<std::vector<common::ImageU8>> frames;
  for (auto& obj : scene.objects) obj = scene::Translated(obj, -4.0 * step);
  for (int f = 0; f < 9; ++f) {
    frames.push_back(testing::RenderMasks(scene.cameras, scene.objects));
    for (auto& obj : scene.objects) obj = scene::Translated(obj, step);
  }
  for (const int coarse_first : {0, 3}) {
    OctreeConfig config{scene.bounds, 7, 2};
    config.coarse_first_depth = coarse_first;
    Octree tree(config, testing::MakeViews(scene.cameras, scene.obstacles));
    long allocations = 0;
    std::int64_t visited = 0;
    for (std::size_t f = 0; f < frames.size(); ++f) {
      for (std::size_t c = 0; c < q.trees.size(); ++c) q.trees[c].Build(frames[f][c].View(), 127);
      const hg::testing::AllocationCounter counter;
      const UpdateStats stats = tree.Update(q.ptrs);
      if (f > 0) allocations += counter.count();
      visited += stats.nodes_visited;
      EXPECT_EQ(stats.nodes_unsplit, 0);
    }
    EXPECT_GT(visited, 10000) << coarse_first;
    EXPECT_EQ(allocations, 0) << coarse_first;
  }
}

}  // namespace
}  // namespace hg::octree
