#include "tracking/particle_filter.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include <gtest/gtest.h>

namespace hg::tracking {
namespace {

using Eigen::Vector3d;

constexpr double kDt = 1.0 / 30.0;

// A 4 x 4 x 2.2 m cell of 4 cm voxels that every camera sees (all FREE).
VoxelMap OpenCell() {
  const VoxelGrid g({Vector3d::Zero(), Vector3d(4, 4, 2.2)}, 0.04);
  return VoxelMap(g, std::vector<VoxelState>(g.size(), VoxelState::kFree));
}

// A standing person as an UNKNOWN ellipsoid blob.
Ellipsoid Person(const Vector3d& centre) { return {centre, Vector3d(0.25, 0.2, 0.85)}; }

void SetBlobs(VoxelMap* map, const std::vector<Ellipsoid>& blobs) {
  std::vector<std::uint32_t> voxels;
  for (const Ellipsoid& b : blobs) AppendVoxelsInside(map->grid(), b, &voxels);
  map->SetUnknown(voxels);
}

TEST(ParticleFilterTest, ClampHalfAxesKeepsHumanSizes) {
  ParticleFilterOptions o;
  const Vector3d big = ParticleFilter::ClampHalfAxes(o, Vector3d(1.0, 1.0, 2.0));
  EXPECT_NEAR(4.0 / 3.0 * std::numbers::pi * big.prod(), o.max_volume_m3, 1e-12);
  EXPECT_LE(big.x(), o.max_half_axis_xy_m);
  EXPECT_LE(big.z(), o.max_half_axis_z_m);
  EXPECT_EQ(ParticleFilter::ClampHalfAxes(o, Vector3d(0.01, 0.01, 0.01)),
            Vector3d(o.min_half_axis_xy_m, o.min_half_axis_xy_m, o.min_half_axis_z_m));
  const Vector3d fine(0.3, 0.25, 0.8);
  EXPECT_EQ(ParticleFilter::ClampHalfAxes(o, fine), fine);
  // A small volume limit pins the short axis at its minimum and shrinks the others.
  o.max_volume_m3 = 0.1;
  const Vector3d pinned = ParticleFilter::ClampHalfAxes(o, Vector3d(0.16, 0.6, 1.0));
  EXPECT_NEAR(4.0 / 3.0 * std::numbers::pi * pinned.prod(), 0.1, 1e-12);
  EXPECT_EQ(pinned.x(), o.min_half_axis_xy_m);
  EXPECT_GE(pinned.z(), o.min_half_axis_z_m);
}

// Without diffusion the particles stay put, so the weights can be checked
// against the likelihood of each particle: w_i = (max(score_i, 0) / best)^p / S.
TEST(ParticleFilterTest, WeightsAreTheSharpenedNormalisedScores) {
  for (const double exponent : {1.0, 8.0}) {
    VoxelMap map = OpenCell();
    SetBlobs(&map, {Person({2.0, 2.0, 0.9})});
    ParticleFilterOptions o;
    o.position_noise_m_per_sqrt_s = 0.0;
    o.vertical_noise_m_per_sqrt_s = 0.0;
    o.axis_noise_m_per_sqrt_s = 0.0;
    o.posture_noise_m_per_sqrt_s = 0.0;
    o.init_position_spread_m = 0.3;  // Some particles end up mostly on free space.
    o.weight_exponent = exponent;
    ParticleFilter f(o);
    f.Reset(Person({2.0, 2.0, 0.9}), Vector3d::Zero(), 3);
    const std::vector<Ellipsoid> before(f.particles().begin(), f.particles().end());
    const LikelihoodWeights w;
    f.Step(kDt, map, w, CollisionWorld());
    std::vector<double> clamped;
    double best = 0.0;
    for (const Ellipsoid& p : before) {
      clamped.push_back(std::max(Score(CountVoxels(map, p), w), 0.0));
      best = std::max(best, clamped.back());
    }
    ASSERT_GT(best, 0.0);
    double total = 0.0;
    for (double& c : clamped) {
      c = std::pow(c / best, exponent);
      total += c;
    }
    int zeros = 0;
    for (std::size_t i = 0; i < before.size(); ++i) {
      EXPECT_NEAR(f.weights()[i], clamped[i] / total, 1e-12) << "p = " << exponent;
      zeros += clamped[i] == 0.0;
    }
    EXPECT_GT(zeros, 0);
    EXPECT_TRUE(f.estimate().weighted);
  }
}

// Places the particles 25 cm off `blob`, with the wrong shape.
void StartOffBlob(const Ellipsoid& blob, ParticleFilter* f) {
  f->Reset({blob.centre_W + Vector3d(0.2, -0.15, 0.05), Vector3d(0.35, 0.35, 0.7)},
           Vector3d::Zero(), 1);
}

void Steps(int n, const VoxelMap& map, ParticleFilter* f) {
  for (int k = 0; k < n; ++k) f->Step(kDt, map, LikelihoodWeights{}, CollisionWorld());
}

TEST(ParticleFilterTest, ConvergesOntoABlob) {
  VoxelMap map = OpenCell();
  const Ellipsoid blob = Person({1.7, 2.3, 0.9});
  SetBlobs(&map, {blob});
  ParticleFilter f(ParticleFilterOptions{});
  StartOffBlob(blob, &f);
  Steps(90, map, &f);
  const FilterEstimate& e = f.estimate();
  EXPECT_LT((e.ellipsoid.centre_W - blob.centre_W).norm(), 0.05)
      << e.ellipsoid.centre_W.transpose();
  // The linear likelihood lets the ellipsoid keep a margin of free space (each
  // free voxel costs a tenth of what an UNKNOWN one earns): it covers the blob
  // and grows by a few centimetres, not more.
  const Vector3d margin = e.ellipsoid.half_axes_m - blob.half_axes_m;
  EXPECT_GT(margin.minCoeff(), -0.05) << e.ellipsoid.half_axes_m.transpose();
  EXPECT_LT(margin.maxCoeff(), 0.2) << e.ellipsoid.half_axes_m.transpose();
  EXPECT_LT(std::sqrt(e.centre_covariance_m2.trace()), 0.2);
  EXPECT_LT(e.velocity_W_mps.norm(), 0.3);
}

// Fewer particles (an object track) and back (it stood up): the cloud stays
// where it was, and the filter keeps converging with either count.
TEST(ParticleFilterTest, ParticleCountChangesKeepTheCloud) {
  VoxelMap map = OpenCell();
  const Ellipsoid blob = Person({1.7, 2.3, 0.9});
  SetBlobs(&map, {blob});
  ParticleFilter f(ParticleFilterOptions{});
  StartOffBlob(blob, &f);
  Steps(30, map, &f);
  auto mean = [&] {
    Vector3d m = Vector3d::Zero();
    for (const Ellipsoid& p : f.particles()) m += p.centre_W;
    return Vector3d(m / static_cast<double>(f.particles().size()));
  };
  const Vector3d before = mean();
  f.SetParticleCount(100);
  ASSERT_EQ(f.particles().size(), 100u);
  EXPECT_LT((mean() - before).norm(), 0.03);
  Steps(30, map, &f);
  EXPECT_LT((f.estimate().ellipsoid.centre_W - blob.centre_W).norm(), 0.06);
  const Vector3d small = mean();
  f.SetParticleCount(ParticleFilterOptions{}.num_particles);
  ASSERT_EQ(f.particles().size(), static_cast<std::size_t>(ParticleFilterOptions{}.num_particles));
  EXPECT_LT((mean() - small).norm(), 1e-9);  // Each particle repeated three times.
  Steps(30, map, &f);
  EXPECT_LT((f.estimate().ellipsoid.centre_W - blob.centre_W).norm(), 0.05);
}

TEST(ParticleFilterTest, FollowsAMovingBlob) {
  VoxelMap map = OpenCell();
  const Vector3d start(0.8, 1.2, 0.9);
  const Vector3d velocity(1.0, 0.4, 0.0);  // 1.08 m/s, a walk.
  ParticleFilter f(ParticleFilterOptions{});
  f.Reset(Person(start), Vector3d::Zero(), 2);
  double worst = 0.0;
  for (int k = 1; k <= 75; ++k) {
    const Ellipsoid blob = Person(start + velocity * (k * kDt));
    SetBlobs(&map, {blob});
    f.Step(kDt, map, LikelihoodWeights{}, CollisionWorld());
    const double err = (f.estimate().ellipsoid.centre_W - blob.centre_W).norm();
    if (k > 15) worst = std::max(worst, err);
  }
  EXPECT_LT(worst, 0.05);
  EXPECT_LT((f.estimate().velocity_W_mps - velocity).norm(), 0.3)
      << f.estimate().velocity_W_mps.transpose();
}

// A person crouches in 0.4 s, the top of the blob going from 1.7 m to 0.9 m
// with the feet on the floor, stays down for a second and stands up again.
// The posture step (top moves, bottom stays) lets the centre's height follow
// within a few frames; independent steps of the centre and of the vertical
// half-axis lag for most of a second (mean error 0.034-0.040 m against
// 0.074-0.095 m over seeds 1-11).
TEST(ParticleFilterTest, FollowsAPersonCrouchingAndStandingUp) {
  auto mean_centre_height_error = [](double posture_noise) {
    VoxelMap map = OpenCell();
    ParticleFilterOptions o;
    o.posture_noise_m_per_sqrt_s = posture_noise;
    ParticleFilter f(o);
    const Vector3d feet(2.0, 2.0, 0.0);
    auto blob_at = [&](int k) {
      // Frames 0-11 down, 12-41 crouched, 42-53 up, then standing.
      double t = 0.0;
      if (k < 12) {
        t = k / 12.0;
      } else if (k < 42) {
        t = 1.0;
      } else if (k < 54) {
        t = 1.0 - (k - 42) / 12.0;
      }
      const double half_height = 0.85 - 0.4 * t;
      return Ellipsoid{feet + Vector3d(0, 0, half_height), Vector3d(0.25, 0.2, half_height)};
    };
    f.Reset(blob_at(0), Vector3d::Zero(), 4);
    double sum = 0.0;
    int n = 0;
    for (int k = 0; k < 90; ++k) {
      const Ellipsoid blob = blob_at(k);
      SetBlobs(&map, {blob});
      f.Step(kDt, map, LikelihoodWeights{}, CollisionWorld());
      const Ellipsoid& e = f.estimate().ellipsoid;
      sum += std::abs(e.centre_W.z() - blob.centre_W.z());
      ++n;
    }
    return sum / n;
  };
  const double with_posture =
      mean_centre_height_error(ParticleFilterOptions{}.posture_noise_m_per_sqrt_s);
  const double without = mean_centre_height_error(0.0);
  RecordProperty("height_error_with_posture_m", std::to_string(with_posture));
  RecordProperty("height_error_without_m", std::to_string(without));
  EXPECT_LT(with_posture, 0.05);
  EXPECT_GT(without, 1.6 * with_posture);
}

TEST(ParticleFilterTest, ParticlesNeverCrossAWall) {
  VoxelMap map = OpenCell();
  // Evidence beyond the wall pulls the cloud towards it.
  SetBlobs(&map, {Person({2.45, 2.0, 0.9})});
  sim::BoxSolid wall;
  wall.centre_W = {2.05, 2.0, 1.1};
  wall.half_extents_m = {0.05, 2.0, 1.1};
  const CollisionWorld world({wall});
  ParticleFilterOptions o;
  ParticleFilter f(o);
  f.Reset(Person({1.4, 2.0, 0.9}), Vector3d(1.5, 0.0, 0.0), 5);
  int collisions = 0;
  for (int k = 0; k < 60; ++k) {
    f.Step(kDt, map, LikelihoodWeights{}, world);
    collisions += f.estimate().collisions;
    for (const Ellipsoid& p : f.particles()) {
      ASSERT_LE(p.centre_W.x(), 2.0 - o.collision_radius_m) << "step " << k;
    }
  }
  EXPECT_GT(collisions, 0);
}

TEST(ParticleFilterTest, SameSeedSameResult) {
  VoxelMap map = OpenCell();
  SetBlobs(&map, {Person({2.0, 2.0, 0.9})});
  ParticleFilter a(ParticleFilterOptions{});
  ParticleFilter b(ParticleFilterOptions{});
  a.Reset(Person({2.1, 2.0, 0.9}), Vector3d::Zero(), 42);
  b.Reset(Person({2.1, 2.0, 0.9}), Vector3d::Zero(), 42);
  for (int k = 0; k < 5; ++k) {
    a.Step(kDt, map, LikelihoodWeights{}, CollisionWorld());
    b.Step(kDt, map, LikelihoodWeights{}, CollisionWorld());
  }
  EXPECT_EQ(a.estimate().ellipsoid.centre_W, b.estimate().ellipsoid.centre_W);
  EXPECT_EQ(a.estimate().ellipsoid.half_axes_m, b.estimate().ellipsoid.half_axes_m);
}

}  // namespace
}  // namespace hg::tracking
