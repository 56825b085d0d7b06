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
/// Several renders against one target (the clip graph's three terms) can share the target-only maps
/// my = G*y and eyy = G*(y y): fill an `SsimTarget` once, then pass it instead of y. Those forwards
/// filter only x, x x, x y and give the same bits as the plain call (both evaluate the same
/// expressions; a build that lets the compiler fuse multiply-adds across statements, GCC's
/// -ffp-contract=fast with FMA enabled, may round the two differently):
///
///     loss::SsimTarget<float, 3> target;
///     loss::fill_ssim_target(frame, target, {}, &pool);    // once per target (and per change of it)
///     float s = loss::ssim_forward(render, target, ctx, &pool);
///
/// Both passes split rows into fixed chunks and sum every output in tap order: bit-identical results
/// for any thread count. The row filters also have an AVX2 copy (`SsimOptions::simd`), without FMA:
/// the same bits on every instruction set.

#include <algorithm>
#include <cstddef>
#include <string>
#include <type_traits>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/isa.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/loss/detail/gaussian_window.hpp"
#include "video3dgs/loss/detail/ssim_kernels.hpp"
#include "video3dgs/loss/l1.hpp"

namespace video3dgs::loss {

/// SSIM constants. The defaults are the reference's (11x11 window, sigma 1.5, K1 = 0.01, K2 = 0.03,
/// data range 1).
struct SsimOptions {
  int radius = 5;     ///< window side 2 r + 1
  double sigma = 1.5;
  double c1 = 0.01 * 0.01;
  double c2 = 0.03 * 0.03;
  /// The filters' instruction set (core/isa.hpp): `portable` or `avx2` (`automatic`: avx2 where the
  /// CPU has it). Every choice gives the same bits; `avx512` is refused (no copy), as is one this CPU
  /// or build lacks.
  Isa simd = Isa::automatic;
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

  // Internals (filled by the forward, read by the backward). n = width * C, r = radius.
  std::vector<Scalar> taps;                ///< 2r + 1 normalised Gaussian taps
  double taps_sigma = 0;                   ///< the sigma `taps` was made for
  int shape[3] = {-1, -1, -1};             ///< width, height, radius the buffers are laid out for
  std::vector<Scalar> h[5];                ///< horizontal-pass maps of x, y, x x, y y, x y (with an `SsimTarget`: x, x x, x y
                                           ///< in h[0..2]), (height + 2r) rows of n, r zero rows each side
  std::vector<Scalar> d_mx, d_exx, d_exy;  ///< dS/dmx, dS/dexx, dS/dexy: height rows of n + 2rC, r*C zeros each side
  std::vector<Scalar> pad;                 ///< per-chunk padded input rows (2 x (n + 2rC))
  std::vector<Scalar> srow;                ///< per-chunk row of S values (n)
  std::vector<double> partial;             ///< per-chunk sums of S
};

/// The target-only statistics of SSIM, my = G*y and eyy = G*(y y), of one target y and one window
/// (radius, sigma; C1, C2 do not enter), filled by `fill_ssim_target`. A forward that takes it reads y
/// through `y` and checks the size and window; the maps are of y's pixels at the fill: refill after
/// changing them (the caller's guarantee; nothing can detect it). Reuse one per target: buffers are
/// resized only when the size or radius changes.
template <class Scalar, int C>
struct SsimTarget {
  ConstImageView<Scalar, C> y;  ///< the target of the last fill (empty: never filled)
  int radius = -1;              ///< window of the last fill
  double sigma = 0;

  /// True if filled for an image of width x height and `o`'s window.
  [[nodiscard]] bool fits(int width, int height, const SsimOptions& o) const noexcept {
    return !y.empty() && y.width() == width && y.height() == height && radius == o.radius && sigma == o.sigma;
  }

  // Internals. n = width * C, r = radius.
  std::vector<Scalar> taps;        ///< 2r + 1 normalised Gaussian taps
  std::vector<Scalar> my, eyy;     ///< G*y, G*(y y): height rows of n
  std::vector<Scalar> h[2];        ///< horizontal passes of y, y y: (height + 2r) rows of n, r zero rows each side
  std::vector<Scalar> pad;         ///< per-chunk padded input row (n + 2rC)
  int shape[3] = {-1, -1, -1};     ///< width, height, radius `h` is laid out for
};

namespace detail {

inline void check_ssim_options(const SsimOptions& o) {
  if (o.radius < 0 || o.radius > 64 || !(o.sigma > 0))
    throw option_error("option.range", "ssim", "needs 0 <= radius <= 64 and sigma > 0");
  if (o.simd == Isa::avx512 || !isa_supported(o.simd))
    throw option_error("option.ssim", "simd", std::string("no ") + isa_name(o.simd) + " copy of the SSIM filters for this build and CPU");
}

/// Whether the filters run their AVX2 copies (options checked by check_ssim_options).
[[nodiscard]] inline bool ssim_avx2(const SsimOptions& o) noexcept { return resolve_isa(o.simd, {Isa::avx2}) == Isa::avx2; }

/// Lays out the buffers for a width x height image (zeroing the padding whenever the layout changes);
/// `maps` horizontal-pass maps (5, or 3 with a shared target).
template <class Scalar, int C>
void ssim_prepare(SsimContext<Scalar, C>& ctx, int w, int h, bool grad, int maps) {
  const int r = ctx.options.radius;
  const std::size_t n = static_cast<std::size_t>(w) * C;
  const std::size_t padded = n + 2 * static_cast<std::size_t>(r) * C;
  const std::size_t taps = static_cast<std::size_t>(2 * r + 1);
  if (ctx.taps.size() != taps || ctx.taps_sigma != ctx.options.sigma) {
    ctx.taps = gaussian_taps<Scalar>(r, ctx.options.sigma);
    ctx.taps_sigma = ctx.options.sigma;
  }
  const bool same = ctx.shape[0] == w && ctx.shape[1] == h && ctx.shape[2] == r;
  const std::size_t map_size = (static_cast<std::size_t>(h) + 2 * static_cast<std::size_t>(r)) * n;
  if (!same) {
    for (auto& m : ctx.h) m.clear();
    ctx.d_mx.clear();
    ctx.d_exx.clear();
    ctx.d_exy.clear();
    ctx.shape[0] = w;
    ctx.shape[1] = h;
    ctx.shape[2] = r;
  }
  for (int k = 0; k < maps; ++k)
    if (ctx.h[k].size() != map_size) ctx.h[k].assign(map_size, Scalar(0));
  if (grad && ctx.d_mx.empty()) {
    const std::size_t size = static_cast<std::size_t>(h) * padded;
    ctx.d_mx.assign(size, Scalar(0));
    ctx.d_exx.assign(size, Scalar(0));
    ctx.d_exy.assign(size, Scalar(0));
  }
  const std::size_t chunks = chunk_count(static_cast<std::size_t>(h), kLossRowsPerChunk);
  if (ctx.pad.size() < chunks * 3 * padded) ctx.pad.assign(chunks * 3 * padded, Scalar(0));
  if (ctx.srow.size() < chunks * n) ctx.srow.resize(chunks * n);
  ctx.partial.assign(chunks, 0.0);
}

/// Copies a row into the interior of a padded row whose r*C margins are zero.
template <class Scalar>
inline void fill_padded(Scalar* padded, const Scalar* row, std::ptrdiff_t n, std::ptrdiff_t margin) {
  for (std::ptrdiff_t i = 0; i < margin; ++i) padded[i] = padded[margin + n + i] = Scalar(0);
  std::copy(row, row + n, padded + margin);
}

/// With `target` (filled for y), h[0..2] hold x, x x, x y and the vertical pass reads my, eyy from it.
template <int NT, class Scalar, int C>
Scalar ssim_run_impl(ConstImageView<Scalar, C> x, ConstImageView<Scalar, C> y, SsimContext<Scalar, C>& ctx,
                     ThreadPool* pool, bool grad, const SsimTarget<Scalar, C>* target) {
  const int W = x.width(), H = x.height(), r = ctx.options.radius, nt = 2 * r + 1;
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(W) * C;
  const std::ptrdiff_t margin = static_cast<std::ptrdiff_t>(r) * C, padded = n + 2 * margin;
  const Scalar* taps = ctx.taps.data();
  const auto rows = static_cast<std::size_t>(H);
  const bool avx2 = ssim_avx2(ctx.options);
  Scalar* const none = nullptr;  // no coefficient maps (a forward without gradient)

  // Horizontal pass of x, y, x x, y y, x y into rows r..r+H-1 of the padded maps.
  parallel_for_chunks(pool, rows, kLossRowsPerChunk, [&](std::size_t chunk, std::size_t b, std::size_t e) {
    Scalar* px = ctx.pad.data() + chunk * 3 * static_cast<std::size_t>(padded);
    Scalar* py = px + padded;
    for (std::size_t row = b; row < e; ++row) {
      fill_padded(px, x.row(static_cast<int>(row)), n, margin);
      fill_padded(py, y.row(static_cast<int>(row)), n, margin);
      const std::size_t o = (row + static_cast<std::size_t>(r)) * static_cast<std::size_t>(n);
      if (target)
        run_kernel<SsimSharedHorizontalRow<NT, C>>(avx2, taps, nt, n, px, py, ctx.h[0].data() + o, ctx.h[1].data() + o, ctx.h[2].data() + o);
      else
        run_kernel<SsimHorizontalRow<NT, C>>(avx2, taps, nt, n, px, py, ctx.h[0].data() + o, ctx.h[1].data() + o, ctx.h[2].data() + o,
                                   ctx.h[3].data() + o, ctx.h[4].data() + o);
    }
  });

  // Vertical pass, S and its coefficient maps (into the interior of their padded rows).
  const Scalar c1 = static_cast<Scalar>(ctx.options.c1), c2 = static_cast<Scalar>(ctx.options.c2);
  parallel_for_chunks(pool, rows, kLossRowsPerChunk, [&](std::size_t chunk, std::size_t b, std::size_t e) {
    Scalar* s_out = ctx.srow.data() + chunk * static_cast<std::size_t>(n);
    double sum = 0;
    for (std::size_t row = b; row < e; ++row) {
      const std::size_t o = row * static_cast<std::size_t>(n);  // first tap row of output row `row`
      if (target) {
        const Scalar *my = target->my.data() + o, *eyy = target->eyy.data() + o;
        if (grad) {
          const std::size_t c = row * static_cast<std::size_t>(padded) + static_cast<std::size_t>(margin);
          run_kernel<SsimSharedVerticalRow<true, NT>>(avx2, taps, nt, n, ctx.h[0].data() + o, ctx.h[1].data() + o, ctx.h[2].data() + o, my, eyy, c1,
                                             c2, s_out, ctx.d_mx.data() + c, ctx.d_exx.data() + c, ctx.d_exy.data() + c);
        } else {
          run_kernel<SsimSharedVerticalRow<false, NT>>(avx2, taps, nt, n, ctx.h[0].data() + o, ctx.h[1].data() + o, ctx.h[2].data() + o, my,
                                                      eyy, c1, c2, s_out, none, none, none);
        }
      } else if (grad) {
        const std::size_t c = row * static_cast<std::size_t>(padded) + static_cast<std::size_t>(margin);
        run_kernel<SsimVerticalRow<true, NT>>(avx2, taps, nt, n, ctx.h[0].data() + o, ctx.h[1].data() + o, ctx.h[2].data() + o,
                                    ctx.h[3].data() + o, ctx.h[4].data() + o, c1, c2, s_out, ctx.d_mx.data() + c,
                                    ctx.d_exx.data() + c, ctx.d_exy.data() + c);
      } else {
        run_kernel<SsimVerticalRow<false, NT>>(avx2, taps, nt, n, ctx.h[0].data() + o, ctx.h[1].data() + o, ctx.h[2].data() + o,
                                             ctx.h[3].data() + o, ctx.h[4].data() + o, c1, c2, s_out, none, none, none);
      }
      for (std::ptrdiff_t i = 0; i < n; ++i) sum += static_cast<double>(s_out[i]);
    }
    ctx.partial[chunk] = sum;
  });
  double total = 0;
  for (double p : ctx.partial) total += p;
  ctx.value = static_cast<Scalar>(total / (static_cast<double>(n) * H));
  return ctx.value;
}

template <class Scalar, int C>
Scalar ssim_run(ConstImageView<Scalar, C> x, ConstImageView<Scalar, C> y, SsimContext<Scalar, C>& ctx, ThreadPool* pool,
                bool grad, const SsimTarget<Scalar, C>* target = nullptr) {
  if (target && target->y.empty()) throw option_error("option.ssim", "target", "an SsimTarget needs fill_ssim_target before use");
  check_same_size(x, y, "ssim");
  if (x.empty()) throw option_error("option.size", "ssim", "empty image");
  check_ssim_options(ctx.options);
  if (target && !target->fits(x.width(), x.height(), ctx.options))
    throw option_error("option.ssim", "target", "filled for another window (radius, sigma) than the context's options");
  ssim_prepare(ctx, x.width(), x.height(), grad, target ? 3 : 5);
  ctx.x = x;
  ctx.y = y;
  ctx.saved_for_backward = grad;
  if (2 * ctx.options.radius + 1 == kDefaultTaps) return ssim_run_impl<kDefaultTaps, Scalar, C>(x, y, ctx, pool, grad, target);
  return ssim_run_impl<0, Scalar, C>(x, y, ctx, pool, grad, target);
}

template <int NT, class Scalar, int C>
void ssim_target_impl(SsimTarget<Scalar, C>& t, bool avx2, ThreadPool* pool) {
  const ConstImageView<Scalar, C> y = t.y;
  const int H = y.height(), r = t.radius, nt = 2 * r + 1;
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(y.width()) * C;
  const std::ptrdiff_t margin = static_cast<std::ptrdiff_t>(r) * C, padded = n + 2 * margin;
  const Scalar* taps = t.taps.data();
  const auto rows = static_cast<std::size_t>(H);
  parallel_for_chunks(pool, rows, kLossRowsPerChunk, [&](std::size_t chunk, std::size_t b, std::size_t e) {
    Scalar* py = t.pad.data() + chunk * static_cast<std::size_t>(padded);
    for (std::size_t row = b; row < e; ++row) {
      fill_padded(py, y.row(static_cast<int>(row)), n, margin);
      const std::size_t o = (row + static_cast<std::size_t>(r)) * static_cast<std::size_t>(n);
      run_kernel<SsimTargetHorizontalRow<NT, C>>(avx2, taps, nt, n, py, t.h[0].data() + o, t.h[1].data() + o);
    }
  });
  parallel_for_chunks(pool, rows, kLossRowsPerChunk, [&](std::size_t, std::size_t b, std::size_t e) {
    for (std::size_t row = b; row < e; ++row) {
      const std::size_t o = row * static_cast<std::size_t>(n);
      run_kernel<SsimTargetVerticalRow<NT>>(avx2, taps, nt, n, t.h[0].data() + o, t.h[1].data() + o, t.my.data() + o, t.eyy.data() + o);
    }
  });
}

template <int NT, class Scalar, int C>
void ssim_backward_impl(SsimContext<Scalar, C>& ctx, Scalar dL_dssim, ImageView<Scalar, C> dL_dx, ThreadPool* pool) {
  const int W = ctx.x.width(), H = ctx.x.height(), r = ctx.options.radius, nt = 2 * r + 1;
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(W) * C;
  const std::ptrdiff_t margin = static_cast<std::ptrdiff_t>(r) * C, padded = n + 2 * margin;
  const Scalar* taps = ctx.taps.data();
  const auto rows = static_cast<std::size_t>(H);
  const Scalar g = dL_dssim / static_cast<Scalar>(static_cast<double>(n) * H);
  const bool avx2 = ssim_avx2(ctx.options);

  // Horizontal pass of the coefficient maps (padded rows) into rows r..r+H-1 of h[0..2].
  parallel_for_chunks(pool, rows, kLossRowsPerChunk, [&](std::size_t, std::size_t b, std::size_t e) {
    for (std::size_t row = b; row < e; ++row) {
      const std::size_t c = row * static_cast<std::size_t>(padded);
      const std::size_t o = (row + static_cast<std::size_t>(r)) * static_cast<std::size_t>(n);
      run_kernel<Horizontal3Row<NT, C>>(avx2, taps, nt, n, ctx.d_mx.data() + c, ctx.d_exx.data() + c, ctx.d_exy.data() + c,
                             ctx.h[0].data() + o, ctx.h[1].data() + o, ctx.h[2].data() + o);
    }
  });
  // Vertical pass and the chain rule into dL/dx.
  parallel_for_chunks(pool, rows, kLossRowsPerChunk, [&](std::size_t, std::size_t b, std::size_t e) {
    for (std::size_t row = b; row < e; ++row) {
      const std::size_t o = row * static_cast<std::size_t>(n);
      const int ri = static_cast<int>(row);
      run_kernel<SsimBackwardVerticalRow<NT>>(avx2, taps, nt, n, ctx.h[0].data() + o, ctx.h[1].data() + o, ctx.h[2].data() + o,
                                     ctx.x.row(ri), ctx.y.row(ri), g, dL_dx.row(ri));
    }
  });
}

}  // namespace detail

/// SSIM of render `x` against target `y` (same size), saving what `ssim_backward` needs.
/// @return mean SSIM over all pixels and channels, in [-1, 1]; exactly 1 when x == y.
template <class Scalar, int C>
Scalar ssim_forward(std::type_identity_t<ConstImageView<Scalar, C>> x, std::type_identity_t<ConstImageView<Scalar, C>> y,
                    SsimContext<Scalar, C>& ctx, ThreadPool* pool = nullptr) {
  return detail::ssim_run<Scalar, C>(x, y, ctx, pool, true);
}

/// SSIM without saving for the backward (less work; for metrics).
template <class Scalar, int C>
Scalar ssim_value(std::type_identity_t<ConstImageView<Scalar, C>> x, std::type_identity_t<ConstImageView<Scalar, C>> y,
                  SsimContext<Scalar, C>& ctx, ThreadPool* pool = nullptr) {
  return detail::ssim_run<Scalar, C>(x, y, ctx, pool, false);
}

/// Computes `target`'s maps my = G*y, eyy = G*(y y) for `options`' window and records y (a view: y
/// must outlive every forward that uses the target, and keep its pixels).
/// @throws option_error `option.size` on an empty image, `option.range` on a bad window
template <class Scalar, int C>
void fill_ssim_target(std::type_identity_t<ConstImageView<Scalar, C>> y, SsimTarget<Scalar, C>& target, const SsimOptions& options = {},
                      ThreadPool* pool = nullptr) {
  if (y.empty()) throw option_error("option.size", "ssim", "empty image");
  detail::check_ssim_options(options);
  const int r = options.radius, w = y.width(), h = y.height();
  const std::size_t n = static_cast<std::size_t>(w) * C, padded = n + 2 * static_cast<std::size_t>(r) * C;
  if (target.taps.size() != static_cast<std::size_t>(2 * r + 1) || target.sigma != options.sigma)
    target.taps = detail::gaussian_taps<Scalar>(r, options.sigma);
  if (target.shape[0] != w || target.shape[1] != h || target.shape[2] != r) {
    for (auto& m : target.h) m.assign((static_cast<std::size_t>(h) + 2 * static_cast<std::size_t>(r)) * n, Scalar(0));
    target.my.resize(static_cast<std::size_t>(h) * n);
    target.eyy.resize(static_cast<std::size_t>(h) * n);
    target.shape[0] = w, target.shape[1] = h, target.shape[2] = r;
  }
  const std::size_t chunks = chunk_count(static_cast<std::size_t>(h), kLossRowsPerChunk);
  if (target.pad.size() < chunks * padded) target.pad.assign(chunks * padded, Scalar(0));
  target.y = y;
  target.radius = r;
  target.sigma = options.sigma;
  if (2 * r + 1 == detail::kDefaultTaps)
    detail::ssim_target_impl<detail::kDefaultTaps, Scalar, C>(target, detail::ssim_avx2(options), pool);
  else
    detail::ssim_target_impl<0, Scalar, C>(target, detail::ssim_avx2(options), pool);
}

/// `ssim_forward` against the target of `target` (filled for x's size and ctx.options' window): the
/// same result, bit for bit, without filtering the target again.
/// @throws option_error `option.size` if x's size is not the target's; option_error `option.ssim`
/// if `target` was never filled or was filled for another window than ctx.options'
template <class Scalar, int C>
Scalar ssim_forward(std::type_identity_t<ConstImageView<Scalar, C>> x, const SsimTarget<Scalar, C>& target, SsimContext<Scalar, C>& ctx,
                    ThreadPool* pool = nullptr) {
  return detail::ssim_run<Scalar, C>(x, target.y, ctx, pool, true, &target);
}

/// `ssim_value` against the target of `target` (as the `ssim_forward` overload).
template <class Scalar, int C>
Scalar ssim_value(std::type_identity_t<ConstImageView<Scalar, C>> x, const SsimTarget<Scalar, C>& target, SsimContext<Scalar, C>& ctx,
                  ThreadPool* pool = nullptr) {
  return detail::ssim_run<Scalar, C>(x, target.y, ctx, pool, false, &target);
}

/// Adds dL/dx = dL_dssim * dSSIM/dx into `dL_dx` (zero it first if it holds nothing else). May be
/// called more than once after one forward (it only uses the context's scratch space).
template <class Scalar, int C>
void ssim_backward(SsimContext<Scalar, C>& ctx, Scalar dL_dssim, std::type_identity_t<ImageView<Scalar, C>> dL_dx,
                   ThreadPool* pool = nullptr) {
  if (!ctx.saved_for_backward)
    throw option_error("option.ssim", "ssim_backward", "needs a preceding ssim_forward (not ssim_value)");
  detail::check_same_size(ctx.x, dL_dx, "ssim_backward");
  detail::check_ssim_options(ctx.options);  // the ISA too: the options may have changed since the forward
  if (2 * ctx.options.radius + 1 == detail::kDefaultTaps)
    detail::ssim_backward_impl<detail::kDefaultTaps, Scalar, C>(ctx, dL_dssim, dL_dx, pool);
  else
    detail::ssim_backward_impl<0, Scalar, C>(ctx, dL_dssim, dL_dx, pool);
}

/// D-SSIM = 1 - SSIM (a loss: 0 when x == y). Saves for `dssim_backward`.
template <class Scalar, int C>
Scalar dssim_forward(std::type_identity_t<ConstImageView<Scalar, C>> x, std::type_identity_t<ConstImageView<Scalar, C>> y,
                     SsimContext<Scalar, C>& ctx, ThreadPool* pool = nullptr) {
  return Scalar(1) - ssim_forward<Scalar, C>(x, y, ctx, pool);
}

/// D-SSIM against the target of `target` (as the `ssim_forward` overload).
template <class Scalar, int C>
Scalar dssim_forward(std::type_identity_t<ConstImageView<Scalar, C>> x, const SsimTarget<Scalar, C>& target, SsimContext<Scalar, C>& ctx,
                     ThreadPool* pool = nullptr) {
  return Scalar(1) - ssim_forward<Scalar, C>(x, target, ctx, pool);
}

/// Adds dL/dx = dL_ddssim * d(1 - SSIM)/dx into `dL_dx`.
template <class Scalar, int C>
void dssim_backward(SsimContext<Scalar, C>& ctx, Scalar dL_ddssim, std::type_identity_t<ImageView<Scalar, C>> dL_dx,
                    ThreadPool* pool = nullptr) {
  ssim_backward<Scalar, C>(ctx, -dL_ddssim, dL_dx, pool);
}

}  // namespace video3dgs::loss
