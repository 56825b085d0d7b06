#pragma once
/// @file
/// A built-in optical-flow estimator: coarse-to-fine Horn-Schunck with warping and median filtering
/// ("classic+" in the sense of Sun, Roth, Black, CVPR 2010, with a quadratic penalty).
///
/// On each pyramid level (grayscale I1, I2, Gaussian pre-smoothing, factor 2), starting from the
/// upsampled coarser flow w0 = (u0, v0), each warp iteration linearises brightness constancy around
/// w0 and solves for the total flow w = w0 + dw:
///
///   E(w) = sum_x (Ix du + Iy dv + It)^2 + alpha^2 (|grad u|^2 + |grad v|^2)
///   Ix, Iy = mean of the gradients of I1 and I2(x + w0),   It = I2(x + w0) - I1
///
/// whose Euler-Lagrange equations (Laplacian ~ 4 (ubar - u), ubar = mean of the 4 neighbours; the
/// factor is absorbed in alpha) give the pointwise update
///
///   c  = (Ix (ubar - u0) + Iy (vbar - v0) + It) / (alpha^2 + Ix^2 + Iy^2)
///   u  = ubar - Ix c,   v = vbar - Iy c
///
/// iterated with red-black successive over-relaxation (each colour reads only the other colour, so
/// the result does not depend on the thread count). Pixels whose warped sample leaves I2 drop their
/// data term. After each warp a 5x5 median filter removes outliers. Intensities are in [0, 1], so
/// `alpha` is in intensity units per pixel of flow gradient.

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/flow/warp.hpp"

namespace video3dgs::flow {

/// Options of `estimate_flow` (defaults measured on the synthetic cases of tests/flow).
struct HornSchunckOptions {
  double alpha = 0.03;        ///< smoothness weight (intensity units, images in [0, 1])
  int min_size = 16;          ///< coarsest level: smaller side >= this
  int max_levels = 8;         ///< pyramid levels at most
  int warps = 3;              ///< linearisations per level
  int iterations = 40;        ///< SOR sweeps per warp
  double omega = 1.8;         ///< over-relaxation factor in (0, 2)
  double presmooth_sigma = 1.0;  ///< Gaussian blur of the input (pixels of the finest level)
  int median_radius = 2;      ///< median filter half-size after each warp (0 = off)

  void validate() const {
    auto bad = [](const char* f, const char* why) { throw option_error("option.flow", f, why); };
    if (!(alpha > 0 && std::isfinite(alpha))) bad("alpha", "must be > 0");
    if (min_size < 4) bad("min_size", "must be >= 4");
    if (max_levels < 1) bad("max_levels", "must be >= 1");
    if (warps < 1 || iterations < 1) bad("warps/iterations", "must be >= 1");
    if (!(omega > 0 && omega < 2)) bad("omega", "must be in (0, 2)");
    if (!(presmooth_sigma >= 0)) bad("presmooth_sigma", "must be >= 0");
    if (median_radius < 0 || median_radius > 5) bad("median_radius", "must be in 0..5");
  }
};

namespace detail {

using Plane = Image<double, 1>;

/// Separable Gaussian blur with replicated borders.
inline Plane blur(const Plane& in, double sigma, ThreadPool* pool) {
  if (sigma <= 0) return in;
  const int r = std::max(1, int(std::ceil(2.5 * sigma)));
  std::vector<double> k(std::size_t(2 * r + 1));
  double s = 0;
  for (int i = -r; i <= r; ++i) s += k[std::size_t(i + r)] = std::exp(-0.5 * i * i / (sigma * sigma));
  for (double& v : k) v /= s;
  const int w = in.width(), h = in.height();
  Plane tmp(w, h), out(w, h);
  parallel_for(pool, std::size_t(h), [&](std::size_t yy) {
    const int y = int(yy);
    for (int x = 0; x < w; ++x) {
      double a = 0;
      for (int i = -r; i <= r; ++i) a += k[std::size_t(i + r)] * in(std::clamp(x + i, 0, w - 1), y);
      tmp(x, y) = a;
    }
  }, 8);
  parallel_for(pool, std::size_t(h), [&](std::size_t yy) {
    const int y = int(yy);
    for (int x = 0; x < w; ++x) {
      double a = 0;
      for (int i = -r; i <= r; ++i) a += k[std::size_t(i + r)] * tmp(x, std::clamp(y + i, 0, h - 1));
      out(x, y) = a;
    }
  }, 8);
  return out;
}

/// Half-size image: blur (sigma 1) then sample at the centres of 2x2 blocks.
inline Plane downsample(const Plane& in, ThreadPool* pool) {
  const Plane b = blur(in, 1.0, pool);
  const int w = std::max(1, in.width() / 2), h = std::max(1, in.height() / 2);
  Plane out(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double px = 2 * x + 0.5, py = 2 * y + 0.5;
      double v;
      sample_bilinear<double, 1>(b.view(), px, py, &v);
      out(x, y) = v;
    }
  return out;
}

template <class Scalar>
Plane to_gray(ConstImageView<Scalar, 3> img) {
  Plane g(img.width(), img.height());
  for (int y = 0; y < img.height(); ++y)
    for (int x = 0; x < img.width(); ++x) {
      const Scalar* p = img.pixel(x, y);
      g(x, y) = 0.299 * double(p[0]) + 0.587 * double(p[1]) + 0.114 * double(p[2]);
    }
  return g;
}

/// Resamples a flow to (w, h), scaling the vectors by the size ratio.
inline Image<double, 2> resize_flow(const Image<double, 2>& f, int w, int h) {
  Image<double, 2> out(w, h);
  const double sx = double(w) / f.width(), sy = double(h) / f.height();
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double v[2];
      sample_bilinear<double, 2>(f.view(), (x + 0.5) / sx - 0.5, (y + 0.5) / sy - 0.5, v);
      out(x, y, 0) = v[0] * sx;
      out(x, y, 1) = v[1] * sy;
    }
  return out;
}

/// Median filter of each flow component over a (2r+1)^2 window (replicated borders).
inline void median_filter(Image<double, 2>& f, int r, ThreadPool* pool) {
  if (r <= 0) return;
  const Image<double, 2> in = f;
  const int w = f.width(), h = f.height();
  parallel_for(pool, std::size_t(h), [&](std::size_t yy) {
    const int y = int(yy);
    std::array<double, 121> buf{};
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 2; ++c) {
        std::size_t n = 0;
        for (int dy = -r; dy <= r; ++dy)
          for (int dx = -r; dx <= r; ++dx) buf[n++] = in(std::clamp(x + dx, 0, w - 1), std::clamp(y + dy, 0, h - 1), c);
        std::nth_element(buf.begin(), buf.begin() + std::ptrdiff_t(n / 2), buf.begin() + std::ptrdiff_t(n));
        f(x, y, c) = buf[n / 2];
      }
  }, 8);
}

/// Central-difference gradient (one-sided at borders).
inline void gradient(const Plane& p, Plane& gx, Plane& gy) {
  const int w = p.width(), h = p.height();
  gx.resize(w, h);
  gy.resize(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int xl = std::max(x - 1, 0), xr = std::min(x + 1, w - 1);
      const int yu = std::max(y - 1, 0), yd = std::min(y + 1, h - 1);
      gx(x, y) = xr > xl ? (p(xr, y) - p(xl, y)) / double(xr - xl) : 0.0;
      gy(x, y) = yd > yu ? (p(x, yd) - p(x, yu)) / double(yd - yu) : 0.0;
    }
}

/// One pyramid level: refines `w` (total flow, level units) in place.
inline void refine_level(const Plane& i1, const Plane& i2, Image<double, 2>& wf, const HornSchunckOptions& o, ThreadPool* pool) {
  const int w = i1.width(), h = i1.height();
  const double a2 = o.alpha * o.alpha;
  Plane i2w(w, h), g1x, g1y, g2x, g2y, ix(w, h), iy(w, h), it(w, h), valid(w, h);
  gradient(i1, g1x, g1y);
  for (int k = 0; k < o.warps; ++k) {
    warp_bilinear<double, 1, double>(i2.view(), wf.view(), i2w.view(), valid.view(), pool);
    gradient(i2w, g2x, g2y);
    for (std::size_t p = 0; p < i1.size(); ++p) {
      const bool ok = valid.data()[p] > 0.5;
      ix.data()[p] = ok ? 0.5 * (g1x.data()[p] + g2x.data()[p]) : 0.0;
      iy.data()[p] = ok ? 0.5 * (g1y.data()[p] + g2y.data()[p]) : 0.0;
      it.data()[p] = ok ? i2w.data()[p] - i1.data()[p] : 0.0;
    }
    const Image<double, 2> w0 = wf;
    for (int s = 0; s < o.iterations; ++s)
      for (int colour = 0; colour < 2; ++colour) {
        parallel_for(pool, std::size_t(h), [&](std::size_t yy) {
          const int y = int(yy);
          const int yu = std::max(y - 1, 0), yd = std::min(y + 1, h - 1);
          for (int x = (y + colour) & 1; x < w; x += 2) {
            const int xl = std::max(x - 1, 0), xr = std::min(x + 1, w - 1);
            double bar[2];
            for (int c = 0; c < 2; ++c)
              bar[c] = 0.25 * (wf(xl, y, c) + wf(xr, y, c) + wf(x, yu, c) + wf(x, yd, c));
            const double gx = ix(x, y), gy = iy(x, y);
            const double cterm = (gx * (bar[0] - w0(x, y, 0)) + gy * (bar[1] - w0(x, y, 1)) + it(x, y)) / (a2 + gx * gx + gy * gy);
            const double nu = bar[0] - gx * cterm, nv = bar[1] - gy * cterm;
            wf(x, y, 0) += o.omega * (nu - wf(x, y, 0));
            wf(x, y, 1) += o.omega * (nv - wf(x, y, 1));
          }
        }, 8);
      }
    median_filter(wf, o.median_radius, pool);
  }
}

}  // namespace detail

/// Dense flow from `a` to `b` (same size, RGB in [0, 1]): pixel x of a moves to x + f(x) in b.
/// Deterministic for any pool. @throws option_error `option.flow` on bad options or sizes.
template <class Scalar>
[[nodiscard]] FlowField<Scalar> estimate_flow(ConstImageView<Scalar, 3> a, ConstImageView<Scalar, 3> b,
                                              const HornSchunckOptions& o = {}, ThreadPool* pool = nullptr) {
  o.validate();
  if (a.empty() || a.width() != b.width() || a.height() != b.height())
    throw option_error("option.flow", "estimate_flow", "needs two non-empty images of the same size");
  std::vector<detail::Plane> p1{detail::blur(detail::to_gray<Scalar>(a), o.presmooth_sigma, pool)};
  std::vector<detail::Plane> p2{detail::blur(detail::to_gray<Scalar>(b), o.presmooth_sigma, pool)};
  while (int(p1.size()) < o.max_levels && std::min(p1.back().width(), p1.back().height()) / 2 >= o.min_size) {
    p1.push_back(detail::downsample(p1.back(), pool));
    p2.push_back(detail::downsample(p2.back(), pool));
  }
  Image<double, 2> wf(p1.back().width(), p1.back().height());
  for (int l = int(p1.size()) - 1; l >= 0; --l) {
    const auto& i1 = p1[std::size_t(l)];
    if (wf.width() != i1.width() || wf.height() != i1.height()) wf = detail::resize_flow(wf, i1.width(), i1.height());
    detail::refine_level(i1, p2[std::size_t(l)], wf, o, pool);
  }
  return wf.template cast<Scalar>();
}

/// Owning-image convenience.
template <class Scalar>
[[nodiscard]] FlowField<Scalar> estimate_flow(const Image<Scalar, 3>& a, const Image<Scalar, 3>& b, const HornSchunckOptions& o = {},
                                              ThreadPool* pool = nullptr) {
  return estimate_flow<Scalar>(a.view(), b.view(), o, pool);
}

}  // namespace video3dgs::flow
