#pragma once
/// @file
/// Mean squared error and PSNR (data range R, default 1):
///
///   MSE  = 1/(N C) sum_{p,c} (a_pc - b_pc)^2
///   PSNR = 10 log10(R^2 / MSE)   [dB];   +infinity when MSE == 0 (identical images).
///
/// Sums run in double over fixed row chunks reduced in order: identical for any thread count.

#include <cmath>
#include <cstddef>
#include <limits>
#include <string>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"

namespace video3dgs::metrics {

/// Mean squared error over all pixels and channels (images of the same size, not empty).
template <class Scalar, int C>
[[nodiscard]] double mse(ConstImageView<Scalar, C> a, ConstImageView<Scalar, C> b, ThreadPool* pool = nullptr) {
  if (a.width() != b.width() || a.height() != b.height())
    throw option_error("option.size", "mse", "images differ in size (" + std::to_string(a.width()) + "x" + std::to_string(a.height()) + " vs " +
                                                 std::to_string(b.width()) + "x" + std::to_string(b.height()) + ")");
  if (a.empty()) throw option_error("option.size", "mse", "empty image");
  constexpr std::size_t kRows = 8;
  const std::size_t h = static_cast<std::size_t>(a.height());
  std::vector<double> partial(chunk_count(h, kRows), 0.0);
  const int n = a.width() * C;
  parallel_for_chunks(pool, h, kRows, [&](std::size_t chunk, std::size_t begin, std::size_t end) {
    double s = 0;
    for (std::size_t y = begin; y < end; ++y) {
      const Scalar* ar = a.row(static_cast<int>(y));
      const Scalar* br = b.row(static_cast<int>(y));
      for (int i = 0; i < n; ++i) {
        const double d = static_cast<double>(ar[i]) - static_cast<double>(br[i]);
        s += d * d;
      }
    }
    partial[chunk] = s;
  });
  double total = 0;
  for (double p : partial) total += p;
  return total / (static_cast<double>(a.pixel_count()) * C);
}

/// PSNR in dB for data range `range` (1 for images in [0, 1]); +infinity for identical images.
template <class Scalar, int C>
[[nodiscard]] double psnr(ConstImageView<Scalar, C> a, ConstImageView<Scalar, C> b, ThreadPool* pool = nullptr,
                          double range = 1.0) {
  const double e = mse<Scalar, C>(a, b, pool);
  if (e == 0.0) return std::numeric_limits<double>::infinity();
  return 10.0 * std::log10(range * range / e);
}

/// Overloads for owning images.
template <class Scalar, int C>
[[nodiscard]] double mse(const Image<Scalar, C>& a, const Image<Scalar, C>& b, ThreadPool* pool = nullptr) {
  return mse<Scalar, C>(a.view(), b.view(), pool);
}
template <class Scalar, int C>
[[nodiscard]] double psnr(const Image<Scalar, C>& a, const Image<Scalar, C>& b, ThreadPool* pool = nullptr,
                          double range = 1.0) {
  return psnr<Scalar, C>(a.view(), b.view(), pool, range);
}

}  // namespace video3dgs::metrics
