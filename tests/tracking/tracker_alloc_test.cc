// After warm-up, a tracking cycle allocates nothing: snapshot -> UNKNOWN
// voxels, filters, births and deaths. This file replaces the global operator
// new of tracking_test to count calls while a test asks for it.
#include <atomic>
#include <cstdlib>
#include <new>
#include <vector>

#include <gtest/gtest.h>

#include "tracking/tracker.h"

namespace {
std::atomic<bool> g_counting{false};
std::atomic<long> g_allocations{0};
}  // namespace

void* operator new(std::size_t size) {
  if (g_counting.load(std::memory_order_relaxed)) g_allocations.fetch_add(1);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

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
  g_allocations = 0;
  g_counting = true;
  for (int f = 10; f < frames; ++f) tracker.Update(snaps[f]);
  g_counting = false;
  EXPECT_EQ(g_allocations.load(), 0);
  // The counted cycles did the work: a death after the second person left,
  // and a birth when someone came back.
  EXPECT_GE(tracker.stats().deaths, 1u);
  EXPECT_GE(tracker.stats().births, 3u);
}

}  // namespace
}  // namespace hg::tracking
