#pragma once
/// @file
/// `SplitLrAdam`: the Adam policy (optim/policies.hpp) with a second learning rate for the trailing
/// columns of each row. A Gaussian's SH coefficients are one row of 3K scalars (DC first, 3 values);
/// 3DGS trains the DC band at lr and the other bands at lr / 20. Element j of the group's buffer uses
///
///     lr_j = lr                if (j mod row_width) <  lead
///     lr_j = lr * tail_scale   otherwise
///
/// and Adam's update (`Adam::Step`) otherwise unchanged; with tail_scale = 1 it is plain Adam. The
/// optimizer passes the position of each range (`PositionalOptimizerPolicy`), so nothing needs
/// re-pointing after rows are edited.
///
/// `active` (0 = all) columns of each row are stepped and the others left as they are. For a column
/// whose gradient is exactly 0 and whose two moments are 0 (an SH band that has never been active:
/// the trainer raises the active degree and never lowers it) Adam's step is m = 0, v = 0,
/// p -= step * 0 / (0 + eps), which leaves p's bits unchanged: skipping it gives the same result for
/// less memory traffic. A column with a nonzero moment would instead stop moving along it.

#include <algorithm>
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
    std::size_t row_width = 1;
    std::size_t lead = 1;        ///< leading columns at lr
    double tail_scale = 1;       ///< the others at lr * tail_scale
    std::size_t active = 0;      ///< leading columns stepped (0 = all; see the file comment)
  };
  /// The two steps' constants of one group step (`PreparedOptimizerPolicy`), for any number of ranges.
  template <class Scalar>
  struct Prepared {
    const Hyper& h;
    Adam::Step<Scalar> lead, tail;
    Prepared(const Hyper& hyper, double lr, std::uint64_t k) : h(hyper), lead(hyper, lr, k), tail(hyper, lr * hyper.tail_scale, k) {}
    /// n entries starting at index `first` of the group's buffer.
    void operator()(Scalar* p, const Scalar* g, const std::array<Scalar*, kMoments>& m, std::size_t n, std::size_t first) const {
      const std::size_t active = h.active == 0 ? h.row_width : std::min(h.active, h.row_width);
      if (active == h.row_width && (h.tail_scale == 1.0 || h.row_width <= h.lead)) {
        lead.apply(p, g, m[0], m[1], n);
        return;
      }
      std::size_t col = first % h.row_width;
      for (std::size_t i = 0; i < n;) {
        const bool skipped = col >= active, is_lead = col < h.lead;
        const std::size_t end = skipped ? h.row_width : is_lead ? std::min(h.lead, active) : active;
        const std::size_t run = std::min(n - i, end - col);
        if (!skipped) (is_lead || h.tail_scale == 1.0 ? lead : tail).apply(p + i, g + i, m[0] + i, m[1] + i, run);
        i += run;
        col = (col + run) % h.row_width;
      }
    }
  };
  /// One step on n entries starting at index `first` of the group's buffer.
  template <class Scalar>
  static void update(const Hyper& h, double lr, std::uint64_t k, Scalar* p, const Scalar* g,
                     const std::array<Scalar*, kMoments>& m, std::size_t n, std::size_t first) {
    Prepared<Scalar>(h, lr, k)(p, g, m, n, first);
  }
};

}  // namespace video3dgs
