#pragma once
/// @file
/// Per-pixel merge of the foreground and background renders by a learnable alpha map.
///
///   A = sigmoid(a)                       a: one logit per pixel (a = 0 gives the reference init 0.5)
///   I = A * F + (1 - A) * B              per channel
///
/// Backward (g = dL/dI):
///   dL/dF = A g,   dL/dB = (1 - A) g,   dL/da = A (1 - A) sum_c g_c (F_c - B_c)
///
/// The reference stores A directly; a logit keeps A in (0, 1) under any learning rate, so the merge
/// can never leave the convex hull of the two renders.

#include <cmath>

#include "video3dgs/core/assert.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"

namespace video3dgs {

/// Numerically safe logistic function (no overflow for |x| large).
template <class Scalar>
[[nodiscard]] inline Scalar stable_sigmoid(Scalar x) noexcept {
  if (x >= Scalar(0)) return Scalar(1) / (Scalar(1) + std::exp(-x));
  const Scalar e = std::exp(x);
  return e / (Scalar(1) + e);
}

/// Forward: out = A F + (1 - A) B with A = sigmoid(logit). All images share width and height.
template <class Scalar, int C>
void alpha_merge_forward(ConstImageView<Scalar, C> frg, ConstImageView<Scalar, C> bkg, ConstImageView<Scalar, 1> logit,
                         ImageView<Scalar, C> out, ThreadPool* pool = nullptr) {
  VIDEO3DGS_ASSERT(frg.width() == bkg.width() && frg.height() == bkg.height() && logit.width() == frg.width() &&
                       logit.height() == frg.height() && out.width() == frg.width() && out.height() == frg.height(),
                   "alpha_merge_forward: size mismatch");
  parallel_for(pool, static_cast<std::size_t>(frg.height()), [&](std::size_t yy) {
    const int y = static_cast<int>(yy);
    const Scalar* f = frg.row(y);
    const Scalar* b = bkg.row(y);
    const Scalar* l = logit.row(y);
    Scalar* o = out.row(y);
    for (int x = 0; x < frg.width(); ++x) {
      const Scalar a = stable_sigmoid(l[x]);
      for (int c = 0; c < C; ++c) o[x * C + c] = a * f[x * C + c] + (Scalar(1) - a) * b[x * C + c];
    }
  }, 8);
}

/// Backward. Gradients are written into dL_dfrg, dL_dbkg and dL_dlogit, or added to them if
/// `accumulate` (the autodiff tape's convention); any of them may be an empty view to skip it.
template <class Scalar, int C>
void alpha_merge_backward(ConstImageView<Scalar, C> frg, ConstImageView<Scalar, C> bkg, ConstImageView<Scalar, 1> logit,
                          ConstImageView<Scalar, C> dL_dout, ImageView<Scalar, C> dL_dfrg, ImageView<Scalar, C> dL_dbkg,
                          ImageView<Scalar, 1> dL_dlogit, ThreadPool* pool = nullptr, bool accumulate = false) {
  VIDEO3DGS_ASSERT(dL_dout.width() == frg.width() && dL_dout.height() == frg.height(), "alpha_merge_backward: size mismatch");
  const auto put = [accumulate](Scalar& dst, Scalar v) {
    if (accumulate)
      dst += v;
    else
      dst = v;
  };
  parallel_for(pool, static_cast<std::size_t>(frg.height()), [&](std::size_t yy) {
    const int y = static_cast<int>(yy);
    const Scalar* f = frg.row(y);
    const Scalar* b = bkg.row(y);
    const Scalar* l = logit.row(y);
    const Scalar* g = dL_dout.row(y);
    for (int x = 0; x < frg.width(); ++x) {
      const Scalar a = stable_sigmoid(l[x]);
      Scalar da = 0;
      for (int c = 0; c < C; ++c) {
        const Scalar gc = g[x * C + c];
        if (!dL_dfrg.empty()) put(dL_dfrg.row(y)[x * C + c], a * gc);
        if (!dL_dbkg.empty()) put(dL_dbkg.row(y)[x * C + c], (Scalar(1) - a) * gc);
        da += gc * (f[x * C + c] - b[x * C + c]);
      }
      if (!dL_dlogit.empty()) put(dL_dlogit.row(y)[x], a * (Scalar(1) - a) * da);
    }
  }, 8);
}

}  // namespace video3dgs
