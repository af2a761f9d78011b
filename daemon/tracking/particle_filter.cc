#include "tracking/particle_filter.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "common/check.h"

namespace hg::tracking {

using Eigen::Vector3d;

ParticleFilter::ParticleFilter(const ParticleFilterOptions& options) : options_(options) {
  HG_CHECK(options_.num_particles > 0);
  const auto n = static_cast<std::size_t>(options_.num_particles);
  particles_.resize(n);
  scratch_.resize(n);
  weights_.assign(n, 1.0 / static_cast<double>(n));
  collided_.assign(n, 0);
  collision_free_.reserve(n);
}

void ParticleFilter::SetParticleCount(int count) {
  HG_CHECK(count >= 1 && count <= options_.num_particles);
  const auto n = static_cast<std::size_t>(count);
  const std::size_t old = particles_.size();
  if (n == old) return;
  scratch_.resize(n);  // Within the capacity reserved at construction.
  for (std::size_t i = 0; i < n; ++i) scratch_[i] = particles_[i * old / n];
  particles_.resize(n);
  particles_.swap(scratch_);
  weights_.assign(n, 1.0 / static_cast<double>(n));
  collided_.resize(n);
  UpdateCloudBounds();
}

Vector3d ParticleFilter::ClampHalfAxes(const ParticleFilterOptions& o, const Vector3d& h) {
  const Vector3d lo(o.min_half_axis_xy_m, o.min_half_axis_xy_m, o.min_half_axis_z_m);
  const Vector3d hi(o.max_half_axis_xy_m, o.max_half_axis_xy_m, o.max_half_axis_z_m);
  Vector3d out = h.cwiseMax(lo).cwiseMin(hi);
  // Shrink the axes that are above their minimum until the volume fits; each
  // round pins at least one more axis at its minimum or meets the limit.
  const double max_product = o.max_volume_m3 / (4.0 / 3.0 * std::numbers::pi);
  for (int round = 0; round < 3; ++round) {
    const double product = out.prod();
    if (product <= max_product) break;
    double pinned = 1.0;
    int free_axes = 0;
    for (int a = 0; a < 3; ++a) {
      if (out[a] > lo[a]) {
        ++free_axes;
      } else {
        pinned *= out[a];
      }
    }
    if (free_axes == 0) break;
    const double free_product = product / pinned;
    const double f = std::pow(max_product / pinned / free_product, 1.0 / free_axes);
    for (int a = 0; a < 3; ++a) {
      if (out[a] > lo[a]) out[a] = std::max(lo[a], out[a] * f);
    }
  }
  return out;
}

void ParticleFilter::Reset(const Ellipsoid& initial, const Vector3d& velocity_W_mps,
                           std::uint64_t seed) {
  rng_.seed(seed);
  normal_.reset();
  const Vector3d h0 = ClampHalfAxes(options_, initial.half_axes_m);
  for (Ellipsoid& p : particles_) {
    for (int a = 0; a < 3; ++a) {
      p.centre_W[a] = initial.centre_W[a] + options_.init_position_spread_m * normal_(rng_);
      p.half_axes_m[a] = h0[a] + options_.init_axis_spread_m * normal_(rng_);
    }
    p.half_axes_m = ClampHalfAxes(options_, p.half_axes_m);
  }
  std::fill(weights_.begin(), weights_.end(), 1.0 / static_cast<double>(weights_.size()));
  estimate_ = FilterEstimate{};
  estimate_.velocity_W_mps = velocity_W_mps;
  Estimate(0.0, false);
  UpdateCloudBounds();
}

void ParticleFilter::Step(double dt_s, const VoxelMap& map, const LikelihoodWeights& w,
                          const CollisionWorld& world, std::span<const HalfSpace> own_region) {
  const std::size_t n = particles_.size();
  const double sqrt_dt = std::sqrt(std::max(dt_s, 0.0));
  const double s_xy = options_.position_noise_m_per_sqrt_s * sqrt_dt;
  const double s_z = options_.vertical_noise_m_per_sqrt_s * sqrt_dt;
  const double s_axis = options_.axis_noise_m_per_sqrt_s * sqrt_dt;
  const double s_posture = options_.posture_noise_m_per_sqrt_s * sqrt_dt;
  Vector3d drift = estimate_.velocity_W_mps * dt_s;
  if (!options_.vertical_drift) drift.z() = 0.0;

  // 1-2. Predict and collide.
  collision_free_.clear();
  for (std::size_t i = 0; i < n; ++i) {
    Ellipsoid& p = particles_[i];
    scratch_[i] = p;
    p.centre_W += drift;
    p.centre_W.x() += s_xy * normal_(rng_);
    p.centre_W.y() += s_xy * normal_(rng_);
    p.centre_W.z() += s_z * normal_(rng_);
    for (int a = 0; a < 3; ++a) p.half_axes_m[a] += s_axis * normal_(rng_);
    p.half_axes_m = ClampHalfAxes(options_, p.half_axes_m);
    if (s_posture > 0.0) {
      // The top moves, the bottom stays where it is (within the human sizes).
      const double m_before = p.half_axes_m.z();
      p.half_axes_m.z() += 0.5 * s_posture * normal_(rng_);
      p.half_axes_m = ClampHalfAxes(options_, p.half_axes_m);
      p.centre_W.z() += p.half_axes_m.z() - m_before;
    }
    const bool hit =
        world.CapsuleHits(scratch_[i].centre_W, p.centre_W, options_.collision_radius_m);
    collided_[i] = hit ? 1 : 0;
    if (!hit) collision_free_.push_back(static_cast<int>(i));
  }
  estimate_.collisions = static_cast<int>(n - collision_free_.size());
  if (estimate_.collisions > 0) {
    if (collision_free_.empty()) {
      std::copy(scratch_.begin(), scratch_.end(), particles_.begin());
    } else {
      std::uniform_int_distribution<int> pick(0, static_cast<int>(collision_free_.size()) - 1);
      for (std::size_t i = 0; i < n; ++i) {
        if (collided_[i] != 0) particles_[i] = particles_[collision_free_[pick(rng_)]];
      }
    }
  }

  // 3. Weigh.
  double best = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    if ((i & 255) == 0 && Aborted()) return;
    const Ellipsoid& e = particles_[i];
    const int floor_layer = FloorLayerOf(map, e, options_.support_reach_m);
    const double score = Score(CountVoxels(map, e, own_region, SumAxis::kAuto, floor_layer), w);
    weights_[i] = std::max(score, 0.0);
    best = std::max(best, weights_[i]);
  }
  estimate_.weighted = best > 0.0;
  if (estimate_.weighted) {
    double total = 0.0;
    const double p = options_.weight_exponent;
    for (double& x : weights_) {
      x = p == 1.0 ? x / best : std::pow(x / best, p);
      total += x;
    }
    for (double& x : weights_) x /= total;
  } else {
    std::fill(weights_.begin(), weights_.end(), 1.0 / static_cast<double>(n));
  }

  // 4-5. Estimate, resample.
  Estimate(dt_s, true);
  Resample();
  UpdateCloudBounds();
}

void ParticleFilter::Estimate(double dt_s, bool update_velocity) {
  Vector3d mean = Vector3d::Zero();
  Vector3d axes = Vector3d::Zero();
  for (std::size_t i = 0; i < particles_.size(); ++i) {
    mean += weights_[i] * particles_[i].centre_W;
    axes += weights_[i] * particles_[i].half_axes_m;
  }
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < particles_.size(); ++i) {
    const Vector3d d = particles_[i].centre_W - mean;
    cov.noalias() += weights_[i] * d * d.transpose();
  }
  if (update_velocity && dt_s > 0.0) {
    const Vector3d measured = (mean - estimate_.ellipsoid.centre_W) / dt_s;
    Vector3d v = (1.0 - options_.velocity_gain) * estimate_.velocity_W_mps +
                 options_.velocity_gain * measured;
    const double speed = v.norm();
    if (speed > options_.max_speed_mps) v *= options_.max_speed_mps / speed;
    estimate_.velocity_W_mps = v;
  }
  estimate_.ellipsoid.centre_W = mean;
  estimate_.ellipsoid.half_axes_m = axes;
  estimate_.centre_covariance_m2 = cov;
}

void ParticleFilter::UpdateCloudBounds() {
  common::Box3& b = estimate_.cloud_bounds;
  b.min = Vector3d::Constant(std::numeric_limits<double>::infinity());
  b.max = -b.min;
  for (const Ellipsoid& p : particles_) {
    b.min = b.min.cwiseMin(p.centre_W - p.half_axes_m);
    b.max = b.max.cwiseMax(p.centre_W + p.half_axes_m);
  }
}

void ParticleFilter::Resample() {
  // Systematic: one uniform offset, n evenly spaced pointers into the CDF.
  const std::size_t n = particles_.size();
  const double step = 1.0 / static_cast<double>(n);
  double u = uniform_(rng_) * step;
  double cdf = weights_[0];
  std::size_t j = 0;
  for (std::size_t i = 0; i < n; ++i) {
    while (u > cdf && j + 1 < n) cdf += weights_[++j];
    scratch_[i] = particles_[j];
    u += step;
  }
  particles_.swap(scratch_);
}

}  // namespace hg::tracking
