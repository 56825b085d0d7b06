#pragma once
/// @file
/// EWA projection of one Gaussian (forward and backward).
///
/// Forward (camera x_c = W mean + t, W = R of the camera):
///   (tx, ty, tz) = x_c;  cull unless near < tz <= far and every input is finite
///   u = fx tx/tz + cx,  v = fy ty/tz + cy,  depth = tz
///   tx' = clamp(tx/tz, -lx-, lx+) tz   (ty' likewise; lx+ = (w-cx)/fx + (f-1) w/(2fx), f = 1.3)
///   J = [[fx/tz, 0, -fx tx'/tz²], [0, fy/tz, -fy ty'/tz²]],  T = J W  (2x3)
///   cov = T Sigma T^T + h I = [[a, b], [b, c]]   (h = 0.3 low-pass; Sigma from covariance.hpp)
///   det = ac - b²,  conic = (c/det, -b/det, a/det)
///   o = sigmoid(l) rho,  rho = 1, or sqrt(((a-h)(c-h) - b²)/det) in antialiased mode
///   radius = ceil(3 sqrt(lambda_max)),  lambda_max = (a+c)/2 + sqrt(max(0.1, ((a+c)/2)² - det))
///   footprint: power = d^T conic d / 2 <= p_max = ln(o / alpha_min) (alpha >= alpha_min there)
///
/// Backward (given dL/du, dL/dv, dL/dconic, dL/ddepth, dL/do):
///   dconic/d(a,b,c):  dA = (-A², -2AB, -B²),  dB = (-AB, -(AC + B²), -BC),  dC = (-B², -2BC, -C²)
///   (= (-c², 2bc, -b²)/det², ...; written with the conic so nothing overflows; 2x2 block in double)
///   dL/dSigma = La t0 t0^T + Lb t0 t1^T + Lc t1 t1^T      (t0, t1 rows of T)
///   dL/dt0 = 2 La Sigma t0 + Lb Sigma t1,  dL/dt1 = Lb Sigma t0 + 2 Lc Sigma t1,  dL/dJ = dL/dT W^T
///   dJ02/dtx = -fx/tz², dJ02/dtz = 2 fx tx/tz³ when unclamped; when clamped (tx/tz = k fixed)
///   J02 = -fx k/tz: dJ02/dtx = 0, dJ02/dtz = fx k/tz²;  dJ00/dtz = -fx/tz²  (y likewise)
///   du/dtx = fx/tz, du/dtz = -fx tx/tz²;  dL/dmean = W^T dL/dx_c;  dL/dl = dL/do rho o_s (1 - o_s)

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Core>

#include "video3dgs/core/camera.hpp"
#include "video3dgs/gaussian/activations.hpp"
#include "video3dgs/gaussian/covariance.hpp"
#include "video3dgs/rasterizer/settings.hpp"

namespace video3dgs {

/// The screen-space Gaussian the compositor needs.
template <class Scalar>
struct ProjectedGaussian {
  Scalar u = 0, v = 0;        ///< 2D mean (pixels; pixel (i, j) has its centre at (i + .5, j + .5))
  Scalar depth = 0;           ///< camera z
  Scalar conic[3] = {0, 0, 0};///< inverse 2D covariance (A, B, C): power = (A dx² + C dy²)/2 + B dx dy
  Scalar cov[3] = {0, 0, 0};  ///< 2D covariance (a, b, c) including the low-pass
  Scalar opacity = 0;         ///< effective opacity (sigmoid x antialiasing compensation)
  Scalar p_max = 0;           ///< footprint: pixels with power <= p_max can reach alpha >= alpha_min
  int radius = 0;             ///< ceil(3 sqrt(lambda_max)), pixels
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;  ///< footprint bounding box of pixels [x0, x1) x [y0, y1), inside the image
};

namespace detail {
template <class Scalar>
inline bool all_finite(const Scalar* p, int n) noexcept {
  for (int i = 0; i < n; ++i)
    if (!std::isfinite(p[i])) return false;
  return true;
}
template <class Scalar>
struct FovLimits {
  Scalar x_neg, x_pos, y_neg, y_pos;
};
template <class Scalar, int C>
inline FovLimits<Scalar> fov_limits(const Camera<Scalar>& cam, const RasterSettings<Scalar, C>& s) noexcept {
  // The frame of the bounds: the render, or the image it is a window of (principal point shifted back
  // by the window's origin).
  const bool framed = s.clamp_frame_width > 0 && s.clamp_frame_height > 0;
  const Scalar W = Scalar(framed ? s.clamp_frame_width : cam.width), H = Scalar(framed ? s.clamp_frame_height : cam.height);
  const Scalar cx = framed ? cam.cx + Scalar(s.clamp_frame_x) : cam.cx, cy = framed ? cam.cy + Scalar(s.clamp_frame_y) : cam.cy;
  const Scalar ex = (s.fov_clamp - Scalar(1)) * Scalar(0.5) * W / cam.fx;
  const Scalar ey = (s.fov_clamp - Scalar(1)) * Scalar(0.5) * H / cam.fy;
  return {cx / cam.fx + ex, (W - cx) / cam.fx + ex, cy / cam.fy + ey, (H - cy) / cam.fy + ey};
}
/// The screen-space covariance of a Gaussian whose camera-space mean is xc (z > 0): the projection's
/// Jacobian J at the mean (its x/z, y/z clamped to the widened field of view), T = J R, the 3D
/// covariance Sigma and the 2D covariance T Sigma T^T plus the low-pass (a, b, c) with its
/// determinant. The 2x2 block is in double: a c overflows float for covariances beyond ~1e19 px².
/// Shared by the forward and backward passes so that both see the same numbers.
template <class Scalar>
struct ScreenCovariance {
  Scalar inv_z, kx, ky;
  bool clamp_x, clamp_y;  ///< x/z (y/z) lies outside the widened field of view and was clamped
  Eigen::Matrix<Scalar, 2, 3> T;
  Eigen::Matrix<Scalar, 3, 3> Sigma;
  double a, b, c, det;
};
template <class Scalar, int C>
inline ScreenCovariance<Scalar> screen_covariance(const Camera<Scalar>& cam, const RasterSettings<Scalar, C>& s,
                                                  const Eigen::Matrix<Scalar, 3, 1>& xc, const Scalar* log_scale,
                                                  const Scalar* rotation) noexcept {
  ScreenCovariance<Scalar> r;
  r.inv_z = Scalar(1) / xc.z();
  const auto lim = fov_limits(cam, s);
  const Scalar rx = xc.x() * r.inv_z, ry = xc.y() * r.inv_z;
  r.clamp_x = rx < -lim.x_neg || rx > lim.x_pos, r.clamp_y = ry < -lim.y_neg || ry > lim.y_pos;
  r.kx = std::clamp(rx, -lim.x_neg, lim.x_pos), r.ky = std::clamp(ry, -lim.y_neg, lim.y_pos);
  Eigen::Matrix<Scalar, 2, 3> J;
  J << cam.fx * r.inv_z, 0, -cam.fx * r.kx * r.inv_z, 0, cam.fy * r.inv_z, -cam.fy * r.ky * r.inv_z;
  r.T = J * cam.R;
  r.Sigma = covariance_3d(log_scale, rotation);
  const Eigen::Matrix<Scalar, 2, 2> cov = r.T * r.Sigma * r.T.transpose();
  const double h = double(s.low_pass);
  r.a = double(cov(0, 0)) + h, r.b = double(cov(0, 1)), r.c = double(cov(1, 1)) + h;
  r.det = r.a * r.c - r.b * r.b;
  return r;
}
}  // namespace detail

/// Projects one Gaussian. Returns false if it is culled (behind / on the near plane, beyond far, any
/// non-finite input or intermediate, opacity below alpha_min, degenerate covariance, or a footprint
/// outside the image); `out` is then unspecified.
template <class Scalar, int C>
inline bool project_gaussian(const Camera<Scalar>& cam, const RasterSettings<Scalar, C>& s, const Scalar* mean,
                             const Scalar* log_scale, const Scalar* rotation, Scalar opacity_logit,
                             ProjectedGaussian<Scalar>& out) noexcept {
  using Vec3 = Eigen::Matrix<Scalar, 3, 1>;
  if (!detail::all_finite(mean, 3) || !detail::all_finite(log_scale, 3) || !detail::all_finite(rotation, 4) ||
      !std::isfinite(opacity_logit))
    return false;
  const Vec3 xc = cam.R * Vec3(mean[0], mean[1], mean[2]) + cam.t;
  const Scalar tz = xc.z();
  if (!(tz > s.near_plane) || !(tz <= s.far_plane) || !std::isfinite(xc.x()) || !std::isfinite(xc.y())) return false;
  const auto sc = detail::screen_covariance(cam, s, xc, log_scale, rotation);
  const Scalar inv_z = sc.inv_z;
  const double h = double(s.low_pass), a = sc.a, b = sc.b, c = sc.c, det = sc.det;
  if (!std::isfinite(a) || !std::isfinite(b) || !std::isfinite(c) || !(det > 0) || !std::isfinite(det)) return false;
  Scalar rho = 1;
  if (s.antialiased) {
    const double det0 = (a - h) * (c - h) - b * b;
    rho = static_cast<Scalar>(std::sqrt(std::max(0.0, det0 / det)));
  }
  const Scalar o = sigmoid(opacity_logit) * rho;
  if (!(o >= s.alpha_min)) return false;
  out.conic[0] = static_cast<Scalar>(c / det);
  out.conic[1] = static_cast<Scalar>(-b / det);
  out.conic[2] = static_cast<Scalar>(a / det);
  out.cov[0] = static_cast<Scalar>(a), out.cov[1] = static_cast<Scalar>(b), out.cov[2] = static_cast<Scalar>(c);
  if (!(out.conic[0] > Scalar(0)) || !(out.conic[2] > Scalar(0))) return false;  // underflow: no footprint
  out.opacity = o;
  out.u = cam.fx * xc.x() * inv_z + cam.cx;
  out.v = cam.fy * xc.y() * inv_z + cam.cy;
  out.depth = tz;
  if (!std::isfinite(out.u) || !std::isfinite(out.v) || !detail::all_finite(out.conic, 3)) return false;
  const double mid = 0.5 * (a + c);
  const double lambda = mid + std::sqrt(std::max(0.1, mid * mid - det));
  const double r = std::ceil(3.0 * std::sqrt(lambda));
  out.radius = r < double(1 << 30) ? static_cast<int>(r) : (1 << 30);
  // Footprint of alpha >= alpha_min, widened slightly so rounding never drops a contributing pixel.
  out.p_max = std::log(o / s.alpha_min) + Scalar(0.01);
  const Scalar ex = static_cast<Scalar>(std::sqrt(2.0 * double(out.p_max) * a) + 0.01);
  const Scalar ey = static_cast<Scalar>(std::sqrt(2.0 * double(out.p_max) * c) + 0.01);
  // Pixel i is inside when its centre i + 0.5 lies in [u - ex, u + ex].
  const Scalar fx0 = std::ceil(out.u - ex - Scalar(0.5)), fx1 = std::floor(out.u + ex - Scalar(0.5)) + 1;
  const Scalar fy0 = std::ceil(out.v - ey - Scalar(0.5)), fy1 = std::floor(out.v + ey - Scalar(0.5)) + 1;
  const Scalar W = Scalar(cam.width), H = Scalar(cam.height);
  if (!(fx1 > 0 && fy1 > 0 && fx0 < W && fy0 < H)) return false;  // also rejects NaN
  out.x0 = static_cast<int>(std::max(fx0, Scalar(0)));
  out.y0 = static_cast<int>(std::max(fy0, Scalar(0)));
  out.x1 = static_cast<int>(std::min(fx1, W));
  out.y1 = static_cast<int>(std::min(fy1, H));
  return out.x0 < out.x1 && out.y0 < out.y1;
}

/// Gradients arriving at one projected Gaussian.
template <class Scalar>
struct ProjectedGaussianGrad {
  Scalar u = 0, v = 0, depth = 0, opacity = 0;
  Scalar conic[3] = {0, 0, 0};
};

/// Backward of `project_gaussian` (for a Gaussian it did not cull): adds into dL_dmean (3) and writes
/// dL_dlog_scale (3), dL_drotation (4), dL_dopacity_logit (1).
template <class Scalar, int C>
inline void project_gaussian_backward(const Camera<Scalar>& cam, const RasterSettings<Scalar, C>& s,
                                      const Scalar* mean, const Scalar* log_scale, const Scalar* rotation,
                                      Scalar opacity_logit, const ProjectedGaussianGrad<Scalar>& g,
                                      Scalar* dL_dmean, Scalar* dL_dlog_scale, Scalar* dL_drotation,
                                      Scalar* dL_dopacity_logit) noexcept {
  using Vec3 = Eigen::Matrix<Scalar, 3, 1>;
  using Mat3 = Eigen::Matrix<Scalar, 3, 3>;
  const Vec3 xc = cam.R * Vec3(mean[0], mean[1], mean[2]) + cam.t;
  const Scalar tx = xc.x(), ty = xc.y();
  const auto sc = detail::screen_covariance(cam, s, xc, log_scale, rotation);
  const Scalar inv_z = sc.inv_z, inv_z2 = inv_z * inv_z, kx = sc.kx, ky = sc.ky;
  const bool clamp_x = sc.clamp_x, clamp_y = sc.clamp_y;
  const auto& T = sc.T;
  const auto& Sigma = sc.Sigma;
  const double h = double(s.low_pass), a = sc.a, b = sc.b, c = sc.c, det = sc.det;
  const double inv_det = 1.0 / det;

  // Opacity: o = sigmoid(l) rho.
  const Scalar os = sigmoid(opacity_logit);
  double rho = 1, da = 0, db = 0, dc = 0;
  if (s.antialiased) {
    const double det0 = (a - h) * (c - h) - b * b;
    const double r = std::max(0.0, det0 / det);
    rho = std::sqrt(r);
    if (rho > 0) {
      const double dL_dr = double(g.opacity) * double(os) * 0.5 / rho;  // d rho / d r = 1 / (2 rho)
      // r = det0 / det: dr/da = ((c - h) - r c) / det, dr/dc = ((a - h) - r a) / det, dr/db = 2 b (r - 1) / det
      da += dL_dr * ((c - h) - r * c) * inv_det;
      dc += dL_dr * ((a - h) - r * a) * inv_det;
      db += dL_dr * 2.0 * b * (r - 1.0) * inv_det;
    }
  }
  *dL_dopacity_logit = static_cast<Scalar>(double(g.opacity) * rho) * os * (Scalar(1) - os);

  // conic = (c, -b, a) / det  (written with the conic itself so nothing overflows).
  const double A = c * inv_det, B = -b * inv_det, Cc = a * inv_det;
  const double gA = g.conic[0], gB = g.conic[1], gC = g.conic[2];
  da += -A * A * gA - A * B * gB - B * B * gC;
  db += -2.0 * A * B * gA - (A * Cc + B * B) * gB - 2.0 * B * Cc * gC;
  dc += -B * B * gA - B * Cc * gB - Cc * Cc * gC;
  const Scalar dL_da = static_cast<Scalar>(da), dL_db = static_cast<Scalar>(db), dL_dc = static_cast<Scalar>(dc);

  // cov = T Sigma T^T.
  const Vec3 t0 = T.row(0).transpose(), t1 = T.row(1).transpose();
  const Mat3 dSigma = dL_da * t0 * t0.transpose() + dL_db * t0 * t1.transpose() + dL_dc * t1 * t1.transpose();
  covariance_3d_backward(log_scale, rotation, dSigma, dL_dlog_scale, dL_drotation);
  const Vec3 st0 = Sigma * t0, st1 = Sigma * t1;
  Eigen::Matrix<Scalar, 2, 3> dT;
  dT.row(0) = (Scalar(2) * dL_da * st0 + dL_db * st1).transpose();
  dT.row(1) = (dL_db * st0 + Scalar(2) * dL_dc * st1).transpose();
  const Eigen::Matrix<Scalar, 2, 3> dJ = dT * cam.R.transpose();

  // J entries -> camera point.
  Scalar dtx = 0, dty = 0, dtz = 0;
  dtz += -cam.fx * inv_z2 * dJ(0, 0) - cam.fy * inv_z2 * dJ(1, 1);
  if (clamp_x) {
    dtz += cam.fx * kx * inv_z2 * dJ(0, 2);
  } else {
    dtx += -cam.fx * inv_z2 * dJ(0, 2);
    dtz += Scalar(2) * cam.fx * tx * inv_z2 * inv_z * dJ(0, 2);
  }
  if (clamp_y) {
    dtz += cam.fy * ky * inv_z2 * dJ(1, 2);
  } else {
    dty += -cam.fy * inv_z2 * dJ(1, 2);
    dtz += Scalar(2) * cam.fy * ty * inv_z2 * inv_z * dJ(1, 2);
  }
  // 2D mean and depth.
  dtx += cam.fx * inv_z * g.u;
  dty += cam.fy * inv_z * g.v;
  dtz += -cam.fx * tx * inv_z2 * g.u - cam.fy * ty * inv_z2 * g.v + g.depth;
  const Vec3 dmean = cam.R.transpose() * Vec3(dtx, dty, dtz);
  for (int k = 0; k < 3; ++k) dL_dmean[k] += dmean[k];
}

}  // namespace video3dgs
