#include "tracking/voxel_map.h"

#include <algorithm>
#include <random>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "common/config_error.h"

namespace hg::tracking {
namespace {

using Eigen::Vector3d;

// Binary fractions: the voxel counts are exact.
VoxelGrid SmallGrid() {
  return VoxelGrid({Vector3d(0.125, -0.25, 0.0), Vector3d(1.375, 0.75, 0.75)}, 0.0625);
}

std::vector<VoxelState> RandomStatics(const VoxelGrid& g, std::mt19937_64* rng) {
  std::vector<VoxelState> s(g.size(), VoxelState::kFree);
  std::uniform_int_distribution<int> pick(0, 9);
  for (auto& x : s) {
    const int r = pick(*rng);
    x = r == 0 ? VoxelState::kKnown : (r <= 2 ? VoxelState::kOccluded : VoxelState::kFree);
  }
  return s;
}

TEST(VoxelGridTest, CoversBoundsAndIndexes) {
  const VoxelGrid g = SmallGrid();
  EXPECT_EQ(g.nx(), 20);
  EXPECT_EQ(g.ny(), 16);
  EXPECT_EQ(g.nz(), 12);
  EXPECT_EQ(g.size(), 20u * 16u * 12u);
  const Eigen::Vector3i c = g.Coords(g.Index(3, 7, 11));
  EXPECT_EQ(c, Eigen::Vector3i(3, 7, 11));
  EXPECT_EQ(g.VoxelOf(g.Centre(3, 7, 11)), Eigen::Vector3i(3, 7, 11));
  EXPECT_TRUE(g.covered().Contains(Vector3d(1.375, 0.75, 0.75)));
  // A size that is not a multiple of the voxel: the grid reaches past max.
  const VoxelGrid h({Vector3d::Zero(), Vector3d(1.0, 1.01, 1.0)}, 0.125);
  EXPECT_EQ(h.ny(), 9);
}

TEST(VoxelGridTest, RejectsBadInput) {
  EXPECT_THROW(VoxelGrid({Vector3d::Zero(), Vector3d::Ones()}, 0.0), common::ConfigError);
  EXPECT_THROW(VoxelGrid({Vector3d::Ones(), Vector3d::Zero()}, 0.1), common::ConfigError);
  EXPECT_THROW(VoxelGrid({Vector3d::Zero(), Vector3d(100000, 1, 1)}, 0.1), common::ConfigError);
  const VoxelGrid g = SmallGrid();
  EXPECT_THROW(VoxelMap(g, std::vector<VoxelState>(3)), common::ConfigError);
  EXPECT_THROW(VoxelMap(g, std::vector<VoxelState>(g.size(), VoxelState::kUnknown)),
               common::ConfigError);
}

// Prefix counts of every row and every column, recounted from State().
void ExpectPrefixMatchesStates(const VoxelMap& map) {
  const VoxelGrid& g = map.grid();
  for (int y = 0; y < g.ny(); ++y) {
    for (int x = 0; x < g.nx(); ++x) {
      const RowCounts* p = map.ColumnPrefix(x, y);
      int u = 0, o = 0, k = 0;
      for (int z = 0; z <= g.nz(); ++z) {
        ASSERT_EQ(p[z].unknown(), u) << x << " " << y << " " << z;
        ASSERT_EQ(p[z].occluded(), o);
        ASSERT_EQ(p[z].known(), k);
        if (z == g.nz()) break;
        const VoxelState s = map.State(x, y, z);
        u += s == VoxelState::kUnknown;
        o += s == VoxelState::kOccluded;
        k += s == VoxelState::kKnown;
      }
    }
  }
  for (int z = 0; z < g.nz(); ++z) {
    for (int y = 0; y < g.ny(); ++y) {
      const RowCounts* p = map.RowPrefix(y, z);
      int u = 0, o = 0, k = 0;
      for (int x = 0; x < g.nx(); ++x) {
        ASSERT_EQ(p[x].unknown(), u);
        ASSERT_EQ(p[x].occluded(), o);
        ASSERT_EQ(p[x].known(), k);
        const VoxelState s = map.State(x, y, z);
        u += s == VoxelState::kUnknown;
        o += s == VoxelState::kOccluded;
        k += s == VoxelState::kKnown;
      }
      ASSERT_EQ(p[g.nx()].unknown(), u);
      ASSERT_EQ(p[g.nx()].occluded(), o);
      ASSERT_EQ(p[g.nx()].known(), k);
    }
  }
}

TEST(VoxelMapTest, IncrementalUpdatesEqualFromScratch) {
  std::mt19937_64 rng(11);
  const VoxelGrid g = SmallGrid();
  const std::vector<VoxelState> statics = RandomStatics(g, &rng);
  VoxelMap incremental(g, statics);
  ExpectPrefixMatchesStates(incremental);
  std::uniform_int_distribution<std::uint32_t> voxel(0, static_cast<std::uint32_t>(g.size() - 1));
  std::vector<std::uint32_t> set;
  for (int cycle = 0; cycle < 30; ++cycle) {
    // Keep part of the previous set (moving blobs), add new voxels and repeats.
    std::vector<std::uint32_t> next;
    for (const std::uint32_t i : set) {
      if (rng() % 3 != 0) next.push_back(i);
    }
    const int added = static_cast<int>(rng() % 300);
    for (int k = 0; k < added; ++k) next.push_back(voxel(rng));
    if (!next.empty()) next.push_back(next.front());  // A duplicate.
    set = next;
    incremental.SetUnknown(set);

    VoxelMap scratch(g, statics);
    scratch.SetUnknown(set);
    const std::set<std::uint32_t> expected_unknown = [&] {
      std::set<std::uint32_t> e;
      for (const std::uint32_t i : set) {
        if (statics[i] == VoxelState::kFree) e.insert(i);
      }
      return e;
    }();
    for (std::uint32_t i = 0; i < g.size(); ++i) {
      const VoxelState want = expected_unknown.count(i) != 0 ? VoxelState::kUnknown : statics[i];
      ASSERT_EQ(incremental.State(i), want) << "cycle " << cycle << " voxel " << i;
      ASSERT_EQ(incremental.StaticState(i), statics[i]);
    }
    const auto listed = incremental.unknown_voxels();
    EXPECT_EQ(std::set<std::uint32_t>(listed.begin(), listed.end()), expected_unknown);
    EXPECT_EQ(listed.size(), expected_unknown.size()) << "each voxel listed once";
    for (int z = 0; z < g.nz(); ++z) {
      for (int y = 0; y < g.ny(); ++y) {
        const RowCounts* a = incremental.RowPrefix(y, z);
        const RowCounts* b = scratch.RowPrefix(y, z);
        for (int x = 0; x <= g.nx(); ++x) {
          ASSERT_EQ(a[x].unknown(), b[x].unknown());
          ASSERT_EQ(a[x].occluded(), b[x].occluded());
          ASSERT_EQ(a[x].known(), b[x].known());
        }
      }
    }
    ExpectPrefixMatchesStates(incremental);
  }
}

TEST(VoxelMapTest, RebuildsOnlyChangedRows) {
  const VoxelGrid g = SmallGrid();
  VoxelMap map(g, std::vector<VoxelState>(g.size(), VoxelState::kFree));
  map.SetUnknown(std::vector<std::uint32_t>{g.Index(1, 2, 3), g.Index(5, 2, 3), g.Index(0, 4, 4)});
  EXPECT_EQ(map.rows_rebuilt_last_update(), 2);
  EXPECT_EQ(map.columns_rebuilt_last_update(), 3);
  // Same set again: nothing changes.
  map.SetUnknown(std::vector<std::uint32_t>{g.Index(5, 2, 3), g.Index(1, 2, 3), g.Index(0, 4, 4)});
  EXPECT_EQ(map.rows_rebuilt_last_update(), 0);
  EXPECT_EQ(map.columns_rebuilt_last_update(), 0);
  // One voxel leaves, one enters another row.
  map.SetUnknown(std::vector<std::uint32_t>{g.Index(1, 2, 3), g.Index(5, 2, 3), g.Index(0, 9, 9)});
  EXPECT_EQ(map.rows_rebuilt_last_update(), 2);
  EXPECT_EQ(map.columns_rebuilt_last_update(), 2);
  EXPECT_EQ(map.State(0, 4, 4), VoxelState::kFree);
  EXPECT_EQ(map.State(0, 9, 9), VoxelState::kUnknown);
  ExpectPrefixMatchesStates(map);
}

// Static labels win over occupancy: an obstacle stays an obstacle, and space
// no camera sees stays OCCLUDED (the reconstruction could not certify it free;
// no camera saw a person there).
TEST(VoxelMapTest, KnownAndOccludedStayStatic) {
  const VoxelGrid g = SmallGrid();
  std::vector<VoxelState> s(g.size(), VoxelState::kFree);
  s[g.Index(2, 2, 2)] = VoxelState::kKnown;
  s[g.Index(3, 2, 2)] = VoxelState::kOccluded;
  VoxelMap map(g, s);
  map.SetUnknown(std::vector<std::uint32_t>{g.Index(2, 2, 2), g.Index(3, 2, 2), g.Index(4, 2, 2)});
  EXPECT_EQ(map.State(2, 2, 2), VoxelState::kKnown);
  EXPECT_EQ(map.State(3, 2, 2), VoxelState::kOccluded);
  EXPECT_EQ(map.State(4, 2, 2), VoxelState::kUnknown);
  ASSERT_EQ(map.unknown_voxels().size(), 1u);
  EXPECT_EQ(map.unknown_voxels()[0], g.Index(4, 2, 2));
  ExpectPrefixMatchesStates(map);
  map.SetUnknown({});
  EXPECT_EQ(map.State(3, 2, 2), VoxelState::kOccluded);
  EXPECT_EQ(map.State(4, 2, 2), VoxelState::kFree);
}

// Space out of every camera's view stays FREE whatever the reconstruction
// says: occupied only because no camera could carve it, it is no evidence.
TEST(VoxelMapTest, OutOfViewNeverBecomesUnknown) {
  const VoxelGrid g = SmallGrid();
  std::vector<std::uint8_t> out_of_view(g.size(), 0);
  out_of_view[g.Index(5, 5, 11)] = 1;
  VoxelMap map(g, std::vector<VoxelState>(g.size(), VoxelState::kFree), out_of_view);
  map.SetUnknown(std::vector<std::uint32_t>{g.Index(5, 5, 11), g.Index(5, 5, 10)});
  EXPECT_EQ(map.State(5, 5, 11), VoxelState::kFree);
  EXPECT_EQ(map.State(5, 5, 10), VoxelState::kUnknown);
  ASSERT_EQ(map.unknown_voxels().size(), 1u);
  ExpectPrefixMatchesStates(map);
  EXPECT_THROW(VoxelMap(g, std::vector<VoxelState>(g.size(), VoxelState::kFree),
                        std::vector<std::uint8_t>(5, 0)),
               common::ConfigError);
}

// The surface under a point: the top of the highest KNOWN voxel below it in
// its column, within reach of the ellipsoid's bottom.
TEST(VoxelMapTest, SupportLayerIsTheTopOfTheObstacleBelow) {
  const VoxelGrid g = SmallGrid();  // Origin z 0, 0.0625 m voxels, 12 layers.
  std::vector<VoxelState> s(g.size(), VoxelState::kFree);
  for (const int z : {1, 4, 5}) s[g.Index(3, 3, z)] = VoxelState::kKnown;
  const VoxelMap map(g, s);
  auto at = [&](int z, double dz) {
    Vector3d p = g.Centre(3, 3, z);
    p.z() += dz;
    return p;
  };
  EXPECT_EQ(map.SupportLayer(at(9, 0.0), 10.0), 6);  // On the top of layers 4-5.
  EXPECT_EQ(map.SupportLayer(at(6, 0.0), 10.0), 6);
  EXPECT_EQ(map.SupportLayer(at(3, 0.0), 10.0), 2);   // Between: on layer 1.
  EXPECT_EQ(map.SupportLayer(at(0, 0.0), 10.0), 0);   // Below everything.
  EXPECT_EQ(map.SupportLayer(at(4, 0.0), 10.0), 0);   // Inside the obstacle.
  EXPECT_EQ(map.SupportLayer(at(11, 1.0), 10.0), 6);  // Above the grid: its top voxel's.
  // The top (z = 6 * 0.0625 = 0.375) out of reach of the ellipsoid's bottom.
  EXPECT_EQ(map.SupportLayer(at(9, 0.0), 0.375), 6);
  EXPECT_EQ(map.SupportLayer(at(9, 0.0), 0.37), 0);
  // Outside the grid in x or y, or below it.
  EXPECT_EQ(map.SupportLayer(g.Centre(3, 3, 9) - Vector3d(1.0, 0.0, 0.0), 10.0), 0);
  EXPECT_EQ(map.SupportLayer(g.Centre(3, 3, 0) - Vector3d(0.0, 0.0, 0.1), 10.0), 0);
  // Another column has no obstacle.
  EXPECT_EQ(map.SupportLayer(g.Centre(4, 3, 9), 10.0), 0);
}

// Snapshot cells map to the voxels they overlap with positive volume.
TEST(VoxelMapTest, SnapshotCellsMapToOverlappingVoxels) {
  std::mt19937_64 rng(5);
  const VoxelGrid g = SmallGrid();
  VoxelMap map(g, std::vector<VoxelState>(g.size(), VoxelState::kFree));
  for (int trial = 0; trial < 5; ++trial) {
    pipeline::OccupancySnapshot snap;
    // A publishing grid that is offset and coarser or finer than the voxels,
    // reaching outside the tracking grid on some sides.
    snap.depth = 3 + trial % 3;
    const int n = 1 << snap.depth;
    snap.bounds.min = Vector3d(0.0137 * trial - 0.1, -0.3313, -0.0271);
    snap.bounds.max = snap.bounds.min + Vector3d(1.2371, 0.9123, 0.7719);
    std::uniform_int_distribution<int> cell(0, n - 1);
    for (int k = 0; k < 40; ++k) {
      pipeline::GridRun r;
      r.x = static_cast<std::uint16_t>(cell(rng));
      r.y = static_cast<std::uint16_t>(cell(rng));
      r.z = static_cast<std::uint16_t>(cell(rng));
      r.length = static_cast<std::uint16_t>(1 + rng() % 4);  // May run past the grid's end.
      snap.occupied.push_back(r);
    }
    map.SetUnknownFromSnapshot(snap);
    const Vector3d size = snap.bounds.Size() / n;
    std::set<std::uint32_t> expected;
    for (const pipeline::GridRun& r : snap.occupied) {
      for (int cx = r.x; cx < std::min(r.x + r.length, n); ++cx) {
        const Vector3d lo = snap.bounds.min + size.cwiseProduct(Vector3d(cx, r.y, r.z));
        const Vector3d hi = lo + size;
        for (int z = 0; z < g.nz(); ++z) {
          for (int y = 0; y < g.ny(); ++y) {
            for (int x = 0; x < g.nx(); ++x) {
              const Vector3d vlo = g.origin() + g.voxel_m() * Vector3d(x, y, z);
              const Vector3d vhi = vlo + Vector3d::Constant(g.voxel_m());
              if ((vhi.array() > lo.array()).all() && (vlo.array() < hi.array()).all()) {
                expected.insert(g.Index(x, y, z));
              }
            }
          }
        }
      }
    }
    const auto got = map.unknown_voxels();
    EXPECT_EQ(std::set<std::uint32_t>(got.begin(), got.end()), expected) << "trial " << trial;
    EXPECT_FALSE(expected.empty());
    ExpectPrefixMatchesStates(map);
  }
}

}  // namespace
}  // namespace hg::tracking
