#include "tracking/collision.h"

#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

namespace hg::tracking {
namespace {

using Eigen::Vector3d;

double SegSeg(const Vector3d& a, const Vector3d& b, const Vector3d& c, const Vector3d& d) {
  return std::sqrt(SegmentSegmentDistanceSquared(a, b, c, d));
}

// Minimum of f over `samples` + 1 evenly spaced segment parameters: an upper
// bound of the true minimum, and within |p1 - p0| / samples of it when f is a
// distance (1-Lipschitz in the point).
template <typename F>
double SampledMin(F f, int samples) {
  double best = f(0.0);
  for (int i = 1; i <= samples; ++i) best = std::min(best, f(static_cast<double>(i) / samples));
  return best;
}

double PointBoxDistance(const Vector3d& p_W, const sim::BoxSolid& b) {
  const Vector3d p = b.R_WB.transpose() * (p_W - b.centre_W);
  return (p.cwiseAbs() - b.half_extents_m).cwiseMax(0.0).norm();
}

TEST(SegmentSegmentTest, HandBuiltCases) {
  // Crossing.
  EXPECT_NEAR(SegSeg({-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}), 0.0, 1e-15);
  // Skew, closest points inside both: the distance is the offset along z.
  EXPECT_NEAR(SegSeg({-1, 0, 0}, {1, 0, 0}, {0, -1, 0.5}, {0, 1, 0.5}), 0.5, 1e-15);
  // Closest points at endpoints.
  EXPECT_NEAR(SegSeg({0, 0, 0}, {1, 0, 0}, {2, 1, 0}, {3, 1, 0}), std::sqrt(2.0), 1e-15);
  // Parallel, overlapping along x: the perpendicular offset.
  EXPECT_NEAR(SegSeg({0, 0, 0}, {2, 0, 0}, {1, 0.5, 0}, {3, 0.5, 0}), 0.5, 1e-15);
  // Parallel, disjoint along x: end to end.
  EXPECT_NEAR(SegSeg({0, 0, 0}, {1, 0, 0}, {2, 0.5, 0}, {3, 0.5, 0}), std::hypot(1.0, 0.5), 1e-15);
  // Anti-parallel, collinear and apart.
  EXPECT_NEAR(SegSeg({0, 0, 0}, {1, 0, 0}, {3, 0, 0}, {2, 0, 0}), 1.0, 1e-15);
  // Degenerate: point-point, point-segment, segment-point.
  EXPECT_NEAR(SegSeg({1, 1, 1}, {1, 1, 1}, {1, 1, 2}, {1, 1, 2}), 1.0, 1e-15);
  EXPECT_NEAR(SegSeg({0.5, 0.25, 0}, {0.5, 0.25, 0}, {0, 0, 0}, {1, 0, 0}), 0.25, 1e-15);
  EXPECT_NEAR(SegSeg({0, 0, 0}, {1, 0, 0}, {-0.75, 0, 0}, {-0.75, 0, 0}), 0.75, 1e-15);
}

TEST(SegmentSegmentTest, MatchesSampling) {
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < 300; ++k) {
    const Vector3d a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng));
    const Vector3d c(u(rng), u(rng), u(rng)), d(u(rng), u(rng), u(rng));
    const double exact = SegSeg(a, b, c, d);
    // Distance from a point of ab to segment cd (exact for a point).
    const double sampled = SampledMin(
        [&](double t) {
          const Vector3d p = a + t * (b - a);
          return SegSeg(p, p, c, d);
        },
        4000);
    EXPECT_LE(exact, sampled + 1e-12);
    EXPECT_GE(exact, sampled - (b - a).norm() / 4000 - 1e-12);
  }
}

TEST(CapsuleCapsuleTest, TouchingAndJustMissing) {
  // Two capsules side by side, axes 0.5 apart: radii 0.25 + 0.25 touch.
  const sim::CapsuleSolid cap{{0, 0.5, 0}, {1, 0.5, 0}, 0.25};
  EXPECT_TRUE(CapsuleHits({0, 0, 0}, {1, 0, 0}, 0.25, cap));
  EXPECT_FALSE(CapsuleHits({0, 0, 0}, {1, 0, 0}, 0.25 - 1e-9, cap));
  // Parallel but shifted past the end: the round caps decide.
  EXPECT_TRUE(CapsuleHits({1.375, 0.5, 0}, {2.5, 0.5, 0}, 0.125, cap));  // 0.375 = 0.25 + 0.125.
  EXPECT_FALSE(CapsuleHits({1.375 + 1e-9, 0.5, 0}, {2.5, 0.5, 0}, 0.125, cap));
  // Degenerate particle move (no motion): a ball.
  EXPECT_TRUE(CapsuleHits({0.5, 0.5, 0.375}, {0.5, 0.5, 0.375}, 0.125, cap));
  EXPECT_FALSE(CapsuleHits({0.5, 0.5, 0.375 + 1e-9}, {0.5, 0.5, 0.375 + 1e-9}, 0.125, cap));
}

TEST(CapsuleBoxTest, HandBuiltCases) {
  sim::BoxSolid box;  // Unit cube centred at the origin.
  box.half_extents_m = Vector3d::Constant(0.5);
  // Parallel to a face, 0.25 away.
  EXPECT_NEAR(SegmentBoxDistanceSquared({-0.2, 0.75, 0}, {0.2, 0.75, 0}, box), 0.0625, 1e-15);
  EXPECT_TRUE(CapsuleHits({-0.2, 0.75, 0}, {0.2, 0.75, 0}, 0.25, box));
  EXPECT_FALSE(CapsuleHits({-0.2, 0.75 + 1e-9, 0}, {0.2, 0.75 + 1e-9, 0}, 0.25, box));
  // Parallel to a face and far longer than the box.
  EXPECT_TRUE(CapsuleHits({-5, 0.75, 0.1}, {5, 0.75, 0.1}, 0.25, box));
  // Passing a vertical edge diagonally: nearest to the edge x = y = 0.5.
  // Line x + y = 1 runs through the edge point (0.5, 0.5).
  EXPECT_NEAR(SegmentBoxDistanceSquared({1.0, 0.0, 0.0}, {0.0, 1.0, 0.0}, box), 0.0, 1e-15);
  const Vector3d q0(1.5, 0.0, 0.0), q1(0.0, 1.5, 0.0);  // Line x + y = 1.5.
  EXPECT_NEAR(std::sqrt(SegmentBoxDistanceSquared(q0, q1, box)), 0.5 / std::sqrt(2.0), 1e-15);
  // Near a corner from outside along the diagonal.
  EXPECT_NEAR(std::sqrt(SegmentBoxDistanceSquared({1, 1, 1}, {2, 2, 2}, box)), std::sqrt(3.0) * 0.5,
              1e-15);
  // Through the box.
  EXPECT_EQ(SegmentBoxDistanceSquared({-2, 0.1, 0.2}, {2, -0.1, 0.3}, box), 0.0);
  // Degenerate segment: the point's distance.
  EXPECT_NEAR(SegmentBoxDistanceSquared({0.5, 0.5, 1.25}, {0.5, 0.5, 1.25}, box), 0.5625, 1e-15);
  // Rotated box: 45 degrees about z, so its corner points along +x at 0.5 sqrt(2).
  sim::BoxSolid rotated = box;
  rotated.R_WB = Eigen::AngleAxisd(M_PI / 4, Vector3d::UnitZ()).toRotationMatrix();
  const double reach = 0.5 * std::sqrt(2.0);
  EXPECT_TRUE(CapsuleHits({reach + 0.25, -1, 0}, {reach + 0.25, 1, 0}, 0.25 + 1e-12, rotated));
  EXPECT_FALSE(CapsuleHits({reach + 0.25, -1, 0}, {reach + 0.25, 1, 0}, 0.25 - 1e-9, rotated));
}

TEST(CapsuleBoxTest, MatchesSampling) {
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  std::uniform_real_distribution<double> h(0.05, 0.8);
  for (int k = 0; k < 300; ++k) {
    sim::BoxSolid box;
    box.centre_W = Vector3d(u(rng), u(rng), u(rng)) * 0.3;
    box.half_extents_m = Vector3d(h(rng), h(rng), h(rng));
    box.R_WB = (Eigen::AngleAxisd(u(rng), Vector3d::UnitZ()) *
                Eigen::AngleAxisd(u(rng), Vector3d::UnitY()) *
                Eigen::AngleAxisd(u(rng), Vector3d::UnitX()))
                   .toRotationMatrix();
    const Vector3d p0(u(rng), u(rng), u(rng)), p1(u(rng), u(rng), u(rng));
    const double exact = std::sqrt(SegmentBoxDistanceSquared(p0, p1, box));
    const double sampled =
        SampledMin([&](double t) { return PointBoxDistance(p0 + t * (p1 - p0), box); }, 20000);
    EXPECT_LE(exact, sampled + 1e-12);
    EXPECT_GE(exact, sampled - (p1 - p0).norm() / 20000 - 1e-12);
  }
}

TEST(CapsuleCylinderTest, PointDistance) {
  const sim::CylinderSolid cyl{{0, 0, 0}, {0, 0, 1}, 0.5};
  EXPECT_NEAR(PointCylinderDistance({0.75, 0, 0.5}, cyl), 0.25, 1e-15);    // Side.
  EXPECT_NEAR(PointCylinderDistance({0.1, 0.2, 1.25}, cyl), 0.25, 1e-15);  // Top cap.
  EXPECT_NEAR(PointCylinderDistance({0, 0.8, -0.4}, cyl), 0.5, 1e-15);     // Below the rim.
  EXPECT_EQ(PointCylinderDistance({0.1, 0.1, 0.1}, cyl), 0.0);             // Inside.
}

TEST(CapsuleCylinderTest, HandBuiltCases) {
  const sim::CylinderSolid cyl{{0, 0, 0}, {0, 0, 1}, 0.5};
  // Parallel to the axis beside the side: touching and just missing.
  EXPECT_TRUE(SegmentNearCylinder({0.75, 0, 0.2}, {0.75, 0, 0.8}, cyl, 0.25));
  EXPECT_FALSE(SegmentNearCylinder({0.75 + 1e-4, 0, 0.2}, {0.75 + 1e-4, 0, 0.8}, cyl, 0.25));
  // Across the top, parallel to the cap.
  EXPECT_TRUE(SegmentNearCylinder({-2, 0.1, 1.25}, {2, 0.1, 1.25}, cyl, 0.25));
  EXPECT_FALSE(SegmentNearCylinder({-2, 0.1, 1.2501}, {2, 0.1, 1.2501}, cyl, 0.25));
  // Past the rim diagonally: 0.283 from the rim, so a 0.25 capsule misses,
  // although it reaches the capsule around the cylinder's axis (0.728 < 0.75).
  const Vector3d rim(0.7, 0.0, 1.2);
  EXPECT_FALSE(
      SegmentNearCylinder(rim + Vector3d(0, -0.3, 0), rim + Vector3d(0, 0.3, 0), cyl, 0.25));
  EXPECT_LE(SegmentSegmentDistanceSquared(rim, rim, cyl.a_W, cyl.b_W), 0.75 * 0.75);
  EXPECT_TRUE(
      SegmentNearCylinder(rim + Vector3d(0, -0.3, 0), rim + Vector3d(0, 0.3, 0), cyl, 0.29));
  // Degenerate move inside the cylinder; through the cylinder.
  EXPECT_TRUE(SegmentNearCylinder({0, 0, 0.5}, {0, 0, 0.5}, cyl, 0.0));
  EXPECT_TRUE(SegmentNearCylinder({-3, 0.2, 0.5}, {3, 0.2, 0.5}, cyl, 0.01));
  // Degenerate cylinder (a == b): treated as the ball around it, never less.
  const sim::CylinderSolid disk{{0, 0, 0}, {0, 0, 0}, 0.5};
  EXPECT_TRUE(SegmentNearCylinder({0, 0, 0.6}, {0, 0, 0.6}, disk, 0.1));
}

TEST(CapsuleCylinderTest, ConservativeAgainstSampling) {
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  std::uniform_real_distribution<double> r(0.05, 0.6);
  int hits = 0;
  for (int k = 0; k < 400; ++k) {
    const sim::CylinderSolid cyl{Vector3d(u(rng), u(rng), u(rng)) * 0.4,
                                 Vector3d(u(rng), u(rng), u(rng)) * 0.4, r(rng)};
    const Vector3d p0(u(rng), u(rng), u(rng)), p1(u(rng), u(rng), u(rng));
    const double radius = r(rng);
    const double len = (p1 - p0).norm();
    const double sampled =
        SampledMin([&](double t) { return PointCylinderDistance(p0 + t * (p1 - p0), cyl); }, 20000);
    const bool hit = SegmentNearCylinder(p0, p1, cyl, radius);
    hits += hit;
    if (sampled <= radius) {
      EXPECT_TRUE(hit) << k;  // Never misses a hit.
    }
    // Tight: the true minimum is at least sampled - len / 20000.
    if (hit) {
      EXPECT_LE(sampled - len / 20000, radius + 1e-7 * len + 1e-12) << k;
    }
  }
  EXPECT_GT(hits, 50);
  EXPECT_LT(hits, 350);
}

TEST(CollisionWorldTest, BroadPhaseEqualsTestingEveryShape) {
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<double> u(0.0, 4.0);
  std::uniform_real_distribution<double> s(0.05, 0.4);
  std::uniform_real_distribution<double> d(-0.3, 0.3);
  std::vector<CollisionShape> shapes;
  for (int k = 0; k < 30; ++k) {
    const Vector3d c(u(rng), u(rng), u(rng) * 0.6);
    if (k % 3 == 0) {
      sim::BoxSolid b;
      b.centre_W = c;
      b.half_extents_m = Vector3d(s(rng), s(rng), s(rng));
      b.R_WB = Eigen::AngleAxisd(u(rng), Vector3d::UnitZ()).toRotationMatrix();
      shapes.emplace_back(b);
    } else if (k % 3 == 1) {
      shapes.emplace_back(sim::CylinderSolid{c, c + Vector3d(d(rng), d(rng), 1.0), s(rng)});
    } else {
      shapes.emplace_back(sim::CapsuleSolid{c, c + Vector3d(d(rng), d(rng), d(rng)), s(rng)});
    }
  }
  // One large table top spanning many broad-phase cells.
  sim::BoxSolid top;
  top.centre_W = Vector3d(2, 2, 0.9);
  top.half_extents_m = Vector3d(1.5, 1.2, 0.025);
  shapes.emplace_back(top);
  const CollisionWorld world(shapes, 0.5);
  int hits = 0;
  for (int k = 0; k < 3000; ++k) {
    const Vector3d p0(u(rng), u(rng), u(rng) * 0.6);
    const Vector3d p1 = p0 + Vector3d(d(rng), d(rng), d(rng));
    bool any = false;
    for (const CollisionShape& sh : shapes) any = any || CapsuleHits(p0, p1, 0.2, sh);
    ASSERT_EQ(world.CapsuleHits(p0, p1, 0.2), any) << k;
    hits += any;
  }
  EXPECT_GT(hits, 100);
  EXPECT_FALSE(CollisionWorld().CapsuleHits({0, 0, 0}, {1, 1, 1}, 1.0));
}

}  // namespace
}  // namespace hg::tracking
