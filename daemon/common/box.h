#pragma once
/// @file
/// Axis-aligned boxes in the world frame (metres).

#include <Eigen/Core>

#include "common/limits.h"

namespace hg::common {

/// Closed axis-aligned box [min, max] in metres. Value type, thread-compatible.
struct Box3 {
  Eigen::Vector3d min = Eigen::Vector3d::Zero();
  Eigen::Vector3d max = Eigen::Vector3d::Zero();

  [[nodiscard]] bool Contains(const Eigen::Vector3d& p_W) const {
    return (p_W.array() >= min.array()).all() && (p_W.array() <= max.array()).all();
  }
  /// Finite corners and max > min on every axis (NaN and infinity are invalid: an
  /// infinite box has no finite cells and a NaN one contains nothing).
  [[nodiscard]] bool IsValid() const {
    return min.allFinite() && max.allFinite() && (max.array() > min.array()).all();
  }
  /// IsValid(), and every coordinate within +-kMaxCoordinateM: what a cell's
  /// bounds may be.
  [[nodiscard]] bool IsPlausibleCell() const {
    return IsValid() && min.cwiseAbs().maxCoeff() <= kMaxCoordinateM &&
           max.cwiseAbs().maxCoeff() <= kMaxCoordinateM;
  }
  [[nodiscard]] Eigen::Vector3d Size() const { return max - min; }
  [[nodiscard]] double Volume() const { return Size().prod(); }
  /// Corner i, bit 0 selects x max, bit 1 y max, bit 2 z max.
  [[nodiscard]] Eigen::Vector3d Corner(int i) const {
    return {(i & 1) ? max.x() : min.x(), (i & 2) ? max.y() : min.y(), (i & 4) ? max.z() : min.z()};
  }
};

}  // namespace hg::common
