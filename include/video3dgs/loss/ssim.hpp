#pragma once
/// @file
/// SSIM and the D-SSIM loss 1 - SSIM, forward and backward (gradient w.r.t. the first image, the
/// render x; the second, y, is the target).
///
/// Forward, per channel, with G the (2r+1)^2 Gaussian window (r = 5, sigma = 1.5, sums to 1) applied
/// with zero padding ("same" size, as the 3DGS reference's conv2d with padding r):
///   mx = G*x, my = G*y, exx = G*(x x), eyy = G*(y y), exy = G*(x y)
///   A1 = 2 mx my + C1,   A2 = 2 (exy - mx my) + C2
///   B1 = mx^2 + my^2 + C1,   B2 = (exx - mx^2) + (eyy - my^2) + C2
///   S_p = A1 A2 / (B1 B2),   SSIM = 1/M sum_p S_p,   M = width * height * channels
/// (C1 = 0.01^2, C2 = 0.03^2 for data range 1).
///
/// Backward. Treating mx, exx, exy as the independent inputs of S_p:
///   dS/dmx  = 2 [my (A2 - A1) - mx S (B2 - B1)] / (B1 B2)
///   dS/dexx = -S / B2
///   dS/dexy = 2 A1 / (B1 B2)
/// and since mx(p) = sum_q G(p - q) x(q) with G symmetric, the adjoint of "filter with zero padding" is
/// the same filter:
///   dSSIM/dx = 1/M [ G*(dS/dmx) + 2 x G*(dS/dexx) + y G*(dS/dexy) ].
/// The forward stores the three coefficient maps; the backward is three more separable filters.
///
/// Usage (one reusable context per image size keeps the calls free of heap allocation):
///
///     loss::SsimContext<float, 3> ctx;
///     float s = loss::ssim_forward(render, target, ctx, &pool);
///     loss::ssim_backward(ctx, dL_ds, dL_drender, &pool);   // adds into dL_drender
///
/// Both passes split rows into fixed chunks and sum every output in tap order: bit-identical results
/// for any thread count.

#include <algorithm>
#include <cstddef>
#include <stdexcept>
#include <type_traits>
#include <vector>

#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/loss/detail/gaussian_window.hpp"
#include "video3dgs/loss/l1.hpp"

namespace video3dgs::loss {

/// SSIM constants. The defaults are the reference's (11x11 window, sigma 1.5, K1 = 0.01, K2 = 0.03,
/// data range 1).
struct SsimOptions {
  int radius = 5;     ///< window side 2 r + 1
  double sigma = 1.5;
  double c1 = 0.01 * 0.01;
  double c2 = 0.03 * 0.03;
};

/// Saved state and scratch space of SSIM. Reuse one per image size: buffers are resized only when the
/// size changes. The images it views (render, target) must outlive the backward call.
template <class Scalar, int C>
struct SsimContext {
  explicit SsimContext(SsimOptions opts = {}) : options(opts) {}

  SsimOptions options;
  Scalar value = 0;                 ///< SSIM of the last forward
  ConstImageView<Scalar, C> x, y;   ///< the inputs of the last forward
  bool saved_for_backward = false;  ///< false after `ssim_value` (forward only)

  // Internals (filled by the forward, read by the backward):
  std::vector<Scalar> taps;                   ///< 2r + 1 normalised Gaussian taps
  double taps_sigma = 0;                      ///< the sigma `taps` was made for
  std::vector<Scalar> d_mx, d_exx, d_exy;     ///< dS/dmx, dS/dexx, dS/dexy, width*height*C each
  std::vector<Scalar> h[5];                   ///< horizontal-pass results
  std::vector<Scalar> rows;                   ///< per-chunk vertical accumulators
  std::vector<double> partial;                ///< per-chunk sums of S
};

namespace detail {

template <class Scalar, int C>
void ssim_prepare(SsimContext<Scalar, C>& ctx, int w, int h, int maps, bool grad) {
  const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * C;
  const std::size_t taps = static_cast<std::size_t>(2 * ctx.options.radius + 1);
  if (ctx.taps.size() != taps || ctx.taps_sigma != ctx.options.sigma) {
    ctx.taps = gaussian_taps<Scalar>(ctx.options.radius, ctx.options.sigma);
    ctx.taps_sigma = ctx.options.sigma;
  }
  for (int q = 0; q < maps; ++q) ctx.h[q].resize(n);
  if (grad) {
    ctx.d_mx.resize(n);
    ctx.d_exx.resize(n);
    ctx.d_exy.resize(n);
  }
  const std::size_t chunks = chunk_count(static_cast<std::size_t>(h), kLossRowsPerChunk);
  ctx.rows.resize(std::max(ctx.rows.size(), chunks * static_cast<std::size_t>(maps) * static_cast<std::size_t>(w) * C));
  ctx.partial.assign(chunks, 0.0);
}

/// S for one row of filtered statistics (and, if Grad, its coefficient maps); returns the row sum
/// (in double, in index order). S overwrites `mx` so that the element loop has no reduction and
/// vectorises.
template <bool Grad, class Scalar>
double ssim_row(Scalar* mx, const Scalar* my, const Scalar* exx, const Scalar* eyy, const Scalar* exy, Scalar c1,
                Scalar c2, std::ptrdiff_t n, Scalar* dmx, Scalar* dexx, Scalar* dexy) {
  for (std::ptrdiff_t i = 0; i < n; ++i) {
    const Scalar ax = mx[i], ay = my[i];
    const Scalar mx2 = ax * ax, my2 = ay * ay, mxy = ax * ay;
    const Scalar A1 = Scalar(2) * mxy + c1;
    const Scalar A2 = Scalar(2) * (exy[i] - mxy) + c2;
    const Scalar B1 = mx2 + my2 + c1;
    const Scalar B2 = (exx[i] - mx2) + (eyy[i] - my2) + c2;
    const Scalar D = B1 * B2;
    const Scalar S = (A1 * A2) / D;  // a division (not a reciprocal) keeps SSIM(x, x) == 1 exactly
    mx[i] = S;
    if constexpr (Grad) {
      const Scalar inv = Scalar(1) / D;
      dmx[i] = Scalar(2) * (ay * (A2 - A1) - ax * S * (B2 - B1)) * inv;
      dexx[i] = -S / B2;
      dexy[i] = Scalar(2) * A1 * inv;
    }
  }
  double s_row = 0;
  for (std::ptrdiff_t i = 0; i < n; ++i) s_row += static_cast<double>(mx[i]);
  return s_row;
}

template <class Scalar, int C>
Scalar ssim_run(ConstImageView<Scalar, C> x, ConstImageView<Scalar, C> y, SsimContext<Scalar, C>& ctx, ThreadPool* pool,
                bool grad) {
  check_same_size(x, y, "ssim");
  if (x.empty()) throw std::invalid_argument("video3dgs::loss: ssim of an empty image");
  if (ctx.options.radius < 0 || !(ctx.options.sigma > 0))
    throw std::invalid_argument("video3dgs::loss: ssim needs radius >= 0 and sigma > 0");
  const int W = x.width(), H = x.height(), r = ctx.options.radius;
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(W) * C;
  ssim_prepare(ctx, W, H, 5, grad);
  ctx.x = x;
  ctx.y = y;
  ctx.saved_for_backward = grad;
  const Scalar* taps = ctx.taps.data();
  const int ntaps = 2 * r + 1;

  // Horizontal pass of x, y, x x, y y, x y.
  parallel_for_chunks(pool, static_cast<std::size_t>(H), kLossRowsPerChunk, [&](std::size_t, std::size_t b, std::size_t e) {
    for (std::size_t row = b; row < e; ++row) {
      const Scalar* xr = x.row(static_cast<int>(row));
      const Scalar* yr = y.row(static_cast<int>(row));
      Scalar* hx = ctx.h[0].data() + row * n;
      Scalar* hy = ctx.h[1].data() + row * n;
      Scalar* hxx = ctx.h[2].data() + row * n;
      Scalar* hyy = ctx.h[3].data() + row * n;
      Scalar* hxy = ctx.h[4].data() + row * n;
      for (std::ptrdiff_t i = 0; i < n; ++i) hx[i] = hy[i] = hxx[i] = hyy[i] = hxy[i] = Scalar(0);
      for (int k = 0; k < ntaps; ++k) {
        const TapRange t = tap_range(k, r, C, n);
        if (t.lo < t.hi) ssim_tap(taps[k], xr + t.offset, yr + t.offset, hx, hy, hxx, hyy, hxy, t.lo, t.hi);
      }
    }
  });

  // Vertical pass, S and its coefficient maps.
  const Scalar c1 = static_cast<Scalar>(ctx.options.c1), c2 = static_cast<Scalar>(ctx.options.c2);
  parallel_for_chunks(pool, static_cast<std::size_t>(H), kLossRowsPerChunk, [&](std::size_t chunk, std::size_t b, std::size_t e) {
    Scalar* acc = ctx.rows.data() + chunk * 5 * static_cast<std::size_t>(n);
    Scalar *mx = acc, *my = acc + n, *exx = acc + 2 * n, *eyy = acc + 3 * n, *exy = acc + 4 * n;
    double sum = 0;
    for (std::size_t row = b; row < e; ++row) {
      for (std::ptrdiff_t i = 0; i < 5 * n; ++i) acc[i] = Scalar(0);
      for (int k = 0; k < ntaps; ++k) {
        const std::ptrdiff_t yy = static_cast<std::ptrdiff_t>(row) + k - r;
        if (yy < 0 || yy >= H) continue;
        for (int q = 0; q < 5; ++q) axpy(acc + q * n, taps[k], ctx.h[q].data() + yy * n, n);
      }
      const double s_row = grad ? ssim_row<true>(mx, my, exx, eyy, exy, c1, c2, n, ctx.d_mx.data() + row * n,
                                                 ctx.d_exx.data() + row * n, ctx.d_exy.data() + row * n)
                                : ssim_row<false, Scalar>(mx, my, exx, eyy, exy, c1, c2, n, nullptr, nullptr, nullptr);
      sum += s_row;
    }
    ctx.partial[chunk] = sum;
  });
  double total = 0;
  for (double p : ctx.partial) total += p;
  ctx.value = static_cast<Scalar>(total / static_cast<double>(n * H));
  return ctx.value;
}

}  // namespace detail

/// SSIM of render `x` against target `y` (same size), saving what `ssim_backward` needs.
/// @return mean SSIM over all pixels and channels, in [-1, 1]; exactly 1 when x == y.
template <class Scalar, int C>
Scalar ssim_forward(std::type_identity_t<ConstImageView<Scalar, C>> x, std::type_identity_t<ConstImageView<Scalar, C>> y,
                    SsimContext<Scalar, C>& ctx, ThreadPool* pool = nullptr) {
  return detail::ssim_run<Scalar, C>(x, y, ctx, pool, true);
}

/// SSIM without saving for the backward (about a third less work; for metrics).
template <class Scalar, int C>
Scalar ssim_value(std::type_identity_t<ConstImageView<Scalar, C>> x, std::type_identity_t<ConstImageView<Scalar, C>> y,
                  SsimContext<Scalar, C>& ctx, ThreadPool* pool = nullptr) {
  return detail::ssim_run<Scalar, C>(x, y, ctx, pool, false);
}

/// Adds dL/dx = dL_dssim * dSSIM/dx into `dL_dx` (zero it first if it holds nothing else). May be
/// called more than once after one forward (it only uses the context's scratch space).
template <class Scalar, int C>
void ssim_backward(SsimContext<Scalar, C>& ctx, Scalar dL_dssim, std::type_identity_t<ImageView<Scalar, C>> dL_dx,
                   ThreadPool* pool = nullptr) {
  if (!ctx.saved_for_backward)
    throw std::logic_error("video3dgs::loss: ssim_backward needs a preceding ssim_forward (not ssim_value)");
  detail::check_same_size(ctx.x, dL_dx, "ssim_backward");
  const int W = ctx.x.width(), H = ctx.x.height(), r = ctx.options.radius;
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(W) * C;
  const Scalar* taps = ctx.taps.data();
  const int ntaps = 2 * r + 1;
  const Scalar g = dL_dssim / static_cast<Scalar>(static_cast<double>(n) * H);
  const Scalar* coef[3] = {ctx.d_mx.data(), ctx.d_exx.data(), ctx.d_exy.data()};

  parallel_for_chunks(pool, static_cast<std::size_t>(H), kLossRowsPerChunk, [&](std::size_t, std::size_t b, std::size_t e) {
    for (std::size_t row = b; row < e; ++row) {
      for (int q = 0; q < 3; ++q) {
        const Scalar* src = coef[q] + row * n;
        Scalar* dst = ctx.h[q].data() + row * n;
        for (std::ptrdiff_t i = 0; i < n; ++i) dst[i] = Scalar(0);
        for (int k = 0; k < ntaps; ++k) {
          const detail::TapRange t = detail::tap_range(k, r, C, n);
          if (t.lo < t.hi) detail::tap(taps[k], src + t.offset, dst, t.lo, t.hi);
        }
      }
    }
  });

  parallel_for_chunks(pool, static_cast<std::size_t>(H), kLossRowsPerChunk, [&](std::size_t chunk, std::size_t b, std::size_t e) {
    Scalar* acc = ctx.rows.data() + chunk * 5 * static_cast<std::size_t>(n);
    for (std::size_t row = b; row < e; ++row) {
      for (std::ptrdiff_t i = 0; i < 3 * n; ++i) acc[i] = Scalar(0);
      for (int k = 0; k < ntaps; ++k) {
        const std::ptrdiff_t yy = static_cast<std::ptrdiff_t>(row) + k - r;
        if (yy < 0 || yy >= H) continue;
        for (int q = 0; q < 3; ++q) detail::axpy(acc + q * n, taps[k], ctx.h[q].data() + yy * n, n);
      }
      const Scalar* xr = ctx.x.row(static_cast<int>(row));
      const Scalar* yr = ctx.y.row(static_cast<int>(row));
      Scalar* out = dL_dx.row(static_cast<int>(row));
      const Scalar *a0 = acc, *a1 = acc + n, *a2 = acc + 2 * n;
      for (std::ptrdiff_t i = 0; i < n; ++i) out[i] += g * (a0[i] + Scalar(2) * xr[i] * a1[i] + yr[i] * a2[i]);
    }
  });
}

/// D-SSIM = 1 - SSIM (a loss: 0 when x == y). Saves for `dssim_backward`.
template <class Scalar, int C>
Scalar dssim_forward(std::type_identity_t<ConstImageView<Scalar, C>> x, std::type_identity_t<ConstImageView<Scalar, C>> y,
                     SsimContext<Scalar, C>& ctx, ThreadPool* pool = nullptr) {
  return Scalar(1) - ssim_forward<Scalar, C>(x, y, ctx, pool);
}

/// Adds dL/dx = dL_ddssim * d(1 - SSIM)/dx into `dL_dx`.
template <class Scalar, int C>
void dssim_backward(SsimContext<Scalar, C>& ctx, Scalar dL_ddssim, std::type_identity_t<ImageView<Scalar, C>> dL_dx,
                    ThreadPool* pool = nullptr) {
  ssim_backward<Scalar, C>(ctx, -dL_ddssim, dL_dx, pool);
}

}  // namespace video3dgs::loss
