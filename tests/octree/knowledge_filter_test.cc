#include "octree/knowledge_filter.h"

#include <gtest/gtest.h>

#include "scene/shapes.h"
#include "support/random_scene.h"

namespace hg::octree {
namespace {

struct Carved {
  std::vector<silhouette::SilhouetteQuadtree> trees;
  std::unique_ptr<Octree> tree;
};

Carved Carve(const std::vector<scene::Shape>& objects) {
  const common::Box3 bounds{{0, 0, 0}, {2, 2, 2}};
  std::vector<geometry::CameraModel> cams;
  for (int i = 0; i < 6; ++i) {
    const double a = i * M_PI / 3;
    cams.push_back(testing::LookAtCamera({1 + 3 * std::cos(a), 1 + 3 * std::sin(a), 1.0 + (i % 2)},
                                         {1, 1, 1}, 240, 180, 200));
  }
  const auto masks = testing::RenderMasks(cams, objects);
  Carved out;
  for (const auto& c : cams) out.trees.emplace_back(c.width, c.height);
  std::vector<const silhouette::SilhouetteQuadtree*> ptrs;
  for (std::size_t i = 0; i < cams.size(); ++i) {
    out.trees[i].Build(masks[i].View(), 127);
    ptrs.push_back(&out.trees[i]);
  }
  out.tree = std::make_unique<Octree>(OctreeConfig{bounds, 6, 2}, testing::MakeViews(cams, {}));
  out.tree->Update(ptrs);
  return out;
}

TEST(KnowledgeFilterTest, DropsSmallBlobsKeepsLargeOnes) {
  const scene::Sphere big{{0.6, 0.6, 1.0}, 0.3};
  const scene::Sphere speck{{1.5, 1.5, 1.4}, 0.03};
  const Carved c = Carve({big, speck});
  const KnowledgeFilterResult all = FilterSmallComponents(*c.tree, 0.0);
  EXPECT_EQ(all.dropped_components, 0);
  EXPECT_GE(all.components, 2);
  const KnowledgeFilterResult r = FilterSmallComponents(*c.tree, 0.01);
  EXPECT_GE(r.dropped_components, 1);
  EXPECT_GT(r.dropped_volume_m3, 0.0);
  EXPECT_LT(r.dropped_volume_m3, 0.01 * r.dropped_components);
  EXPECT_EQ(r.StateAt(*c.tree, speck.centre_W), PointState::kFree);
  EXPECT_NE(c.tree->StateAt(speck.centre_W), PointState::kFree);
  EXPECT_EQ(r.StateAt(*c.tree, big.centre_W), PointState::kOccupied);
}

TEST(KnowledgeFilterTest, DiagonalNeighboursFormOneComponent) {
  // Two capsules meeting only at a point: one component, not dropped when the sum is large.
  const scene::Capsule a{{0.5, 0.5, 0.5}, {1.0, 1.0, 1.0}, 0.12};
  const scene::Capsule b{{1.0, 1.0, 1.0}, {1.5, 0.5, 1.5}, 0.12};
  const Carved c = Carve({a, b});
  const KnowledgeFilterResult r = FilterSmallComponents(*c.tree, 0.0);
  const KnowledgeFilterResult big = FilterSmallComponents(*c.tree, 0.02);
  EXPECT_EQ(big.StateAt(*c.tree, {0.5, 0.5, 0.5}), PointState::kOccupied);
  EXPECT_EQ(big.StateAt(*c.tree, {1.5, 0.5, 1.5}), PointState::kOccupied);
  EXPECT_GE(r.components, 1);
}

}  // namespace
}  // namespace hg::octree
