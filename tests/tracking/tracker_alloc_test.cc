// After warm-up, a tracking cycle allocates nothing: snapshot -> UNKNOWN
// voxels, filters, births and deaths. This file replaces the global operator
// new of tracking_test to count calls while a test asks for it.
#include <atomic>
#include <cstdlib>
#include <new>
#include <vector>

#include <gtest/gtest.h>

#include "support/allocation_counter.h"
#include "tracking/tracker.h"

namespace hg::tracking {
namespace {

using Eigen::Vector3d;

// Occupied runs of the snapshot grid (depth 7 over a 4 m cube) inside the blobs.
void FillSnapshot(const std::vector<Ellipsoid>& blobs, pipeline::OccupancySnapshot* snap) {
  snap->occupied.clear();
  const double cell = 4.0 / 128;
  for (int z = 0; z < 128; ++z) {
    for (int y = 0; y < 128; ++y) {
      int start = -1;
      for (int x = 0; x <= 128; ++x) {
        bool in = false;
        const Vector3d p((x + 0.5) * cell, (y + 0.5) * cell, (z + 0.5) * cell);
        for (const Ellipsoid& b : blobs) in = in || (x < 128 && b.Contains(p));
        if (in && start < 0) start = x;
        if (!in && start >= 0) {
          snap->occupied.push_back({static_cast<std::uint16_t>(start),
                                    static_cast<std::uint16_t>(y), static_cast<std::uint16_t>(z),
                                    static_cast<std::uint16_t>(x - start)});
          start = -1;
        }
      }
    }
  }
}

TEST(TrackerAllocationTest, NoAllocationPerCycleAfterWarmUp) {
  const VoxelGrid g({Vector3d::Zero(), Vector3d(4, 4, 2.2)}, 0.04);
  sim::BoxSolid table;
  table.centre_W = {3.2, 3.2, 0.9};
  table.half_extents_m = {0.4, 0.4, 0.03};
  Tracker tracker(TrackerOptions{},
                  VoxelMap(g, std::vector<VoxelState>(g.size(), VoxelState::kFree)),
                  CollisionWorld({table}));
  // Two people walking towards each other, then one leaves and comes back.
  // The snapshots are built before counting (the pipeline reuses its own).
  const int frames = 90;
  std::vector<pipeline::OccupancySnapshot> snaps(frames);
  for (int f = 0; f < frames; ++f) {
    const double t = f / 30.0;
    std::vector<Ellipsoid> blobs = {{{0.8 + 0.9 * t, 1.8, 0.9}, {0.25, 0.2, 0.85}}};
    if (f < 40 || f >= 75) blobs.push_back({{3.2 - 0.9 * t, 2.25, 0.9}, {0.25, 0.2, 0.85}});
    FillSnapshot(blobs, &snaps[f]);
    snaps[f].bounds = {Vector3d::Zero(), Vector3d::Constant(4.0)};
    snaps[f].depth = 7;
    snaps[f].stamp_ns = static_cast<std::int64_t>(f) * 33'333'333;
  }
  for (int f = 0; f < 10; ++f) tracker.Update(snaps[f]);  // Warm-up: births.
  ASSERT_EQ(tracker.tracks().size(), 2u);
  long allocations = 0;
  {
    const hg::testing::AllocationCounter counter;
    for (int f = 10; f < frames; ++f) tracker.Update(snaps[f]);
    allocations = counter.count();
  }
  EXPECT_EQ(allocations, 0);
  // The counted cycles did the work: a death after the second person left,
  // and a birth when someone came back.
  EXPECT_GE(tracker.stats().deaths, 1u);
  EXPECT_GE(tracker.stats().births, 3u);
}

}  // namespace
}  // namespace hg::tracking
