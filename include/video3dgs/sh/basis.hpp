#pragma once
/// @file
/// Real spherical-harmonic basis of degree 0..3 (the 3DGS convention) and its derivative.
///
///   colour_c(d) = max(sum_k B_k(d) f_kc + 1/2, 0),    d = (mean - camera centre) / |mean - camera centre|
///
/// Basis (x, y, z = d): B0 = C0; B1..3 = -C1 y, C1 z, -C1 x; B4..8 = C2_0 xy, C2_1 yz, C2_2 (2z²-x²-y²),
/// C2_3 xz, C2_4 (x²-y²); B9..15 = C3_0 y(3x²-y²), C3_1 xyz, C3_2 y(4z²-x²-y²), C3_3 z(2z²-3x²-3y²),
/// C3_4 x(4z²-x²-y²), C3_5 z(x²-y²), C3_6 x(x²-3y²).
///
/// Backward: dL/df_kc = B_k dL/dcolour_c (0 where the clamp is active);
///           dL/dd = sum_kc f_kc dB_k/dd dL/dcolour_c;  dL/dmean = (I - d d^T) / |v| dL/dd.
///
/// Coefficient layout for one Gaussian: `coeffs[k * Channels + c]`, k = 0 .. (degree+1)² - 1.
/// Only the first (active_degree+1)² coefficients are read; the others get a zero gradient.

#include <algorithm>
#include <array>
#include <cmath>

#include <Eigen/Core>

namespace video3dgs::sh {

/// Number of coefficients per channel for a degree: (degree + 1)².
[[nodiscard]] constexpr int coeff_count(int degree) noexcept { return (degree + 1) * (degree + 1); }
inline constexpr int kMaxDegree = 3;

inline constexpr double kC0 = 0.28209479177387814;
inline constexpr double kC1 = 0.4886025119029199;
inline constexpr double kC2[5] = {1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
                                  -1.0925484305920792, 0.5462742152960396};
inline constexpr double kC3[7] = {-0.5900435899266435, 2.890611442640554, -0.4570457994644658,
                                  0.3731763325901154, -0.4570457994644658, 1.445305721320277,
                                  -0.5900435899266435};

/// B_k(d) for k < coeff_count(degree); d is a unit vector.
template <class Scalar>
inline void basis(int degree, Scalar x, Scalar y, Scalar z, Scalar* B) noexcept {
  B[0] = Scalar(kC0);
  if (degree < 1) return;
  B[1] = Scalar(-kC1) * y;
  B[2] = Scalar(kC1) * z;
  B[3] = Scalar(-kC1) * x;
  if (degree < 2) return;
  const Scalar xx = x * x, yy = y * y, zz = z * z;
  B[4] = Scalar(kC2[0]) * x * y;
  B[5] = Scalar(kC2[1]) * y * z;
  B[6] = Scalar(kC2[2]) * (2 * zz - xx - yy);
  B[7] = Scalar(kC2[3]) * x * z;
  B[8] = Scalar(kC2[4]) * (xx - yy);
  if (degree < 3) return;
  B[9] = Scalar(kC3[0]) * y * (3 * xx - yy);
  B[10] = Scalar(kC3[1]) * x * y * z;
  B[11] = Scalar(kC3[2]) * y * (4 * zz - xx - yy);
  B[12] = Scalar(kC3[3]) * z * (2 * zz - 3 * xx - 3 * yy);
  B[13] = Scalar(kC3[4]) * x * (4 * zz - xx - yy);
  B[14] = Scalar(kC3[5]) * z * (xx - yy);
  B[15] = Scalar(kC3[6]) * x * (xx - 3 * yy);
}

/// dB_k/dx, dB_k/dy, dB_k/dz for k < coeff_count(degree) (k = 0 has zero derivative).
template <class Scalar>
inline void basis_derivative(int degree, Scalar x, Scalar y, Scalar z, Scalar* dx, Scalar* dy, Scalar* dz) noexcept {
  dx[0] = dy[0] = dz[0] = 0;
  if (degree < 1) return;
  const Scalar c1 = Scalar(kC1);
  dx[1] = 0, dy[1] = -c1, dz[1] = 0;
  dx[2] = 0, dy[2] = 0, dz[2] = c1;
  dx[3] = -c1, dy[3] = 0, dz[3] = 0;
  if (degree < 2) return;
  const Scalar xx = x * x, yy = y * y, zz = z * z;
  const Scalar a0 = Scalar(kC2[0]), a1 = Scalar(kC2[1]), a2 = Scalar(kC2[2]), a3 = Scalar(kC2[3]), a4 = Scalar(kC2[4]);
  dx[4] = a0 * y, dy[4] = a0 * x, dz[4] = 0;
  dx[5] = 0, dy[5] = a1 * z, dz[5] = a1 * y;
  dx[6] = -2 * a2 * x, dy[6] = -2 * a2 * y, dz[6] = 4 * a2 * z;
  dx[7] = a3 * z, dy[7] = 0, dz[7] = a3 * x;
  dx[8] = 2 * a4 * x, dy[8] = -2 * a4 * y, dz[8] = 0;
  if (degree < 3) return;
  const Scalar b0 = Scalar(kC3[0]), b1 = Scalar(kC3[1]), b2 = Scalar(kC3[2]), b3 = Scalar(kC3[3]),
               b4 = Scalar(kC3[4]), b5 = Scalar(kC3[5]), b6 = Scalar(kC3[6]);
  dx[9] = 6 * b0 * x * y, dy[9] = b0 * (3 * xx - 3 * yy), dz[9] = 0;
  dx[10] = b1 * y * z, dy[10] = b1 * x * z, dz[10] = b1 * x * y;
  dx[11] = -2 * b2 * x * y, dy[11] = b2 * (4 * zz - xx - 3 * yy), dz[11] = 8 * b2 * y * z;
  dx[12] = -6 * b3 * x * z, dy[12] = -6 * b3 * y * z, dz[12] = b3 * (6 * zz - 3 * xx - 3 * yy);
  dx[13] = b4 * (4 * zz - 3 * xx - yy), dy[13] = -2 * b4 * x * y, dz[13] = 8 * b4 * x * z;
  dx[14] = 2 * b5 * x * z, dy[14] = -2 * b5 * y * z, dz[14] = b5 * (xx - yy);
  dx[15] = b6 * (3 * xx - 3 * yy), dy[15] = -6 * b6 * x * y, dz[15] = 0;
}

/// Unit view direction from the camera centre to `mean`, and 1/|mean - centre| (0 if they coincide,
/// in which case the direction is +z and its gradient is zero).
template <class Scalar>
inline Eigen::Matrix<Scalar, 3, 1> view_direction(const Eigen::Matrix<Scalar, 3, 1>& mean,
                                                  const Eigen::Matrix<Scalar, 3, 1>& centre, Scalar& inv_len) noexcept {
  const Eigen::Matrix<Scalar, 3, 1> v = mean - centre;
  const Scalar n = v.norm();
  if (!(n > Scalar(0)) || !std::isfinite(n)) {
    inv_len = Scalar(0);
    return Eigen::Matrix<Scalar, 3, 1>(0, 0, 1);
  }
  inv_len = Scalar(1) / n;
  return v * inv_len;
}

/// colour_c = max(sum_k B_k(dir) coeffs[k*Channels+c] + 1/2, 0) with the first coeff_count(degree)
/// coefficients; `clamped[c]` records whether the clamp was active (gradient zero). A non-finite sum
/// (a non-finite coefficient read) is returned as it is, never clamped to 0, so callers see it.
template <class Scalar, int Channels>
inline void evaluate(int degree, const Eigen::Matrix<Scalar, 3, 1>& dir, const Scalar* coeffs, Scalar* colour,
                     bool* clamped = nullptr) noexcept {
  Scalar B[16];
  basis(degree, dir.x(), dir.y(), dir.z(), B);
  const int K = coeff_count(degree);
  for (int c = 0; c < Channels; ++c) {
    Scalar s = 0;
    for (int k = 0; k < K; ++k) s += B[k] * coeffs[k * Channels + c];
    s += Scalar(0.5);
    if (clamped) clamped[c] = s < Scalar(0);
    colour[c] = std::isfinite(s) ? std::max(s, Scalar(0)) : s;
  }
}

/// Backward of `evaluate`: adds dL/dcoeffs (first coeff_count(degree) coefficients) into
/// `dL_dcoeffs` and returns dL/ddir. `clamped` is what `evaluate` recorded.
template <class Scalar, int Channels>
inline Eigen::Matrix<Scalar, 3, 1> evaluate_backward(int degree, const Eigen::Matrix<Scalar, 3, 1>& dir, const Scalar* coeffs,
                                                     const bool* clamped, const Scalar* dL_dcolour,
                                                     Scalar* dL_dcoeffs) noexcept {
  Scalar B[16], dBx[16], dBy[16], dBz[16];
  basis(degree, dir.x(), dir.y(), dir.z(), B);
  basis_derivative(degree, dir.x(), dir.y(), dir.z(), dBx, dBy, dBz);
  const int K = coeff_count(degree);
  Scalar g[Channels];
  for (int c = 0; c < Channels; ++c) g[c] = clamped[c] ? Scalar(0) : dL_dcolour[c];
  Eigen::Matrix<Scalar, 3, 1> dd = Eigen::Matrix<Scalar, 3, 1>::Zero();
  for (int k = 0; k < K; ++k) {
    Scalar fk = 0;
    for (int c = 0; c < Channels; ++c) {
      dL_dcoeffs[k * Channels + c] += B[k] * g[c];
      fk += coeffs[k * Channels + c] * g[c];
    }
    dd.x() += dBx[k] * fk;
    dd.y() += dBy[k] * fk;
    dd.z() += dBz[k] * fk;
  }
  return dd;
}

/// Backward of `view_direction`: dL/dmean = (I - d d^T) dL/dd / |v|.
template <class Scalar>
[[nodiscard]] inline Eigen::Matrix<Scalar, 3, 1> view_direction_backward(const Eigen::Matrix<Scalar, 3, 1>& dir, Scalar inv_len,
                                                                        const Eigen::Matrix<Scalar, 3, 1>& dL_ddir) noexcept {
  return (dL_ddir - dir * dir.dot(dL_ddir)) * inv_len;
}

/// The DC coefficient that yields colour `rgb` (inverse of colour = C0 f + 1/2).
template <class Scalar>
[[nodiscard]] constexpr Scalar rgb_to_dc(Scalar rgb) noexcept { return (rgb - Scalar(0.5)) / Scalar(kC0); }
template <class Scalar>
[[nodiscard]] constexpr Scalar dc_to_rgb(Scalar dc) noexcept { return dc * Scalar(kC0) + Scalar(0.5); }

}  // namespace video3dgs::sh
