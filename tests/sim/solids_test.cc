#include "sim/solids.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

namespace hg::sim {
namespace {

using Eigen::Vector3d;

Vector3d RandomUnit(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Vector3d d;
  do {
    d = Vector3d(n(rng), n(rng), n(rng));
  } while (d.norm() < 1e-6);
  return d.normalized();
}

/// A random unit vector perpendicular to unit `axis`.
Vector3d RandomPerpendicular(std::mt19937_64& rng, const Vector3d& axis) {
  Vector3d d;
  do {
    d = RandomUnit(rng);
    d -= d.dot(axis) * axis;
  } while (d.norm() < 1e-3);
  return d.normalized();
}

Eigen::Matrix3d RandomRotation(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-M_PI, M_PI);
  return (Eigen::AngleAxisd(u(rng), RandomUnit(rng)) * Eigen::AngleAxisd(u(rng), RandomUnit(rng)))
      .toRotationMatrix();
}

/// A point on the surface of the capsule.
Vector3d CapsuleSurfacePoint(std::mt19937_64& rng, const CapsuleSolid& c) {
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const Vector3d e = c.b_W - c.a_W;
  const double length = e.norm();
  const double pick = u01(rng);
  if (length > 0.0 && pick < 0.5) {
    const Vector3d w = e / length;
    return c.a_W + u01(rng) * e + c.radius_m * RandomPerpendicular(rng, w);
  }
  Vector3d d = RandomUnit(rng);
  const bool at_b = pick >= 0.75;
  if (length > 0.0) {
    // Outward hemisphere at the chosen end.
    const double side = d.dot(e);
    if ((at_b && side < 0.0) || (!at_b && side > 0.0)) d -= 2.0 * side / (length * length) * e;
  }
  return (at_b ? c.b_W : c.a_W) + c.radius_m * d;
}

/// A point on the surface of the cylinder (side or caps).
Vector3d CylinderSurfacePoint(std::mt19937_64& rng, const CylinderSolid& c) {
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const Vector3d e = c.b_W - c.a_W;
  const Vector3d w = e.normalized();
  const Vector3d radial = RandomPerpendicular(rng, w);
  const double pick = u01(rng);
  if (pick < 0.5) return c.a_W + u01(rng) * e + c.radius_m * radial;
  const Vector3d base = pick < 0.75 ? c.a_W : c.b_W;
  return base + c.radius_m * std::sqrt(u01(rng)) * radial;
}

/// A point on the surface of the box.
Vector3d BoxSurfacePoint(std::mt19937_64& rng, const BoxSolid& b) {
  std::uniform_real_distribution<double> u11(-1.0, 1.0);
  std::uniform_int_distribution<int> face(0, 5);
  Vector3d local(u11(rng), u11(rng), u11(rng));
  const int f = face(rng);
  local[f / 2] = (f % 2 == 0) ? -1.0 : 1.0;
  return b.centre_W + b.R_WB * local.cwiseProduct(b.half_extents_m);
}

CapsuleSolid RandomCapsule(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> pos(-2.0, 2.0);
  std::uniform_real_distribution<double> len(0.0, 1.0);
  std::uniform_real_distribution<double> rad(0.02, 0.4);
  CapsuleSolid c;
  c.a_W = Vector3d(pos(rng), pos(rng), pos(rng));
  c.b_W = c.a_W + len(rng) * RandomUnit(rng);
  c.radius_m = rad(rng);
  return c;
}

double SegmentDistance(const Vector3d& a, const Vector3d& b, const Vector3d& p) {
  const Vector3d e = b - a;
  const double len2 = e.squaredNorm();
  const double s = len2 > 0.0 ? std::clamp((p - a).dot(e) / len2, 0.0, 1.0) : 0.0;
  return (a + s * e - p).norm();
}

TEST(TessellateTest, CapsuleMeshContainsTheCapsuleSurface) {
  std::mt19937_64 rng(101);
  for (const int segments : {8, 12, 24, 40}) {
    for (int trial = 0; trial < 6; ++trial) {
      const CapsuleSolid capsule = RandomCapsule(rng);
      const geometry::TriangleMesh mesh = Tessellate(capsule, segments);
      const MeshSolid solid{mesh};
      for (int i = 0; i < 300; ++i) {
        const Vector3d p = CapsuleSurfacePoint(rng, capsule);
        ASSERT_TRUE(Contains(solid, p)) << "segments " << segments << " point " << p.transpose();
      }
      // Not far larger than needed: every vertex lies between r and the proven scale.
      const int m = std::max(2, segments / 4);
      const double scale = 1.0 / (std::cos(M_PI / segments) * std::cos(M_PI / (4.0 * m)));
      for (const Vector3d& v : mesh.vertices) {
        const double d = SegmentDistance(capsule.a_W, capsule.b_W, v);
        EXPECT_GE(d, capsule.radius_m * (1.0 - 1e-9));
        EXPECT_LE(d, capsule.radius_m * scale * (1.0 + 1e-9));
      }
      // Points clearly outside the scaled capsule are outside the mesh.
      for (int i = 0; i < 50; ++i) {
        CapsuleSolid grown = capsule;
        grown.radius_m *= scale * 1.05;
        EXPECT_FALSE(Contains(solid, CapsuleSurfacePoint(rng, grown)));
      }
    }
  }
}

TEST(TessellateTest, SphereIsADegenerateCapsule) {
  std::mt19937_64 rng(102);
  CapsuleSolid sphere;
  sphere.a_W = sphere.b_W = Vector3d(0.3, -0.2, 1.1);
  sphere.radius_m = 0.25;
  for (const int segments : {8, 24}) {
    const MeshSolid solid{Tessellate(sphere, segments)};
    for (int i = 0; i < 500; ++i) {
      const Vector3d p = sphere.a_W + sphere.radius_m * RandomUnit(rng);
      ASSERT_TRUE(Contains(solid, p)) << p.transpose();
    }
    EXPECT_FALSE(Contains(solid, sphere.a_W + Vector3d(0.0, 0.0, 0.35)));
    EXPECT_TRUE(Contains(solid, sphere.a_W));
  }
}

TEST(TessellateTest, CylinderMeshContainsTheCylinderSurface) {
  std::mt19937_64 rng(103);
  for (const int segments : {8, 16, 24}) {
    for (int trial = 0; trial < 6; ++trial) {
      const CapsuleSolid c = RandomCapsule(rng);
      CylinderSolid cylinder{c.a_W, c.a_W + (c.b_W - c.a_W).normalized() * 0.6, c.radius_m};
      const MeshSolid solid{Tessellate(cylinder, segments)};
      for (int i = 0; i < 300; ++i) {
        const Vector3d p = CylinderSurfacePoint(rng, cylinder);
        ASSERT_TRUE(Contains(cylinder, p));
        ASSERT_TRUE(Contains(solid, p)) << "segments " << segments << " point " << p.transpose();
      }
      // Beyond the caps is outside.
      const Vector3d w = (cylinder.b_W - cylinder.a_W).normalized();
      EXPECT_FALSE(Contains(solid, cylinder.b_W + 0.01 * w));
      EXPECT_FALSE(Contains(solid, cylinder.a_W - 0.01 * w));
    }
  }
}

TEST(TessellateTest, BoxMeshIsTheBox) {
  std::mt19937_64 rng(104);
  std::uniform_real_distribution<double> half(0.05, 1.0);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  for (int trial = 0; trial < 10; ++trial) {
    BoxSolid box;
    box.centre_W = Vector3d(u(rng), u(rng), u(rng));
    box.half_extents_m = Vector3d(half(rng), half(rng), half(rng));
    box.R_WB = RandomRotation(rng);
    const geometry::TriangleMesh mesh = Tessellate(box);
    EXPECT_EQ(mesh.vertices.size(), 8U);
    EXPECT_EQ(mesh.triangles.size(), 12U);
    const MeshSolid solid{mesh};
    for (int i = 0; i < 200; ++i) {
      ASSERT_TRUE(Contains(solid, BoxSurfacePoint(rng, box)));
    }
    // Random points: the mesh and the box agree.
    const common::Box3 bounds = Bounds(box);
    std::uniform_real_distribution<double> ux(bounds.min.x() - 0.1, bounds.max.x() + 0.1);
    std::uniform_real_distribution<double> uy(bounds.min.y() - 0.1, bounds.max.y() + 0.1);
    std::uniform_real_distribution<double> uz(bounds.min.z() - 0.1, bounds.max.z() + 0.1);
    int inside = 0;
    for (int i = 0; i < 500; ++i) {
      const Vector3d p(ux(rng), uy(rng), uz(rng));
      const bool in_box = Contains(box, p);
      inside += in_box ? 1 : 0;
      ASSERT_EQ(Contains(solid, p), in_box) << p.transpose();
    }
    EXPECT_GT(inside, 0);
  }
}

TEST(BoundsTest, ContainSurfaceSamplesAndAreTight) {
  std::mt19937_64 rng(105);
  for (int trial = 0; trial < 20; ++trial) {
    const CapsuleSolid capsule = RandomCapsule(rng);
    const CylinderSolid cylinder{capsule.a_W, capsule.b_W, capsule.radius_m};
    BoxSolid box{capsule.a_W, Vector3d(0.3, 0.2, 0.1), RandomRotation(rng)};
    const std::vector<std::pair<SolidGeometry, std::function<Vector3d()>>> cases = {
        {capsule, [&] { return CapsuleSurfacePoint(rng, capsule); }},
        {cylinder, [&] { return CylinderSurfacePoint(rng, cylinder); }},
        {box, [&] { return BoxSurfacePoint(rng, box); }},
    };
    for (const auto& [solid, sample] : cases) {
      const common::Box3 bounds = Bounds(solid);
      Vector3d lo = Vector3d::Constant(1e9);
      Vector3d hi = Vector3d::Constant(-1e9);
      for (int i = 0; i < 4000; ++i) {
        const Vector3d p = sample();
        ASSERT_TRUE((p.array() >= bounds.min.array() - 1e-9).all() &&
                    (p.array() <= bounds.max.array() + 1e-9).all())
            << p.transpose();
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
      }
      // Tight: the samples reach close to every face of the bounds.
      const double size = (bounds.max - bounds.min).maxCoeff();
      EXPECT_LT((lo - bounds.min).maxCoeff(), 0.1 * size);
      EXPECT_LT((bounds.max - hi).maxCoeff(), 0.1 * size);
    }
  }
  MeshSolid mesh{geometry::TriangleMesh::Box(Vector3d(1, 2, 3), Vector3d(2, 4, 5))};
  const common::Box3 b = Bounds(mesh);
  EXPECT_EQ(b.min, Vector3d(1, 2, 3));
  EXPECT_EQ(b.max, Vector3d(2, 4, 5));
}

TEST(ContainsTest, ClosedMeshByParity) {
  // Two disjoint boxes in one mesh, and a hollow frame (a box with a hole
  // through it, as a closed non-convex surface built from four bars).
  geometry::TriangleMesh mesh = geometry::TriangleMesh::Box(Vector3d(0, 0, 0), Vector3d(1, 1, 1));
  mesh.Append(geometry::TriangleMesh::Box(Vector3d(2, 0, 0), Vector3d(3, 1, 1)));
  const MeshSolid solid{mesh};
  const BoxSolid box_a{Vector3d(0.5, 0.5, 0.5), Vector3d::Constant(0.5)};
  const BoxSolid box_b{Vector3d(2.5, 0.5, 0.5), Vector3d::Constant(0.5)};
  // Grid points on the faces, edges and vertices' planes (worst case for parity).
  for (int i = -2; i <= 14; ++i) {
    for (int j = -2; j <= 6; ++j) {
      for (int k = -2; k <= 6; ++k) {
        const Vector3d p(0.25 * i, 0.25 * j, 0.25 * k);
        const bool expected = Contains(box_a, p) || Contains(box_b, p);
        ASSERT_EQ(Contains(solid, p), expected) << p.transpose();
      }
    }
  }
  std::mt19937_64 rng(106);
  std::uniform_real_distribution<double> ux(-0.5, 3.5);
  std::uniform_real_distribution<double> u(-0.5, 1.5);
  for (int i = 0; i < 2000; ++i) {
    const Vector3d p(ux(rng), u(rng), u(rng));
    ASSERT_EQ(Contains(solid, p), Contains(box_a, p) || Contains(box_b, p)) << p.transpose();
  }
  // An open mesh (one triangle) contains only its own points.
  geometry::TriangleMesh open;
  open.vertices = {Vector3d(0, 0, 0), Vector3d(1, 0, 0), Vector3d(0, 1, 0)};
  open.triangles = {{0, 1, 2}};
  EXPECT_TRUE(Contains(MeshSolid{open}, Vector3d(0.2, 0.2, 0.0)));
  EXPECT_FALSE(Contains(MeshSolid{geometry::TriangleMesh{}}, Vector3d::Zero()));
}

TEST(ContainsTest, PrimitivesAgreeWithDistances) {
  std::mt19937_64 rng(107);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  for (int trial = 0; trial < 2000; ++trial) {
    const CapsuleSolid c = RandomCapsule(rng);
    const Vector3d p(u(rng), u(rng), u(rng));
    EXPECT_EQ(Contains(c, p), SegmentDistance(c.a_W, c.b_W, p) <= c.radius_m);
  }
  const CylinderSolid cylinder{Vector3d(0, 0, 0), Vector3d(0, 0, 2), 0.5};
  EXPECT_TRUE(Contains(cylinder, Vector3d(0.49, 0, 1.99)));
  EXPECT_FALSE(Contains(cylinder, Vector3d(0.49, 0, 2.01)));
  EXPECT_FALSE(Contains(cylinder, Vector3d(0.36, 0.36, 1.0)));
  EXPECT_TRUE(Contains(cylinder, Vector3d(0.35, 0.35, 1.0)));
}

}  // namespace
}  // namespace hg::sim
