#pragma once
/// @file
/// `SplitLrAdam`: the Adam policy (optim/policies.hpp) with a second learning rate for the trailing
/// columns of each row. A Gaussian's SH coefficients are one row of 3K scalars (DC first, 3 values);
/// 3DGS trains the DC band at lr and the other bands at lr / 20. With `Hyper::base` pointing at the
/// group's buffer, element j of the buffer uses
///
///     lr_j = lr                if (j mod row_width) <  lead
///     lr_j = lr * tail_scale   otherwise
///
/// and the Adam update of policies.hpp otherwise unchanged. With `base == nullptr` it is plain Adam.
/// After a row edit the caller re-points `base` at the (re-bound) buffer.

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>

#include "video3dgs/optim/policies.hpp"

namespace video3dgs {

struct SplitLrAdam {
  static constexpr int kMoments = 2;
  static constexpr const char* name = "adam_split_lr";
  struct Hyper : Adam::Hyper {  ///< Adam's beta1, beta2, eps and:
    const void* base = nullptr;  ///< start of the group's (single) buffer; null = plain Adam
    std::size_t row_width = 1;
    std::size_t lead = 1;        ///< leading columns at lr
    double tail_scale = 1;       ///< the others at lr * tail_scale
  };
  template <class Scalar>
  static void update(const Hyper& h, double lr, std::uint64_t k, Scalar* p, const Scalar* g,
                     const std::array<Scalar*, kMoments>& m, std::size_t n) {
    if (h.base == nullptr || h.tail_scale == 1.0 || h.row_width <= h.lead) {
      Adam::update<Scalar>(h, lr, k, p, g, m, n);
      return;
    }
    const double bc1 = 1 - std::pow(h.beta1, double(k));
    const double bc2 = 1 - std::pow(h.beta2, double(k));
    const Scalar b1 = Scalar(h.beta1), b2 = Scalar(h.beta2);
    const Scalar step_lead = Scalar(lr / bc1), step_tail = Scalar(lr * h.tail_scale / bc1);
    const Scalar inv_sqrt_bc2 = Scalar(1 / std::sqrt(bc2));
    const Scalar eps = Scalar(h.eps);
    std::size_t col = static_cast<std::size_t>(p - static_cast<const Scalar*>(h.base)) % h.row_width;
    Scalar* m1 = m[0];
    Scalar* m2 = m[1];
    for (std::size_t i = 0; i < n; ++i) {
      const Scalar gi = g[i];
      m1[i] = b1 * m1[i] + (Scalar(1) - b1) * gi;
      m2[i] = b2 * m2[i] + (Scalar(1) - b2) * gi * gi;
      const Scalar step = col < h.lead ? step_lead : step_tail;
      p[i] -= step * m1[i] / (std::sqrt(m2[i]) * inv_sqrt_bc2 + eps);
      if (++col == h.row_width) col = 0;
    }
  }
};

}  // namespace video3dgs
