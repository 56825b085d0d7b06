#pragma once
/// @file
/// Mean absolute error with an optional per-pixel weight, forward and backward.
///
///   L1 = 1/(N C) sum_{p,c} w_p |x_pc - y_pc|          (w_p = 1 without a weight map)
///
/// Backward (x is the render, y the target):
///   dL/dx_pc = dL/dL1 * w_p * sign(x_pc - y_pc) / (N C),   sign(0) = 0.
///
/// N = width * height, C = channels. A weight map such as (1 + 2 W) (detail emphasis) keeps the
/// same normalisation, so the loss scale grows with the mean weight.

#include <cmath>
#include <cstddef>
#include <string>
#include <type_traits>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"

namespace video3dgs::loss {

/// Rows per parallel chunk for the loss kernels (fixed, so results do not depend on the thread count).
inline constexpr std::size_t kLossRowsPerChunk = 8;

namespace detail {
template <class A, class B>
void check_same_size(const A& a, const B& b, const char* what) {
  if (a.width() != b.width() || a.height() != b.height())
    throw option_error("option.size", what,
                       "images differ in size (" + std::to_string(a.width()) + "x" + std::to_string(a.height()) + " vs " +
                           std::to_string(b.width()) + "x" + std::to_string(b.height()) + ")");
}
/// sum_i |x_i - y_i| over [0, n), summed in 16 interleaved lanes (vectorisable; the order depends on
/// n only, so the result is deterministic), lanes then added in order.
template <class Scalar>
[[nodiscard]] Scalar sum_abs_diff(const Scalar* x, const Scalar* y, int n) noexcept {
  constexpr int kLanes = 16;
  Scalar lane[kLanes] = {};
  int i = 0;
  for (; i + kLanes <= n; i += kLanes)
    for (int j = 0; j < kLanes; ++j) lane[j] += std::abs(x[i + j] - y[i + j]);
  for (int j = 0; i < n; ++i, ++j) lane[j] += std::abs(x[i] - y[i]);
  Scalar s = 0;
  for (int j = 0; j < kLanes; ++j) s += lane[j];
  return s;
}

/// out_i += g sign(x_i - y_i), sign(0) = 0.
template <class Scalar>
void add_sign_diff(const Scalar* x, const Scalar* y, Scalar g, Scalar* out, int n) noexcept {
  for (int i = 0; i < n; ++i) {
    const Scalar d = x[i] - y[i];
    out[i] += g * static_cast<Scalar>((d > Scalar(0)) - (d < Scalar(0)));
  }
}

}  // namespace detail

/// Saved by `l1_forward` for `l1_backward`. The images it views must outlive the backward call.
template <class Scalar, int C>
struct L1Context {
  ConstImageView<Scalar, C> x;       ///< the render
  ConstImageView<Scalar, C> y;       ///< the target
  ConstImageView<Scalar, 1> weight;  ///< empty = unweighted
  Scalar value = 0;                  ///< L1 of the last forward
  std::vector<double> partial;       ///< per-chunk sums (reused across calls)
};

/// L1 between render `x` and target `y` (same size), optionally weighted per pixel by `weight`
/// (same size, or empty). Deterministic for any thread count.
template <class Scalar, int C>
Scalar l1_forward(std::type_identity_t<ConstImageView<Scalar, C>> x, std::type_identity_t<ConstImageView<Scalar, C>> y,
                  L1Context<Scalar, C>& ctx, ThreadPool* pool = nullptr,
                  std::type_identity_t<ConstImageView<Scalar, 1>> weight = {}) {
  detail::check_same_size(x, y, "l1");
  if (!weight.empty()) detail::check_same_size(x, weight, "l1 weight");
  if (x.empty()) throw option_error("option.size", "l1", "empty image");
  ctx.x = x;
  ctx.y = y;
  ctx.weight = weight;
  const std::size_t h = static_cast<std::size_t>(x.height());
  const int n = x.width() * C;
  ctx.partial.assign(chunk_count(h, kLossRowsPerChunk), 0.0);
  parallel_for_chunks(pool, h, kLossRowsPerChunk, [&](std::size_t chunk, std::size_t b, std::size_t e) {
    double sum = 0;
    for (std::size_t row = b; row < e; ++row) {
      const Scalar* xr = x.row(static_cast<int>(row));
      const Scalar* yr = y.row(static_cast<int>(row));
      Scalar s = 0;
      if (weight.empty()) {
        s = detail::sum_abs_diff(xr, yr, n);
      } else {
        const Scalar* wr = weight.row(static_cast<int>(row));
        for (int px = 0; px < x.width(); ++px) {
          Scalar a = 0;
          for (int c = 0; c < C; ++c) a += std::abs(xr[px * C + c] - yr[px * C + c]);
          s += wr[px] * a;
        }
      }
      sum += static_cast<double>(s);
    }
    ctx.partial[chunk] = sum;
  });
  double total = 0;
  for (double p : ctx.partial) total += p;
  ctx.value = static_cast<Scalar>(total / (static_cast<double>(x.pixel_count()) * C));
  return ctx.value;
}

/// Adds dL/dx = dL_dl1 * dL1/dx into `dL_dx` (zero it first if it holds nothing else).
template <class Scalar, int C>
void l1_backward(const L1Context<Scalar, C>& ctx, Scalar dL_dl1, std::type_identity_t<ImageView<Scalar, C>> dL_dx,
                 ThreadPool* pool = nullptr) {
  detail::check_same_size(ctx.x, dL_dx, "l1_backward");
  const Scalar g = dL_dl1 / static_cast<Scalar>(static_cast<double>(ctx.x.pixel_count()) * C);
  const int w = ctx.x.width();
  parallel_for_chunks(pool, static_cast<std::size_t>(ctx.x.height()), kLossRowsPerChunk,
                      [&](std::size_t, std::size_t b, std::size_t e) {
                        for (std::size_t row = b; row < e; ++row) {
                          const int r = static_cast<int>(row);
                          const Scalar* xr = ctx.x.row(r);
                          const Scalar* yr = ctx.y.row(r);
                          const Scalar* wr = ctx.weight.empty() ? nullptr : ctx.weight.row(r);
                          Scalar* out = dL_dx.row(r);
                          if (!wr) {
                            detail::add_sign_diff(xr, yr, g, out, w * C);
                            continue;
                          }
                          for (int px = 0; px < w; ++px) {
                            const Scalar gp = g * wr[px];
                            for (int c = 0; c < C; ++c) {
                              const Scalar d = xr[px * C + c] - yr[px * C + c];
                              out[px * C + c] += gp * static_cast<Scalar>((d > Scalar(0)) - (d < Scalar(0)));
                            }
                          }
                        }
                      });
}

}  // namespace video3dgs::loss
