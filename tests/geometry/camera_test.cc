#include "geometry/camera.h"

#include "geometry/footprint.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>
#include <Eigen/LU>

namespace hg::geometry {
namespace {

CameraModel MakeCamera() {
  CameraModel c;
  c.name = "cam";
  c.width = 640;
  c.height = 480;
  c.K << 800, 0.5, 320, 0, 790, 240, 0, 0, 1;
  c.distortion = {0.1, -0.05, 0.001, 0.002, 0.01};
  // 90 degrees about z: exact in floating point.
  c.R_CW << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  c.t_CW = Eigen::Vector3d(0.1, -0.2, 2.0);
  return c;
}

// PixelOf is the pixel u with u - 0.5 <= x < u + 0.5, clamped far outside any
// image: at pixel edges, just beside them, negative coordinates, large magnitudes.
TEST(PixelOfTest, IsTheFloorOfTheShiftedCoordinate) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> wide(-5000.0, 5000.0);
  auto expected = [](double x) {
    if (x + 0.5 <= -1e9) return -1'000'000'000;
    if (x + 0.5 >= 1e9) return 1'000'000'000;
    return static_cast<int>(std::floor(x + 0.5));
  };
  std::vector<double> xs = {0.0, -0.0, 0.5, -0.5, 1.5, -1.5, 2e9, -2e9, 1e9, -1e9 - 0.5};
  for (int k = -50; k <= 50; ++k) {
    const double edge = k + 0.5;
    xs.push_back(edge);
    xs.push_back(std::nextafter(edge, -1e300));
    xs.push_back(std::nextafter(edge, 1e300));
    xs.push_back(k);
  }
  for (int k = 0; k < 20000; ++k) xs.push_back(wide(rng));
  for (const double x : xs) EXPECT_EQ(PixelOf(x), expected(x)) << x;
#if defined(__SSE2__)
  // The two-at-a-time version that footprints use gives the same pixels.
  for (std::size_t i = 0; i + 1 < xs.size(); ++i) {
    int out[2];
    BoxProjector::PixelsOf(_mm_set_pd(xs[i + 1], xs[i]), out);
    EXPECT_EQ(out[0], expected(xs[i])) << xs[i];
    EXPECT_EQ(out[1], expected(xs[i + 1])) << xs[i + 1];
  }
#endif
}

TEST(CameraModelTest, DistortNormalizedMatchesOpenCvFormula) {
  const CameraModel c = MakeCamera();
  // OpenCV: r2 = x^2 + y^2, radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3,
  // x' = x radial + 2 p1 x y + p2 (r2 + 2 x^2), y' = y radial + p1 (r2 + 2 y^2) + 2 p2 x y.
  // At (0.3, -0.2): r2 = 0.13, radial = 1.01217697,
  // x' = 0.303653091 - 0.00012 + 0.00062, y' = -0.202435394 + 0.00021 - 0.00024.
  const Eigen::Vector2d d = c.DistortNormalized(Eigen::Vector2d(0.3, -0.2));
  EXPECT_NEAR(d.x(), 0.304153091, 1e-15);
  EXPECT_NEAR(d.y(), -0.202465394, 1e-15);

  // The origin is a fixed point of every distortion.
  const Eigen::Vector2d o = c.DistortNormalized(Eigen::Vector2d::Zero());
  EXPECT_EQ(o.x(), 0.0);
  EXPECT_EQ(o.y(), 0.0);
}

TEST(CameraModelTest, ProjectAppliesPoseDistortionAndIntrinsics) {
  const CameraModel c = MakeCamera();
  // p_C = R p_W + t = (-0.3 + 0.1, 0.5 - 0.2, 1 + 2) = (-0.2, 0.3, 3); the pixel is
  // K * distort(-0.2/3, 0.1), evaluated independently with the formula above.
  const std::optional<Eigen::Vector2d> uv = c.Project(Eigen::Vector3d(0.5, 0.3, 1.0));
  ASSERT_TRUE(uv.has_value());
  EXPECT_NEAR(uv->x(), 266.6669266585942, 1e-9);
  EXPECT_NEAR(uv->y(), 319.11943380058983, 1e-9);

  // On the camera plane and behind it there is no projection.
  EXPECT_FALSE(c.Project(Eigen::Vector3d(0.0, 0.0, -2.0)).has_value());
  EXPECT_FALSE(c.Project(Eigen::Vector3d(1.0, 1.0, -3.0)).has_value());
}

TEST(CameraModelTest, PinholeProjectionMatrixAndCentreAgree) {
  const CameraModel c = MakeCamera();
  EXPECT_TRUE(c.HasDistortion());
  const CameraModel pin = c.Pinhole();
  EXPECT_FALSE(pin.HasDistortion());
  EXPECT_EQ(pin.K, c.K);
  EXPECT_EQ(pin.R_CW, c.R_CW);
  EXPECT_EQ(pin.t_CW, c.t_CW);

  EXPECT_NEAR(c.ToCamera(c.CentreW()).norm(), 0.0, 1e-12);

  const Eigen::Matrix<double, 3, 4> P = c.ProjectionMatrix();
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> coord(-1.0, 1.0);
  for (int i = 0; i < 100; ++i) {
    const Eigen::Vector3d p_W(coord(rng), coord(rng), coord(rng));
    const Eigen::Vector3d p_C = c.ToCamera(p_W);
    ASSERT_GT(p_C.z(), 0.0);
    const Eigen::Vector3d h = P * p_W.homogeneous();
    const Eigen::Vector2d expected = c.ProjectPinholeC(p_C);
    EXPECT_NEAR(h.x() / h.z(), expected.x(), 1e-9);
    EXPECT_NEAR(h.y() / h.z(), expected.y(), 1e-9);
    // Without distortion, Project is the pinhole projection.
    const std::optional<Eigen::Vector2d> uv = pin.Project(p_W);
    ASSERT_TRUE(uv.has_value());
    EXPECT_NEAR((*uv - expected).norm(), 0.0, 1e-9);
  }
}

TEST(DecomposeProjectionTest, RecoversRandomCamerasAtAnyScaleAndSign) {
  std::mt19937_64 rng(20240611);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::uniform_real_distribution<double> focal(100.0, 3000.0);
  std::uniform_real_distribution<double> aspect(0.9, 1.1);
  std::uniform_real_distribution<double> principal(0.0, 2000.0);
  std::uniform_real_distribution<double> log_scale(-3.0, 3.0);
  for (int trial = 0; trial < 500; ++trial) {
    Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
    K(0, 0) = focal(rng);
    K(1, 1) = K(0, 0) * aspect(rng);
    K(0, 1) = trial % 2 == 0 ? 0.0 : 2.0 * unit(rng);
    K(0, 2) = principal(rng);
    K(1, 2) = principal(rng);
    const Eigen::Matrix3d R = Eigen::Quaterniond(unit(rng), unit(rng), unit(rng), unit(rng))
                                  .normalized()
                                  .toRotationMatrix();
    const Eigen::Vector3d t(5 * unit(rng), 5 * unit(rng), 5 * unit(rng));
    // Every fifth trial at an extreme scale (1e-300 or 1e300 times): products
    // such as the determinant of P's left block over- or underflow there.
    const double magnitude = trial % 5 == 4 ? (trial % 10 == 4 ? 1e-300 : 1e300) : 1.0;
    const double scale = (trial % 3 == 0 ? -1.0 : 1.0) * magnitude * std::pow(10.0, log_scale(rng));
    Eigen::Matrix<double, 3, 4> Rt;
    Rt << R, t;
    const Eigen::Matrix<double, 3, 4> P = scale * K * Rt;

    std::string error;
    const std::optional<DecomposeResult> d = DecomposeProjection(P, &error);
    ASSERT_TRUE(d.has_value()) << "trial " << trial << ": " << error;
    EXPECT_EQ(d->K(2, 2), 1.0);
    EXPECT_EQ(d->K(1, 0), 0.0);
    EXPECT_EQ(d->K(2, 0), 0.0);
    EXPECT_EQ(d->K(2, 1), 0.0);
    EXPECT_LT((d->K - K).norm() / K.norm(), 1e-11) << "trial " << trial << "\n" << d->K;
    EXPECT_LT((d->R_CW - R).norm(), 1e-11) << "trial " << trial;
    EXPECT_NEAR(d->R_CW.determinant(), 1.0, 1e-12);
    EXPECT_LT((d->t_CW - t).norm(), 1e-10 * (1.0 + t.norm())) << "trial " << trial;
  }
}

TEST(DecomposeProjectionTest, RejectsRankDeficientLeftBlock) {
  const std::string at_infinity =
      "P's left 3x3 block is singular: a camera at infinity, not a pinhole camera";
  Eigen::Matrix<double, 3, 4> P;
  P << 800, 0, 320, 1, 0, 800, 240, 2, 0, 0, 0, 1;  // Third row of the 3x3 block is zero.
  std::string error;
  EXPECT_FALSE(DecomposeProjection(P, &error).has_value());
  EXPECT_EQ(error, at_infinity);  // P itself has rank 3.

  // Third row a combination of the first two in the 3x3 block, at a large
  // overall scale; with the last column too, P has rank 2.
  P << 800, 0, 320, 1, 0, 800, 240, 2, 1600, 800, 880, 3;
  P *= 1e6;
  error.clear();
  EXPECT_FALSE(DecomposeProjection(P, &error).has_value());
  EXPECT_EQ(error, at_infinity);
  P << 800, 0, 320, 1, 0, 800, 240, 2, 1600, 800, 880, 4;
  P *= 1e6;
  error.clear();
  EXPECT_FALSE(DecomposeProjection(P, &error).has_value());
  EXPECT_EQ(error, "P has rank < 3");

  error.clear();
  EXPECT_FALSE(DecomposeProjection(Eigen::Matrix<double, 3, 4>::Zero(), &error).has_value());
  EXPECT_EQ(error, "P has rank < 3");

  // A null error pointer is allowed.
  EXPECT_FALSE(DecomposeProjection(Eigen::Matrix<double, 3, 4>::Zero(), nullptr).has_value());

  P.setIdentity();
  P(1, 1) = std::nan("");
  EXPECT_FALSE(DecomposeProjection(P, &error).has_value());
}

}  // namespace
}  // namespace hg::geometry
