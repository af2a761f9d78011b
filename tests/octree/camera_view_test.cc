// The static obstacle relation of a box: the verdict it gives equals the one
// looked up directly, and a clear or a behind box passes that on to its sub-boxes.
#include <random>

#include <gtest/gtest.h>

#include "octree/camera_view.h"
#include "octree/octree.h"
#include "silhouette/quadtree.h"
#include "support/random_scene.h"

namespace hg::octree {
namespace {

TEST(ObstacleRelationTest, SameVerdictAndMonotoneOnSubBoxes) {
  int seen_clear = 0, seen_behind = 0, seen_partial = 0;
  for (int seed = 0; seed < 8; ++seed) {
    testing::RandomSceneOptions opt;
    opt.num_cameras = 4;
    opt.num_objects = 3;
    opt.num_obstacles = 2 + seed % 3;
    const testing::RandomScene scene = testing::MakeRandomScene(500 + seed, opt);
    const auto masks = testing::RenderMasks(scene.cameras, scene.objects);
    const auto views = testing::MakeViews(scene.cameras, scene.obstacles);
    std::mt19937_64 rng(seed);
    for (std::size_t c = 0; c < views.size(); ++c) {
      const CameraView& view = views[c];
      if (!view.has_obstacles()) continue;
      silhouette::SilhouetteQuadtree quadtree(view.width(), view.height());
      quadtree.Build(masks[c].View(), 127);
      for (int trial = 0; trial < 400; ++trial) {
        const int level = std::uniform_int_distribution<int>(2, 6)(rng);
        std::uniform_int_distribution<std::uint32_t> coordinate(0, (1u << level) - 1);
        const Cell cell{level, coordinate(rng), coordinate(rng), coordinate(rng)};
        const common::Box3 box = CellBox(scene.bounds, cell);
        const geometry::Footprint fp = view.projector().Project(box.min, box.max);
        const ObstacleRelation relation = RelateToObstacles(view, fp);
        bool geometric_direct = false, geometric_cached = false;
        const Verdict direct =
            Classify(view, &quadtree, fp, ObstacleRelation::kUnknown, &geometric_direct);
        const Verdict cached = Classify(view, &quadtree, fp, relation, &geometric_cached);
        ASSERT_EQ(direct, cached) << "seed " << seed << " camera " << c;
        ASSERT_EQ(geometric_direct, geometric_cached);
        seen_clear += relation == ObstacleRelation::kClear;
        seen_behind += relation == ObstacleRelation::kBehind;
        seen_partial += relation == ObstacleRelation::kPartial;
        if (relation == ObstacleRelation::kPartial) continue;
        // Clear passes to every sub-box; behind makes every sub-box hidden
        // (a sub-box outside the image is hidden too, and vacuously clear).
        for (std::uint32_t i = 0; i < 8; ++i) {
          const common::Box3 sub = CellBox(scene.bounds, cell.Child(i));
          const geometry::Footprint sub_fp = view.projector().Project(sub.min, sub.max);
          if (relation == ObstacleRelation::kClear) {
            EXPECT_EQ(RelateToObstacles(view, sub_fp), ObstacleRelation::kClear)
                << "seed " << seed << " camera " << c << " child " << i;
          } else {
            bool geometric = false;
            EXPECT_EQ(Classify(view, &quadtree, sub_fp, ObstacleRelation::kUnknown, &geometric),
                      Verdict::kHidden)
                << "seed " << seed << " camera " << c << " child " << i;
          }
        }
      }
    }
  }
  // The random scenes exercise every relation.
  EXPECT_GT(seen_clear, 100);
  EXPECT_GT(seen_behind, 10);
  EXPECT_GT(seen_partial, 100);
}

}  // namespace
}  // namespace hg::octree
