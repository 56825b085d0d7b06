#pragma once
/// @file
/// 3D covariance of a Gaussian from its unnormalised quaternion and log-scale, forward and backward.
///
/// Forward:   q_n = q / |q|,  R = R(q_n),  S = diag(exp(log_s)),  M = R S,  Sigma = M M^T.
///
/// Backward (G = dL/dSigma, entries treated as independent; need not be symmetric):
///   dL/dM       = (G + G^T) M
///   dL/dR_ij    = dL/dM_ij s_j                  dL/ds_j = sum_i dL/dM_ij R_ij
///   dL/dlog_s_j = s_j dL/ds_j
///   dL/dq_n     = sum_ij dL/dR_ij dR_ij/dq_n    (dR/dw, dR/dx, dR/dy, dR/dz written out below)
///   dL/dq       = (dL/dq_n - q_n <q_n, dL/dq_n>) / |q|
///
/// with R(w, x, y, z) = [[1-2(y²+z²), 2(xy-wz), 2(xz+wy)],
///                       [2(xy+wz), 1-2(x²+z²), 2(yz-wx)],
///                       [2(xz-wy), 2(yz+wx), 1-2(x²+y²)]].

#include <array>

#include <Eigen/Core>

#include "video3dgs/gaussian/activations.hpp"

namespace video3dgs {

/// Rotation matrix of a unit quaternion (w, x, y, z).
template <class Scalar>
[[nodiscard]] inline Eigen::Matrix<Scalar, 3, 3> rotation_from_unit_quaternion(const std::array<Scalar, 4>& q) noexcept {
  const Scalar w = q[0], x = q[1], y = q[2], z = q[3];
  Eigen::Matrix<Scalar, 3, 3> R;
  R << 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
       2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
       2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y);
  return R;
}

/// dL/dq_n given dL/dR (3x3), for R = rotation_from_unit_quaternion(q_n).
template <class Scalar>
[[nodiscard]] inline std::array<Scalar, 4> rotation_from_unit_quaternion_backward(
    const std::array<Scalar, 4>& q, const Eigen::Matrix<Scalar, 3, 3>& G) noexcept {
  const Scalar w = q[0], x = q[1], y = q[2], z = q[3];
  std::array<Scalar, 4> d;
  // dR/dw = [[0,-2z,2y],[2z,0,-2x],[-2y,2x,0]]
  d[0] = 2 * (-z * G(0, 1) + y * G(0, 2) + z * G(1, 0) - x * G(1, 2) - y * G(2, 0) + x * G(2, 1));
  // dR/dx = [[0,2y,2z],[2y,-4x,-2w],[2z,2w,-4x]]
  d[1] = 2 * (y * G(0, 1) + z * G(0, 2) + y * G(1, 0) - 2 * x * G(1, 1) - w * G(1, 2) + z * G(2, 0) + w * G(2, 1) -
              2 * x * G(2, 2));
  // dR/dy = [[-4y,2x,2w],[2x,0,2z],[-2w,2z,-4y]]
  d[2] = 2 * (-2 * y * G(0, 0) + x * G(0, 1) + w * G(0, 2) + x * G(1, 0) + z * G(1, 2) - w * G(2, 0) + z * G(2, 1) -
              2 * y * G(2, 2));
  // dR/dz = [[-4z,-2w,2x],[2w,-4z,2y],[2x,2y,0]]
  d[3] = 2 * (-2 * z * G(0, 0) - w * G(0, 1) + x * G(0, 2) + w * G(1, 0) - 2 * z * G(1, 1) + y * G(1, 2) +
              x * G(2, 0) + y * G(2, 1));
  return d;
}

/// Sigma = R(q/|q|) diag(exp(log_s))^2 R^T.
/// @param log_scale 3 values; @param quaternion 4 values (w, x, y, z), any norm (zero -> identity).
template <class Scalar>
[[nodiscard]] inline Eigen::Matrix<Scalar, 3, 3> covariance_3d(const Scalar* log_scale, const Scalar* quaternion) noexcept {
  std::array<Scalar, 4> qn{};
  Scalar inv_norm = 0;
  normalize_quaternion(quaternion, qn, inv_norm);
  const Eigen::Matrix<Scalar, 3, 3> R = rotation_from_unit_quaternion(qn);
  Eigen::Matrix<Scalar, 3, 3> M;
  for (int j = 0; j < 3; ++j) M.col(j) = R.col(j) * scale_from_log(log_scale[j]);
  return M * M.transpose();
}

/// Backward of `covariance_3d`: writes dL/dlog_s (3) and dL/dq (4) given G = dL/dSigma.
template <class Scalar>
inline void covariance_3d_backward(const Scalar* log_scale, const Scalar* quaternion,
                                   const Eigen::Matrix<Scalar, 3, 3>& dL_dSigma, Scalar* dL_dlog_scale,
                                   Scalar* dL_dquaternion) noexcept {
  std::array<Scalar, 4> qn{};
  Scalar inv_norm = 0;
  const bool ok = normalize_quaternion(quaternion, qn, inv_norm);
  const Eigen::Matrix<Scalar, 3, 3> R = rotation_from_unit_quaternion(qn);
  Scalar s[3];
  Eigen::Matrix<Scalar, 3, 3> M;
  for (int j = 0; j < 3; ++j) {
    s[j] = scale_from_log(log_scale[j]);
    M.col(j) = R.col(j) * s[j];
  }
  const Eigen::Matrix<Scalar, 3, 3> dM = (dL_dSigma + dL_dSigma.transpose()) * M;
  Eigen::Matrix<Scalar, 3, 3> dR;
  for (int j = 0; j < 3; ++j) {
    dR.col(j) = dM.col(j) * s[j];
    dL_dlog_scale[j] = dM.col(j).dot(R.col(j)) * scale_from_log_grad(log_scale[j]);
  }
  if (!ok) {
    for (int i = 0; i < 4; ++i) dL_dquaternion[i] = Scalar(0);
    return;
  }
  const std::array<Scalar, 4> dqn = rotation_from_unit_quaternion_backward(qn, dR);
  normalize_quaternion_backward(qn, inv_norm, dqn, dL_dquaternion);
}

}  // namespace video3dgs
