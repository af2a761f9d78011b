#pragma once
/// @file
/// One person's particle filter (SIR): each particle is an axis-aligned
/// ellipsoid (centre x, y, z and half-axes k, l, m), propagated with constant
/// velocity and Gaussian diffusion, kept out of obstacles, weighted by the
/// voxel likelihood and resampled systematically.

#include <atomic>
#include <cstdint>
#include <random>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "common/box.h"
#include "tracking/collision.h"
#include "tracking/likelihood.h"
#include "tracking/voxel_map.h"

namespace hg::tracking {

/// Settings of one filter. Diffusion is Brownian: the standard deviation of a
/// step of dt seconds is noise * sqrt(dt).
struct ParticleFilterOptions {
  int num_particles = 300;
  /// Horizontal (x, y) diffusion of the centre, m / sqrt(s): 4.6 cm per step at 30 Hz.
  double position_noise_m_per_sqrt_s = 0.25;
  /// Vertical diffusion of the centre, m / sqrt(s).
  double vertical_noise_m_per_sqrt_s = 0.12;
  /// Diffusion of each half-axis, m / sqrt(s).
  double axis_noise_m_per_sqrt_s = 0.06;
  /// Diffusion of the ellipsoid's top with its bottom fixed (centre z and
  /// half-axis m move together by half of it), m / sqrt(s): a person
  /// crouching, lying down or getting up changes height at up to 2 m/s while
  /// the feet stay on the floor, which independent steps of the centre and
  /// of the half-axis rarely propose together.
  double posture_noise_m_per_sqrt_s = 0.3;
  /// Human sizes: half-axes k, l (x, y) and m (z) stay in these ranges. The
  /// horizontal minimum is not below collision_radius_m, so the swept capsule
  /// stays inside the space the particle's ellipsoid sweeps.
  double min_half_axis_xy_m = 0.2;
  double max_half_axis_xy_m = 0.6;
  double min_half_axis_z_m = 0.25;
  double max_half_axis_z_m = 1.0;
  /// Largest ellipsoid volume (4/3 pi k l m), m^3: a standing adult with arms
  /// out fits, two people side by side do not.
  double max_volume_m3 = 0.6;
  /// Low-pass gain of the velocity estimate per step (0: constant, 1: last step only).
  double velocity_gain = 0.3;
  /// Constant-velocity drift also along z. Off by default: people walk on the
  /// floor, and the vertical velocity of the cloud's mean is mostly noise that
  /// would move the cloud up and down; crouching and standing up are left to
  /// the vertical diffusion. The reported velocity keeps its z component.
  bool vertical_drift = false;
  /// The velocity estimate is clamped to this speed.
  double max_speed_mps = 2.5;
  /// Radius of the capsule swept between a particle's previous and predicted
  /// centre; it must not touch an obstacle. Not larger than any half-axis.
  double collision_radius_m = 0.2;
  /// Sharpness of the weights: w_i = (max(Score_i, 0) / max_j Score_j)^p. The
  /// paper's weights are the scores themselves (p = 1); a particle's score
  /// then barely drops when its ellipsoid grows past the person (each extra
  /// free voxel costs a tenth of what a missed person voxel costs), so the
  /// estimate is too large, and next to an obstacle the person stands on
  /// (whose voxels cost much more) its centre is pushed away. A larger p
  /// makes a few per cent of score a clear preference.
  double weight_exponent = 8.0;
  /// An obstacle top under a particle's centre is its floor (below it every
  /// position scores like space below the cell's floor, KNOWN or not) when it
  /// lies at most this far above the ellipsoid's bottom: a person standing
  /// on a table is scored as one standing on the floor. 0: the cell's floor only.
  double support_reach_m = 0.25;
  /// Spread of the particles around the initial ellipsoid (standard deviations).
  double init_position_spread_m = 0.08;
  double init_axis_spread_m = 0.04;
};

/// The filter's output after a step.
struct FilterEstimate {
  Ellipsoid ellipsoid;  ///< Weighted mean of the particles' centres and half-axes.
  Eigen::Matrix3d centre_covariance_m2 = Eigen::Matrix3d::Zero();  ///< Weighted, of the centres.
  Eigen::Vector3d velocity_W_mps = Eigen::Vector3d::Zero();        ///< Low-pass filtered.
  /// Bounds of the union of the particles' ellipsoids (after resampling).
  common::Box3 cloud_bounds;
  /// Some particle scored above zero in the last step (otherwise the weights
  /// were uniform).
  bool weighted = false;
  int collisions = 0;  ///< Particles whose predicted move hit an obstacle in the last step.
};

/// SIR particle filter over ellipsoids. Memory is allocated at construction;
/// Reset() and Step() allocate nothing. Single-thread (owns its random engine).
class ParticleFilter {
 public:
  explicit ParticleFilter(const ParticleFilterOptions& options);

  /// Places the particles around `initial` (its half-axes clamped to the human
  /// ranges) with the given velocity and reseeds the random engine.
  void Reset(const Ellipsoid& initial, const Eigen::Vector3d& velocity_W_mps, std::uint64_t seed);

  /// One step of dt_s seconds:
  /// 1. predict: centre += velocity * dt + diffusion, half-axes += diffusion
  ///    (clamped to the human ranges and max_volume_m3);
  /// 2. collide: a particle whose capsule (previous -> predicted centre,
  ///    collision_radius_m) touches an obstacle of `world` is replaced by a
  ///    copy of a uniformly drawn collision-free particle; when all collide,
  ///    every particle keeps its previous state;
  /// 3. weigh: w_i proportional to (max(Score_i, 0) / max_j Score_j)^p with
  ///    p = weight_exponent (uniform when no particle scores above zero),
  ///    Score over CountVoxels(map, particle, own_region) with the floor of
  ///    FloorLayerOf(map, particle, support_reach_m);
  /// 4. estimate: weighted means, centre covariance, velocity low-pass;
  /// 5. resample (systematic).
  void Step(double dt_s, const VoxelMap& map, const LikelihoodWeights& weights,
            const CollisionWorld& world, std::span<const HalfSpace> own_region = {});

  /// While `*abort` (may be null) is true, Step() returns early, leaving the
  /// filter in no defined state: for stopping a tracker that is discarded.
  void set_abort(const std::atomic<bool>* abort) { abort_ = abort; }

  /// Sets the number of particles to `count` in [1, options().num_particles]
  /// without allocating: an evenly spaced subset of the current particles,
  /// or each repeated (after a step they are equally weighted, so either
  /// keeps their distribution).
  void SetParticleCount(int count);

  [[nodiscard]] const FilterEstimate& estimate() const { return estimate_; }
  /// The particles (after the last resampling: equally weighted).
  [[nodiscard]] std::span<const Ellipsoid> particles() const { return particles_; }
  /// Normalised weights of the last step, before resampling.
  [[nodiscard]] std::span<const double> weights() const { return weights_; }
  [[nodiscard]] const ParticleFilterOptions& options() const { return options_; }

  /// Clamps half-axes to the human ranges and the volume limit of `options`.
  [[nodiscard]] static Eigen::Vector3d ClampHalfAxes(const ParticleFilterOptions& options,
                                                     const Eigen::Vector3d& half_axes_m);

 private:
  void Estimate(double dt_s, bool update_velocity);
  [[nodiscard]] bool Aborted() const {
    return abort_ != nullptr && abort_->load(std::memory_order_relaxed);
  }
  void Resample();
  void UpdateCloudBounds();

  ParticleFilterOptions options_;
  std::mt19937_64 rng_;
  const std::atomic<bool>* abort_ = nullptr;
  std::normal_distribution<double> normal_{0.0, 1.0};
  std::uniform_real_distribution<double> uniform_{0.0, 1.0};
  std::vector<Ellipsoid> particles_;
  std::vector<Ellipsoid> scratch_;  // Previous states, then resampling output.
  std::vector<double> weights_;
  std::vector<std::uint8_t> collided_;
  std::vector<int> collision_free_;
  FilterEstimate estimate_;
};

}  // namespace hg::tracking
