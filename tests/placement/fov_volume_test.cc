#include "placement/fov_volume.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "common/config_error.h"
#include "geometry/mesh.h"

namespace hg::placement {
namespace {

using Eigen::Vector3d;

Intrinsics MakeIntrinsics(int width, int height, double f) {
  Intrinsics in;
  in.width = width;
  in.height = height;
  in.K << f, 0, (width - 1) / 2.0, 0, f, (height - 1) / 2.0, 0, 0, 1;
  return in;
}

bool InFrustum(const CameraPose& pose, const Intrinsics& in, const Vector3d& p_W) {
  const Vector3d p_C = pose.R_WC.transpose() * (p_W - pose.position_W);
  if (p_C.z() <= 0) return false;
  const Vector3d px = in.K * (p_C / p_C.z());
  return px.x() >= -0.5 && px.x() <= in.width - 0.5 && px.y() >= -0.5 && px.y() <= in.height - 0.5;
}

// Triangles in blocks with bounding boxes, for segment queries.
class SegmentOracle {
 public:
  explicit SegmentOracle(const geometry::TriangleMesh& mesh) {
    constexpr int kBlock = 8;
    for (size_t t0 = 0; t0 < mesh.triangles.size(); t0 += kBlock) {
      Block b;
      b.min = Vector3d::Constant(1e300);
      b.max = -b.min;
      for (size_t t = t0; t < std::min(mesh.triangles.size(), t0 + kBlock); ++t) {
        std::array<Vector3d, 3> tri;
        for (int i = 0; i < 3; ++i) {
          tri[i] = mesh.vertices[mesh.triangles[t][i]];
          b.min = b.min.cwiseMin(tri[i]);
          b.max = b.max.cwiseMax(tri[i]);
        }
        b.triangles.push_back(tri);
      }
      blocks_.push_back(b);
    }
  }

  // True iff the open segment a-b crosses a triangle.
  [[nodiscard]] bool Blocked(const Vector3d& a, const Vector3d& b) const {
    const Vector3d d = b - a;
    for (const Block& block : blocks_) {
      double t0 = 0, t1 = 1;
      bool miss = false;
      for (int k = 0; k < 3 && !miss; ++k) {
        if (std::abs(d[k]) < 1e-300) {
          miss = a[k] < block.min[k] || a[k] > block.max[k];
        } else {
          double ta = (block.min[k] - a[k]) / d[k];
          double tb = (block.max[k] - a[k]) / d[k];
          if (ta > tb) std::swap(ta, tb);
          t0 = std::max(t0, ta);
          t1 = std::min(t1, tb);
          miss = t0 > t1;
        }
      }
      if (miss) continue;
      for (const auto& tri : block.triangles) {
        if (Hits(a, d, tri)) return true;
      }
    }
    return false;
  }

 private:
  struct Block {
    Vector3d min, max;
    std::vector<std::array<Vector3d, 3>> triangles;
  };
  static bool Hits(const Vector3d& a, const Vector3d& d, const std::array<Vector3d, 3>& tri) {
    const Vector3d e1 = tri[1] - tri[0];
    const Vector3d e2 = tri[2] - tri[0];
    const Vector3d p = d.cross(e2);
    const double det = e1.dot(p);
    if (std::abs(det) < 1e-300) return false;
    const Vector3d s = a - tri[0];
    const double u = s.dot(p) / det;
    if (u < 0 || u > 1) return false;
    const Vector3d q = s.cross(e1);
    const double v = d.dot(q) / det;
    if (v < 0 || u + v > 1) return false;
    const double t = e2.dot(q) / det;
    return t > 0 && t < 1;
  }
  std::vector<Block> blocks_;
};

struct Estimate {
  double volume = 0;
  double sigma = 0;
};

// Monte Carlo volume of the points of `box` with inside(p) and seen(p).
Estimate Sample(const common::Box3& box, const std::function<bool(const Vector3d&)>& inside,
                const std::function<bool(const Vector3d&)>& seen, int n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> ux(box.min.x(), box.max.x());
  std::uniform_real_distribution<double> uy(box.min.y(), box.max.y());
  std::uniform_real_distribution<double> uz(box.min.z(), box.max.z());
  int hits = 0;
  for (int i = 0; i < n; ++i) {
    const Vector3d p(ux(rng), uy(rng), uz(rng));
    if (inside(p) && seen(p)) ++hits;
  }
  const double frac = static_cast<double>(hits) / n;
  return {box.Volume() * frac, box.Volume() * std::sqrt(std::max(frac * (1 - frac), 1.0 / n) / n)};
}

// Sampled seen volume of a box cell with mesh obstacles.
Estimate SampleSeen(const common::Box3& cell, const geometry::TriangleMesh& obstacles,
                    const CameraPose& pose, const Intrinsics& in, int n, std::uint64_t seed) {
  const SegmentOracle oracle(obstacles);
  return Sample(
      cell, [](const Vector3d&) { return true; },
      [&](const Vector3d& p) {
        return InFrustum(pose, in, p) && !oracle.Blocked(pose.position_W, p);
      },
      n, seed);
}

Vector3d RandomIn(std::mt19937_64& rng, const Vector3d& lo, const Vector3d& hi) {
  std::uniform_real_distribution<double> u(0, 1);
  return {lo.x() + u(rng) * (hi.x() - lo.x()), lo.y() + u(rng) * (hi.y() - lo.y()),
          lo.z() + u(rng) * (hi.z() - lo.z())};
}

common::Box3 MakeBox(const Vector3d& min, const Vector3d& max) {
  common::Box3 b;
  b.min = min;
  b.max = max;
  return b;
}

// ---------------------------------------------------------------------------
// Closed forms.

TEST(FovVolumeTest, FrustumOnFarWallIsAPyramid) {
  const FovScene scene(MakeBox({0, 0, 0}, {4, 4, 3}), {});
  const CameraPose pose = CameraPose::LookAt({2, 0.5, 1.5}, {2, 4, 1.5});
  const Intrinsics in = MakeIntrinsics(640, 480, 1000);
  FovEvaluator evaluator;
  const double d = 3.5;  // to the wall y = 4
  const double expected = d * 0.64 * d * 0.48 * d / 3.0;
  EXPECT_NEAR(evaluator.Volume(scene, pose, in), expected, 1e-12 * expected);
  EXPECT_EQ(evaluator.stats().cell_faces, 2);  // only the far wall's two triangles
}

TEST(FovVolumeTest, RightAngleFrustumFromCubeCentreIsASixth) {
  const FovScene scene(MakeBox({-1, -1, -1}, {1, 1, 1}), {});
  const Intrinsics in = MakeIntrinsics(400, 400, 200);  // image borders at 45 degrees
  FovEvaluator evaluator;
  double sum = 0;
  for (const Vector3d& dir :
       {Vector3d(1, 0, 0), Vector3d(-1, 0, 0), Vector3d(0, 1, 0), Vector3d(0, -1, 0)}) {
    const double v = evaluator.Volume(scene, CameraPose::LookAt({0, 0, 0}, dir), in);
    EXPECT_NEAR(v, 8.0 / 6.0, 1e-12);
    sum += v;
  }
  for (const Vector3d& dir : {Vector3d(0, 0, 1), Vector3d(0, 0, -1)}) {
    const double v =
        evaluator.Volume(scene, CameraPose::LookAt({0, 0, 0}, dir, Vector3d::UnitY()), in);
    EXPECT_NEAR(v, 8.0 / 6.0, 1e-12);
    sum += v;
  }
  EXPECT_NEAR(sum, 8.0, 1e-11);  // six pyramids fill the cube
}

TEST(FovVolumeTest, WideFrustumFromCubeCentreCutsTheSideWalls) {
  // |y|, |z| <= 2 x from the centre of [-1, 1]^3: int_0^1 (2 min(1, 2x))^2 dx = 8/3.
  const FovScene scene(MakeBox({-1, -1, -1}, {1, 1, 1}), {});
  const Intrinsics in = MakeIntrinsics(400, 400, 100);  // borders at u = +-2
  FovEvaluator evaluator;
  EXPECT_NEAR(evaluator.Volume(scene, CameraPose::LookAt({0, 0, 0}, {1, 0, 0}), in), 8.0 / 3.0,
              1e-12);
}

TEST(FovVolumeTest, WholeBoxSeenFromACorner) {
  const common::Box3 cell = MakeBox({0, 0, 0}, {4, 4, 3});
  const FovScene scene(cell, {});
  const Intrinsics in = MakeIntrinsics(1000, 1000, 150);
  FovEvaluator evaluator;
  // Outside the corner, and exactly on it (the three walls through the camera
  // are seen edge-on).
  for (const Vector3d& eye : {Vector3d(-1, -1, -1), Vector3d(0, 0, 0)}) {
    const CameraPose pose = CameraPose::LookAt(eye, {4, 4, 3});
    for (int i = 0; i < 8; ++i) {
      if ((cell.Corner(i) - eye).norm() > 0) {
        ASSERT_TRUE(InFrustum(pose, in, cell.Corner(i))) << i;
      }
    }
    EXPECT_NEAR(evaluator.Volume(scene, pose, in), 48.0, 1e-10);
  }
}

TEST(FovVolumeTest, BoxObstacleCastsAPyramidalShadow) {
  // Camera at the centre of [-1, 1]^3 looking along +x through the wall x = 1
  // (pyramid 4/3); the obstacle's front face x = 0.5, |y|, |z| <= 0.1 hides the
  // cone |y|, |z| <= 0.2 x for x in [0.5, 1]: int 0.16 x^2 dx = 0.16 * 0.875 / 3.
  const geometry::TriangleMesh box =
      geometry::TriangleMesh::Box({0.5, -0.1, -0.1}, {0.7, 0.1, 0.1});
  const FovScene scene(MakeBox({-1, -1, -1}, {1, 1, 1}), box);
  const Intrinsics in = MakeIntrinsics(400, 400, 200);
  FovEvaluator evaluator;
  const double expected = 4.0 / 3.0 - 0.16 * 0.875 / 3.0;
  EXPECT_NEAR(evaluator.Volume(scene, CameraPose::LookAt({0, 0, 0}, {1, 0, 0}), in), expected,
              1e-12);
  // With borders at u, v = +-0.8 instead, the camera at (x, y, z) near the
  // centre sees the pyramid to the far wall minus the shadow, both unchanged by
  // sideways moves (shear): V = 2.56 / 3 (1 - x)^3 - 0.04 ((1 - x)^3 - a^3) /
  // (3 a^2), a = 0.5 - x, dV/dx = -2.56 (1 - x)^2 - ..., sideways 0. Off the
  // centre, because there the obstacle's and the wall's diagonals project onto
  // one line: at such coincidences the derivative with the combinatorics held
  // fixed is not the volume's.
  const Vector3d eye(0, 0.02, -0.03);
  const VolumeGradient g = evaluator.VolumeAndGradient(
      scene, CameraPose::LookAt(eye, eye + Vector3d::UnitX()), MakeIntrinsics(400, 400, 250));
  EXPECT_NEAR(g.volume_m3, (2.56 - 0.16 * 0.875) / 3.0, 1e-12);
  EXPECT_NEAR(g.gradient[0], -2.56 - 0.2 / 3.0, 1e-10);
  EXPECT_NEAR(g.gradient[1], 0.0, 1e-10);
  EXPECT_NEAR(g.gradient[2], 0.0, 1e-10);
  // The symmetric pose with borders at +-1, nudged by 1e-9: dV/dx = -4 - 0.2 / 3.
  const Vector3d nudged(1e-9, 2e-9, 3e-9);
  const VolumeGradient g1 = evaluator.VolumeAndGradient(
      scene, CameraPose::LookAt(nudged, nudged + Vector3d::UnitX()), in);
  EXPECT_NEAR(g1.gradient[0], -4.0 - 0.2 / 3.0, 1e-6);
}

TEST(FovVolumeTest, CameraOutsideTheCellSeesOnlyTheCell) {
  // Looking through the wall x = 0 of [0, 2] x [-1, 1]^2 from x = -1 with a
  // 90-degree frustum: the pyramid to x = 2 minus the one to x = 0 (truncated),
  // clipped by the side walls. Cross-section at distance s = x + 1:
  // (2 min(1, s))^2 for s in [1, 3] = 4 * 2 = 8.
  const FovScene scene(MakeBox({0, -1, -1}, {2, 1, 1}), {});
  const Intrinsics in = MakeIntrinsics(300, 300, 150);
  FovEvaluator evaluator;
  EXPECT_NEAR(evaluator.Volume(scene, CameraPose::LookAt({-1, 0, 0}, {1, 0, 0}), in), 8.0, 1e-12);
  // Looking away from the cell: nothing.
  EXPECT_NEAR(evaluator.Volume(scene, CameraPose::LookAt({-1, 0, 0}, {-2, 0, 0}), in), 0.0, 1e-15);
}

// ---------------------------------------------------------------------------
// Mesh preparation and input errors.

TEST(FovVolumeTest, OccluderMeshFindsClosedConvexComponents) {
  geometry::TriangleMesh mesh = geometry::TriangleMesh::Box({0, 0, 0}, {1, 1, 1});
  geometry::TriangleMesh inverted = geometry::TriangleMesh::Box({2, 0, 0}, {3, 1, 1});
  for (auto& t : inverted.triangles) std::swap(t[1], t[2]);
  mesh.Append(inverted);
  geometry::TriangleMesh plate;  // open: one quad
  plate.vertices = {{5, 0, 0}, {6, 0, 0}, {6, 1, 0}, {5, 1, 0}};
  plate.triangles = {{0, 1, 2}, {0, 2, 3}};
  mesh.Append(plate);
  const OccluderMesh occ(mesh);
  ASSERT_EQ(occ.NumComponents(), 3);
  int closed = 0;
  for (int c = 0; c < 3; ++c) {
    const auto& comp = occ.component(c);
    if (!comp.closed) continue;
    ++closed;
    EXPECT_TRUE(comp.convex);
    double v6 = 0;  // outward after preparation
    for (int t = comp.first_triangle; t < comp.first_triangle + comp.num_triangles; ++t) {
      const auto& tri = occ.mesh().triangles[t];
      v6 += occ.mesh().vertices[tri[0]].dot(
          occ.mesh().vertices[tri[1]].cross(occ.mesh().vertices[tri[2]]));
    }
    EXPECT_NEAR(v6 / 6, 1.0, 1e-12);
  }
  EXPECT_EQ(closed, 2);
}

TEST(FovVolumeTest, BadMeshesAreRejected) {
  geometry::TriangleMesh open;
  open.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  open.triangles = {{0, 1, 2}};
  EXPECT_THROW(FovScene(open, {}), common::ConfigError);
  geometry::TriangleMesh bad_index = open;
  bad_index.triangles = {{0, 1, 3}};
  EXPECT_THROW(OccluderMesh{bad_index}, common::ConfigError);
  EXPECT_THROW(FovScene(MakeBox({0, 0, 0}, {1, 0, 1}), {}), common::ConfigError);
  EXPECT_THROW((void)CapsuleHullMesh({Vector3d::Zero(), Vector3d::UnitZ(), 0.0}),
               common::ConfigError);
}

// ---------------------------------------------------------------------------
// Against sampling.

// 5 sigma of the estimate plus a hair for the volume's own rounding.
void ExpectAgrees(double exact, const Estimate& sampled, const std::string& what) {
  EXPECT_NEAR(exact, sampled.volume, 5 * sampled.sigma + 1e-9) << what;
}

TEST(FovVolumeTest, RandomBoxObstaclesMatchSampling) {
  const common::Box3 cell = MakeBox({0, 0, 0}, {4, 4, 3});
  std::mt19937_64 rng(11);
  FovEvaluator evaluator;
  for (int scene_index = 0; scene_index < 4; ++scene_index) {
    geometry::TriangleMesh obstacles;
    for (int k = 0; k < 6; ++k) {
      const Vector3d c = RandomIn(rng, {0.3, 0.3, 0.0}, {3.7, 3.7, 2.0});
      const Vector3d h = RandomIn(rng, {0.1, 0.1, 0.1}, {0.6, 0.6, 0.8});
      // Some boxes intersect each other or stick out of the cell.
      obstacles.Append(geometry::TriangleMesh::Box(c - h, c + h));
    }
    const FovScene scene(cell, obstacles);
    // Inside the cell, and outside it above a corner.
    const Vector3d eye = scene_index % 2 == 0 ? RandomIn(rng, {0.2, 0.2, 2.3}, {3.8, 3.8, 2.9})
                                              : Vector3d(-0.3, -0.3, 3.6);
    const CameraPose pose = CameraPose::LookAt(eye, RandomIn(rng, {1, 1, 0}, {3, 3, 1}));
    const Intrinsics in = MakeIntrinsics(640, 480, 400);
    const double exact = evaluator.Volume(scene, pose, in);
    ExpectAgrees(exact, SampleSeen(cell, obstacles, pose, in, 300000, 100 + scene_index),
                 "scene " + std::to_string(scene_index));
  }
}

TEST(FovVolumeTest, OpenAndCrossingObstaclesMatchSampling) {
  // A two-sided plate (open mesh), a tilted plate crossing a box, a box through
  // the cell's wall; camera looking at them from both sides of the plate.
  const common::Box3 cell = MakeBox({0, 0, 0}, {3, 3, 2});
  geometry::TriangleMesh obstacles;
  geometry::TriangleMesh plate;
  plate.vertices = {{1, 0.5, 0.2}, {2, 0.5, 0.2}, {2, 1.2, 1.5}, {1, 1.4, 1.5}};
  plate.triangles = {{0, 1, 2}, {0, 2, 3}};
  obstacles.Append(plate);
  obstacles.Append(geometry::TriangleMesh::Box({1.2, 0.6, 0.5}, {1.8, 1.4, 0.9}));
  obstacles.Append(geometry::TriangleMesh::Box({2.6, 1.5, 0.0}, {3.4, 2.0, 1.0}));
  const FovScene scene(cell, obstacles);
  const Intrinsics in = MakeIntrinsics(800, 600, 450);
  FovEvaluator evaluator;
  int index = 0;
  for (const Vector3d& eye :
       {Vector3d(1.5, -0.5, 1.0), Vector3d(1.5, 2.8, 1.2), Vector3d(0.2, 0.2, 1.9)}) {
    const CameraPose pose = CameraPose::LookAt(eye, {1.6, 1.0, 0.7});
    const double exact = evaluator.Volume(scene, pose, in);
    ExpectAgrees(exact, SampleSeen(cell, obstacles, pose, in, 300000, 200 + index),
                 "eye " + std::to_string(index));
    ++index;
  }
}

TEST(FovVolumeTest, LargeNonConvexSheetMatchesSampling) {
  // A corrugated open sheet of 2 * 14 * 14 triangles (one component, seen from
  // both sides, hiding parts of itself) over a box, looked at from above and
  // from below the sheet.
  const common::Box3 cell = MakeBox({0, 0, 0}, {3, 3, 2});
  geometry::TriangleMesh sheet;
  constexpr int kN = 14;
  for (int j = 0; j <= kN; ++j) {
    for (int i = 0; i <= kN; ++i) {
      const double x = 0.2 + 2.6 * i / kN;
      const double y = 0.2 + 2.6 * j / kN;
      sheet.vertices.emplace_back(x, y, 1.0 + 0.25 * std::sin(4 * x) * std::cos(3 * y));
    }
  }
  for (int j = 0; j < kN; ++j) {
    for (int i = 0; i < kN; ++i) {
      const int a = j * (kN + 1) + i;
      sheet.triangles.push_back({a, a + 1, a + kN + 2});
      sheet.triangles.push_back({a, a + kN + 2, a + kN + 1});
    }
  }
  geometry::TriangleMesh obstacles = sheet;
  obstacles.Append(geometry::TriangleMesh::Box({1.2, 1.2, 0.0}, {1.8, 1.8, 0.6}));
  const FovScene scene(cell, obstacles);
  ASSERT_FALSE(scene.obstacles().component(0).closed);
  const Intrinsics in = MakeIntrinsics(640, 480, 350);
  FovEvaluator evaluator;
  int index = 0;
  for (const Vector3d& eye : {Vector3d(0.1, 0.3, 1.9), Vector3d(2.9, 2.5, 0.2)}) {
    const CameraPose pose = CameraPose::LookAt(eye, {1.6, 1.4, 1.0});
    const double exact = evaluator.Volume(scene, pose, in);
    EXPECT_GT(evaluator.stats().obstacle_faces, 100);
    ExpectAgrees(exact, SampleSeen(cell, obstacles, pose, in, 300000, 250 + index),
                 "eye " + std::to_string(index));
    ++index;
  }
}

TEST(FovVolumeTest, CameraInsideAnObstacleSeesItsInside) {
  // Inside the closed box [-0.5, 0.5]^3 the camera sees up to the box's walls:
  // with a 90-degree frustum along +x, the pyramid to x = 0.5.
  const FovScene scene(MakeBox({-1, -1, -1}, {1, 1, 1}),
                       geometry::TriangleMesh::Box({-0.5, -0.5, -0.5}, {0.5, 0.5, 0.5}));
  FovEvaluator evaluator;
  EXPECT_NEAR(evaluator.Volume(scene, CameraPose::LookAt({0, 0, 0}, {1, 0, 0}),
                               MakeIntrinsics(400, 400, 200)),
              1.0 / 6.0, 1e-12);
}

TEST(FovVolumeTest, NonConvexCellMatchesSampling) {
  // L-shaped prism: [0,3]x[0,1] u [0,1]x[0,3], z in [0, 2].
  const std::array<Eigen::Vector2d, 6> outline = {Eigen::Vector2d(0, 0), Eigen::Vector2d(3, 0),
                                                  Eigen::Vector2d(3, 1), Eigen::Vector2d(1, 1),
                                                  Eigen::Vector2d(1, 3), Eigen::Vector2d(0, 3)};
  geometry::TriangleMesh cell;
  for (double z : {0.0, 2.0}) {
    for (const auto& p : outline) cell.vertices.emplace_back(p.x(), p.y(), z);
  }
  for (int i = 0; i < 6; ++i) {  // walls
    const int j = (i + 1) % 6;
    cell.triangles.push_back({i, j, j + 6});
    cell.triangles.push_back({i, j + 6, i + 6});
  }
  // Floor and ceiling: fan from the reflex corner 3 covers the L.
  for (const auto& [a, b] : std::array<std::pair<int, int>, 4>{{{4, 5}, {5, 0}, {0, 1}, {1, 2}}}) {
    cell.triangles.push_back({3, b, a});
    cell.triangles.push_back({9, a + 6, b + 6});
  }
  const auto inside = [](const Vector3d& p) {
    return p.z() >= 0 && p.z() <= 2 &&
           ((p.x() >= 0 && p.x() <= 3 && p.y() >= 0 && p.y() <= 1) ||
            (p.x() >= 0 && p.x() <= 1 && p.y() >= 0 && p.y() <= 3));
  };
  const geometry::TriangleMesh obstacles =
      geometry::TriangleMesh::Box({0.3, 1.5, 0.0}, {0.7, 1.9, 1.2});
  const FovScene scene(cell, obstacles);
  EXPECT_NEAR(scene.CellVolume(), 10.0, 1e-12);
  const SegmentOracle oracle(obstacles);
  const Intrinsics in = MakeIntrinsics(640, 480, 300);
  FovEvaluator evaluator;
  int index = 0;
  // Inside the L, outside it in the notch (looking across both arms), outside.
  for (const auto& [eye, target] : std::array<std::pair<Vector3d, Vector3d>, 3>{
           {{Vector3d(2.8, 0.5, 1.5), Vector3d(0.5, 2.0, 0.5)},
            {Vector3d(2.5, 2.5, 1.8), Vector3d(0.5, 0.5, 0.5)},
            {Vector3d(4.0, -1.0, 3.0), Vector3d(0.8, 1.5, 0.5)}}}) {
    const CameraPose pose = CameraPose::LookAt(eye, target);
    const double exact = evaluator.Volume(scene, pose, in);
    const Estimate sampled = Sample(
        MakeBox({0, 0, 0}, {3, 3, 2}), inside,
        [&](const Vector3d& p) { return InFrustum(pose, in, p) && !oracle.Blocked(eye, p); },
        300000, 300 + index);
    ExpectAgrees(exact, sampled, "eye " + std::to_string(index));
    ++index;
  }
}

#ifdef HG_SOURCE_DIR
TEST(FovVolumeTest, PaperCellMatchesSampling) {
  const geometry::TriangleMesh obstacles =
      geometry::LoadMesh(std::string(HG_SOURCE_DIR) + "/config/paper_cell/obstacles.obj");
  const common::Box3 cell = MakeBox({0, 0, 0}, {4, 4, 3});
  const FovScene scene(cell, obstacles);
  // Two of the paper cell's cameras (a corner and a wall centre), outside the cell.
  const Intrinsics corner = MakeIntrinsics(1920, 1080, 1083.5787063372297);
  const Intrinsics wall = MakeIntrinsics(1920, 1080, 980.1749836231245);
  FovEvaluator evaluator;
  const CameraPose cam0 = CameraPose::LookAt({-0.3, -0.3, 3.6}, {2, 2, 1});
  const CameraPose cam4 = CameraPose::LookAt({2, -0.4, 2.6}, {2, 2, 1});
  ExpectAgrees(evaluator.Volume(scene, cam0, corner),
               SampleSeen(cell, obstacles, cam0, corner, 300000, 400), "cam0");
  ExpectAgrees(evaluator.Volume(scene, cam4, wall),
               SampleSeen(cell, obstacles, cam4, wall, 300000, 401), "cam4");
}
#endif

// ---------------------------------------------------------------------------
// Object-free volume.

TEST(FovVolumeTest, BoxObjectIsAnObstacle) {
  const common::Box3 cell = MakeBox({0, 0, 0}, {4, 4, 3});
  const geometry::TriangleMesh table = geometry::TriangleMesh::Box({2.5, 0.5, 0}, {3.5, 1.5, 0.8});
  const geometry::TriangleMesh person = geometry::TriangleMesh::Box({1.6, 1.8, 0}, {2.1, 2.2, 1.8});
  geometry::TriangleMesh both = table;
  both.Append(person);
  const FovScene scene(cell, table);
  const FovScene scene_with_person(cell, both);
  const OccluderMesh object(person);
  FovEvaluator evaluator;
  const Intrinsics in = MakeIntrinsics(1280, 720, 700);
  std::mt19937_64 rng(5);
  for (int i = 0; i < 4; ++i) {
    const CameraPose pose = CameraPose::LookAt(RandomIn(rng, {-0.5, -0.5, 2.0}, {4.5, 0.5, 3.5}),
                                               RandomIn(rng, {1.5, 1.5, 0.5}, {2.5, 2.5, 1.5}));
    const double free = evaluator.Volume(scene, pose, in, &object);
    EXPECT_NEAR(free, evaluator.Volume(scene_with_person, pose, in), 1e-9);
    EXPECT_LT(free, evaluator.Volume(scene, pose, in));
  }
}

// True iff the segment p-q comes within the capsule's radius of its axis
// (closest points of two segments).
bool SegmentNearCapsule(const Vector3d& p, const Vector3d& q, const Capsule& c) {
  const Vector3d d1 = q - p, d2 = c.b_W - c.a_W, r = p - c.a_W;
  const double a = d1.dot(d1), e = d2.dot(d2), f = d2.dot(r);
  const double cc = d1.dot(r), b = d1.dot(d2);
  double s = 0, t = 0;
  if (e < 1e-300) {
    s = std::clamp(-cc / a, 0.0, 1.0);
  } else {
    const double denom = a * e - b * b;
    s = denom > 1e-300 ? std::clamp((b * f - cc * e) / denom, 0.0, 1.0) : 0.0;
    t = (b * s + f) / e;
    if (t < 0) {
      t = 0;
      s = std::clamp(-cc / a, 0.0, 1.0);
    } else if (t > 1) {
      t = 1;
      s = std::clamp((b - cc) / a, 0.0, 1.0);
    }
  }
  return ((p + s * d1) - (c.a_W + t * d2)).norm() <= c.radius_m;
}

TEST(FovVolumeTest, CapsuleHullContainsTheCapsule) {
  std::mt19937_64 rng(21);
  for (int segments : {4, 8, 12, 16}) {
    const Capsule capsule{RandomIn(rng, {-1, -1, -1}, {1, 1, 1}),
                          RandomIn(rng, {-1, -1, -1}, {1, 1, 1}), 0.15};
    const geometry::TriangleMesh hull = CapsuleHullMesh(capsule, segments);
    const OccluderMesh occ(hull);
    ASSERT_EQ(occ.NumComponents(), 1);
    EXPECT_TRUE(occ.component(0).closed);
    EXPECT_TRUE(occ.component(0).convex);
    // Outward as built.
    double v6 = 0;
    for (const auto& t : hull.triangles) {
      v6 += hull.vertices[t[0]].dot(hull.vertices[t[1]].cross(hull.vertices[t[2]]));
    }
    const double capsule_volume =
        std::numbers::pi * 0.15 * 0.15 * ((capsule.b_W - capsule.a_W).norm() + 4.0 / 3.0 * 0.15);
    EXPECT_GT(v6 / 6, capsule_volume);
    EXPECT_LT(v6 / 6, 2.0 * capsule_volume);
    // Every face plane keeps every capsule point inside: check the points of
    // the capsule surface that lie farthest along each face normal.
    const Vector3d axis = capsule.b_W - capsule.a_W;
    for (const auto& t : hull.triangles) {
      const Vector3d& p0 = hull.vertices[t[0]];
      const Vector3d n = (hull.vertices[t[1]] - p0).cross(hull.vertices[t[2]] - p0);
      if (n.norm() < 1e-12) continue;
      const Vector3d u = n.normalized();
      const Vector3d end = u.dot(axis) > 0 ? capsule.b_W : capsule.a_W;
      EXPECT_LE(u.dot(end + capsule.radius_m * u - p0), 1e-12);
    }
  }
}

TEST(FovVolumeTest, CapsuleObjectFreeVolumeIsConservative) {
  const common::Box3 cell = MakeBox({0, 0, 0}, {4, 4, 3});
  const geometry::TriangleMesh table = geometry::TriangleMesh::Box({2.5, 0.5, 0}, {3.5, 1.5, 0.8});
  const FovScene scene(cell, table);
  // A standing person: legs, torso, arm, head.
  const std::vector<Capsule> person = {{{1.9, 2.0, 0.1}, {1.95, 2.0, 0.85}, 0.08},
                                       {{2.1, 2.0, 0.1}, {2.05, 2.0, 0.85}, 0.08},
                                       {{2.0, 2.0, 0.9}, {2.0, 2.0, 1.45}, 0.17},
                                       {{2.2, 2.0, 1.4}, {2.5, 2.2, 1.2}, 0.05},
                                       {{2.0, 2.0, 1.62}, {2.0, 2.0, 1.62}, 0.11}};
  const OccluderMesh object = CapsulesOccluder(person, 16);
  const SegmentOracle table_oracle(table);
  const SegmentOracle hull_oracle(object.mesh());
  const Intrinsics in = MakeIntrinsics(1280, 720, 700);
  FovEvaluator evaluator;
  int index = 0;
  for (const Vector3d& eye : {Vector3d(-0.3, -0.3, 3.6), Vector3d(2.0, 0.1, 2.5)}) {
    const CameraPose pose = CameraPose::LookAt(eye, {2, 2, 1});
    const double free_exact = evaluator.Volume(scene, pose, in, &object);
    // Points free of the real capsules, and of their hulls; every point free of
    // the hulls must be free of the capsules.
    const auto seen = [&](const Vector3d& p) {
      return InFrustum(pose, in, p) && !table_oracle.Blocked(eye, p);
    };
    const auto free_of_capsules = [&](const Vector3d& p) {
      return std::none_of(person.begin(), person.end(),
                          [&](const Capsule& c) { return SegmentNearCapsule(eye, p, c); });
    };
    int violations = 0;
    const Estimate capsules = Sample(
        cell, [](const Vector3d&) { return true; },
        [&](const Vector3d& p) {
          if (!seen(p)) return false;
          const bool free_capsule = free_of_capsules(p);
          if (!hull_oracle.Blocked(eye, p) && !free_capsule) ++violations;
          return free_capsule;
        },
        300000, 500 + index);
    EXPECT_EQ(violations, 0);
    const Estimate hulls = Sample(
        cell, [](const Vector3d&) { return true; },
        [&](const Vector3d& p) { return seen(p) && !hull_oracle.Blocked(eye, p); }, 300000,
        500 + index);
    ExpectAgrees(free_exact, hulls, "hulls " + std::to_string(index));
    EXPECT_LE(free_exact, capsules.volume + 5 * capsules.sigma);
    // Close: the hulls hide only a little more than the capsules do.
    const double shadow = evaluator.Volume(scene, pose, in) - free_exact;
    EXPECT_GT(free_exact, capsules.volume - 0.1 * shadow - 5 * capsules.sigma);
    EXPECT_LT(free_exact, evaluator.Volume(scene, pose, in));
    ++index;
  }
}

// ---------------------------------------------------------------------------
// Gradient.

CameraPose Perturbed(const CameraPose& pose, int k, double h) {
  CameraPose p = pose;
  if (k < 3) {
    p.position_W[k] += h;
  } else {
    p.R_WC = pose.R_WC * Eigen::AngleAxisd(h, Vector3d::Unit(k - 3)).toRotationMatrix();
  }
  return p;
}

// Checks the gradient at random poses; returns how many poses were checked
// (the others sit next to a kink where finite differences disagree with
// themselves).
int CheckGradients(const FovScene& scene, const Intrinsics& in, const Vector3d& lo,
                   const Vector3d& hi, const Vector3d& target_lo, const Vector3d& target_hi,
                   int poses, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  FovEvaluator evaluator;
  int checked = 0;
  for (int i = 0; i < poses; ++i) {
    CameraPose pose =
        CameraPose::LookAt(RandomIn(rng, lo, hi), RandomIn(rng, target_lo, target_hi));
    std::uniform_real_distribution<double> roll(-0.5, 0.5);
    pose.R_WC = pose.R_WC * Eigen::AngleAxisd(roll(rng), Vector3d::UnitZ()).toRotationMatrix();
    const VolumeGradient g = evaluator.VolumeAndGradient(scene, pose, in);
    EXPECT_NEAR(g.volume_m3, evaluator.Volume(scene, pose, in), 1e-12 * (1 + g.volume_m3));
    bool smooth = true;
    Eigen::Matrix<double, 6, 1> fd;
    for (int k = 0; k < 6; ++k) {
      const auto diff = [&](double h) {
        return (evaluator.Volume(scene, Perturbed(pose, k, h), in) -
                evaluator.Volume(scene, Perturbed(pose, k, -h), in)) /
               (2 * h);
      };
      fd[k] = diff(1e-6);
      const double coarse = diff(4e-6);
      smooth = smooth && std::abs(fd[k] - coarse) < 1e-4 * (1 + std::abs(fd[k]));
    }
    if (!smooth) continue;
    ++checked;
    for (int k = 0; k < 6; ++k) {
      EXPECT_NEAR(g.gradient[k], fd[k], 1e-5 * (1 + std::abs(fd[k])))
          << "pose " << i << " parameter " << k;
    }
  }
  return checked;
}

TEST(FovVolumeTest, GradientMatchesFiniteDifferencesWithBoxes) {
  geometry::TriangleMesh obstacles = geometry::TriangleMesh::Box({2.5, 0.5, 0}, {3.5, 1.5, 0.8});
  obstacles.Append(geometry::TriangleMesh::Box({0.5, 2.5, 0}, {1.0, 3.5, 1.9}));
  obstacles.Append(geometry::TriangleMesh::Box({1.8, 1.8, 0}, {2.2, 2.2, 1.7}));
  const FovScene scene(MakeBox({0, 0, 0}, {4, 4, 3}), obstacles);
  const int checked = CheckGradients(scene, MakeIntrinsics(640, 480, 450), {-0.5, -0.5, 1.5},
                                     {4.5, 4.5, 3.5}, {1, 1, 0}, {3, 3, 1.5}, 12, 31);
  EXPECT_GE(checked, 9);
}

#ifdef HG_SOURCE_DIR
TEST(FovVolumeTest, GradientMatchesFiniteDifferencesInThePaperCell) {
  const FovScene scene(
      MakeBox({0, 0, 0}, {4, 4, 3}),
      geometry::LoadMesh(std::string(HG_SOURCE_DIR) + "/config/paper_cell/obstacles.obj"));
  const int checked = CheckGradients(scene, MakeIntrinsics(1920, 1080, 1000), {-0.4, -0.4, 2.0},
                                     {4.4, 4.4, 3.6}, {1.5, 1.5, 0.5}, {2.5, 2.5, 1.5}, 6, 41);
  EXPECT_GE(checked, 4);
}
#endif

TEST(FovVolumeTest, RotationParameterDerivativeChainsToYaw) {
  // Yaw about the world z axis: R_WC(psi) = Rz(psi) R0.
  const FovScene scene(MakeBox({0, 0, 0}, {4, 4, 3}),
                       geometry::TriangleMesh::Box({1.5, 1.5, 0}, {2.5, 2.5, 1}));
  const Intrinsics in = MakeIntrinsics(640, 480, 400);
  const CameraPose pose = CameraPose::LookAt({0.5, 0.3, 2.5}, {2.2, 2.8, 0.5});
  FovEvaluator evaluator;
  const VolumeGradient g = evaluator.VolumeAndGradient(scene, pose, in);
  Eigen::Matrix3d dRz;
  dRz << 0, -1, 0, 1, 0, 0, 0, 0, 0;  // d/dpsi Rz at psi = 0
  const double analytic =
      RotationParameterDerivative(pose.R_WC, dRz * pose.R_WC, g.gradient.tail<3>());
  const double h = 1e-6;
  CameraPose plus = pose, minus = pose;
  plus.R_WC = Eigen::AngleAxisd(h, Vector3d::UnitZ()).toRotationMatrix() * pose.R_WC;
  minus.R_WC = Eigen::AngleAxisd(-h, Vector3d::UnitZ()).toRotationMatrix() * pose.R_WC;
  const double fd =
      (evaluator.Volume(scene, plus, in) - evaluator.Volume(scene, minus, in)) / (2 * h);
  EXPECT_NEAR(analytic, fd, 1e-4 * (1 + std::abs(fd)));
  EXPECT_GT(std::abs(fd), 1e-3);
}

}  // namespace
}  // namespace hg::placement
