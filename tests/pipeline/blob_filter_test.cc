#include "pipeline/blob_filter.h"

#include <array>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace hg::pipeline {
namespace {

enum : std::uint8_t { kFree = 0, kOccupied = 1, kOccluded = 2 };

// A dense n^3 grid of cell states, x fastest.
struct Grid {
  int n;
  std::vector<std::uint8_t> cells;
  explicit Grid(int size) : n(size), cells(static_cast<std::size_t>(size) * size * size, kFree) {}
  std::uint8_t& at(int x, int y, int z) {
    return cells[x + n * (y + static_cast<std::size_t>(n) * z)];
  }
  [[nodiscard]] std::uint8_t at(int x, int y, int z) const {
    return cells[x + n * (y + static_cast<std::size_t>(n) * z)];
  }
};

// The runs of one state, in the snapshot's order (z, y, then x).
std::vector<GridRun> RunsOf(const Grid& g, std::uint8_t state) {
  std::vector<GridRun> runs;
  for (int z = 0; z < g.n; ++z) {
    for (int y = 0; y < g.n; ++y) {
      for (int x = 0; x < g.n; ++x) {
        if (g.at(x, y, z) != state) continue;
        if (!runs.empty() && runs.back().y == y && runs.back().z == z &&
            runs.back().x + runs.back().length == x) {
          ++runs.back().length;
        } else {
          runs.push_back({static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                          static_cast<std::uint16_t>(z), 1});
        }
      }
    }
  }
  return runs;
}

// The oracle: flood fill of not-free cells over the 26 neighbours, cell by
// cell; returns the grid with the dropped occupied cells made free.
Grid Oracle(const Grid& g, std::size_t min_cells) {
  Grid out = g;
  std::vector<int> label(g.cells.size(), -1);
  for (int start = 0; start < static_cast<int>(g.cells.size()); ++start) {
    if (g.cells[start] == kFree || label[start] >= 0) continue;
    std::vector<int> members{start};
    label[start] = start;
    for (std::size_t k = 0; k < members.size(); ++k) {
      const int c = members[k];
      const int x = c % g.n, y = (c / g.n) % g.n, z = c / (g.n * g.n);
      for (int dz = -1; dz <= 1; ++dz) {
        for (int dy = -1; dy <= 1; ++dy) {
          for (int dx = -1; dx <= 1; ++dx) {
            const int nx = x + dx, ny = y + dy, nz = z + dz;
            if (nx < 0 || ny < 0 || nz < 0 || nx >= g.n || ny >= g.n || nz >= g.n) continue;
            const int o = nx + g.n * (ny + g.n * nz);
            if (g.cells[o] == kFree || label[o] >= 0) continue;
            label[o] = start;
            members.push_back(o);
          }
        }
      }
    }
    std::size_t occupied = 0;
    bool keep = false;
    for (const int c : members) {
      const int x = c % g.n, y = (c / g.n) % g.n, z = c / (g.n * g.n);
      keep = keep || g.cells[c] == kOccluded || x == 0 || y == 0 || z == 0 || x == g.n - 1 ||
             y == g.n - 1 || z == g.n - 1;
      occupied += g.cells[c] == kOccupied;
    }
    if (!keep && occupied < min_cells) {
      for (const int c : members) out.cells[c] = kFree;
    }
  }
  return out;
}

TEST(BlobFilterTest, ASmallIsolatedBlobIsDropped) {
  Grid g(16);
  g.at(5, 5, 5) = g.at(6, 5, 5) = g.at(6, 6, 6) = kOccupied;  // 3 cells, corner-connected.
  for (int x = 9; x < 13; ++x) {
    for (int y = 9; y < 13; ++y) g.at(x, y, 9) = kOccupied;  // 16 cells.
  }
  std::vector<GridRun> occupied = RunsOf(g, kOccupied);
  BlobFilter filter(4, 10);
  const BlobFilterStats stats = filter.Apply(&occupied, {});
  EXPECT_EQ(stats.components, 2);
  EXPECT_EQ(stats.dropped_components, 1);
  EXPECT_EQ(stats.dropped_cells, 3u);
  EXPECT_EQ(OccupancySnapshot::Cells(occupied), 16u);
}

TEST(BlobFilterTest, ComponentsCountTheGroupsHoldingOccupiedCells) {
  Grid g(16);
  g.at(2, 2, 2) = kOccluded;  // Occluded alone: not counted.
  g.at(8, 8, 8) = kOccupied;  // Occupied, touching an occluded cell: one group.
  g.at(9, 9, 9) = kOccluded;
  g.at(12, 4, 4) = kOccupied;  // On its own: a second group.
  std::vector<GridRun> occupied = RunsOf(g, kOccupied);
  const std::vector<GridRun> occluded = RunsOf(g, kOccluded);
  BlobFilter filter(4, 1);
  EXPECT_EQ(filter.Apply(&occupied, occluded).components, 2);
  std::vector<GridRun> none;
  EXPECT_EQ(filter.Apply(&none, occluded).components, 0);
}

TEST(BlobFilterTest, BlobsTouchingUnseenSpaceOrTheBoundsAreKept) {
  // Touching an occluded cell at a corner only.
  Grid g(16);
  g.at(5, 5, 5) = kOccupied;
  g.at(6, 6, 6) = kOccluded;
  // Touching the face x = 0.
  g.at(0, 10, 10) = kOccupied;
  // Touching nothing: dropped.
  g.at(10, 3, 12) = kOccupied;
  std::vector<GridRun> occupied = RunsOf(g, kOccupied);
  const std::vector<GridRun> occluded = RunsOf(g, kOccluded);
  BlobFilter filter(4, 100);
  const BlobFilterStats stats = filter.Apply(&occupied, occluded);
  EXPECT_EQ(stats.dropped_cells, 1u);
  ASSERT_EQ(occupied.size(), 2u);
  EXPECT_EQ(occupied[0].x, 5);
  EXPECT_EQ(occupied[1].x, 0);
}

TEST(BlobFilterTest, EqualsAFloodFillOnRandomGrids) {
  std::size_t dropped = 0;
  std::size_t kept = 0;
  for (std::uint32_t seed = 1; seed <= 40; ++seed) {
    std::mt19937 rng(seed);
    const int depth = 3 + static_cast<int>(seed % 3);  // 8, 16 or 32 cells per axis.
    const int n = 1 << depth;
    Grid g(n);
    // Blobs of random size, some occluded cells, a little scattered noise.
    std::uniform_int_distribution<int> pos(0, n - 1);
    std::uniform_int_distribution<int> size(0, 3);
    const int blobs = 3 + static_cast<int>(seed % 8);
    for (int b = 0; b < blobs; ++b) {
      const int cx = pos(rng), cy = pos(rng), cz = pos(rng), r = size(rng);
      const std::uint8_t state = b % 4 == 3 ? kOccluded : kOccupied;
      for (int z = cz - r; z <= cz + r; ++z) {
        for (int y = cy - r; y <= cy + r; ++y) {
          for (int x = cx - r; x <= cx + r; ++x) {
            if (x < 0 || y < 0 || z < 0 || x >= n || y >= n || z >= n) continue;
            if (rng() % 3 != 0) g.at(x, y, z) = state;
          }
        }
      }
    }
    for (int k = 0; k < n * n / 4; ++k) g.at(pos(rng), pos(rng), pos(rng)) = kOccupied;
    const std::size_t min_cells = 1 + rng() % 40;
    const Grid expected = Oracle(g, min_cells);

    std::vector<GridRun> occupied = RunsOf(g, kOccupied);
    BlobFilter filter(depth, min_cells);
    const BlobFilterStats stats = filter.Apply(&occupied, RunsOf(g, kOccluded));
    EXPECT_EQ(occupied.size(), RunsOf(expected, kOccupied).size()) << "seed " << seed;
    const std::vector<GridRun> want = RunsOf(expected, kOccupied);
    ASSERT_EQ(occupied.size(), want.size()) << "seed " << seed;
    for (std::size_t i = 0; i < want.size(); ++i) {
      EXPECT_TRUE(occupied[i].x == want[i].x && occupied[i].y == want[i].y &&
                  occupied[i].z == want[i].z && occupied[i].length == want[i].length)
          << "seed " << seed << " run " << i;
    }
    EXPECT_EQ(stats.dropped_cells,
              OccupancySnapshot::Cells(RunsOf(g, kOccupied)) - OccupancySnapshot::Cells(want))
        << "seed " << seed;
    dropped += stats.dropped_cells;
    kept += OccupancySnapshot::Cells(want);
    // The same filter object again (buffers reused) gives the same.
    std::vector<GridRun> again = RunsOf(g, kOccupied);
    filter.Apply(&again, RunsOf(g, kOccluded));
    EXPECT_EQ(again.size(), want.size()) << "seed " << seed;
  }
  // The scenes exercise both outcomes.
  EXPECT_GT(dropped, 100u);
  EXPECT_GT(kept, 100u);
}

}  // namespace
}  // namespace hg::pipeline
