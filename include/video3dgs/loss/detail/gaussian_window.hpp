#pragma once
/// @file
/// The normalised 1-D Gaussian taps of the SSIM window and the two passes of a zero-padded separable
/// filter on interleaved rows. The 2-D window is the outer product g g^T (sums to 1), so
///   (G * f)(x, y) = sum_{j,k} g[j] g[k] f(x + k - r, y + j - r),  f = 0 outside the image,
/// is a horizontal pass followed by a vertical pass. Each output is summed in tap order, so results
/// do not depend on how rows are split between threads.

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

/// The valid range [lo, hi) of flat indices i in a row of n = width * channels values for which tap
/// k (offset (k - r) * channels) stays inside the row.
struct TapRange {
  std::ptrdiff_t offset, lo, hi;
};
[[nodiscard]] inline TapRange tap_range(int k, int radius, int channels, std::ptrdiff_t n) noexcept {
  const std::ptrdiff_t off = static_cast<std::ptrdiff_t>(k - radius) * channels;
  const std::ptrdiff_t lo = off < 0 ? -off : 0;
  const std::ptrdiff_t hi = off > 0 ? n - off : n;
  return {off, lo, hi < lo ? lo : hi};
}

/// acc[i] += w * src[i], i in [0, n).
template <class Scalar>
inline void axpy(Scalar* VIDEO3DGS_RESTRICT acc, Scalar w, const Scalar* VIDEO3DGS_RESTRICT src, std::ptrdiff_t n) noexcept {
  for (std::ptrdiff_t i = 0; i < n; ++i) acc[i] += w * src[i];
}

}  // namespace video3dgs::loss::detail

namespace video3dgs::loss::detail {

/// One tap of the horizontal SSIM pass over [lo, hi): accumulates w x, w y, w x x, w y y, w x y
/// (x, y already offset by the tap). Separate non-aliasing pointers let the loop vectorise.
template <class Scalar>
inline void ssim_tap(Scalar w, const Scalar* VIDEO3DGS_RESTRICT x, const Scalar* VIDEO3DGS_RESTRICT y,
                     Scalar* VIDEO3DGS_RESTRICT hx, Scalar* VIDEO3DGS_RESTRICT hy, Scalar* VIDEO3DGS_RESTRICT hxx,
                     Scalar* VIDEO3DGS_RESTRICT hyy, Scalar* VIDEO3DGS_RESTRICT hxy, std::ptrdiff_t lo,
                     std::ptrdiff_t hi) noexcept {
  for (std::ptrdiff_t i = lo; i < hi; ++i) {
    const Scalar xv = x[i], yv = y[i];
    hx[i] += w * xv;
    hy[i] += w * yv;
    hxx[i] += w * (xv * xv);
    hyy[i] += w * (yv * yv);
    hxy[i] += w * (xv * yv);
  }
}

/// One tap of a plain horizontal pass over [lo, hi): dst[i] += w src[i] (src already offset).
template <class Scalar>
inline void tap(Scalar w, const Scalar* VIDEO3DGS_RESTRICT src, Scalar* VIDEO3DGS_RESTRICT dst, std::ptrdiff_t lo,
                std::ptrdiff_t hi) noexcept {
  for (std::ptrdiff_t i = lo; i < hi; ++i) dst[i] += w * src[i];
}

}  // namespace video3dgs::loss::detail
