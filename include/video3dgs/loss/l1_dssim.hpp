#pragma once
/// @file
/// The photometric loss of 3DGS / Video-3DGS: a weighted combination of L1 and D-SSIM,
///
///   L = (1 - lambda) L1_w(x, y) + lambda (1 - SSIM(x, y)),     lambda = 0.2 by default,
///
/// where L1_w optionally weights each pixel (e.g. w = 1 + 2 W for the detail-emphasised merged
/// render; SSIM is never weighted). Backward (chain rule through both terms):
///
///   dL/dx = dL_dout [ (1 - lambda) dL1_w/dx - lambda dSSIM/dx ].
///
///     loss::L1DssimContext<float, 3> ctx;                  // reuse across iterations
///     float L = loss::l1_dssim_forward(render, frame, ctx, &pool);
///     grad.fill(0);
///     loss::l1_dssim_backward(ctx, 1.0f, grad.view(), &pool);
///
/// Renders against one target may share its SSIM statistics (`SsimTarget`, ssim.hpp): pass the filled
/// target instead of y; the value and gradient are bit-identical.

#include <string>
#include <type_traits>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/loss/l1.hpp"
#include "video3dgs/loss/ssim.hpp"

namespace video3dgs::loss {

struct L1DssimOptions {
  double lambda_dssim = 0.2;  ///< weight of D-SSIM; L1 gets 1 - lambda_dssim
  SsimOptions ssim{};
};

/// Saved state of `l1_dssim_forward` (both terms' contexts and values).
template <class Scalar, int C>
struct L1DssimContext {
  explicit L1DssimContext(L1DssimOptions opts = {}) : options(opts), ssim(opts.ssim) {}

  L1DssimOptions options;
  L1Context<Scalar, C> l1;
  SsimContext<Scalar, C> ssim;
  Scalar l1_value = 0;    ///< L1_w of the last forward
  Scalar ssim_value = 0;  ///< SSIM of the last forward
  Scalar value = 0;       ///< L of the last forward
};

namespace detail {
template <class Scalar, int C>
Scalar l1_dssim_run(ConstImageView<Scalar, C> x, ConstImageView<Scalar, C> y, L1DssimContext<Scalar, C>& ctx, ThreadPool* pool,
                    ConstImageView<Scalar, 1> weight, const SsimTarget<Scalar, C>* target) {
  const double lambda = ctx.options.lambda_dssim;
  if (!(lambda >= 0.0 && lambda <= 1.0)) throw option_error("option.range", "lambda_dssim", "must be in [0, 1]");
  if (target && target->y.empty()) throw option_error("option.ssim", "target", "an SsimTarget needs fill_ssim_target before use");
  ctx.ssim.options = ctx.options.ssim;
  ctx.l1_value = l1_forward<Scalar, C>(x, y, ctx.l1, pool, weight);
  ctx.ssim_value = target ? ssim_forward<Scalar, C>(x, *target, ctx.ssim, pool) : ssim_forward<Scalar, C>(x, y, ctx.ssim, pool);
  ctx.value = static_cast<Scalar>((1.0 - lambda) * static_cast<double>(ctx.l1_value) +
                                  lambda * (1.0 - static_cast<double>(ctx.ssim_value)));
  return ctx.value;
}
}  // namespace detail

/// L = (1 - lambda) L1_w + lambda (1 - SSIM) of render `x` against target `y`; `weight` (1 channel,
/// same size, or empty) weights the L1 term per pixel.
template <class Scalar, int C>
Scalar l1_dssim_forward(std::type_identity_t<ConstImageView<Scalar, C>> x, std::type_identity_t<ConstImageView<Scalar, C>> y,
                        L1DssimContext<Scalar, C>& ctx, ThreadPool* pool = nullptr,
                        std::type_identity_t<ConstImageView<Scalar, 1>> weight = {}) {
  return detail::l1_dssim_run<Scalar, C>(x, y, ctx, pool, weight, nullptr);
}

/// The same L against the target of `target` (filled by `fill_ssim_target` for x's size and
/// ctx.options.ssim's window): bit-identical, without filtering the target again.
/// @throws as the `ssim_forward` overload (ssim.hpp)
template <class Scalar, int C>
Scalar l1_dssim_forward(std::type_identity_t<ConstImageView<Scalar, C>> x, const SsimTarget<Scalar, C>& target,
                        L1DssimContext<Scalar, C>& ctx, ThreadPool* pool = nullptr,
                        std::type_identity_t<ConstImageView<Scalar, 1>> weight = {}) {
  return detail::l1_dssim_run<Scalar, C>(x, target.y, ctx, pool, weight, &target);
}

/// Adds dL/dx = dL_dout * dL/dx into `dL_dx` (zero it first if it holds nothing else).
template <class Scalar, int C>
void l1_dssim_backward(L1DssimContext<Scalar, C>& ctx, Scalar dL_dout, std::type_identity_t<ImageView<Scalar, C>> dL_dx,
                       ThreadPool* pool = nullptr) {
  const Scalar lambda = static_cast<Scalar>(ctx.options.lambda_dssim);
  l1_backward<Scalar, C>(ctx.l1, (Scalar(1) - lambda) * dL_dout, dL_dx, pool);
  ssim_backward<Scalar, C>(ctx.ssim, -lambda * dL_dout, dL_dx, pool);
}

}  // namespace video3dgs::loss
