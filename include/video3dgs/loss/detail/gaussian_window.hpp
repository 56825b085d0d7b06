#pragma once
/// @file
/// The normalised 1-D Gaussian taps of the SSIM window. The 2-D window is the outer product g g^T
/// (it sums to 1), so filtering with zero padding,
///   (G * f)(x, y) = sum_{j,k} g[j] g[k] f(x + k - r, y + j - r),  f = 0 outside the image,
/// is a horizontal pass followed by a vertical pass (see ssim_kernels.hpp).

#include <cmath>
#include <cstddef>
#include <vector>

#if defined(__GNUC__) || defined(__clang__) || defined(_MSC_VER)
#define VIDEO3DGS_RESTRICT __restrict
#else
#define VIDEO3DGS_RESTRICT
#endif

namespace video3dgs::loss::detail {

/// g[k] = exp(-(k - r)^2 / (2 sigma^2)) / sum, k = 0..2r (computed in double, then cast).
template <class Scalar>
[[nodiscard]] std::vector<Scalar> gaussian_taps(int radius, double sigma) {
  std::vector<double> g(static_cast<std::size_t>(2 * radius + 1));
  double sum = 0;
  for (int k = -radius; k <= radius; ++k) {
    const double v = std::exp(-static_cast<double>(k * k) / (2.0 * sigma * sigma));
    g[static_cast<std::size_t>(k + radius)] = v;
    sum += v;
  }
  std::vector<Scalar> out(g.size());
  for (std::size_t i = 0; i < g.size(); ++i) out[i] = static_cast<Scalar>(g[i] / sum);
  return out;
}

}  // namespace video3dgs::loss::detail
