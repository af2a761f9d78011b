#include "geometry/obstacle_depth.h"
#include "support/random_scene.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

namespace hg::geometry {
namespace {

constexpr float kNone = ObstacleDepthMap::kNone;

CameraModel MakeCamera(int width, int height, double fx, double fy, double cx, double cy) {
  CameraModel camera;
  camera.name = "test";
  camera.width = width;
  camera.height = height;
  camera.K << fx, 0, cx, 0, fy, cy, 0, 0, 1;
  return camera;
}

Eigen::Matrix3d RandomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> normal;
  Eigen::Quaterniond q(normal(rng), normal(rng), normal(rng), normal(rng));
  q.normalize();
  return q.toRotationMatrix();
}

/// Pinhole projection written out here, independent of camera.cc.
Eigen::Vector2d Project(const CameraModel& camera, const Eigen::Vector3d& p_C) {
  const double x = p_C.x() / p_C.z();
  const double y = p_C.y() / p_C.z();
  return {camera.K(0, 0) * x + camera.K(0, 1) * y + camera.K(0, 2),
          camera.K(1, 1) * y + camera.K(1, 2)};
}

/// Camera-frame point -> world point for the camera's pose.
Eigen::Vector3d ToWorld(const CameraModel& camera, const Eigen::Vector3d& p_C) {
  return camera.R_CW.transpose() * (p_C - camera.t_CW);
}

/// A random scene described in the camera frame, stored in world coordinates:
/// triangles of all sizes (sub-pixel to far larger than the image), some behind
/// or crossing the near plane or the image border, and rotated boxes, some of
/// which contain the camera.
std::vector<TriangleMesh> RandomScene(const CameraModel& camera, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  auto range = [&](double lo, double hi) { return lo + (hi - lo) * uniform(rng); };
  std::vector<TriangleMesh> meshes;

  TriangleMesh triangles;
  const int triangle_count = 6 + static_cast<int>(uniform(rng) * 10);
  for (int i = 0; i < triangle_count; ++i) {
    // Centre anywhere in a frustum-ish volume, size log-uniform from 0.1 mm to 4 m.
    const double z = uniform(rng) < 0.15 ? range(-0.3, 0.2) : range(0.05, 8.0);
    const Eigen::Vector3d centre(range(-1.2, 1.2) * std::abs(z) + range(-0.3, 0.3),
                                 range(-1.0, 1.0) * std::abs(z) + range(-0.3, 0.3), z);
    const double size = std::exp(range(std::log(1e-4), std::log(4.0)));
    const int base = static_cast<int>(triangles.vertices.size());
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d offset(range(-1, 1), range(-1, 1), range(-1, 1));
      triangles.vertices.push_back(ToWorld(camera, centre + size * offset));
    }
    triangles.triangles.push_back({base, base + 1, base + 2});
  }
  meshes.push_back(triangles);

  const int box_count = static_cast<int>(uniform(rng) * 4);
  for (int i = 0; i < box_count; ++i) {
    const Eigen::Vector3d half(range(0.05, 1.0), range(0.05, 1.0), range(0.05, 1.0));
    TriangleMesh box = TriangleMesh::Box(-half, half);
    const Eigen::Matrix3d R = RandomRotation(rng);
    const Eigen::Vector3d centre_C(range(-1.5, 1.5), range(-1.5, 1.5), range(-0.5, 5.0));
    for (Eigen::Vector3d& p : box.vertices) p = ToWorld(camera, centre_C + R * p);
    meshes.push_back(box);
  }
  return meshes;
}

// Every obstacle point (in front of the millimetre-scale near plane) that
// projects into the image must lie at or behind near_depth of its pixel.
TEST(RenderObstacleDepthTest, NearDepthIsALowerBoundOnRandomScenes) {
  std::mt19937_64 rng(0x0b57ac1e);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  long long checks = 0;
  long long sub_pixel_checks = 0;
  for (int scene = 0; scene < testing::SoakSeeds(60); ++scene) {
    SCOPED_TRACE(scene);
    const double fx = 120 + 60 * uniform(rng);
    CameraModel camera = MakeCamera(160, 120, fx, fx * (0.9 + 0.2 * uniform(rng)),
                                    70 + 20 * uniform(rng), 50 + 20 * uniform(rng));
    if (scene % 3 == 0) camera.K(0, 1) = 4 * (uniform(rng) - 0.5);  // Some skew.
    camera.R_CW = RandomRotation(rng);
    camera.t_CW = Eigen::Vector3d(uniform(rng), uniform(rng), uniform(rng)) * 6 -
                  Eigen::Vector3d::Constant(3);
    const std::vector<TriangleMesh> meshes = RandomScene(camera, rng);
    const ObstacleDepthMap map = RenderObstacleDepth(camera, meshes);
    ASSERT_EQ(map.width, camera.width);
    ASSERT_EQ(map.height, camera.height);
    ASSERT_EQ(map.near_depth.size(), 160u * 120u);
    ASSERT_EQ(map.centre_depth.size(), 160u * 120u);

    for (const TriangleMesh& mesh : meshes) {
      for (const auto& t : mesh.triangles) {
        const Eigen::Vector3d& a = mesh.vertices[t[0]];
        const Eigen::Vector3d& b = mesh.vertices[t[1]];
        const Eigen::Vector3d& c = mesh.vertices[t[2]];
        const double extent = std::max({(b - a).norm(), (c - a).norm(), (c - b).norm()});
        for (int s = 0; s < 400; ++s) {
          // Vertices and edge points first (where rasterisation is most fragile),
          // then uniform interior samples.
          double w0, w1;
          if (s < 3) {
            w0 = s == 0;
            w1 = s == 1;
          } else if (s < 30) {
            const double x = uniform(rng);
            const int edge = s % 3;
            w0 = edge == 0 ? x : (edge == 1 ? 0 : 1 - x);
            w1 = edge == 0 ? 1 - x : (edge == 1 ? x : 0);
          } else {
            w0 = uniform(rng);
            w1 = uniform(rng);
            if (w0 + w1 > 1) {
              w0 = 1 - w0;
              w1 = 1 - w1;
            }
          }
          const Eigen::Vector3d p_W = w0 * a + w1 * b + (1 - w0 - w1) * c;
          const Eigen::Vector3d p_C = camera.R_CW * p_W + camera.t_CW;
          if (p_C.z() < 2e-3) continue;
          const Eigen::Vector2d uv = Project(camera, p_C);
          const double pu = std::floor(uv.x() + 0.5);
          const double pv = std::floor(uv.y() + 0.5);
          if (pu < 0 || pv < 0 || pu >= camera.width || pv >= camera.height) continue;
          const size_t index = static_cast<size_t>(pv) * camera.width + static_cast<size_t>(pu);
          const float near = map.near_depth[index];
          ASSERT_NE(near, kNone) << "pixel " << pu << "," << pv << " z " << p_C.z();
          ASSERT_LE(static_cast<double>(near), p_C.z())
              << "pixel " << pu << "," << pv << " uv " << uv.transpose();
          ++checks;
          if (extent < 1e-3) ++sub_pixel_checks;
        }
      }
    }

    // The surface hit at a pixel centre projects into that pixel, so its depth
    // can never be in front of the pixel's lower bound.
    for (size_t i = 0; i < map.near_depth.size(); ++i) {
      if (map.centre_depth[i] == kNone) continue;
      ASSERT_NE(map.near_depth[i], kNone) << i;
      ASSERT_LE(map.near_depth[i], map.centre_depth[i]) << i;
    }
  }
  // The sampling must actually have exercised the property.
  EXPECT_GT(checks, 50000);
  EXPECT_GT(sub_pixel_checks, 100);
}

// A million metres from the origin (a site frame), an obstacle a few
// centimetres in front of the lens: near_depth stays at or in front of the
// exact depth of the obstacle at every pixel centre it covers. Transformed as
// R p + t, terms of 1e6 m cancelled to 1e-10 m of error, more than the 1e-9
// relative margin of a 2 cm depth, and the bound came out behind the surface.
TEST(RenderObstacleDepthTest, NearDepthIsALowerBoundFarFromTheOrigin) {
  std::mt19937_64 rng(0xfa4);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  long long checks = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    CameraModel camera = MakeCamera(32, 24, 40, 40, 15.5, 11.5);
    camera.R_CW = RandomRotation(rng);
    const Eigen::Vector3d centre_W(1e6 * (2 * uniform(rng) - 1), 1e6 * (2 * uniform(rng) - 1),
                                   1e6 * (2 * uniform(rng) - 1));
    camera.t_CW = -camera.R_CW * centre_W;
    // A nearly fronto-parallel triangle covering the whole image, 1 .. 50 cm away.
    const double z0 = 0.01 + 0.49 * uniform(rng);
    TriangleMesh mesh;
    for (const auto& [x, y] : {std::pair{-3.0, -3.0}, {3.0, -3.0}, {0.0, 3.0}}) {
      mesh.vertices.push_back(
          ToWorld(camera, Eigen::Vector3d(x * z0, y * z0, z0 * (1 + 1e-7 * uniform(rng)))));
    }
    mesh.triangles = {{0, 1, 2}};
    const ObstacleDepthMap map = RenderObstacleDepth(camera, {mesh});
    // The vertices' exact camera coordinates, R p + t in 113-bit arithmetic.
    __float128 v[3][3];
    for (int i = 0; i < 3; ++i) {
      for (int r = 0; r < 3; ++r) {
        v[i][r] = camera.t_CW[r];
        for (int a = 0; a < 3; ++a) {
          v[i][r] += static_cast<__float128>(camera.R_CW(r, a)) * mesh.vertices[i][a];
        }
      }
    }
    // Plane n . p = d through them.
    __float128 e1[3], e2[3], n[3];
    for (int r = 0; r < 3; ++r) {
      e1[r] = v[1][r] - v[0][r];
      e2[r] = v[2][r] - v[0][r];
    }
    n[0] = e1[1] * e2[2] - e1[2] * e2[1];
    n[1] = e1[2] * e2[0] - e1[0] * e2[2];
    n[2] = e1[0] * e2[1] - e1[1] * e2[0];
    const __float128 d = n[0] * v[0][0] + n[1] * v[0][1] + n[2] * v[0][2];
    for (int pv = 0; pv < camera.height; ++pv) {
      for (int pu = 0; pu < camera.width; ++pu) {
        // The ray through the pixel centre, (xn, yn, 1), meets the plane at depth z.
        const __float128 xn = (pu - static_cast<__float128>(camera.K(0, 2))) / camera.K(0, 0);
        const __float128 yn = (pv - static_cast<__float128>(camera.K(1, 2))) / camera.K(1, 1);
        const double z = static_cast<double>(d / (n[0] * xn + n[1] * yn + n[2]));
        const float near = map.near_depth[static_cast<size_t>(pv) * camera.width + pu];
        ASSERT_NE(near, kNone) << "trial " << trial << " pixel " << pu << "," << pv;
        ASSERT_LE(static_cast<double>(near), z) << "trial " << trial << " pixel " << pu << "," << pv
                                                << " camera at " << centre_W.transpose();
        ++checks;
      }
    }
  }
  EXPECT_EQ(checks, 3000LL * 32 * 24);
}

TEST(RenderObstacleDepthTest, TrianglesBehindTheCameraLeaveTheMapEmpty) {
  const CameraModel camera = MakeCamera(40, 30, 30, 30, 19.5, 14.5);
  TriangleMesh mesh;
  mesh.vertices = {{-1, -1, -0.5}, {1, -1, -0.5}, {0, 1, -2}, {0, 0, 0}};
  mesh.triangles = {{0, 1, 2}, {0, 1, 3}};
  const ObstacleDepthMap map = RenderObstacleDepth(camera, {mesh});
  for (size_t i = 0; i < map.near_depth.size(); ++i) {
    EXPECT_EQ(map.near_depth[i], kNone);
    EXPECT_EQ(map.centre_depth[i], kNone);
  }
}

// Triangles are clipped 1 mm in front of the camera. One that reaches in
// front of the camera within that distance (inside its lens) could cover any
// pixel at any depth from 0 on: the whole view is blocked, never left clear.
// Near but beside the view, behind the camera, or beyond the near plane: not.
TEST(RenderObstacleDepthTest, AnObstacleInsideTheNearPlaneBlocksTheWholeView) {
  const CameraModel camera = MakeCamera(40, 30, 30, 30, 19.5, 14.5);
  auto plate = [](double x, double z, double half) {
    TriangleMesh mesh;
    mesh.vertices = {
        {x - half, -half, z}, {x + half, -half, z}, {x + half, half, z}, {x - half, half, z}};
    mesh.triangles = {{0, 1, 2}, {0, 2, 3}};
    return mesh;
  };
  struct Case {
    const char* what;
    TriangleMesh mesh;
    bool blocked;
  };
  const Case cases[] = {
      {"plate 0.5 mm in front", plate(0.0, 5e-4, 5e-3), true},
      {"plate 0.5 mm in front, its edge 0.2 mm beside the axis", plate(2e-4 + 5e-3, 5e-4, 5e-3),
       true},
      {"plate 2 mm in front, covering the middle", plate(0.0, 2e-3, 5e-4), false},
      {"plate 0.5 mm in front, 1 m to the side", plate(1.0, 5e-4, 5e-3), false},
      {"plate 0.5 mm behind", plate(0.0, -5e-4, 5e-3), false},
      // Covering the whole view within 10 cm (the camera inside a housing
      // modelled with the obstacles) blocks it too; beyond, or leaving a
      // corner open, not.
      {"plate 2 mm in front, covering the view", plate(0.0, 2e-3, 5e-3), true},
      {"plate 9 cm in front, covering the view", plate(0.0, 0.09, 0.1), true},
      {"plate 11 cm in front, covering the view", plate(0.0, 0.11, 0.1), false},
      {"plate 9 cm in front, a corner of the view open", plate(0.003, 0.09, 0.06), false},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    const ObstacleDepthMap map = RenderObstacleDepth(camera, {c.mesh});
    EXPECT_EQ(map.blocked, c.blocked);
    const float centre = map.near_depth[static_cast<std::size_t>(15 * 40 + 20)];
    if (c.blocked) {
      EXPECT_EQ(*std::max_element(map.near_depth.begin(), map.near_depth.end()), 0.0F);
    } else if (c.mesh.vertices[0].z() > 1e-3 && c.mesh.vertices[0].x() < 0) {
      EXPECT_NEAR(centre, c.mesh.vertices[0].z(), 1e-6);
    } else {
      EXPECT_EQ(centre, kNone);
    }
  }
}

/// Square [-0.5, 0.5]^2 in the camera's x-y, on the plane z = z0 + slope * x.
TriangleMesh Square(const CameraModel& camera, double z0, double slope) {
  TriangleMesh mesh;
  for (const auto& [x, y] : {std::pair{-0.5, -0.5}, {0.5, -0.5}, {0.5, 0.5}, {-0.5, 0.5}}) {
    mesh.vertices.push_back(ToWorld(camera, Eigen::Vector3d(x, y, z0 + slope * x)));
  }
  mesh.triangles = {{0, 1, 2}, {0, 2, 3}};
  return mesh;
}

// 150 px focal length, square of 1 m at 2 m: u, v in [42, 117] x [22, 97].
CameraModel SquareCamera(std::mt19937_64* rng) {
  CameraModel camera = MakeCamera(160, 120, 150, 150, 79.5, 59.5);
  if (rng != nullptr) {
    camera.R_CW = RandomRotation(*rng);
    camera.t_CW = Eigen::Vector3d(0.3, -1.7, 2.2);
  }
  return camera;
}

TEST(RenderObstacleDepthTest, NearDepthIsTightOnAFrontoParallelSquare) {
  std::mt19937_64 rng(7);
  for (const bool posed : {false, true}) {
    const CameraModel camera = SquareCamera(posed ? &rng : nullptr);
    const ObstacleDepthMap map = RenderObstacleDepth(camera, {Square(camera, 2.0, 0.0)});
    for (int v = 0; v < camera.height; ++v) {
      for (int u = 0; u < camera.width; ++u) {
        const float near = map.near_depth[v * camera.width + u];
        if (u >= 44 && u <= 115 && v >= 24 && v <= 95) {
          EXPECT_LE(near, 2.0f);
          EXPECT_NEAR(near, 2.0, 1e-5) << u << "," << v;
        } else if (u <= 40 || u >= 119 || v <= 20 || v >= 99) {
          EXPECT_EQ(near, kNone) << u << "," << v;
        }
      }
    }
  }
}

TEST(RenderObstacleDepthTest, NearDepthIsTightOnATiltedSquare) {
  // Plane z = 2 + 0.5 x, i.e. z = 2 / (1 - 0.5 xn) along the ray (xn, yn, 1).
  // z grows with xn, so over a pixel square the smallest z is on its left side.
  const CameraModel camera = SquareCamera(nullptr);
  const ObstacleDepthMap map = RenderObstacleDepth(camera, {Square(camera, 2.0, 0.5)});
  int checked = 0;
  for (int v = 30; v <= 90; ++v) {
    for (int u = 50; u <= 110; ++u) {
      const double xn_min = (u - 0.5 - 79.5) / 150.0;
      const double z_min = 2.0 / (1.0 - 0.5 * xn_min);
      const float near = map.near_depth[v * camera.width + u];
      EXPECT_LE(near, z_min) << u << "," << v;
      EXPECT_NEAR(near, z_min, 1e-5) << u << "," << v;
      ++checked;
    }
  }
  EXPECT_GT(checked, 3000);
}

TEST(RenderObstacleDepthTest, NearDepthCoversOnlyPixelsTouchingTheTriangle) {
  // Right triangle at z = 1 whose hypotenuse runs diagonally through the image:
  // its bounding box is the whole image, but pixels well beyond the hypotenuse
  // must stay empty (exact separating-axis test, not a bounding box).
  const CameraModel camera = MakeCamera(64, 64, 100, 100, 31.5, 31.5);
  TriangleMesh mesh;
  // Image corners (-0.5, -0.5), (63.5, -0.5), (-0.5, 63.5) back-projected at z = 1.
  mesh.vertices = {{-0.32, -0.32, 1}, {0.32, -0.32, 1}, {-0.32, 0.32, 1}};
  mesh.triangles = {{0, 1, 2}};
  const ObstacleDepthMap map = RenderObstacleDepth(camera, {mesh});
  for (int v = 0; v < 64; ++v) {
    for (int u = 0; u < 64; ++u) {
      const float near = map.near_depth[v * 64 + u];
      // Hypotenuse: u + v = 63; a pixel square touches it iff u + v - 1 <= 63.
      if (u + v <= 61) {
        EXPECT_NEAR(near, 1.0, 1e-6) << u << "," << v;
      } else if (u + v >= 65) {
        EXPECT_EQ(near, kNone) << u << "," << v;
      } else if (u + v == 64) {
        EXPECT_NE(near, kNone) << u << "," << v;  // Touches at a corner only.
      }
    }
  }
}

TEST(RenderObstacleDepthTest, CentreDepthOfAFrontoParallelQuad) {
  const CameraModel camera = SquareCamera(nullptr);
  // Far quad first: the nearer one must win regardless of order.
  const ObstacleDepthMap map =
      RenderObstacleDepth(camera, {Square(camera, 3.0, 0.0), Square(camera, 2.0, 0.0)});
  for (int v = 50; v <= 70; ++v) {
    for (int u = 70; u <= 90; ++u) {
      EXPECT_NEAR(map.centre_depth[v * camera.width + u], 2.0, 1e-6) << u << "," << v;
    }
  }
  // Square at 3 m covers [54.5, 104.5]: only the 2 m square is seen beyond it.
  EXPECT_NEAR(map.centre_depth[60 * camera.width + 45], 2.0, 1e-6);
  EXPECT_EQ(map.centre_depth[60 * camera.width + 30], kNone);
  EXPECT_EQ(map.centre_depth[5 * camera.width + 80], kNone);
}

TEST(RenderObstacleDepthTest, CentreDepthIsPerspectiveCorrect) {
  const CameraModel camera = SquareCamera(nullptr);
  const ObstacleDepthMap map = RenderObstacleDepth(camera, {Square(camera, 2.0, 0.5)});
  for (int v = 30; v <= 90; v += 3) {
    for (int u = 50; u <= 110; u += 3) {
      const double xn = (u - 79.5) / 150.0;
      EXPECT_NEAR(map.centre_depth[v * camera.width + u], 2.0 / (1.0 - 0.5 * xn), 1e-5)
          << u << "," << v;
    }
  }
}

// ---------------------------------------------------------------------------
// DepthPyramid against brute force.

std::vector<float> RandomMap(int width, int height, std::mt19937_64& rng) {
  // A few discrete levels so that thresholds hit stored values exactly, plus
  // infinities for "no obstacle".
  std::uniform_int_distribution<int> pick(0, 9);
  std::vector<float> values(static_cast<size_t>(width) * height);
  for (float& value : values) {
    const int k = pick(rng);
    value = k == 9 ? kNone : 0.5f * static_cast<float>(k);
  }
  // Occasionally a smooth region, so that whole subtrees agree.
  if (pick(rng) < 3) {
    const int x0 = width / 4;
    const int y0 = height / 4;
    for (int y = y0; y < height; ++y) {
      for (int x = x0; x < width; ++x) values[static_cast<size_t>(y) * width + x] = kNone;
    }
  }
  return values;
}

TEST(DepthPyramidTest, RectPredicatesMatchBruteForce) {
  std::mt19937_64 rng(99);
  const std::pair<int, int> sizes[] = {{1, 1},   {1, 17},  {29, 1},  {2, 2},    {37, 23},
                                       {64, 64}, {65, 33}, {3, 100}, {160, 120}};
  long long queries = 0;
  long long true_answers = 0;
  for (const auto& [width, height] : sizes) {
    for (int map_index = 0; map_index < 4; ++map_index) {
      const std::vector<float> values = RandomMap(width, height, rng);
      const DepthPyramid min_pyramid(values, width, height, DepthPyramid::Kind::kMin);
      const DepthPyramid max_pyramid(values, width, height, DepthPyramid::Kind::kMax);
      ASSERT_FALSE(min_pyramid.empty());
      EXPECT_EQ(min_pyramid.Global(), *std::min_element(values.begin(), values.end()));
      EXPECT_EQ(max_pyramid.Global(), *std::max_element(values.begin(), values.end()));

      std::uniform_int_distribution<int> ux(0, width - 1);
      std::uniform_int_distribution<int> uy(0, height - 1);
      std::uniform_int_distribution<int> level(-1, 10);
      std::uniform_real_distribution<double> real(-0.2, 5.0);
      for (int q = 0; q < 400; ++q) {
        int u0 = ux(rng), u1 = ux(rng), v0 = uy(rng), v1 = uy(rng);
        if (u0 > u1) std::swap(u0, u1);
        if (v0 > v1) std::swap(v0, v1);
        if (q % 10 == 0) {  // Small rects are the common case in the octree.
          u1 = std::min(u0 + q % 3, width - 1);
          v1 = std::min(v0 + q % 4, height - 1);
        }
        const PixelRect rect{u0, v0, u1, v1};
        const int l = level(rng);
        const double z =
            l == 10 ? std::numeric_limits<double>::infinity() : (l == -1 ? real(rng) : 0.5 * l);
        bool all_greater = true;
        bool all_less = true;
        for (int v = v0; v <= v1; ++v) {
          for (int u = u0; u <= u1; ++u) {
            const double value = values[static_cast<size_t>(v) * width + u];
            all_greater = all_greater && value > z;
            all_less = all_less && value < z;
          }
        }
        ASSERT_EQ(min_pyramid.AllGreater(rect, z), all_greater)
            << width << "x" << height << " rect " << u0 << "," << v0 << "-" << u1 << "," << v1
            << " z " << z;
        ASSERT_EQ(max_pyramid.AllLess(rect, z), all_less)
            << width << "x" << height << " rect " << u0 << "," << v0 << "-" << u1 << "," << v1
            << " z " << z;
        ++queries;
        true_answers += all_greater + all_less;
      }
    }
  }
  // Both answers must have occurred often enough to mean something.
  EXPECT_GT(true_answers, queries / 10);
  EXPECT_LT(true_answers, 2 * queries - queries / 10);
}

TEST(DepthPyramidTest, PyramidOverRenderedMapAnswersLikeThePixels) {
  const CameraModel camera = SquareCamera(nullptr);
  const ObstacleDepthMap map = RenderObstacleDepth(camera, {Square(camera, 2.0, 0.0)});
  const DepthPyramid pyramid(map.near_depth, map.width, map.height, DepthPyramid::Kind::kMin);
  EXPECT_NEAR(pyramid.Global(), 2.0, 1e-5);
  EXPECT_TRUE(pyramid.AllGreater({50, 30, 100, 90}, 1.99));
  EXPECT_FALSE(pyramid.AllGreater({50, 30, 100, 90}, 2.0));
  EXPECT_TRUE(pyramid.AllGreater({0, 0, 30, 119}, 1e9));  // Left of the square: no obstacle.
  EXPECT_FALSE(pyramid.AllGreater({0, 0, 42, 119}, 1e9));
}

}  // namespace
}  // namespace hg::geometry
