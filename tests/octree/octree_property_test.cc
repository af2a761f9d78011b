// Seeded property tests of the octree against exact ground truth and the dense oracle.
#include <random>
#include <set>

#include <gtest/gtest.h>

#include "octree/octree.h"
#include "scene/exact_mask.h"
#include "silhouette/quadtree.h"
#include "support/dense_carve.h"
#include "support/random_scene.h"

namespace hg::octree {
namespace {

using testing::DenseGrid;
using testing::RandomScene;

struct Quadtrees {
  std::vector<silhouette::SilhouetteQuadtree> trees;
  std::vector<const silhouette::SilhouetteQuadtree*> ptrs;
  explicit Quadtrees(const std::vector<geometry::CameraModel>& cams) {
    for (const auto& c : cams) trees.emplace_back(c.width, c.height);
    for (const auto& t : trees) ptrs.push_back(&t);
  }
  void Build(const std::vector<common::ImageU8>& masks) {
    for (std::size_t i = 0; i < trees.size(); ++i) trees[i].Build(masks[i].View(), 127);
  }
};

std::vector<geometry::ObstacleDepthMap> DepthMaps(const std::vector<CameraView>& views) {
  std::vector<geometry::ObstacleDepthMap> maps;
  bool any = false;
  for (const auto& v : views) any = any || v.has_obstacles();
  if (!any) return maps;
  for (const auto& v : views) {
    geometry::ObstacleDepthMap m = v.depth_map();
    if (m.near_depth.empty()) {  // Camera without obstacle pixels.
      m.width = v.width();
      m.height = v.height();
      m.near_depth.assign(static_cast<std::size_t>(v.width()) * v.height(),
                          geometry::ObstacleDepthMap::kNone);
      m.centre_depth = m.near_depth;
    }
    maps.push_back(std::move(m));
  }
  return maps;
}

std::vector<const common::ImageU8*> Pointers(const std::vector<common::ImageU8>& masks) {
  std::vector<const common::ImageU8*> p;
  for (const auto& m : masks) p.push_back(&m);
  return p;
}

// A point inside the shape within ~1e-9 m of its surface: silhouette edges are
// where an off-by-a-fraction-of-a-pixel footprint would free object space.
Eigen::Vector3d SampleNearSurface(const scene::Shape& shape, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const Eigen::Vector3d inside = scene::SampleInside(shape, [&] { return u01(rng); });
  const Eigen::Vector3d dir =
      Eigen::Vector3d(u01(rng) - 0.5, u01(rng) - 0.5, u01(rng) - 0.5).normalized();
  double lo = 0.0, hi = 10.0;  // inside + lo * dir is inside, + hi * dir is outside.
  while (hi - lo > 1e-10) {
    const double mid = 0.5 * (lo + hi);
    (scene::Contains(shape, inside + mid * dir) ? lo : hi) = mid;
  }
  return inside + lo * dir;
}

// Every point sampled inside an object (half of them at its surface) must not be free.
void ExpectObjectsNotFree(const Octree& tree, const std::vector<scene::Shape>& objects,
                          std::mt19937_64& rng, int samples_per_object) {
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  for (std::size_t o = 0; o < objects.size(); ++o) {
    for (int i = 0; i < samples_per_object; ++i) {
      const Eigen::Vector3d p = i % 2 == 0
                                    ? scene::SampleInside(objects[o], [&] { return u01(rng); })
                                    : SampleNearSurface(objects[o], rng);
      const PointState s = tree.StateAt(p);
      ASSERT_NE(s, PointState::kFree) << "object " << o << " point " << p.transpose();
    }
  }
}

// Octree free set equals the oracle's; the octree's occluded cells are occluded there too.
void ExpectMatchesOracle(const DenseGrid& octree_grid, const DenseGrid& oracle) {
  ASSERT_EQ(octree_grid.states.size(), oracle.states.size());
  std::size_t free_cells = 0;
  for (std::size_t i = 0; i < oracle.states.size(); ++i) {
    const auto a = static_cast<LeafState>(octree_grid.states[i]);
    const auto b = static_cast<LeafState>(oracle.states[i]);
    ASSERT_EQ(a == LeafState::kFree, b == LeafState::kFree) << "cell " << i;
    if (a == LeafState::kOccluded) {
      ASSERT_EQ(b, LeafState::kOccluded) << "cell " << i;
    }
    free_cells += a == LeafState::kFree;
  }
  // The scenes are built so that most of the cell is certified free: a test that
  // passes only because nothing is free would prove nothing.
  EXPECT_GT(free_cells, oracle.states.size() / 4);
}

// Nothing is free in `tree` that the exact result (same depth) keeps occupied or occluded.
void ExpectFreeOnlyWhereExactIsFree(const Octree& tree, const Octree& exact, int frame) {
  const DenseGrid got = testing::Rasterize(tree);
  const DenseGrid want = testing::Rasterize(exact);
  ASSERT_EQ(got.states.size(), want.states.size());
  for (std::size_t i = 0; i < want.states.size(); ++i) {
    if (got.states[i] == static_cast<std::uint8_t>(LeafState::kFree)) {
      ASSERT_EQ(want.states[i], static_cast<std::uint8_t>(LeafState::kFree))
          << "frame " << frame << " cell " << i;
    }
  }
}

// The scene of the moving-sequence tests: five cameras, three objects, two obstacles.
RandomScene SequenceScene(std::uint64_t seed) {
  testing::RandomSceneOptions opt;
  opt.num_cameras = 5;
  opt.num_objects = 3;
  opt.num_obstacles = 2;
  return testing::MakeRandomScene(seed, opt);
}

class RandomSceneTest : public ::testing::TestWithParam<int> {};

TEST_P(RandomSceneTest, ObjectsNeverFreeAndOctreeEqualsDenseCarve) {
  const int seed = GetParam();
  testing::RandomSceneOptions opt;
  opt.num_cameras = 3 + seed % 4;
  opt.num_objects = 1 + seed % 4;
  opt.num_obstacles = (seed % 3 == 0) ? 0 : 1 + seed % 4;
  const RandomScene scene = testing::MakeRandomScene(1000 + seed, opt);
  const auto masks = testing::RenderMasks(scene.cameras, scene.objects);
  const auto views = testing::MakeViews(scene.cameras, scene.obstacles);
  Quadtrees qt(scene.cameras);
  qt.Build(masks);
  // Exact boundaries, so that every cell can be compared with the oracle.
  Octree tree({scene.bounds, 6, 1 + seed % 3, /*boundary_coarsening=*/0}, views);
  const UpdateStats stats = tree.Update(qt.ptrs);
  EXPECT_FALSE(stats.aborted);
  std::mt19937_64 rng(seed);
  ExpectObjectsNotFree(tree, scene.objects, rng, 2000);
  const DenseGrid oracle =
      testing::DenseCarve(scene.bounds, 6, scene.cameras, Pointers(masks), DepthMaps(views));
  ExpectMatchesOracle(testing::Rasterize(tree), oracle);

  // Coarse geometric boundaries only take free space away.
  Octree coarse({scene.bounds, 6, 2, /*boundary_coarsening=*/2}, views);
  coarse.Update(qt.ptrs);
  ExpectObjectsNotFree(coarse, scene.objects, rng, 2000);
  const DenseGrid coarse_grid = testing::Rasterize(coarse);
  for (std::size_t i = 0; i < oracle.states.size(); ++i) {
    if (coarse_grid.states[i] == static_cast<std::uint8_t>(LeafState::kFree)) {
      ASSERT_EQ(oracle.states[i], static_cast<std::uint8_t>(LeafState::kFree)) << "cell " << i;
    }
  }
  EXPECT_LE(coarse.NumNodes(), tree.NumNodes());

  // Free space is certified by a camera that really sees it: for points the
  // octree calls free, some camera sees the point unobstructed on background.
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  int checked = 0;
  for (int i = 0; i < 3000; ++i) {
    const Eigen::Vector3d p(2 * u01(rng), 2 * u01(rng), 2 * u01(rng));
    if (tree.StateAt(p) != PointState::kFree) continue;
    ++checked;
    bool certified = false;
    for (std::size_t c = 0; c < scene.cameras.size() && !certified; ++c) {
      const auto& cam = scene.cameras[c];
      const Eigen::Vector3d pc = cam.ToCamera(p);
      if (pc.z() <= 0) continue;
      const Eigen::Vector2d uv = cam.ProjectPinholeC(pc);
      const int u = static_cast<int>(std::floor(uv.x() + 0.5));
      const int v = static_cast<int>(std::floor(uv.y() + 0.5));
      if (u < 0 || v < 0 || u >= cam.width || v >= cam.height) continue;
      certified = masks[c].At(u, v) <= 127 && testing::VisibleFrom(cam, scene.obstacles, p);
    }
    ASSERT_TRUE(certified) << "free point seen by no camera: " << p.transpose();
  }
  EXPECT_GT(checked, 100);
}

INSTANTIATE_TEST_SUITE_P(Seeds, RandomSceneTest, ::testing::Range(0, 24));

// Moving objects: the incremental octree equals a from-scratch build every
// frame, leaf by leaf, and one thread equals several.
TEST(OctreeSequenceTest, IncrementalEqualsFromScratchAndThreadsAgree) {
  RandomScene scene = SequenceScene(77);
  const auto views = testing::MakeViews(scene.cameras, scene.obstacles);
  Quadtrees qt(scene.cameras);
  Octree incremental({scene.bounds, 7, 1}, views);
  Octree incremental_mt({scene.bounds, 7, 3}, views);
  std::mt19937_64 rng(5);
  const Eigen::Vector3d velocity(0.02, -0.015, 0.01);
  for (int frame = 0; frame < 50; ++frame) {
    for (auto& obj : scene.objects) obj = scene::Translated(obj, velocity);
    const auto masks = testing::RenderMasks(scene.cameras, scene.objects);
    qt.Build(masks);
    const UpdateStats inc = incremental.Update(qt.ptrs);
    incremental_mt.Update(qt.ptrs);
    Octree scratch({scene.bounds, 7, 1}, views);
    // Fresh quadtrees: everything changed.
    Quadtrees fresh(scene.cameras);
    fresh.Build(masks);
    const UpdateStats full = scratch.Update(fresh.ptrs);
    ASSERT_EQ(testing::Leaves(incremental), testing::Leaves(scratch)) << "frame " << frame;
    ASSERT_EQ(testing::Leaves(incremental_mt), testing::Leaves(scratch)) << "frame " << frame;
    if (frame > 0) {
      EXPECT_LT(inc.verdicts_computed, full.verdicts_computed) << frame;
    }
    ExpectObjectsNotFree(incremental, scene.objects, rng, 300);
  }
}

// Quadtrees built several times between two updates (the octree missed
// versions): the changes since the version it used are found, not everything
// recomputed, and the result equals a from-scratch build.
TEST(OctreeSequenceTest, MissedVersionsAreFoundAndNotRecomputedWhole) {
  RandomScene scene = SequenceScene(91);
  const auto views = testing::MakeViews(scene.cameras, scene.obstacles);
  Quadtrees qt(scene.cameras);
  Octree incremental({scene.bounds, 7, 2}, views);
  // The same, but handed new quadtrees every update: everything changed.
  Octree replaced({scene.bounds, 7, 2}, views);
  const Eigen::Vector3d velocity(-0.015, 0.02, 0.005);
  for (int frame = 0; frame < 24; ++frame) {
    // One to three builds per update; one object moves, the others stand.
    const int builds = 1 + frame % 3;
    std::vector<common::ImageU8> masks;
    for (int b = 0; b < builds; ++b) {
      scene.objects[0] = scene::Translated(scene.objects[0], velocity);
      masks = testing::RenderMasks(scene.cameras, scene.objects);
      qt.Build(masks);
    }
    const UpdateStats inc = incremental.Update(qt.ptrs);
    Octree scratch({scene.bounds, 7, 1}, views);
    Quadtrees fresh(scene.cameras);
    fresh.Build(masks);
    scratch.Update(fresh.ptrs);
    ASSERT_EQ(testing::Leaves(incremental), testing::Leaves(scratch)) << "frame " << frame;
    const UpdateStats whole = replaced.Update(fresh.ptrs);
    ASSERT_EQ(testing::Leaves(replaced), testing::Leaves(scratch)) << "frame " << frame;
    if (frame > 0) {
      EXPECT_LT(inc.verdicts_computed, whole.verdicts_computed / 2) << frame;
    }
  }
}

// Aborting at random moments never frees anything the exact result keeps
// occupied, and a completed update afterwards equals a from-scratch build.
TEST(OctreeAbortTest, AbortAnywhereStaysConservativeAndRecovers) {
  testing::RandomSceneOptions opt;
  opt.num_cameras = 4;
  opt.num_objects = 3;
  opt.num_obstacles = 2;
  RandomScene scene = testing::MakeRandomScene(31, opt);
  const auto views = testing::MakeViews(scene.cameras, scene.obstacles);
  Quadtrees qt(scene.cameras);
  Octree tree({scene.bounds, 6, 2}, views);
  std::mt19937_64 rng(9);
  int aborted_frames = 0;
  for (int frame = 0; frame < 40; ++frame) {
    const Eigen::Vector3d step(0.03 * std::sin(frame * 0.3), 0.02, -0.01);
    for (auto& obj : scene.objects) obj = scene::Translated(obj, step);
    const auto masks = testing::RenderMasks(scene.cameras, scene.objects);
    qt.Build(masks);
    UpdateControl control;
    const bool complete = frame % 7 == 6;
    if (!complete) control.node_budget = static_cast<std::int64_t>(rng() % 1500);
    const UpdateStats stats = tree.Update(qt.ptrs, control);
    aborted_frames += stats.aborted;

    Octree exact({scene.bounds, 6, 1}, views);
    Quadtrees fresh(scene.cameras);
    fresh.Build(masks);
    exact.Update(fresh.ptrs);
    ExpectFreeOnlyWhereExactIsFree(tree, exact, frame);
    ExpectObjectsNotFree(tree, scene.objects, rng, 300);
    if (complete) {
      EXPECT_FALSE(stats.aborted);
      ASSERT_EQ(testing::Leaves(tree), testing::Leaves(exact)) << "frame " << frame;
    }
  }
  EXPECT_GT(aborted_frames, 20);
}

// Coarse first: a completed update gives the same leaves as a plain one; an
// update aborted after its coarse pass is conservative and certifies at least
// what a tree of the coarse depth does, whatever was left unrefined.
TEST(OctreeCoarseFirstTest, SameLeavesWhenCompleteAndCoarseResultWhenAborted) {
  RandomScene scene = SequenceScene(44);
  const auto views = testing::MakeViews(scene.cameras, scene.obstacles);
  constexpr int kDepth = 8, kCoarse = 4;
  OctreeConfig config{scene.bounds, kDepth, 2};
  config.coarse_first_depth = kCoarse;
  Octree coarse_first(config, views);
  Octree plain({scene.bounds, kDepth, 2}, views);
  Quadtrees qt(scene.cameras);
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  int aborted_after_coarse = 0;
  for (int frame = 0; frame < 40; ++frame) {
    // In two frames of every four the objects stand still: nothing changes in
    // the masks, and what an abort left unrefined must not come back as it was.
    const Eigen::Vector3d step(0.03 * std::cos(frame * 0.4), -0.02, 0.01);
    if (frame % 4 < 2) {
      for (auto& obj : scene.objects) obj = scene::Translated(obj, step);
    }
    const auto masks = testing::RenderMasks(scene.cameras, scene.objects);
    qt.Build(masks);
    plain.Update(qt.ptrs);
    UpdateControl control;
    const bool complete = frame % 4 == 3;
    if (!complete) control.node_budget = static_cast<std::int64_t>(rng() % 20000);
    const UpdateStats stats = coarse_first.Update(qt.ptrs, control);
    if (complete) {
      ASSERT_FALSE(stats.aborted);
      ASSERT_EQ(stats.refined_level, kDepth);
      ASSERT_EQ(stats.nodes_pending, 0);
      ASSERT_EQ(testing::Leaves(coarse_first), testing::Leaves(plain)) << "frame " << frame;
    }
    ExpectFreeOnlyWhereExactIsFree(coarse_first, plain, frame);
    ExpectObjectsNotFree(coarse_first, scene.objects, rng, 200);
    if (!stats.aborted || stats.refined_level < kCoarse) continue;
    ++aborted_after_coarse;
    EXPECT_GT(stats.nodes_pending, 0);
    // Everything a tree of the coarse depth certifies free is free here.
    Octree coarse({scene.bounds, kCoarse, 1}, views);
    Quadtrees fresh(scene.cameras);
    fresh.Build(masks);
    coarse.Update(fresh.ptrs);
    coarse.ForEachLeaf([&](const Cell& cell, LeafState state) {
      if (state != LeafState::kFree) return;
      const common::Box3 box = CellBox(scene.bounds, cell);
      for (int k = 0; k < 4; ++k) {
        const Eigen::Vector3d t(u01(rng), u01(rng), u01(rng));
        const Eigen::Vector3d p = box.min + t.cwiseProduct(box.max - box.min);
        ASSERT_EQ(coarse_first.StateAt(p), PointState::kFree)
            << "frame " << frame << " point " << p.transpose();
      }
    });
    // Not free, as a volume: pending nodes read occupied where the coarse
    // tree may say occluded.
    auto not_free = [](const Octree& t) {
      return t.Volume(LeafState::kOccupied) + t.Volume(LeafState::kOccluded);
    };
    EXPECT_LE(not_free(coarse_first), not_free(coarse) + 1e-9);
  }
  EXPECT_GT(aborted_after_coarse, 10);
}

// The key level is a pass of its own: some aborted updates end refined to
// exactly it, which without it no update does (passes 3, 5, 7).
TEST(OctreeCoarseFirstTest, PassesReachTheKeyLevelOneLevelAtATime) {
  RandomScene scene = SequenceScene(45);
  const auto views = testing::MakeViews(scene.cameras, scene.obstacles);
  const auto masks = testing::RenderMasks(scene.cameras, scene.objects);
  std::set<int> with_key, without_key;
  for (std::int64_t budget = 0; budget < 20000; budget += 250) {
    for (const int key : {0, 6}) {
      OctreeConfig config{scene.bounds, 7, 1};
      config.coarse_first_depth = 3;
      config.key_level = key;
      Octree tree(config, views);
      Quadtrees qt(scene.cameras);
      qt.Build(masks);
      UpdateControl control;
      control.node_budget = budget;
      const UpdateStats stats = tree.Update(qt.ptrs, control);
      (key == 0 ? without_key : with_key).insert(stats.refined_level);
    }
  }
  // Without a key level: passes 3, 5, 7. With key level 6: 3, 4, 5, 6, 7.
  EXPECT_EQ(without_key.count(4), 0u);
  EXPECT_EQ(without_key.count(6), 0u);
  EXPECT_EQ(with_key.count(4), 1u);
  EXPECT_EQ(with_key.count(5), 1u);
  EXPECT_EQ(with_key.count(6), 1u);
  EXPECT_EQ(with_key.count(7), 1u);  // Budgets large enough to complete.
}

// A lost camera sees nothing: nothing it alone certified stays free.
TEST(OctreeLostCameraTest, LosingACameraOnlyGrowsOccupiedSpace) {
  testing::RandomSceneOptions opt;
  opt.num_cameras = 4;
  opt.num_objects = 2;
  const RandomScene scene = testing::MakeRandomScene(4242, opt);
  const auto masks = testing::RenderMasks(scene.cameras, scene.objects);
  const auto views = testing::MakeViews(scene.cameras, scene.obstacles);
  Quadtrees qt(scene.cameras);
  qt.Build(masks);
  Octree tree({scene.bounds, 6, 2, 0}, views);
  tree.Update(qt.ptrs);
  const DenseGrid before = testing::Rasterize(tree);
  auto lost = qt.ptrs;
  lost[1] = nullptr;
  tree.Update(lost);
  const DenseGrid after = testing::Rasterize(tree);
  std::vector<const common::ImageU8*> oracle_masks = Pointers(masks);
  oracle_masks[1] = nullptr;
  ExpectMatchesOracle(after, testing::DenseCarve(scene.bounds, 6, scene.cameras, oracle_masks, {}));
  std::size_t grown = 0;
  for (std::size_t i = 0; i < before.states.size(); ++i) {
    if (before.states[i] != static_cast<std::uint8_t>(LeafState::kFree)) {
      ASSERT_NE(after.states[i], static_cast<std::uint8_t>(LeafState::kFree));
    }
    grown += before.states[i] != after.states[i];
  }
  EXPECT_GT(grown, 0u);
  // All cameras lost: nothing is free, everything is occluded.
  std::vector<const silhouette::SilhouetteQuadtree*> none(qt.ptrs.size(), nullptr);
  tree.Update(none);
  EXPECT_DOUBLE_EQ(tree.Volume(LeafState::kFree), 0.0);
  EXPECT_NEAR(tree.Volume(LeafState::kOccluded), scene.bounds.Volume(), 1e-9);
  // The camera comes back: the result equals a fresh build again.
  qt.Build(masks);
  tree.Update(qt.ptrs);
  Octree fresh({scene.bounds, 6, 1, 0}, views);
  fresh.Update(qt.ptrs);
  EXPECT_EQ(testing::Leaves(tree), testing::Leaves(fresh));
}

}  // namespace
}  // namespace hg::octree
