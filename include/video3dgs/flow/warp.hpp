#pragma once
/// @file
/// Optical-flow fields, bilinear backward warping, the forward-backward occlusion check and the
/// endpoint error.
///
/// A flow field from frame a to frame b is an `Image<Scalar, 2>` the size of a: pixel x of a (centre
/// x + 0.5) moves to x + f(x) in b, in pixels (u right, v down). Warping b back onto a's grid:
///
///   (warp b by f)(x) = b(x + f(x))         bilinear, pixel centres at integer + 0.5
///
/// A sample is valid if x + f(x) lies inside [0, W-1] x [0, H-1] in pixel-index coordinates (no
/// extrapolation; outside samples are clamped to the border and marked invalid).
///
/// Forward-backward check (Sundaram, Brox, Keutzer, ECCV 2010), for the pixels x of b with backward
/// flow g = f_{b->a} and forward flow f = f_{a->b}:
///
///   r(x) = g(x) + f(x + g(x))                (0 for a consistent, unoccluded pixel)
///   visible  <=>  |r|^2 <= alpha1 (|g(x)|^2 + |f(x + g(x))|^2) + alpha2   and   x + g(x) inside a
///
/// with alpha1 = 0.01, alpha2 = 0.5 (px^2) by default.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>

#include "video3dgs/core/assert.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"

namespace video3dgs::flow {

/// A dense flow field (u, v) per pixel, in pixels.
template <class Scalar>
using FlowField = Image<Scalar, 2>;
using FlowFieldF = FlowField<float>;
using FlowFieldD = FlowField<double>;

namespace detail {

/// Bilinear sample of channel block at continuous pixel-index coordinates (px, py) (centre of pixel
/// (i, j) at (i, j)), clamped to the border. Writes C values to `out`.
template <class Scalar, int C>
inline void sample_bilinear(ConstImageView<Scalar, C> img, double px, double py, Scalar* out) noexcept {
  const int w = img.width(), h = img.height();
  px = std::clamp(px, 0.0, double(w - 1));
  py = std::clamp(py, 0.0, double(h - 1));
  const int x0 = std::min(static_cast<int>(px), w - 1), y0 = std::min(static_cast<int>(py), h - 1);
  const int x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
  const double fx = px - x0, fy = py - y0;
  const Scalar* a = img.pixel(x0, y0);
  const Scalar* b = img.pixel(x1, y0);
  const Scalar* c = img.pixel(x0, y1);
  const Scalar* d = img.pixel(x1, y1);
  for (int k = 0; k < C; ++k) {
    const double top = (1 - fx) * double(a[k]) + fx * double(b[k]);
    const double bot = (1 - fx) * double(c[k]) + fx * double(d[k]);
    out[k] = static_cast<Scalar>((1 - fy) * top + fy * bot);
  }
}

inline bool inside(double px, double py, int w, int h) noexcept {
  return px >= 0 && py >= 0 && px <= double(w - 1) && py <= double(h - 1);
}

}  // namespace detail

/// out(x) = src(x + flow(x)) (bilinear). `valid` (optional, empty view to skip) gets 1 where the
/// sample lies inside src, else 0. `flow`, `out` and `valid` have the output size; `src` any size.
/// Non-finite flow vectors give an invalid sample (value clamped to the nearest border pixel).
template <class Scalar, int C, class FlowScalar>
void warp_bilinear(ConstImageView<Scalar, C> src, ConstImageView<FlowScalar, 2> flow, ImageView<Scalar, C> out,
                   ImageView<Scalar, 1> valid = {}, ThreadPool* pool = nullptr) {
  VIDEO3DGS_ASSERT(out.width() == flow.width() && out.height() == flow.height(), "warp_bilinear: flow/out size mismatch");
  VIDEO3DGS_ASSERT(valid.empty() || (valid.width() == flow.width() && valid.height() == flow.height()),
                   "warp_bilinear: valid size mismatch");
  if (src.empty()) throw option_error("option.flow", "warp", "cannot warp an empty image");
  parallel_for(pool, static_cast<std::size_t>(flow.height()), [&](std::size_t yy) {
    const int y = static_cast<int>(yy);
    const FlowScalar* f = flow.row(y);
    Scalar* o = out.row(y);
    for (int x = 0; x < flow.width(); ++x) {
      double px = x + double(f[2 * x]), py = y + double(f[2 * x + 1]);
      bool ok = std::isfinite(px) && std::isfinite(py);
      if (!ok) px = x, py = y;
      ok = ok && detail::inside(px, py, src.width(), src.height());
      detail::sample_bilinear<Scalar, C>(src, px, py, o + std::ptrdiff_t(x) * C);
      if (!valid.empty()) valid.row(y)[x] = ok ? Scalar(1) : Scalar(0);
    }
  }, 8);
}

/// Owning-image convenience: returns the warped image.
template <class Scalar, int C, class FlowScalar>
[[nodiscard]] Image<Scalar, C> warp_bilinear(const Image<Scalar, C>& src, const FlowField<FlowScalar>& flow, ThreadPool* pool = nullptr) {
  Image<Scalar, C> out(flow.width(), flow.height());
  warp_bilinear<Scalar, C, FlowScalar>(src.view(), flow.view(), out.view(), {}, pool);
  return out;
}

/// Thresholds of the forward-backward check (see the file comment).
struct ConsistencyOptions {
  double alpha1 = 0.01;  ///< relative term
  double alpha2 = 0.5;   ///< absolute term, px^2
};

/// Visibility of the pixels of frame b: 1 where the backward flow `g` (b -> a, size of b) agrees with
/// the forward flow `f` (a -> b, size of a) and lands inside a, else 0.
template <class Scalar>
[[nodiscard]] Image<Scalar, 1> consistency_mask(ConstImageView<Scalar, 2> f_ab, ConstImageView<Scalar, 2> g_ba,
                                                const ConsistencyOptions& o = {}, ThreadPool* pool = nullptr) {
  Image<Scalar, 1> mask(g_ba.width(), g_ba.height());
  if (f_ab.empty()) return mask;
  parallel_for(pool, static_cast<std::size_t>(g_ba.height()), [&](std::size_t yy) {
    const int y = static_cast<int>(yy);
    for (int x = 0; x < g_ba.width(); ++x) {
      const double gu = g_ba.row(y)[2 * x], gv = g_ba.row(y)[2 * x + 1];
      const double px = x + gu, py = y + gv;
      bool ok = std::isfinite(px) && std::isfinite(py) && detail::inside(px, py, f_ab.width(), f_ab.height());
      if (ok) {
        Scalar fw[2];
        detail::sample_bilinear<Scalar, 2>(f_ab, px, py, fw);
        const double ru = gu + double(fw[0]), rv = gv + double(fw[1]);
        const double r2 = ru * ru + rv * rv;
        const double m2 = gu * gu + gv * gv + double(fw[0]) * double(fw[0]) + double(fw[1]) * double(fw[1]);
        ok = std::isfinite(r2) && r2 <= o.alpha1 * m2 + o.alpha2;
      }
      mask(x, y) = ok ? Scalar(1) : Scalar(0);
    }
  }, 8);
  return mask;
}

/// Mean endpoint error |f - gt| over the pixels where `mask` (optional) is > 0.5.
/// @return mean EPE in pixels (NaN if no pixel counts)
template <class Scalar, class GtScalar>
[[nodiscard]] double endpoint_error(ConstImageView<Scalar, 2> f, ConstImageView<GtScalar, 2> gt, ConstImageView<Scalar, 1> mask = {}) {
  if (f.width() != gt.width() || f.height() != gt.height())
    throw option_error("option.flow", "endpoint_error", "flow fields differ in size");
  double sum = 0;
  std::size_t n = 0;
  for (int y = 0; y < f.height(); ++y)
    for (int x = 0; x < f.width(); ++x) {
      if (!mask.empty() && !(mask.row(y)[x] > Scalar(0.5))) continue;
      const double du = double(f.row(y)[2 * x]) - double(gt.row(y)[2 * x]);
      const double dv = double(f.row(y)[2 * x + 1]) - double(gt.row(y)[2 * x + 1]);
      sum += std::sqrt(du * du + dv * dv);
      ++n;
    }
  return n ? sum / double(n) : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace video3dgs::flow
