#include "scene/exact_mask.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <optional>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "scene/shapes.h"

namespace hg::scene {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector2d;
using Eigen::Vector3d;
using geometry::CameraModel;

double Uniform(std::mt19937_64& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

Vector3d UniformInCube(std::mt19937_64& rng, double half) {
  return {Uniform(rng, -half, half), Uniform(rng, -half, half), Uniform(rng, -half, half)};
}

Vector3d RandomUnit(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  for (;;) {
    const Vector3d d(n(rng), n(rng), n(rng));
    if (d.norm() > 1e-6) return d.normalized();
  }
}

Matrix3d RandomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  q.normalize();
  return q.toRotationMatrix();
}

Shape RandomShapeAt(std::mt19937_64& rng, const Vector3d& centre, double size_lo, double size_hi) {
  switch (std::uniform_int_distribution<int>(0, 2)(rng)) {
    case 0:
      return Sphere{centre, Uniform(rng, size_lo, size_hi)};
    case 1:
      return OrientedBox{centre,
                         Vector3d(Uniform(rng, size_lo, size_hi), Uniform(rng, size_lo, size_hi),
                                  Uniform(rng, size_lo, size_hi)),
                         RandomRotation(rng)};
    default: {
      const Vector3d half_axis = RandomUnit(rng) * Uniform(rng, size_lo, 2.0 * size_hi);
      return Capsule{centre - half_axis, centre + half_axis, Uniform(rng, size_lo, size_hi)};
    }
  }
}

Shape RandomShape(std::mt19937_64& rng, double centre_half, double size_lo, double size_hi) {
  const Vector3d centre = UniformInCube(rng, centre_half);
  return RandomShapeAt(rng, centre, size_lo, size_hi);
}

// Shapes around a camera: some behind it, some crossing its image plane z = 0,
// most in front, some containing the camera centre.
std::vector<Shape> ShapesAroundCamera(std::mt19937_64& rng, const CameraModel& camera) {
  std::vector<Shape> shapes;
  const int count = std::uniform_int_distribution<int>(1, 4)(rng);
  for (int i = 0; i < count; ++i) {
    const Vector3d c_C(Uniform(rng, -0.8, 0.8), Uniform(rng, -0.6, 0.6), Uniform(rng, -0.6, 2.5));
    const Vector3d c_W = camera.R_CW.transpose() * (c_C - camera.t_CW);
    shapes.push_back(RandomShapeAt(rng, c_W, 0.05, 0.6));
  }
  return shapes;
}

// A point known to be inside the shape.
Vector3d InteriorPoint(const Shape& shape) {
  if (const auto* s = std::get_if<Sphere>(&shape)) return s->centre_W;
  if (const auto* b = std::get_if<OrientedBox>(&shape)) return b->centre_W;
  const auto& c = std::get<Capsule>(shape);
  return 0.5 * (c.a_W + c.b_W);
}

// Points on or next to the surface, where a silhouette is hardest to get right.
Vector3d SampleNearSurface(const Shape& shape, std::mt19937_64& rng) {
  if (std::holds_alternative<Sphere>(shape)) return Support(shape, RandomUnit(rng));
  if (const auto* b = std::get_if<OrientedBox>(&shape)) {
    Vector3d q_B(Uniform(rng, -1, 1), Uniform(rng, -1, 1), Uniform(rng, -1, 1));
    const int axis = std::uniform_int_distribution<int>(0, 2)(rng);
    q_B[axis] = q_B[axis] < 0 ? -1.0 : 1.0;
    return b->centre_W + b->R_WB * q_B.cwiseProduct(b->half_extents_m);
  }
  const auto& c = std::get<Capsule>(shape);
  const double s = Uniform(rng, 0, 1);
  return c.a_W + s * (c.b_W - c.a_W) + c.radius_m * RandomUnit(rng);
}

CameraModel MakeCamera(std::mt19937_64& rng, int width, int height, const Matrix3d& R_CW,
                       const Vector3d& centre_W) {
  CameraModel camera;
  camera.name = "test";
  camera.width = width;
  camera.height = height;
  const double fx = Uniform(rng, 0.6, 1.4) * width;
  camera.K << fx, Uniform(rng, -0.02, 0.02) * fx, width * Uniform(rng, 0.4, 0.6), 0,
      fx * Uniform(rng, 0.9, 1.1), height * Uniform(rng, 0.4, 0.6), 0, 0, 1;
  camera.R_CW = R_CW;
  camera.t_CW = -R_CW * centre_W;
  return camera;
}

// Camera at centre_W looking at target_W (not straight up or down).
Matrix3d LookAt(const Vector3d& centre_W, const Vector3d& target_W) {
  const Vector3d z = (target_W - centre_W).normalized();
  const Vector3d x = z.cross(Vector3d::UnitZ()).normalized();
  const Vector3d y = z.cross(x);
  Matrix3d R_CW;
  R_CW.row(0) = x.transpose();
  R_CW.row(1) = y.transpose();
  R_CW.row(2) = z.transpose();
  return R_CW;
}

// Independent projection following the documented model (OpenCV k1 k2 p1 p2 k3).
std::optional<Vector2d> ProjectToPixelCoords(const CameraModel& camera, const Vector3d& p_W,
                                             bool distort) {
  const Vector3d p_C = camera.R_CW * p_W + camera.t_CW;
  if (!(p_C.z() > 0.0)) return std::nullopt;
  double x = p_C.x() / p_C.z();
  double y = p_C.y() / p_C.z();
  if (distort) {
    const auto& k = camera.distortion;
    const double r2 = x * x + y * y;
    const double radial = 1 + k[0] * r2 + k[1] * r2 * r2 + k[4] * r2 * r2 * r2;
    const double xd = x * radial + 2 * k[2] * x * y + k[3] * (r2 + 2 * x * x);
    const double yd = y * radial + k[2] * (r2 + 2 * y * y) + 2 * k[3] * x * y;
    x = xd;
    y = yd;
  }
  const Matrix3d& K = camera.K;
  return Vector2d(K(0, 0) * x + K(0, 1) * y + K(0, 2), K(1, 1) * y + K(1, 2));
}

// The pixel whose square [u-0.5, u+0.5) x [v-0.5, v+0.5) holds the point, if in the image.
std::optional<std::array<int, 2>> PixelOf(const CameraModel& camera, const Vector3d& p_W,
                                          bool distort) {
  const std::optional<Vector2d> uv = ProjectToPixelCoords(camera, p_W, distort);
  if (!uv) return std::nullopt;
  const double u = std::floor(uv->x() + 0.5);
  const double v = std::floor(uv->y() + 0.5);
  if (!(u >= 0 && v >= 0 && u < camera.width && v < camera.height)) return std::nullopt;
  return std::array<int, 2>{static_cast<int>(u), static_cast<int>(v)};
}

common::ImageU8 Dilate(const common::ImageU8& in) {
  common::ImageU8 out(in.width, in.height, 0);
  for (int v = 0; v < in.height; ++v) {
    for (int u = 0; u < in.width; ++u) {
      if (in.At(u, v) == 0) continue;
      for (int dv = -1; dv <= 1; ++dv) {
        for (int du = -1; du <= 1; ++du) {
          const int uu = u + du;
          const int vv = v + dv;
          if (uu >= 0 && vv >= 0 && uu < in.width && vv < in.height) out.At(uu, vv) = 255;
        }
      }
    }
  }
  return out;
}

long long CountForeground(const common::ImageU8& mask) {
  return std::count_if(mask.pixels.begin(), mask.pixels.end(), [](auto p) { return p != 0; });
}

// Number of pixels foreground in `a` but not in `b`.
long long CountNotIn(const common::ImageU8& a, const common::ImageU8& b) {
  long long n = 0;
  for (std::size_t i = 0; i < a.pixels.size(); ++i) n += (a.pixels[i] != 0 && b.pixels[i] == 0);
  return n;
}

// Analytic ray hits (ray from origin o along unit d, t >= 0).
bool RayHits(const Shape& shape, const Vector3d& o, const Vector3d& d) {
  if (const auto* s = std::get_if<Sphere>(&shape)) {
    const Vector3d oc = s->centre_W - o;
    const double tc = d.dot(oc);
    const double dist2 = oc.squaredNorm() - tc * tc;
    const double r2 = s->radius_m * s->radius_m;
    return dist2 <= r2 && tc + std::sqrt(r2 - dist2) >= 0.0;
  }
  if (const auto* b = std::get_if<OrientedBox>(&shape)) {
    const Vector3d o_B = b->R_WB.transpose() * (o - b->centre_W);
    const Vector3d d_B = b->R_WB.transpose() * d;
    double t0 = 0.0;
    double t1 = std::numeric_limits<double>::infinity();
    for (int i = 0; i < 3; ++i) {
      const double h = b->half_extents_m[i];
      if (std::abs(d_B[i]) < 1e-300) {
        if (std::abs(o_B[i]) > h) return false;
        continue;
      }
      double ta = (-h - o_B[i]) / d_B[i];
      double tb = (h - o_B[i]) / d_B[i];
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
    return t0 <= t1;
  }
  // Capsule = two end balls plus the cylinder piece between them.
  const auto& c = std::get<Capsule>(shape);
  const double r = c.radius_m;
  if (RayHits(Sphere{c.a_W, r}, o, d) || RayHits(Sphere{c.b_W, r}, o, d)) return true;
  const double length = (c.b_W - c.a_W).norm();
  if (length == 0.0) return false;
  const Vector3d axis = (c.b_W - c.a_W) / length;
  const Vector3d w = o - c.a_W;
  const Vector3d d_perp = d - d.dot(axis) * axis;
  const Vector3d w_perp = w - w.dot(axis) * axis;
  const double qa = d_perp.squaredNorm();
  if (qa < 1e-18) return false;  // Along the axis: only the end balls can be hit.
  const double qb = 2.0 * w_perp.dot(d_perp);
  const double qc = w_perp.squaredNorm() - r * r;
  const double disc = qb * qb - 4.0 * qa * qc;
  if (disc < 0.0) return false;
  // Ray parameters within radius r of the axis line...
  double t0 = std::max(0.0, (-qb - std::sqrt(disc)) / (2.0 * qa));
  double t1 = (-qb + std::sqrt(disc)) / (2.0 * qa);
  // ...and between the end planes (axial coordinate s(t) = s0 + t k in [0, L]).
  const double s0 = w.dot(axis);
  const double k = d.dot(axis);
  if (std::abs(k) < 1e-300) {
    if (s0 < 0.0 || s0 > length) return false;
  } else {
    double ta = -s0 / k;
    double tb = (length - s0) / k;
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  return t0 <= t1;
}

// Inverts the lens by fixed-point iteration (a different method from the
// renderer's); nullopt when it does not reproduce xd to 1e-12.
std::optional<Vector2d> UndistortFixedPoint(const std::array<double, 5>& k, const Vector2d& xd) {
  const auto distort = [&k](const Vector2d& xy) {
    const double x = xy.x();
    const double y = xy.y();
    const double r2 = x * x + y * y;
    const double radial = 1 + k[0] * r2 + k[1] * r2 * r2 + k[4] * r2 * r2 * r2;
    return std::pair<double, Vector2d>(radial,
                                       Vector2d(2 * k[2] * x * y + k[3] * (r2 + 2 * x * x),
                                                k[2] * (r2 + 2 * y * y) + 2 * k[3] * x * y));
  };
  Vector2d x = xd;
  for (int i = 0; i < 500; ++i) {
    const auto [radial, tangential] = distort(x);
    const Vector2d next = (xd - tangential) / radial;
    const bool settled = (next - x).norm() <= 1e-15;
    x = next;
    if (settled) break;
  }
  const auto [radial, tangential] = distort(x);
  if (!((x * radial + tangential - xd).norm() <= 1e-12)) return std::nullopt;
  return x;
}

// Mask of pixels where some ray of an n x n grid over the closed pixel square
// (edges and corners included) hits a shape, optionally through the lens.
common::ImageU8 RayCastMask(const CameraModel& camera, const std::vector<Shape>& shapes, int n,
                            bool distort = false) {
  common::ImageU8 mask(camera.width, camera.height, 0);
  const Matrix3d K_inv = camera.K.inverse();
  const Vector3d o_W = camera.CentreW();
  for (int v = 0; v < camera.height; ++v) {
    for (int u = 0; u < camera.width; ++u) {
      for (int i = 0; i < n * n && mask.At(u, v) == 0; ++i) {
        const double du = static_cast<double>(i % n) / (n - 1) - 0.5;
        const double dv = static_cast<double>(i / n) / (n - 1) - 0.5;
        Vector3d ray_C = K_inv * Vector3d(u + du, v + dv, 1.0);
        if (distort) {
          const std::optional<Vector2d> xy =
              UndistortFixedPoint(camera.distortion, ray_C.head<2>() / ray_C.z());
          if (!xy) {
            ADD_FAILURE() << "reference undistortion failed at " << u << "," << v;
            continue;
          }
          ray_C = Vector3d(xy->x(), xy->y(), 1.0);
        }
        const Vector3d d_W = (camera.R_CW.transpose() * ray_C).normalized();
        for (const Shape& shape : shapes) {
          if (RayHits(shape, o_W, d_W)) {
            mask.At(u, v) = 255;
            break;
          }
        }
      }
    }
  }
  return mask;
}

template <class Rng>
auto U01(Rng& rng) {
  return [&rng] { return std::uniform_real_distribution<double>(0.0, 1.0)(rng); };
}

// ---------------------------------------------------------------------------
// Shapes.

TEST(ShapesTest, ContainsBasics) {
  const Sphere sphere{Vector3d(1, 2, 3), 0.5};
  EXPECT_TRUE(Contains(sphere, Vector3d(1, 2, 3)));
  EXPECT_TRUE(Contains(sphere, Vector3d(1.49, 2, 3)));
  EXPECT_FALSE(Contains(sphere, Vector3d(1.51, 2, 3)));

  const Matrix3d R = Eigen::AngleAxisd(std::numbers::pi / 2, Vector3d::UnitZ()).toRotationMatrix();
  const OrientedBox box{Vector3d(0, 0, 1), Vector3d(0.5, 0.1, 0.2), R};
  // The long box axis (x) now points along world y.
  EXPECT_TRUE(Contains(box, Vector3d(0, 0.45, 1)));
  EXPECT_FALSE(Contains(box, Vector3d(0.45, 0, 1)));
  EXPECT_TRUE(Contains(box, Vector3d(0.09, -0.49, 1.19)));
  EXPECT_FALSE(Contains(box, Vector3d(0, 0, 1.21)));

  const Capsule capsule{Vector3d(0, 0, 0), Vector3d(0, 0, 2), 0.3};
  EXPECT_TRUE(Contains(capsule, Vector3d(0.29, 0, 1)));
  EXPECT_FALSE(Contains(capsule, Vector3d(0.31, 0, 1)));
  EXPECT_TRUE(Contains(capsule, Vector3d(0, 0, 2.29)));
  EXPECT_FALSE(Contains(capsule, Vector3d(0, 0, -0.31)));
  EXPECT_FALSE(Contains(capsule, Vector3d(0.25, 0, 2.25)));  // Outside the rounded end.
}

TEST(ShapesTest, SupportIsExtremeBoundaryPoint) {
  std::mt19937_64 rng(11);
  auto u01 = U01(rng);
  for (int trial = 0; trial < 60; ++trial) {
    const Shape shape = RandomShape(rng, 1.0, 0.05, 0.5);
    std::vector<Vector3d> inside;
    for (int i = 0; i < 300; ++i) inside.push_back(SampleInside(shape, u01));
    const Vector3d centre = InteriorPoint(shape);
    for (int j = 0; j < 20; ++j) {
      const Vector3d d = RandomUnit(rng) * Uniform(rng, 0.1, 10.0);
      const Vector3d s = Support(shape, d);
      for (const Vector3d& p : inside) ASSERT_LE(d.dot(p), d.dot(s) + 1e-12);
      // On the boundary: just inside towards an interior point, just outside along d.
      EXPECT_TRUE(Contains(shape, centre + (1.0 - 1e-9) * (s - centre)));
      EXPECT_FALSE(Contains(shape, s + 1e-9 * d.normalized()));
    }
  }
}

TEST(ShapesTest, BoundsAreTightAxisAlignedSupport) {
  std::mt19937_64 rng(12);
  for (int trial = 0; trial < 60; ++trial) {
    const Shape shape = RandomShape(rng, 1.0, 0.05, 0.5);
    const common::Box3 b = Bounds(shape);
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(b.max[i], Support(shape, Vector3d::Unit(i))[i], 1e-12);
      EXPECT_NEAR(b.min[i], Support(shape, -Vector3d::Unit(i))[i], 1e-12);
    }
  }
}

TEST(ShapesTest, VolumeMatchesMonteCarlo) {
  std::mt19937_64 rng(13);
  for (int trial = 0; trial < 12; ++trial) {
    const Shape shape = RandomShape(rng, 1.0, 0.05, 0.5);
    const common::Box3 b = Bounds(shape);
    constexpr int kSamples = 200000;
    int hits = 0;
    for (int i = 0; i < kSamples; ++i) {
      const Vector3d p(Uniform(rng, b.min.x(), b.max.x()), Uniform(rng, b.min.y(), b.max.y()),
                       Uniform(rng, b.min.z(), b.max.z()));
      hits += Contains(shape, p);
    }
    const double estimate = b.Volume() * hits / kSamples;
    EXPECT_NEAR(Volume(shape), estimate, 0.02 * Volume(shape)) << "trial " << trial;
  }
}

TEST(ShapesTest, VolumeFormulas) {
  EXPECT_NEAR(Volume(Sphere{Vector3d::Zero(), 2.0}), 32.0 / 3.0 * std::numbers::pi, 1e-12);
  EXPECT_NEAR(Volume(OrientedBox{Vector3d::Zero(), Vector3d(1, 2, 3), Matrix3d::Identity()}), 48.0,
              1e-12);
  EXPECT_NEAR(Volume(Capsule{Vector3d::Zero(), Vector3d(0, 3, 4), 1.0}),
              5.0 * std::numbers::pi + 4.0 / 3.0 * std::numbers::pi, 1e-12);
}

// ---------------------------------------------------------------------------
// Pinhole exact mask.

TEST(ExactMaskTest, EveryShapePointProjectsIntoForeground) {
  std::mt19937_64 rng(21);
  auto u01 = U01(rng);
  const std::array<std::array<int, 2>, 3> sizes{{{64, 48}, {120, 90}, {320, 240}}};
  long long checked = 0;
  for (int trial = 0; trial < 18; ++trial) {
    const auto [width, height] = sizes[trial % 3];
    const CameraModel camera =
        MakeCamera(rng, width, height, RandomRotation(rng), UniformInCube(rng, 1.0));
    const std::vector<Shape> shapes = ShapesAroundCamera(rng, camera);
    const common::ImageU8 mask = RenderExactMask(camera, shapes);
    ASSERT_EQ(mask.width, width);
    ASSERT_EQ(mask.height, height);
    for (const Shape& shape : shapes) {
      for (int i = 0; i < 4000; ++i) {
        const Vector3d p = (i % 2 == 0) ? SampleInside(shape, u01) : SampleNearSurface(shape, rng);
        const auto pixel = PixelOf(camera, p, /*distort=*/false);
        if (!pixel) continue;
        ++checked;
        ASSERT_EQ(mask.At((*pixel)[0], (*pixel)[1]), 255)
            << "trial " << trial << " pixel " << (*pixel)[0] << "," << (*pixel)[1];
      }
    }
  }
  EXPECT_GT(checked, 40000);  // The check above must not be vacuous.
}

TEST(ExactMaskTest, SphereSilhouetteIsTight) {
  // A pixel's pyramid holds exactly the rays within angle delta (its largest
  // corner angle) of its centre ray at most; the sphere subtends alpha about
  // its centre direction. So angle(centre ray, sphere) > alpha + delta means
  // background and < alpha - delta means foreground.
  std::mt19937_64 rng(31);
  for (int trial = 0; trial < 20; ++trial) {
    const int width = trial % 2 == 0 ? 64 : 160;
    const int height = trial % 2 == 0 ? 48 : 120;
    const Vector3d centre_W = UniformInCube(rng, 2.0) + Vector3d(0, 0, 4);
    const CameraModel camera =
        MakeCamera(rng, width, height, LookAt(centre_W, UniformInCube(rng, 0.3)), centre_W);
    const Sphere sphere{UniformInCube(rng, 0.5), Uniform(rng, 0.1, 0.8)};
    const common::ImageU8 mask = RenderExactMask(camera, {sphere});
    const Vector3d c_C = camera.R_CW * sphere.centre_W + camera.t_CW;
    ASSERT_GT(c_C.z(), sphere.radius_m);
    const double alpha = std::asin(sphere.radius_m / c_C.norm());
    const Matrix3d K_inv = camera.K.inverse();
    long long fg = 0;
    for (int v = 0; v < height; ++v) {
      for (int u = 0; u < width; ++u) {
        const Vector3d ray = (K_inv * Vector3d(u, v, 1)).normalized();
        double delta = 0.0;
        for (int i = 0; i < 4; ++i) {
          const Vector3d corner =
              (K_inv * Vector3d(u + ((i & 1) ? 0.5 : -0.5), v + ((i & 2) ? 0.5 : -0.5), 1))
                  .normalized();
          delta = std::max(delta, std::acos(std::clamp(ray.dot(corner), -1.0, 1.0)));
        }
        const double theta = std::acos(std::clamp(ray.dot(c_C.normalized()), -1.0, 1.0));
        fg += mask.At(u, v) != 0;
        if (theta > alpha + delta + 1e-7) {
          ASSERT_EQ(mask.At(u, v), 0) << "trial " << trial << " at " << u << "," << v;
        }
        if (theta < alpha - delta - 1e-7) {
          ASSERT_EQ(mask.At(u, v), 255) << "trial " << trial << " at " << u << "," << v;
        }
      }
    }
    EXPECT_GT(fg, 0);
  }
}

TEST(ExactMaskTest, NoForegroundFarFromRayCastSilhouette) {
  // Tightness for every shape type: each exact foreground pixel has a pixel
  // within one step that a dense ray cast finds (the shapes are many pixels
  // across, so a shape that touches a pixel covers sample rays next to it).
  std::mt19937_64 rng(41);
  long long exact_total = 0;
  for (int trial = 0; trial < 8; ++trial) {
    const Vector3d centre_W = UniformInCube(rng, 1.0) + Vector3d(3, 0, 1);
    const CameraModel camera =
        MakeCamera(rng, 96, 72, LookAt(centre_W, UniformInCube(rng, 0.2)), centre_W);
    std::vector<Shape> shapes;
    for (int i = 0; i < 3; ++i) shapes.push_back(RandomShape(rng, 0.5, 0.12, 0.3));
    const common::ImageU8 exact = RenderExactMask(camera, shapes);
    const common::ImageU8 cast = RayCastMask(camera, shapes, 5);
    exact_total += CountForeground(exact);
    EXPECT_EQ(CountNotIn(cast, exact), 0) << "trial " << trial;          // Correct...
    EXPECT_EQ(CountNotIn(exact, Dilate(cast)), 0) << "trial " << trial;  // ...and tight.
  }
  EXPECT_GT(exact_total, 1000);
}

TEST(ExactMaskTest, ShapeBehindCameraIsInvisible) {
  CameraModel camera;
  camera.width = 40;
  camera.height = 30;
  camera.K << 40, 0, 20, 0, 40, 15, 0, 0, 1;
  const std::vector<Shape> shapes{Sphere{Vector3d(0, 0, -2), 1.0},
                                  Capsule{Vector3d(-5, 0, -0.1), Vector3d(5, 0, -0.1), 0.05}};
  EXPECT_EQ(CountForeground(RenderExactMask(camera, shapes)), 0);
  EXPECT_EQ(CountForeground(RenderExactDistortedMask(camera, shapes)), 0);
}

TEST(ExactMaskTest, CameraInsideShapeSeesOnlyForeground) {
  CameraModel camera;
  camera.width = 40;
  camera.height = 30;
  camera.K << 40, 0, 20, 0, 40, 15, 0, 0, 1;
  camera.R_CW = Eigen::AngleAxisd(0.3, Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const OrientedBox box{Vector3d(0.1, -0.05, 0.02), Vector3d(0.3, 0.2, 0.25),
                        Eigen::AngleAxisd(0.7, Vector3d::UnitY()).toRotationMatrix()};
  EXPECT_EQ(CountForeground(RenderExactMask(camera, {box})), 40 * 30);
}

TEST(ExactMaskTest, EmptyScene) {
  CameraModel camera;
  camera.width = 16;
  camera.height = 8;
  camera.K << 10, 0, 8, 0, 10, 4, 0, 0, 1;
  const common::ImageU8 mask = RenderExactMask(camera, {});
  ASSERT_EQ(mask.pixels.size(), 16u * 8u);
  EXPECT_EQ(CountForeground(mask), 0);
}

// ---------------------------------------------------------------------------
// Distorted exact mask.

// Distortion whose radial map r -> r (1 + k1 r^2 + k2 r^4 + k3 r^6) is
// increasing for every r (k2 > 0.45 k1^2, k3 >= 0), so the lens never folds and
// every point has one distorted projection.
std::array<double, 5> RandomMonotoneDistortion(std::mt19937_64& rng) {
  const double k1 = Uniform(rng, -0.3, 0.3);
  return {k1, 0.5 * k1 * k1 + Uniform(rng, 0.0, 0.05), Uniform(rng, -0.003, 0.003),
          Uniform(rng, -0.003, 0.003), Uniform(rng, 0.0, 0.01)};
}

TEST(ExactDistortedMaskTest, EveryShapePointProjectsIntoForeground) {
  std::mt19937_64 rng(51);
  auto u01 = U01(rng);
  long long checked = 0;
  for (int trial = 0; trial < 8; ++trial) {
    const int width = trial % 2 == 0 ? 64 : 96;
    const int height = trial % 2 == 0 ? 48 : 72;
    CameraModel camera =
        MakeCamera(rng, width, height, RandomRotation(rng), UniformInCube(rng, 1.0));
    camera.distortion = RandomMonotoneDistortion(rng);
    const std::vector<Shape> shapes = ShapesAroundCamera(rng, camera);
    const common::ImageU8 mask = RenderExactDistortedMask(camera, shapes);
    for (const Shape& shape : shapes) {
      for (int i = 0; i < 4000; ++i) {
        const Vector3d p = (i % 2 == 0) ? SampleInside(shape, u01) : SampleNearSurface(shape, rng);
        const auto pixel = PixelOf(camera, p, /*distort=*/true);
        if (!pixel) continue;
        ++checked;
        ASSERT_EQ(mask.At((*pixel)[0], (*pixel)[1]), 255)
            << "trial " << trial << " pixel " << (*pixel)[0] << "," << (*pixel)[1];
      }
    }
  }
  EXPECT_GT(checked, 15000);
}

TEST(ExactDistortedMaskTest, MatchesRayCastThroughLens) {
  // Rays through a grid over each distorted pixel square, edges and corners
  // included, undistorted by a separate method: every hit pixel must be
  // foreground, and every foreground pixel must have a hit pixel next to it.
  std::mt19937_64 rng(55);
  long long exact_total = 0;
  for (int trial = 0; trial < 6; ++trial) {
    const Vector3d centre_W = UniformInCube(rng, 1.0) + Vector3d(3, 0, 1);
    CameraModel camera =
        MakeCamera(rng, 64, 48, LookAt(centre_W, UniformInCube(rng, 0.3)), centre_W);
    camera.distortion = RandomMonotoneDistortion(rng);
    std::vector<Shape> shapes;
    for (int i = 0; i < 3; ++i) shapes.push_back(RandomShape(rng, 0.6, 0.12, 0.3));
    const common::ImageU8 exact = RenderExactDistortedMask(camera, shapes);
    const common::ImageU8 cast = RayCastMask(camera, shapes, 5, /*distort=*/true);
    exact_total += CountForeground(exact);
    EXPECT_EQ(CountNotIn(cast, exact), 0) << "trial " << trial;
    EXPECT_EQ(CountNotIn(exact, Dilate(cast)), 0) << "trial " << trial;
  }
  EXPECT_GT(exact_total, 500);
}

TEST(ExactDistortedMaskTest, NearZeroDistortionMatchesPinholeWithinOnePixel) {
  // With a negligible lens, the undistorted polygons are the pixel squares
  // grown by their margin: a superset of the exact pinhole mask that adds at
  // most a one-pixel border.
  std::mt19937_64 rng(61);
  long long extra = 0;
  long long total = 0;
  for (int trial = 0; trial < 6; ++trial) {
    const Vector3d centre_W = UniformInCube(rng, 1.0) + Vector3d(3, 0, 1);
    CameraModel camera =
        MakeCamera(rng, 80, 60, LookAt(centre_W, UniformInCube(rng, 0.2)), centre_W);
    std::vector<Shape> shapes;
    for (int i = 0; i < 3; ++i) shapes.push_back(RandomShape(rng, 0.5, 0.1, 0.3));
    const common::ImageU8 pinhole = RenderExactMask(camera, shapes);
    camera.distortion = {1e-12, 0, 0, 0, 0};
    const common::ImageU8 distorted = RenderExactDistortedMask(camera, shapes);
    EXPECT_EQ(CountNotIn(pinhole, distorted), 0) << "trial " << trial;
    EXPECT_EQ(CountNotIn(distorted, Dilate(pinhole)), 0) << "trial " << trial;
    extra += CountNotIn(distorted, pinhole);
    total += CountForeground(pinhole);
  }
  ASSERT_GT(total, 0);
  // The margin is about 1/16 pixel, so only a small fraction of pixels is added.
  EXPECT_LT(static_cast<double>(extra), 0.1 * static_cast<double>(total));
}

TEST(ExactDistortedMaskTest, ZeroDistortionIsThePinholeMask) {
  std::mt19937_64 rng(71);
  const CameraModel camera =
      MakeCamera(rng, 64, 48, LookAt(Vector3d(3, 0.5, 1), Vector3d::Zero()), Vector3d(3, 0.5, 1));
  const std::vector<Shape> shapes{Sphere{Vector3d(0, 0, 0), 0.4},
                                  Capsule{Vector3d(0, -1, 0), Vector3d(0.3, 1, 0.5), 0.1}};
  EXPECT_EQ(RenderExactDistortedMask(camera, shapes).pixels,
            RenderExactMask(camera, shapes).pixels);
}

}  // namespace
}  // namespace hg::scene
