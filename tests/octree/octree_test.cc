#include "octree/octree.h"

#include <random>

#include <gtest/gtest.h>

#include "scene/exact_mask.h"
#include "silhouette/undistort.h"
#include "support/random_scene.h"

namespace hg::octree {
namespace {

TEST(CellBoxTest, NeighboursShareFacesAndChildrenTileTheParent) {
  const common::Box3 bounds{{-1.3, 0.1, 0.0}, {2.7, 4.1, 3.3}};
  for (int level = 0; level <= 10; ++level) {
    const std::uint32_t n = 1u << level;
    const common::Box3 last = CellBox(bounds, {level, n - 1, n - 1, n - 1});
    EXPECT_EQ(last.max, bounds.max);
    const common::Box3 a = CellBox(bounds, {level, n / 3, 0, 0});
    const common::Box3 b = CellBox(bounds, {level, n / 3 + 1, 0, 0});
    EXPECT_EQ(a.max.x(), b.min.x());
    if (level < 10) {
      const common::Box3 parent = CellBox(bounds, {level, n / 3, n / 2, 0});
      const common::Box3 c0 = CellBox(bounds, {level + 1, 2 * (n / 3), 2 * (n / 2), 0});
      const common::Box3 c7 = CellBox(bounds, {level + 1, 2 * (n / 3) + 1, 2 * (n / 2) + 1, 1});
      EXPECT_EQ(parent.min, c0.min);
      EXPECT_EQ(parent.max, c7.max);
    }
  }
}

// A person-sized object under a table, with every camera above the table top:
// no camera sees it, so it must be occluded, never free.
TEST(OctreeOcclusionTest, ObjectSeenOnlyThroughObstacleIsOccluded) {
  const common::Box3 bounds{{0, 0, 0}, {4, 4, 2.5}};
  std::vector<geometry::CameraModel> cams;
  const Eigen::Vector3d target(2, 2, 0.8);
  for (int i = 0; i < 4; ++i) {
    const double a = M_PI / 4 + i * M_PI / 2;
    cams.push_back(testing::LookAtCamera({2 + 1.9 * std::cos(a), 2 + 1.9 * std::sin(a), 2.5},
                                         target, 200, 150, 120));
  }
  const std::vector<geometry::TriangleMesh> table = {
      geometry::TriangleMesh::Box({1.0, 1.0, 0.75}, {3.0, 3.0, 0.8})};
  const scene::Shape hidden = scene::Capsule{{1.8, 2.0, 0.2}, {2.2, 2.0, 0.2}, 0.15};
  const scene::Shape visible = scene::Sphere{{0.5, 0.5, 1.5}, 0.2};
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  // Precondition of the test: every point of the hidden object is hidden from every camera.
  for (int i = 0; i < 500; ++i) {
    const Eigen::Vector3d p = scene::SampleInside(hidden, [&] { return u01(rng); });
    for (const auto& c : cams) ASSERT_FALSE(testing::VisibleFrom(c, table, p));
  }
  // The cameras see the table top, not the object: the masks hold only the visible object.
  const auto masks = testing::RenderMasks(cams, {visible});
  std::vector<silhouette::SilhouetteQuadtree> trees;
  for (const auto& c : cams) trees.emplace_back(c.width, c.height);
  std::vector<const silhouette::SilhouetteQuadtree*> ptrs;
  for (std::size_t i = 0; i < cams.size(); ++i) {
    trees[i].Build(masks[i].View(), 127);
    ptrs.push_back(&trees[i]);
  }
  Octree tree({bounds, 7, 2}, testing::MakeViews(cams, table));
  tree.Update(ptrs);
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d p = scene::SampleInside(hidden, [&] { return u01(rng); });
    ASSERT_EQ(tree.StateAt(p), PointState::kOccluded) << p.transpose();
    const Eigen::Vector3d q = scene::SampleInside(visible, [&] { return u01(rng); });
    ASSERT_EQ(tree.StateAt(q), PointState::kOccupied) << q.transpose();
  }
  // Without the table as an obstacle, the same masks would free the hidden object:
  // the obstacle model is what keeps it.
  Octree naive({bounds, 7, 2}, testing::MakeViews(cams, {}));
  naive.Update(ptrs);
  int freed = 0;
  for (int i = 0; i < 200; ++i) {
    freed +=
        naive.StateAt(scene::SampleInside(hidden, [&] { return u01(rng); })) == PointState::kFree;
  }
  EXPECT_GT(freed, 100);
  EXPECT_GT(tree.Volume(LeafState::kFree), 0.5 * bounds.Volume());
}

// Distorting lenses: masks taken through the lens and undistorted conservatively
// still keep every object point occupied.
TEST(OctreeDistortionTest, DistortedCamerasStayConservative) {
  for (int seed = 0; seed < testing::SoakSeeds(6); ++seed) {
    testing::RandomSceneOptions opt;
    opt.num_cameras = 4;
    opt.num_objects = 3;
    opt.width = 120;
    opt.height = 90;
    testing::RandomScene scene = testing::MakeRandomScene(500 + seed, opt);
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    std::vector<silhouette::SilhouetteQuadtree> trees;
    std::vector<geometry::CameraModel> pinholes;
    for (auto& cam : scene.cameras) {
      cam.distortion = {-0.3 + 0.4 * u01(rng), 0.05 * (u01(rng) - 0.5), 0.002 * (u01(rng) - 0.5),
                        0.002 * (u01(rng) - 0.5), 0.01 * (u01(rng) - 0.5)};
      const common::ImageU8 seen = scene::RenderExactDistortedMask(cam, scene.objects);
      silhouette::ConservativeUndistorter undistort(cam);
      common::ImageU8 straight(cam.width, cam.height);
      undistort.Apply(seen.View(), 127, &straight);
      pinholes.push_back(cam.Pinhole());
      trees.emplace_back(cam.width, cam.height);
      trees.back().Build(straight.View(), 127);
    }
    std::vector<const silhouette::SilhouetteQuadtree*> ptrs;
    for (const auto& t : trees) ptrs.push_back(&t);
    Octree tree({scene.bounds, 6, 1}, testing::MakeViews(pinholes, {}));
    tree.Update(ptrs);
    for (const auto& obj : scene.objects) {
      for (int i = 0; i < 1000; ++i) {
        const Eigen::Vector3d p = scene::SampleInside(obj, [&] { return u01(rng); });
        ASSERT_NE(tree.StateAt(p), PointState::kFree) << "seed " << seed << " " << p.transpose();
      }
    }
    EXPECT_GT(tree.Volume(LeafState::kFree), 0.2 * scene.bounds.Volume());
  }
}

TEST(OctreeTest, DeadlineInThePastAbortsAtOnceAndNothingIsFree) {
  testing::RandomSceneOptions opt;
  const testing::RandomScene scene = testing::MakeRandomScene(8, opt);
  const auto masks = testing::RenderMasks(scene.cameras, scene.objects);
  std::vector<silhouette::SilhouetteQuadtree> trees;
  std::vector<const silhouette::SilhouetteQuadtree*> ptrs;
  for (const auto& c : scene.cameras) trees.emplace_back(c.width, c.height);
  for (std::size_t i = 0; i < trees.size(); ++i) {
    trees[i].Build(masks[i].View(), 127);
    ptrs.push_back(&trees[i]);
  }
  Octree tree({scene.bounds, 6, 2}, testing::MakeViews(scene.cameras, {}));
  UpdateControl control;
  control.deadline = std::chrono::steady_clock::now();
  const UpdateStats stats = tree.Update(ptrs, control);
  EXPECT_TRUE(stats.aborted);
  EXPECT_EQ(stats.verdicts_computed, 0);
  EXPECT_EQ(stats.nodes_pending, 512);
  EXPECT_DOUBLE_EQ(tree.Volume(LeafState::kFree), 0.0);
  std::atomic<bool> abort{true};
  UpdateControl raised;
  raised.abort = &abort;
  EXPECT_TRUE(tree.Update(ptrs, raised).aborted);
  EXPECT_DOUBLE_EQ(tree.Volume(LeafState::kFree), 0.0);
  const UpdateStats done = tree.Update(ptrs);
  EXPECT_FALSE(done.aborted);
  EXPECT_GT(tree.Volume(LeafState::kFree), 0.25 * scene.bounds.Volume());
  EXPECT_EQ(tree.StateAt({5, 5, 5}), PointState::kOutside);
}

TEST(OctreeTest, NoCameraMeansEverythingOccluded) {
  const common::Box3 bounds{{0, 0, 0}, {1, 1, 1}};
  Octree tree({bounds, 4, 1}, {});
  tree.Update({});
  EXPECT_NEAR(tree.Volume(LeafState::kOccluded), 1.0, 1e-12);
  EXPECT_EQ(tree.NumLeaves(), 512);
}

}  // namespace
}  // namespace hg::octree
