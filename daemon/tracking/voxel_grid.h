#pragma once
/// @file
/// The regular voxel grid of the tracking stage and the four voxel states of
/// the particle filters' likelihood.

#include <cstddef>
#include <cstdint>

#include <Eigen/Core>

#include "common/box.h"

namespace hg::tracking {

/// What a voxel holds for the likelihood. When several apply, the highest
/// wins: KNOWN > UNKNOWN > OCCLUDED > FREE.
enum class VoxelState : std::uint8_t {
  kFree = 0,      ///< Seen empty by some camera, no obstacle.
  kOccluded = 1,  ///< No camera can see it past the static obstacles (static).
  kUnknown = 2,   ///< Occupied in the current reconstruction and not an obstacle.
  kKnown = 3,     ///< Inside or on a static obstacle (static).
};

/// Cubic voxels of edge voxel_m() from origin(): voxel (x, y, z) covers
/// origin + [x, x+1) * voxel_m etc. The grid covers the requested bounds and
/// may reach past their max by less than one voxel. Voxels are indexed x
/// fastest, then y, then z; a "row" is the nx() voxels of one (y, z).
/// Immutable value type; thread-safe for concurrent reads.
class VoxelGrid {
 public:
  /// Largest nx(): the likelihood adds up to 32 row counts in 21-bit fields
  /// (see RowCounts).
  static constexpr int kMaxRowLength = 65535;

  VoxelGrid() = default;
  /// @throws common::ConfigError when bounds are empty or not finite, voxel_m is
  /// not positive, a row would be longer than kMaxRowLength voxels or the grid
  /// would hold 2^31 voxels or more.
  VoxelGrid(const common::Box3& bounds, double voxel_m);

  [[nodiscard]] int nx() const { return nx_; }
  [[nodiscard]] int ny() const { return ny_; }
  [[nodiscard]] int nz() const { return nz_; }
  [[nodiscard]] std::size_t size() const {
    return static_cast<std::size_t>(nx_) * static_cast<std::size_t>(ny_) *
           static_cast<std::size_t>(nz_);
  }
  [[nodiscard]] int num_rows() const { return ny_ * nz_; }
  [[nodiscard]] double voxel_m() const { return voxel_m_; }
  [[nodiscard]] double voxel_volume_m3() const { return voxel_m_ * voxel_m_ * voxel_m_; }
  [[nodiscard]] const Eigen::Vector3d& origin() const { return origin_; }
  /// The box the voxels cover (origin to origin + n * voxel_m).
  [[nodiscard]] common::Box3 covered() const;

  [[nodiscard]] bool InGrid(int x, int y, int z) const {
    return x >= 0 && y >= 0 && z >= 0 && x < nx_ && y < ny_ && z < nz_;
  }
  [[nodiscard]] std::uint32_t Index(int x, int y, int z) const {
    return static_cast<std::uint32_t>((z * ny_ + y) * nx_ + x);
  }
  [[nodiscard]] Eigen::Vector3i Coords(std::uint32_t index) const {
    const int i = static_cast<int>(index);
    return {i % nx_, (i / nx_) % ny_, i / (nx_ * ny_)};
  }
  /// Row number of (y, z): rows are numbered y fastest.
  [[nodiscard]] int Row(int y, int z) const { return z * ny_ + y; }

  /// Centre coordinates of voxel columns/rows/layers. Every membership test of
  /// the stage evaluates centres through these, so fast and brute-force paths
  /// agree bit for bit.
  [[nodiscard]] double CentreX(int x) const { return origin_.x() + (x + 0.5) * voxel_m_; }
  [[nodiscard]] double CentreY(int y) const { return origin_.y() + (y + 0.5) * voxel_m_; }
  [[nodiscard]] double CentreZ(int z) const { return origin_.z() + (z + 0.5) * voxel_m_; }
  [[nodiscard]] Eigen::Vector3d Centre(int x, int y, int z) const {
    return {CentreX(x), CentreY(y), CentreZ(z)};
  }

  /// Voxel containing p_W (floor of the grid coordinates; may be outside the grid).
  [[nodiscard]] Eigen::Vector3i VoxelOf(const Eigen::Vector3d& p_W) const;

 private:
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();
  double voxel_m_ = 1.0;
  int nx_ = 0;
  int ny_ = 0;
  int nz_ = 0;
};

}  // namespace hg::tracking
