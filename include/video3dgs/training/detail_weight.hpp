#pragma once
/// @file
/// Detail-emphasis weights for the merged L1 term (optional, docs/method.md):
///
///   B   = bilateral(I)   (window (2r+1)^2, spatial sigma_s, range sigma_r on the RGB distance)
///   W_p = mean_c |I_pc - B_pc| / max_q mean_c |I_qc - B_qc|      in [0, 1] (0 where the residual < 1e-5)
///   w_p = 1 + gain W_p
///
/// Computed once per frame per clip (not per iteration); rows in parallel, each pixel on its own,
/// so the map does not depend on the thread count.

#include <algorithm>
#include <cmath>
#include <cstddef>

#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"

namespace video3dgs {

struct BilateralOptions {
  int radius = 3;
  double sigma_space = 2.0;  ///< pixels
  double sigma_range = 0.1;  ///< intensity units (images in [0, 1])
};

/// The weight map w = 1 + gain W of `img` (see the file comment).
template <class Scalar>
[[nodiscard]] Image<Scalar, 1> detail_weight_map(const Image<Scalar, 3>& img, double gain = 2.0, ThreadPool* pool = nullptr,
                                                 const BilateralOptions& o = {}) {
  const int W = img.width(), H = img.height(), r = std::max(0, o.radius);
  Image<Scalar, 1> d(W, H);
  const double is2 = 1.0 / (2 * o.sigma_space * o.sigma_space), ir2 = 1.0 / (2 * o.sigma_range * o.sigma_range);
  parallel_for(pool, std::size_t(H), [&](std::size_t yy) {
    const int y = int(yy);
    for (int x = 0; x < W; ++x) {
      const Scalar* c = img.pixel(x, y);
      double acc[3] = {0, 0, 0}, wsum = 0;
      for (int dy = -r; dy <= r; ++dy)
        for (int dx = -r; dx <= r; ++dx) {
          const int xx = x + dx, yq = y + dy;
          if (xx < 0 || yq < 0 || xx >= W || yq >= H) continue;
          const Scalar* q = img.pixel(xx, yq);
          double dr = 0;
          for (int k = 0; k < 3; ++k) dr += double(q[k] - c[k]) * double(q[k] - c[k]);
          const double w = std::exp(-(dx * dx + dy * dy) * is2 - dr * ir2);
          for (int k = 0; k < 3; ++k) acc[k] += w * double(q[k]);
          wsum += w;
        }
      double e = 0;
      for (int k = 0; k < 3; ++k) e += std::abs(double(c[k]) - acc[k] / wsum);
      d(x, y) = Scalar(e / 3);
    }
  }, 4);
  // Residuals below kFlat are rounding noise of the filter (a flat image): W = 0 there.
  constexpr Scalar kFlat = Scalar(1e-5);
  Scalar mx = 0;
  for (std::size_t i = 0; i < d.size(); ++i) mx = std::max(mx, d.data()[i]);
  for (std::size_t i = 0; i < d.size(); ++i) {
    const Scalar v = d.data()[i];
    d.data()[i] = Scalar(1) + Scalar(gain) * (mx > kFlat && v > kFlat ? v / mx : Scalar(0));
  }
  return d;
}

}  // namespace video3dgs
