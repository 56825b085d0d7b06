#pragma once
/// @file
/// Activations of the Gaussian parameters and their derivatives.
///
///   opacity   o = sigmoid(l) = 1 / (1 + e^{-l})            do/dl = o (1 - o)
///   scale     s = exp(log_s)                                ds/dlog_s = s
///   rotation  q_n = q / |q|   (q = (w, x, y, z) unnormalised)
///             dL/dq = (dL/dq_n - q_n <q_n, dL/dq_n>) / |q|
///
/// Stability: the sigmoid never overflows (branch on the sign of l); exp of the log-scale is taken on a
/// clamped argument (|log_s| <= kMaxLogScale) so that covariances stay finite in float; a quaternion is
/// normalised after scaling by its largest component (no overflow for |q| ~ 1e30), and one whose norm is
/// zero or non-finite maps to the identity with a zero gradient.

#include <algorithm>
#include <array>
#include <cmath>

namespace video3dgs {

/// log-scales are clamped to [-kMaxLogScale, kMaxLogScale] before exp (e^{+-23} ~ 1e+-10): keeps
/// squared scales (covariances) and their products with focal lengths finite in float.
inline constexpr double kMaxLogScale = 23.0;

/// sigmoid(l), stable for any finite l (and +-inf).
template <class Scalar>
[[nodiscard]] inline Scalar sigmoid(Scalar l) noexcept {
  if (l >= Scalar(0)) return Scalar(1) / (Scalar(1) + std::exp(-l));
  const Scalar e = std::exp(l);
  return e / (Scalar(1) + e);
}

/// logit(o) = log(o / (1 - o)), with o clamped into (0, 1) by `eps`.
template <class Scalar>
[[nodiscard]] inline Scalar logit(Scalar o, Scalar eps = Scalar(1e-7)) noexcept {
  o = std::clamp(o, eps, Scalar(1) - eps);
  return std::log(o / (Scalar(1) - o));
}

/// exp of a clamped log-scale (see kMaxLogScale). The derivative of the clamp is taken as 1 inside
/// and 0 outside: `scale_from_log_grad` returns ds/dlog_s.
template <class Scalar>
[[nodiscard]] inline Scalar scale_from_log(Scalar log_s) noexcept {
  return std::exp(std::clamp(log_s, Scalar(-kMaxLogScale), Scalar(kMaxLogScale)));
}
template <class Scalar>
[[nodiscard]] inline Scalar scale_from_log_grad(Scalar log_s) noexcept {
  if (log_s < Scalar(-kMaxLogScale) || log_s > Scalar(kMaxLogScale)) return Scalar(0);
  return std::exp(log_s);
}

/// Normalises q = (w, x, y, z). Returns false (and the identity) if |q| is zero or q is not finite.
/// `inv_norm` receives 1/|q| (0 for the identity fallback).
template <class Scalar>
inline bool normalize_quaternion(const Scalar* q, std::array<Scalar, 4>& qn, Scalar& inv_norm) noexcept {
  Scalar m = 0;
  for (int i = 0; i < 4; ++i) m = std::max(m, std::abs(q[i]));
  if (!(m > Scalar(0)) || !std::isfinite(m)) {
    qn = {Scalar(1), Scalar(0), Scalar(0), Scalar(0)};
    inv_norm = Scalar(0);
    return false;
  }
  const Scalar inv_m = Scalar(1) / m;
  Scalar s = 0;
  for (int i = 0; i < 4; ++i) {
    const Scalar v = q[i] * inv_m;
    s += v * v;
  }
  const Scalar inv_n_scaled = Scalar(1) / std::sqrt(s);  // 1/|q/m|, s in [1, 4]
  for (int i = 0; i < 4; ++i) qn[i] = q[i] * inv_m * inv_n_scaled;
  inv_norm = inv_m * inv_n_scaled;
  return true;
}

/// Backward of `normalize_quaternion`: dL/dq = (dL/dq_n - q_n <q_n, dL/dq_n>) / |q|.
template <class Scalar>
inline void normalize_quaternion_backward(const std::array<Scalar, 4>& qn, Scalar inv_norm,
                                          const std::array<Scalar, 4>& dL_dqn, Scalar* dL_dq) noexcept {
  const Scalar d = qn[0] * dL_dqn[0] + qn[1] * dL_dqn[1] + qn[2] * dL_dqn[2] + qn[3] * dL_dqn[3];
  for (int i = 0; i < 4; ++i) dL_dq[i] = (dL_dqn[i] - qn[i] * d) * inv_norm;
}

}  // namespace video3dgs
