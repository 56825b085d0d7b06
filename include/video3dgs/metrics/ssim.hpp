#pragma once
/// @file
/// SSIM as a metric: the same definition as the loss (loss/ssim.hpp: 11x11 Gaussian window,
/// sigma 1.5, C1 = 0.01^2, C2 = 0.03^2, zero padding, mean over all pixels and channels), computed
/// in double whatever the input scalar, without saving anything for a backward pass.

#include <type_traits>

#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/loss/ssim.hpp"

namespace video3dgs::metrics {

/// SSIM of `a` against `b` (same size), reusing `ctx` (no allocation once it has seen the size).
template <int C>
[[nodiscard]] double ssim(ConstImageView<double, C> a, ConstImageView<double, C> b, loss::SsimContext<double, C>& ctx,
                          ThreadPool* pool = nullptr) {
  return loss::ssim_value<double, C>(a, b, ctx, pool);
}

/// SSIM of `a` against `b` (same size); float inputs are converted to double first.
template <class Scalar, int C>
[[nodiscard]] double ssim(ConstImageView<Scalar, C> a, ConstImageView<Scalar, C> b, ThreadPool* pool = nullptr,
                          loss::SsimOptions options = {}) {
  loss::SsimContext<double, C> ctx(options);
  if constexpr (std::is_same_v<Scalar, double>) {
    return loss::ssim_value<double, C>(a, b, ctx, pool);
  } else {
    const Image<double, C> ad = Image<Scalar, C>::from_view(a).template cast<double>();
    const Image<double, C> bd = Image<Scalar, C>::from_view(b).template cast<double>();
    return loss::ssim_value<double, C>(ad.view(), bd.view(), ctx, pool);
  }
}

/// Overload for owning images.
template <class Scalar, int C>
[[nodiscard]] double ssim(const Image<Scalar, C>& a, const Image<Scalar, C>& b, ThreadPool* pool = nullptr,
                          loss::SsimOptions options = {}) {
  return ssim<Scalar, C>(a.view(), b.view(), pool, options);
}

}  // namespace video3dgs::metrics
