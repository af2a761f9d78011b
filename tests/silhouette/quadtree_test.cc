#include "silhouette/quadtree.h"

#include <random>

#include <gtest/gtest.h>

namespace hg::silhouette {
namespace {

// Random blobby mask: a few filled rectangles and scattered single pixels.
common::ImageU8 RandomMask(std::mt19937_64& rng, int w, int h) {
  common::ImageU8 m(w, h, 0);
  std::uniform_int_distribution<int> uu(0, w - 1), vv(0, h - 1);
  for (int k = 0; k < 6; ++k) {
    int u0 = uu(rng), u1 = uu(rng), v0 = vv(rng), v1 = vv(rng);
    if (u0 > u1) std::swap(u0, u1);
    if (v0 > v1) std::swap(v0, v1);
    const std::uint8_t value = static_cast<std::uint8_t>(128 + rng() % 128);
    for (int v = v0; v <= v1; ++v)
      for (int u = u0; u <= u1; ++u) m.At(u, v) = value;
  }
  for (int k = 0; k < 40; ++k) m.At(uu(rng), vv(rng)) = static_cast<std::uint8_t>(rng() % 256);
  return m;
}

Cover BruteCover(const common::ImageU8& m, const geometry::PixelRect& r, std::uint8_t t) {
  int bits = 0;
  for (int v = r.v0; v <= r.v1; ++v)
    for (int u = r.u0; u <= r.u1; ++u) bits |= m.At(u, v) > t ? 2 : 1;
  return static_cast<Cover>(bits);
}

bool BruteChanged(const common::ImageU8& a, std::uint8_t ta, const common::ImageU8& b,
                  std::uint8_t tb, const geometry::PixelRect& r) {
  for (int v = r.v0; v <= r.v1; ++v) {
    for (int u = r.u0; u <= r.u1; ++u) {
      if ((a.At(u, v) > ta) != (b.At(u, v) > tb)) return true;
    }
  }
  return false;
}

geometry::PixelRect RandomRect(std::mt19937_64& rng, int w, int h) {
  std::uniform_int_distribution<int> uu(0, w - 1), vv(0, h - 1);
  int u0 = uu(rng), v0 = vv(rng);
  // Mostly small rectangles (like octree footprints), sometimes large ones.
  const int max_side = (rng() % 4 == 0) ? std::max(w, h) : 12;
  const int u1 = std::min(w - 1, u0 + static_cast<int>(rng() % max_side));
  const int v1 = std::min(h - 1, v0 + static_cast<int>(rng() % max_side));
  return {u0, v0, u1, v1};
}

TEST(QuadtreeTest, QueryEqualsDenseMaskOnRandomMasksAndRects) {
  std::mt19937_64 rng(11);
  for (const auto& [w, h] : std::vector<std::pair<int, int>>{
           {1, 1}, {7, 5}, {64, 48}, {157, 93}, {320, 240}, {1920, 1080}}) {
    SilhouetteQuadtree tree(w, h);
    common::ImageU8 previous(w, h, 0);
    std::uint8_t previous_threshold = 127;
    for (int frame = 0; frame < 4; ++frame) {
      const common::ImageU8 mask = RandomMask(rng, w, h);
      const std::uint8_t threshold = frame == 3 ? 200 : 127;
      tree.Build(mask.View(), threshold);
      for (int q = 0; q < 400; ++q) {
        const geometry::PixelRect r = RandomRect(rng, w, h);
        ASSERT_EQ(tree.Query(r), BruteCover(mask, r, threshold))
            << w << "x" << h << " rect " << r.u0 << "," << r.v0 << " " << r.u1 << "," << r.v1;
        // Flags compare binary masks, so a new threshold counts as a change too.
        const bool expect_changed =
            frame == 0 || BruteChanged(mask, threshold, previous, previous_threshold, r);
        ASSERT_EQ(tree.AnyChanged(r), expect_changed);
      }
      for (int q = 0; q < 50; ++q) {
        const int u = static_cast<int>(rng() % w), v = static_cast<int>(rng() % h);
        ASSERT_EQ(tree.IsForeground(u, v), mask.At(u, v) > threshold);
      }
      previous = mask;
      previous_threshold = threshold;
    }
  }
}

// ChangedSince(rect, v) is exact at tiles: true iff a tile the rect touches had
// a pixel flip in some build after the v-th (the first build flips every pixel).
TEST(QuadtreeTest, ChangedSinceFindsEveryTileChangedAfterTheVersion) {
  std::mt19937_64 rng(29);
  for (const auto& [w, h] : std::vector<std::pair<int, int>>{{157, 93}, {640, 360}}) {
    SilhouetteQuadtree tree(w, h);
    const int tiles_w = (w + 7) / 8, tiles_h = (h + 7) / 8;
    // changed[k][tile]: the tile flipped in build k + 1.
    std::vector<std::vector<bool>> changed;
    common::ImageU8 previous(w, h, 0);
    for (int build = 1; build <= 6; ++build) {
      // Sparse edits, so that many tiles keep still for several builds.
      common::ImageU8 mask = previous;
      std::uniform_int_distribution<int> uu(0, w - 1), vv(0, h - 1);
      for (int k = 0; k < 5; ++k) {
        const int u0 = uu(rng), v0 = vv(rng);
        const std::uint8_t value = (rng() % 2) != 0 ? 255 : 0;
        for (int v = v0; v < std::min(h, v0 + 20); ++v)
          for (int u = u0; u < std::min(w, u0 + 30); ++u) mask.At(u, v) = value;
      }
      tree.Build(mask.View(), 127);
      std::vector<bool> flips(static_cast<std::size_t>(tiles_w) * tiles_h, build == 1);
      for (int v = 0; v < h; ++v) {
        for (int u = 0; u < w; ++u) {
          if ((mask.At(u, v) > 127) != (previous.At(u, v) > 127)) {
            flips[static_cast<std::size_t>(v / 8) * tiles_w + u / 8] = true;
          }
        }
      }
      changed.push_back(flips);
      previous = mask;
      for (int q = 0; q < 500; ++q) {
        const geometry::PixelRect r = RandomRect(rng, w, h);
        const std::uint64_t since = rng() % (tree.version() + 1);
        bool expect = false;
        for (std::uint64_t k = since; k < tree.version() && !expect; ++k) {
          for (int ty = r.v0 / 8; ty <= r.v1 / 8; ++ty)
            for (int tx = r.u0 / 8; tx <= r.u1 / 8; ++tx)
              expect = expect || changed[k][static_cast<std::size_t>(ty) * tiles_w + tx];
        }
        ASSERT_EQ(tree.ChangedSince(r, since), expect)
            << w << "x" << h << " build " << build << " since " << since << " rect " << r.u0 << ","
            << r.v0 << " " << r.u1 << "," << r.v1;
        if (tree.AnyChanged(r)) {
          ASSERT_TRUE(tree.ChangedSince(r, tree.version() - 1));
        }
      }
    }
    EXPECT_FALSE(tree.ChangedSince({0, 0, w - 1, h - 1}, tree.version()));
    tree.MarkAllChanged();
    EXPECT_TRUE(tree.ChangedSince({3, 3, 3, 3}, tree.version() - 1));
  }
}

TEST(QuadtreeTest, ChangedFlagsFollowSmallEdits) {
  const int w = 200, h = 150;
  common::ImageU8 mask(w, h, 0);
  SilhouetteQuadtree tree(w, h);
  tree.Build(mask.View(), 127);
  EXPECT_TRUE(tree.AnyChanged({0, 0, w - 1, h - 1}));  // First build: all changed.
  tree.Build(mask.View(), 127);
  EXPECT_FALSE(tree.AnyChanged({0, 0, w - 1, h - 1}));
  mask.At(123, 77) = 255;
  tree.Build(mask.View(), 127);
  EXPECT_TRUE(tree.AnyChanged({123, 77, 123, 77}));
  EXPECT_TRUE(tree.AnyChanged({0, 0, w - 1, h - 1}));
  EXPECT_FALSE(tree.AnyChanged({124, 77, 199, 149}));
  EXPECT_FALSE(tree.AnyChanged({0, 0, 122, 149}));
  EXPECT_EQ(tree.Query({123, 77, 123, 77}), Cover::kForeground);
  EXPECT_EQ(tree.Query({120, 70, 130, 80}), Cover::kMixed);
  EXPECT_EQ(tree.Query({0, 0, 100, 100}), Cover::kBackground);
  tree.MarkAllChanged();
  EXPECT_TRUE(tree.AnyChanged({5, 5, 5, 5}));
  EXPECT_EQ(tree.version(), 3u);
}

TEST(QuadtreeTest, WholeImageQueriesAtFullHd) {
  const int w = 1920, h = 1080;
  common::ImageU8 mask(w, h, 255);
  SilhouetteQuadtree tree(w, h);
  tree.Build(mask.View(), 127);
  EXPECT_EQ(tree.Query({0, 0, w - 1, h - 1}), Cover::kForeground);
  mask.At(w - 1, h - 1) = 0;
  tree.Build(mask.View(), 127);
  EXPECT_EQ(tree.Query({0, 0, w - 1, h - 1}), Cover::kMixed);
  EXPECT_EQ(tree.Query({0, 0, w - 2, h - 1}), Cover::kForeground);
  EXPECT_EQ(tree.Query({w - 1, h - 1, w - 1, h - 1}), Cover::kBackground);
}

}  // namespace
}  // namespace hg::silhouette
