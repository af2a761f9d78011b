#pragma once
/// @file
/// Calibrated camera model: OpenCV pinhole with k1 k2 p1 p2 k3 distortion and a
/// world-to-camera pose, x_C = R_CW p_W + t_CW. Pixel centres sit at integer
/// coordinates; pixel (u, v) covers [u-0.5, u+0.5) x [v-0.5, v+0.5).

#include <array>
#include <optional>
#include <string>

#include <Eigen/Core>

namespace hg::geometry {

/// Integer pixel rectangle, inclusive bounds. Empty when u1 < u0 or v1 < v0.
struct PixelRect {
  int u0 = 0;
  int v0 = 0;
  int u1 = -1;
  int v1 = -1;
  [[nodiscard]] bool Empty() const { return u1 < u0 || v1 < v0; }
  [[nodiscard]] long long Area() const {
    return Empty() ? 0 : static_cast<long long>(u1 - u0 + 1) * (v1 - v0 + 1);
  }
};

/// One calibrated camera. Value type, thread-compatible.
struct CameraModel {
  std::string name;
  int width = 0;
  int height = 0;
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();  ///< Intrinsics, K(2,2) == 1.
  /// OpenCV order k1 k2 p1 p2 k3; all zero means a pure pinhole.
  std::array<double, 5> distortion{0, 0, 0, 0, 0};
  Eigen::Matrix3d R_CW = Eigen::Matrix3d::Identity();  ///< World -> camera rotation.
  Eigen::Vector3d t_CW = Eigen::Vector3d::Zero();      ///< World -> camera translation (m).

  [[nodiscard]] bool HasDistortion() const;

  /// Camera centre in world coordinates (m).
  [[nodiscard]] Eigen::Vector3d CentreW() const { return -R_CW.transpose() * t_CW; }

  /// Point in the camera frame.
  [[nodiscard]] Eigen::Vector3d ToCamera(const Eigen::Vector3d& p_W) const {
    return R_CW * p_W + t_CW;
  }

  /// Ideal pinhole projection (no distortion) of a point in the camera frame.
  /// Precondition: p_C.z() > 0.
  [[nodiscard]] Eigen::Vector2d ProjectPinholeC(const Eigen::Vector3d& p_C) const;

  /// Applies the distortion model to normalised image coordinates (x/z, y/z).
  [[nodiscard]] Eigen::Vector2d DistortNormalized(const Eigen::Vector2d& xy) const;

  /// Full projection with distortion of a world point; nullopt when z <= 0.
  [[nodiscard]] std::optional<Eigen::Vector2d> Project(const Eigen::Vector3d& p_W) const;

  /// The same camera without distortion (what the octree sees after the masks
  /// were undistorted conservatively).
  [[nodiscard]] CameraModel Pinhole() const;

  /// 3x4 projection matrix K [R | t] (pinhole part only).
  [[nodiscard]] Eigen::Matrix<double, 3, 4> ProjectionMatrix() const;
};

/// The OpenCV lens model (k1 k2 p1 p2 k3) applied to normalised image
/// coordinates (x/z, y/z); `jacobian`, when not null, receives its derivative.
[[nodiscard]] Eigen::Vector2d ApplyDistortion(const std::array<double, 5>& k,
                                              const Eigen::Vector2d& xy,
                                              Eigen::Matrix2d* jacobian = nullptr);

/// Inverts ApplyDistortion: solves ApplyDistortion(k, x) = xd by damped Newton
/// from the start value in *x, to a residual of 1e-12 * max(1, |xd|). Returns
/// false without convergence or where the Jacobian is not positive (past a fold
/// of the polynomial model, where it no longer describes a lens); *x is then
/// unspecified.
[[nodiscard]] bool InvertDistortion(const std::array<double, 5>& k, const Eigen::Vector2d& xd,
                                    Eigen::Vector2d* x);

/// Decomposes a 3x4 projection matrix of any scale and sign into K, R, t (RQ
/// decomposition, K with positive diagonal and K(2,2) == 1, det R == +1).
/// Returns an error message when P's left 3x3 block has rank < 3.
struct DecomposeResult {
  Eigen::Matrix3d K;
  Eigen::Matrix3d R_CW;
  Eigen::Vector3d t_CW;
};
[[nodiscard]] std::optional<DecomposeResult> DecomposeProjection(
    const Eigen::Matrix<double, 3, 4>& P, std::string* error);

}  // namespace hg::geometry
