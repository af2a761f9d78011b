#include "geometry/camera.h"

#include <algorithm>

#include <cmath>

#include <Eigen/Householder>
#include <Eigen/LU>
#include <Eigen/QR>
#include <Eigen/SVD>

namespace hg::geometry {

bool CameraModel::HasDistortion() const {
  for (double c : distortion) {
    if (c != 0.0) {
      return true;
    }
  }
  return false;
}

Eigen::Vector2d CameraModel::ProjectPinholeC(const Eigen::Vector3d& p_C) const {
  const Eigen::Vector3d xy1(p_C.x() / p_C.z(), p_C.y() / p_C.z(), 1.0);
  const Eigen::Vector3d uvw = K * xy1;
  return uvw.head<2>() / uvw.z();
}

Eigen::Vector2d ApplyDistortion(const std::array<double, 5>& k, const Eigen::Vector2d& xy,
                                Eigen::Matrix2d* jacobian) {
  const double x = xy.x();
  const double y = xy.y();
  const double r2 = x * x + y * y;
  const double radial = 1.0 + r2 * (k[0] + r2 * (k[1] + r2 * k[4]));
  const double p1 = k[2];
  const double p2 = k[3];
  if (jacobian != nullptr) {
    const double d_radial = k[0] + r2 * (2.0 * k[1] + 3.0 * r2 * k[4]);  // d radial / d r2
    (*jacobian)(0, 0) = radial + 2.0 * x * x * d_radial + 2.0 * p1 * y + 6.0 * p2 * x;
    (*jacobian)(0, 1) = 2.0 * x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y;
    (*jacobian)(1, 0) = (*jacobian)(0, 1);
    (*jacobian)(1, 1) = radial + 2.0 * y * y * d_radial + 6.0 * p1 * y + 2.0 * p2 * x;
  }
  return {x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
          y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y};
}

bool InvertDistortion(const std::array<double, 5>& k, const Eigen::Vector2d& xd,
                      Eigen::Vector2d* x) {
  constexpr int kMaxIterations = 60;
  const double target = 1e-12 * std::max(1.0, xd.norm());
  Eigen::Matrix2d jacobian;
  Eigen::Vector2d residual = ApplyDistortion(k, *x, &jacobian) - xd;
  double residual_norm = residual.norm();
  for (int iter = 0; iter < kMaxIterations; ++iter) {
    if (!(jacobian.determinant() > 0.0)) return false;
    if (residual_norm <= target) return x->allFinite();
    const Eigen::Vector2d step = jacobian.inverse() * residual;
    // Halve the step until the residual shrinks: plain Newton overshoots on
    // strongly distorting lenses near the image corners.
    for (double t = 1.0;; t *= 0.5) {
      if (t < 1e-6) return false;
      const Eigen::Vector2d candidate = *x - t * step;
      Eigen::Matrix2d candidate_jacobian;
      const Eigen::Vector2d candidate_residual =
          ApplyDistortion(k, candidate, &candidate_jacobian) - xd;
      const double candidate_norm = candidate_residual.norm();
      if (candidate_norm < residual_norm) {
        *x = candidate;
        jacobian = candidate_jacobian;
        residual = candidate_residual;
        residual_norm = candidate_norm;
        break;
      }
    }
  }
  return false;
}

Eigen::Vector2d CameraModel::DistortNormalized(const Eigen::Vector2d& xy) const {
  return ApplyDistortion(distortion, xy);
}

std::optional<Eigen::Vector2d> CameraModel::Project(const Eigen::Vector3d& p_W) const {
  const Eigen::Vector3d p_C = ToCamera(p_W);
  if (!(p_C.z() > 0.0)) {
    return std::nullopt;
  }
  const Eigen::Vector2d d = DistortNormalized(p_C.head<2>() / p_C.z());
  const Eigen::Vector3d uvw = K * Eigen::Vector3d(d.x(), d.y(), 1.0);
  return Eigen::Vector2d(uvw.head<2>() / uvw.z());
}

CameraModel CameraModel::Pinhole() const {
  CameraModel pinhole = *this;
  pinhole.distortion = {0, 0, 0, 0, 0};
  return pinhole;
}

Eigen::Matrix<double, 3, 4> CameraModel::ProjectionMatrix() const {
  Eigen::Matrix<double, 3, 4> Rt;
  Rt.leftCols<3>() = R_CW;
  Rt.col(3) = t_CW;
  return K * Rt;
}

std::optional<DecomposeResult> DecomposeProjection(const Eigen::Matrix<double, 3, 4>& P,
                                                   std::string* error) {
  auto fail = [error](const char* message) -> std::optional<DecomposeResult> {
    if (error != nullptr) {
      *error = message;
    }
    return std::nullopt;
  };
  if (!P.allFinite()) {
    return fail("P has non-finite entries");
  }

  // P's scale is arbitrary: divided by its largest entry first, so that no
  // step below (determinant, products) overflows or underflows at any scale.
  const double largest = P.cwiseAbs().maxCoeff();
  if (!(largest > 0.0)) return fail("P has rank < 3");
  Eigen::Matrix<double, 3, 4> Ps = P / largest;
  Eigen::Matrix3d M = Ps.leftCols<3>();
  // Rank test relative to the largest singular value, so that the overall scale of P
  // (which is arbitrary) does not matter.
  const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::Matrix3d>(M).singularValues();
  if (!(sv(0) > 0.0) || sv(2) < 1e-9 * sv(0)) {
    const Eigen::Vector3d full = Eigen::JacobiSVD<Eigen::Matrix<double, 3, 4>>(Ps).singularValues();
    if (!(full(0) > 0.0) || full(2) < 1e-9 * full(0)) return fail("P has rank < 3");
    return fail("P's left 3x3 block is singular: a camera at infinity, not a pinhole camera");
  }

  // K has a positive diagonal and R is proper, so det(K R) > 0: a negative
  // determinant means P carries a negative overall scale.
  if (M.determinant() < 0.0) {
    Ps = -Ps;
    M = -M;
  }

  // RQ via QR: with J the row-reversal permutation, (J M)^T = Q U gives
  // M = (J U^T J) (J Q^T), where J U^T J is upper triangular and J Q^T orthogonal.
  Eigen::Matrix3d J = Eigen::Matrix3d::Zero();
  J(0, 2) = J(1, 1) = J(2, 0) = 1.0;
  const Eigen::HouseholderQR<Eigen::Matrix3d> qr((J * M).transpose());
  const Eigen::Matrix3d Q = qr.householderQ();
  const Eigen::Matrix3d U = qr.matrixQR().triangularView<Eigen::Upper>();
  Eigen::Matrix3d K = J * U.transpose() * J;
  Eigen::Matrix3d R = J * Q.transpose();

  // Make the diagonal of K positive; D * D = I keeps the product K R unchanged.
  for (int i = 0; i < 3; ++i) {
    if (K(i, i) < 0.0) {
      K.col(i) = -K.col(i);
      R.row(i) = -R.row(i);
    }
  }
  // P = K [R | t] up to scale, so t = K^-1 p4 with the unnormalised K.
  const Eigen::Vector3d t = K.triangularView<Eigen::Upper>().solve(Ps.col(3));
  K /= K(2, 2);
  K(1, 0) = K(2, 0) = K(2, 1) = 0.0;
  K(2, 2) = 1.0;
  return DecomposeResult{K, R, t};
}

}  // namespace hg::geometry
