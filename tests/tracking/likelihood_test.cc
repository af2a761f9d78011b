#include "tracking/likelihood.h"

#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace hg::tracking {
namespace {

using Eigen::Vector3d;

// The definition: every voxel of the grid, its centre tested with the
// public predicates.
EllipsoidCounts BruteCounts(const VoxelMap& map, const Ellipsoid& e,
                            const std::vector<HalfSpace>& region, int floor_layer = 0) {
  const VoxelGrid& g = map.grid();
  EllipsoidCounts n;
  for (int z = floor_layer; z < g.nz(); ++z) {
    for (int y = 0; y < g.ny(); ++y) {
      for (int x = 0; x < g.nx(); ++x) {
        const Vector3d p = g.Centre(x, y, z);
        if (!e.Contains(p)) continue;
        switch (map.State(x, y, z)) {
          case VoxelState::kUnknown: {
            bool own = true;
            for (const HalfSpace& h : region) own = own && h.Contains(p);
            (own ? n.unknown : n.foreign_unknown)++;
            break;
          }
          case VoxelState::kOccluded:
            ++n.occluded;
            break;
          case VoxelState::kKnown:
            ++n.known;
            break;
          case VoxelState::kFree:
            ++n.free;
            break;
        }
      }
    }
  }
  // Lattice positions below the grid, any x and y (the ellipsoids of these
  // tests stay within 40 voxels of the grid).
  for (int z = -40; z < floor_layer; ++z) {
    for (int y = -40; y < g.ny() + 40; ++y) {
      for (int x = -40; x < g.nx() + 40; ++x) n.below_floor += e.Contains(g.Centre(x, y, z));
    }
  }
  return n;
}

double BruteScore(const VoxelMap& map, const Ellipsoid& e, const std::vector<HalfSpace>& region,
                  const LikelihoodWeights& w) {
  const VoxelGrid& g = map.grid();
  double sum = 0.0;
  for (int z = 0; z < g.nz(); ++z) {
    for (int y = 0; y < g.ny(); ++y) {
      for (int x = 0; x < g.nx(); ++x) {
        const Vector3d p = g.Centre(x, y, z);
        if (!e.Contains(p)) continue;
        bool own = true;
        for (const HalfSpace& h : region) own = own && h.Contains(p);
        switch (map.State(x, y, z)) {
          case VoxelState::kUnknown:
            sum += own ? w.unknown : w.free;
            break;
          case VoxelState::kOccluded:
            sum += w.occluded;
            break;
          case VoxelState::kKnown:
            sum += w.known;
            break;
          case VoxelState::kFree:
            sum += w.free;
            break;
        }
      }
    }
  }
  return sum + w.below_floor * BruteCounts(map, e, region).below_floor;
}

void ExpectSameCounts(const EllipsoidCounts& a, const EllipsoidCounts& b) {
  EXPECT_EQ(a.unknown, b.unknown);
  EXPECT_EQ(a.foreign_unknown, b.foreign_unknown);
  EXPECT_EQ(a.occluded, b.occluded);
  EXPECT_EQ(a.known, b.known);
  EXPECT_EQ(a.free, b.free);
  EXPECT_EQ(a.below_floor, b.below_floor);
}

VoxelMap RandomMap(const VoxelGrid& g, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<VoxelState> s(g.size(), VoxelState::kFree);
  std::vector<std::uint32_t> unknown;
  for (std::uint32_t i = 0; i < g.size(); ++i) {
    const int r = static_cast<int>(rng() % 10);
    if (r == 0) s[i] = VoxelState::kKnown;
    if (r == 1 || r == 2) s[i] = VoxelState::kOccluded;
    if (rng() % 3 == 0) unknown.push_back(i);
  }
  VoxelMap map(g, s);
  map.SetUnknown(unknown);
  return map;
}

// A random ellipsoid around and partly outside the grid of the random tests
// ((-0.3, 0.2, 0) .. (1.1, 1.3, 0.9)), below its floor too.
Ellipsoid RandomEllipsoid(std::mt19937_64* rng) {
  std::uniform_real_distribution<double> cx(-0.6, 1.4), cy(-0.1, 1.6), cz(-0.3, 1.2);
  std::uniform_real_distribution<double> half_axis(0.02, 0.6);
  const Vector3d centre(cx(*rng), cy(*rng), cz(*rng));
  const Vector3d half(half_axis(*rng), half_axis(*rng), half_axis(*rng));
  return {centre, half};
}

// Every way CountVoxels sums.
constexpr SumAxis kAllAxes[] = {SumAxis::kAuto, SumAxis::kX, SumAxis::kZ, SumAxis::kXScalar,
                                SumAxis::kZScalar};

// A 3 x 3 x 3 grid of 0.1 m voxels and a ball reaching the six face
// neighbours of the centre voxel (distance 0.1 <= 0.11) but not the edge
// neighbours (0.141): seven voxels, states set by hand.
TEST(LikelihoodTest, HandBuiltSum) {
  const VoxelGrid g({Vector3d::Zero(), Vector3d::Constant(0.3)}, 0.1);
  std::vector<VoxelState> s(g.size(), VoxelState::kFree);
  s[g.Index(0, 1, 1)] = VoxelState::kKnown;
  s[g.Index(2, 1, 1)] = VoxelState::kKnown;
  s[g.Index(1, 0, 1)] = VoxelState::kOccluded;
  s[g.Index(0, 0, 0)] = VoxelState::kOccluded;  // Corner: outside the ball.
  VoxelMap map(g, s);
  map.SetUnknown(std::vector<std::uint32_t>{g.Index(1, 1, 1), g.Index(0, 1, 1),  // KNOWN wins.
                                            g.Index(2, 2, 2)});                  // Outside.
  const Ellipsoid ball{Vector3d::Constant(0.15), Vector3d::Constant(0.11)};
  const EllipsoidCounts n = CountVoxels(map, ball);
  EXPECT_EQ(n.unknown, 1);
  EXPECT_EQ(n.known, 2);
  EXPECT_EQ(n.occluded, 1);
  EXPECT_EQ(n.free, 3);
  EXPECT_EQ(n.foreign_unknown, 0);
  const LikelihoodWeights w;  // rho 1, sigma 0.1, tau -5, epsilon -0.1.
  EXPECT_DOUBLE_EQ(Score(n, w), 1.0 + 0.1 - 10.0 - 0.3);

  // The centre voxel belongs to another track: it scores as free space.
  const std::vector<HalfSpace> region = {
      HalfSpace::NearerTo(Vector3d(0.15, 0.15, -1.0), Vector3d(0.15, 0.15, 1.0))};
  const EllipsoidCounts m = CountVoxels(map, ball, region);
  EXPECT_EQ(m.unknown, 0);
  EXPECT_EQ(m.foreign_unknown, 1);
  EXPECT_DOUBLE_EQ(Score(m, w), 0.1 - 10.0 - 0.4);
}

TEST(LikelihoodTest, RandomEllipsoidsMatchBruteForce) {
  const VoxelGrid g({Vector3d(-0.3, 0.2, 0.0), Vector3d(1.1, 1.3, 0.9)}, 0.05);
  const VoxelMap map = RandomMap(g, 3);
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const LikelihoodWeights w{1.0, 0.1, -5.0, -0.1, -3.0};
  for (int trial = 0; trial < 400; ++trial) {
    const Ellipsoid e = RandomEllipsoid(&rng);
    std::vector<HalfSpace> region;
    const int planes = trial % 4;
    for (int k = 0; k < planes; ++k) {
      // Bisectors between the ellipsoid's centre and nearby points, some with
      // normals exactly perpendicular to x (n.x == 0) or to z (n.z == 0).
      Vector3d other = e.centre_W + 0.4 * Vector3d(unit(rng), unit(rng), unit(rng));
      if (k == 1) other.x() = e.centre_W.x();
      if (k == 2) other.z() = e.centre_W.z();
      region.push_back(HalfSpace::NearerTo(e.centre_W, other));
    }
    SCOPED_TRACE(trial);
    const EllipsoidCounts brute = BruteCounts(map, e, region);
    const double brute_score = BruteScore(map, e, region, w);
    for (const SumAxis axis : kAllAxes) {
      SCOPED_TRACE(static_cast<int>(axis));
      const EllipsoidCounts fast = CountVoxels(map, e, region, axis);
      ExpectSameCounts(fast, brute);
      EXPECT_NEAR(Score(fast, w), brute_score, 1e-9);
    }
  }
}

// A floor above the grid's bottom (an obstacle top the ellipsoid stands on):
// every lattice position below it counts as below the floor, whatever its state.
TEST(LikelihoodTest, RaisedFloorMatchesBruteForce) {
  const VoxelGrid g({Vector3d(-0.3, 0.2, 0.0), Vector3d(1.1, 1.3, 0.9)}, 0.05);
  const VoxelMap map = RandomMap(g, 11);
  std::mt19937_64 rng(23);
  std::uniform_int_distribution<int> floor_layer(0, g.nz());
  for (int trial = 0; trial < 300; ++trial) {
    const Ellipsoid e = RandomEllipsoid(&rng);
    const int floor = floor_layer(rng);
    std::vector<HalfSpace> region;
    if (trial % 2 == 1) {
      region.push_back(HalfSpace::NearerTo(e.centre_W, e.centre_W + Vector3d(0.2, 0.1, -0.1)));
    }
    SCOPED_TRACE(testing::Message() << "trial " << trial << " floor " << floor);
    const EllipsoidCounts brute = BruteCounts(map, e, region, floor);
    for (const SumAxis axis : kAllAxes) {
      SCOPED_TRACE(static_cast<int>(axis));
      ExpectSameCounts(CountVoxels(map, e, region, axis, floor), brute);
    }
  }
}

// FloorLayerOf: the obstacle top under the centre, when the ellipsoid's
// bottom reaches near it.
TEST(LikelihoodTest, FloorLayerOfAnEllipsoidOnATable) {
  const VoxelGrid g({Vector3d::Zero(), Vector3d(2.0, 2.0, 2.0)}, 0.05);
  std::vector<VoxelState> s(g.size(), VoxelState::kFree);
  for (int y = 10; y < 30; ++y) {
    for (int x = 10; x < 30; ++x) s[g.Index(x, y, 15)] = VoxelState::kKnown;  // Top 0.75-0.8.
  }
  const VoxelMap map(g, s);
  const Ellipsoid on_top{Vector3d(1.0, 1.0, 1.5), Vector3d(0.25, 0.25, 0.75)};
  EXPECT_EQ(FloorLayerOf(map, on_top, 0.25), 16);
  EXPECT_EQ(FloorLayerOf(map, on_top, 0.0), 0);  // 0.8 > the bottom, 0.75.
  // Standing on the floor beside it, the centre above its edge: out of reach.
  const Ellipsoid beside{Vector3d(1.45, 1.0, 0.9), Vector3d(0.25, 0.25, 0.9)};
  EXPECT_EQ(FloorLayerOf(map, beside, 0.25), 0);
  // Under it.
  const Ellipsoid under{Vector3d(1.0, 1.0, 0.35), Vector3d(0.5, 0.3, 0.35)};
  EXPECT_EQ(FloorLayerOf(map, under, 0.25), 0);
}

// Voxel centres exactly on the surface and on the bisector planes: the fast
// path must take the same side as the predicates.
TEST(LikelihoodTest, BoundaryTiesMatchBruteForce) {
  const VoxelGrid g({Vector3d::Zero(), Vector3d(1.0, 1.0, 1.0)}, 0.0625);
  const VoxelMap map = RandomMap(g, 8);
  for (int cx = 3; cx < 13; ++cx) {
    for (int a = 1; a <= 6; ++a) {
      const Vector3d centre = g.Centre(cx, 8, 7);
      const Ellipsoid e{centre, Vector3d(a * 0.0625, (a + 1) * 0.0625, 0.25)};
      // The bisector of two points symmetric about the plane x = CentreX(cx + 1).
      const Vector3d mid = g.Centre(cx + 1, 8, 7);
      const std::vector<HalfSpace> region = {
          HalfSpace::NearerTo(mid - Vector3d(0.1, 0.0, 0.0), mid + Vector3d(0.1, 0.0, 0.0)),
          HalfSpace::NearerTo(mid + Vector3d(0.0, 0.0, 0.125), mid + Vector3d(0.0, 0.0, 0.375))};
      SCOPED_TRACE(testing::Message() << "cx " << cx << " a " << a);
      for (const SumAxis axis : {SumAxis::kX, SumAxis::kZ, SumAxis::kXScalar, SumAxis::kZScalar}) {
        SCOPED_TRACE(static_cast<int>(axis));
        ExpectSameCounts(CountVoxels(map, e, {}, axis), BruteCounts(map, e, {}));
        ExpectSameCounts(CountVoxels(map, e, region, axis), BruteCounts(map, e, region));
      }
    }
  }
}

// Space below the grid is floor: an ellipsoid reaching through it pays for
// every lattice position there, also beyond the grid's sides.
TEST(LikelihoodTest, BelowTheFloorCounts) {
  const VoxelGrid g({Vector3d::Zero(), Vector3d::Ones()}, 0.125);
  const VoxelMap map(g, std::vector<VoxelState>(g.size(), VoxelState::kFree));
  // A ball of radius 0.2 (1.6 voxels) around the centre of voxel (0, 0, 0):
  // the lattice offsets with di^2 + dj^2 + dk^2 <= 2.56.
  const Ellipsoid ball{Vector3d::Constant(0.0625), Vector3d::Constant(0.2)};
  for (const SumAxis axis : {SumAxis::kX, SumAxis::kZ, SumAxis::kXScalar, SumAxis::kZScalar}) {
    const EllipsoidCounts m = CountVoxels(map, ball, {}, axis);
    EXPECT_EQ(m.below_floor, 5);
    EXPECT_EQ(m.free, 4 + 3);
  }
  const EllipsoidCounts n = CountVoxels(map, ball);
  EXPECT_EQ(n.below_floor, 5);  // Layer -1: (0, 0) and its four side neighbours.
  EXPECT_EQ(n.free, 4 + 3);     // In the grid (i, j >= 0): layer 0 and layer 1.
  LikelihoodWeights w;
  EXPECT_DOUBLE_EQ(Score(n, w), -0.7 - 0.5);  // Below the floor scores as free.
  w.below_floor = -5.0;
  EXPECT_DOUBLE_EQ(Score(n, w), -0.7 - 25.0);
  w.below_floor = 0.0;
  EXPECT_DOUBLE_EQ(Score(n, w), -0.7);
}

TEST(LikelihoodTest, EllipsoidOutsideTheGridCountsNothing) {
  const VoxelGrid g({Vector3d::Zero(), Vector3d::Ones()}, 0.1);
  const VoxelMap map = RandomMap(g, 1);
  const EllipsoidCounts n = CountVoxels(map, {Vector3d(5, 5, 5), Vector3d::Constant(0.5)});
  EXPECT_EQ(n.Total(), 0);
  const EllipsoidCounts m = CountVoxels(map, {Vector3d(0.5, 0.5, 0.5), Vector3d::Zero()});
  EXPECT_EQ(m.Total(), 0);
}

TEST(LikelihoodTest, AppendVoxelsInsideMatchesPredicate) {
  const VoxelGrid g({Vector3d::Zero(), Vector3d(1.0, 1.0, 1.0)}, 0.05);
  const Ellipsoid e{Vector3d(0.1, 0.52, 0.47), Vector3d(0.3, 0.2, 0.35)};
  std::vector<std::uint32_t> got;
  AppendVoxelsInside(g, e, &got);
  std::vector<std::uint32_t> want;
  for (std::uint32_t i = 0; i < g.size(); ++i) {
    const Eigen::Vector3i c = g.Coords(i);
    if (e.Contains(g.Centre(c.x(), c.y(), c.z()))) want.push_back(i);
  }
  EXPECT_EQ(got, want);
}

TEST(LikelihoodTest, HalfSpaceNearerTo) {
  const Vector3d a(1.0, 2.0, 0.5);
  const Vector3d b(2.0, 1.0, 0.9);
  const HalfSpace h = HalfSpace::NearerTo(a, b);
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(-1.0, 3.0);
  for (int k = 0; k < 1000; ++k) {
    const Vector3d p(u(rng), u(rng), u(rng));
    const double da = (p - a).norm();
    const double db = (p - b).norm();
    if (std::abs(da - db) < 1e-9) continue;
    EXPECT_EQ(h.Contains(p), da < db);
  }
}

}  // namespace
}  // namespace hg::tracking
