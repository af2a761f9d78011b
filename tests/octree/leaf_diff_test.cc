#include "octree/leaf_diff.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include <gtest/gtest.h>

#include "scene/shapes.h"
#include "support/random_scene.h"

namespace hg::octree {
namespace {

TEST(LeafDiffTest, CountsKeysMissingFromBefore) {
  EXPECT_EQ(CountNewLeaves({}, {}), 0);
  EXPECT_EQ(CountNewLeaves({1, 2, 3}, {1, 2, 3}), 0);
  EXPECT_EQ(CountNewLeaves({1, 2, 3}, {}), 0);
  EXPECT_EQ(CountNewLeaves({}, {4, 9}), 2);
  EXPECT_EQ(CountNewLeaves({1, 3, 5, 7}, {2, 3, 4, 7, 8}), 3);
}

// A sphere carved by six cameras; `shift` moves it along x.
class LeafDiffSceneTest : public ::testing::Test {
 protected:
  LeafDiffSceneTest() {
    for (int i = 0; i < 6; ++i) {
      const double a = i * M_PI / 3;
      cams_.push_back(testing::LookAtCamera(
          {1 + 3 * std::cos(a), 1 + 3 * std::sin(a), 1.0 + (i % 2)}, {1, 1, 1}, 240, 180, 200));
      trees_.emplace_back(240, 180);
    }
    for (auto& t : trees_) ptrs_.push_back(&t);
  }

  void Show(double shift) {
    const auto masks = testing::RenderMasks(cams_, {scene::Sphere{{0.8 + shift, 1.0, 1.0}, 0.3}});
    for (std::size_t i = 0; i < cams_.size(); ++i) trees_[i].Build(masks[i].View(), 127);
  }

  std::unique_ptr<Octree> MakeTree() const {
    return std::make_unique<Octree>(OctreeConfig{{{0, 0, 0}, {2, 2, 2}}, 6, 1},
                                    testing::MakeViews(cams_, {}));
  }

  std::vector<geometry::CameraModel> cams_;
  std::vector<silhouette::SilhouetteQuadtree> trees_;
  std::vector<const silhouette::SilhouetteQuadtree*> ptrs_;
};

TEST_F(LeafDiffSceneTest, KeysListEveryLeafOnceSorted) {
  auto tree = MakeTree();
  Show(0.0);
  tree->Update(ptrs_);
  const std::vector<std::uint64_t> keys = LeafKeys(*tree);
  EXPECT_EQ(static_cast<std::int64_t>(keys.size()), tree->NumLeaves());
  EXPECT_TRUE(std::is_sorted(keys.begin(), keys.end()));
  EXPECT_EQ(std::adjacent_find(keys.begin(), keys.end()), keys.end());
  EXPECT_EQ(CountNewLeaves({}, keys), tree->NumLeaves());
}

TEST_F(LeafDiffSceneTest, AStillSceneWritesNoLeafAMovingOneSome) {
  auto tree = MakeTree();
  Show(0.0);
  tree->Update(ptrs_);
  const std::vector<std::uint64_t> first = LeafKeys(*tree);
  Show(0.0);
  tree->Update(ptrs_);
  const std::vector<std::uint64_t> still = LeafKeys(*tree);
  EXPECT_EQ(CountNewLeaves(first, still), 0);

  Show(0.05);
  tree->Update(ptrs_);
  const std::vector<std::uint64_t> moved = LeafKeys(*tree);
  const std::int64_t written = CountNewLeaves(still, moved);
  EXPECT_GT(written, 0);
  EXPECT_LT(written, tree->NumLeaves());
  // The count is the tree's, not the path's: a tree built from scratch on the
  // same masks holds the same leaves.
  auto scratch = MakeTree();
  scratch->Update(ptrs_);
  EXPECT_EQ(LeafKeys(*scratch), moved);
  // Moving back restores the first tree's leaves exactly.
  Show(0.0);
  tree->Update(ptrs_);
  EXPECT_EQ(LeafKeys(*tree), first);
}

}  // namespace
}  // namespace hg::octree
