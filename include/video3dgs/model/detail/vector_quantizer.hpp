#pragma once
/// @file
/// Deterministic k-means vector quantisation (the SH rest bands of the compact model format,
/// model/compact_io.hpp). Points are n rows of `dim` floats.
///
///   n <= K:  the codebook is the points themselves (index i -> row i).
///   n >  K:  Lloyd's algorithm on a sample of S = min(n, max(sample, K)) rows, row j of the sample
///            being point floor(j n / S); codeword k starts as sample row floor(k S / K). An iteration
///            assigns every sample row to its nearest codeword and moves each codeword to the mean of
///            its rows (summed in double, in row order); a codeword left without rows takes the sample
///            row farthest from its own codeword (the next farthest for the next empty one). After
///            `iterations` such steps the codewords are rounded to half floats (how the file stores
///            them) and every point gets the index of its nearest rounded codeword.
///
/// Nearest = smallest |c|^2 - 2 x.c, computed in float by blocks of 64 rows x all codewords (Eigen's
/// matrix product) - near-ties may resolve either way; the lowest index wins an exact tie. Blocks and
/// chunks depend on n only, so the result is bit-identical for any thread count. Cost: about
/// 2 n K dim flops per assignment (S for each iteration, n once).

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <numeric>
#include <vector>

#include <Eigen/Core>

#include "video3dgs/core/parallel.hpp"
#include "video3dgs/model/detail/compact_codec.hpp"

namespace video3dgs::detail {

struct VectorQuantizerOptions {
  int codebook = 4096;       ///< K, the largest number of codewords
  int iterations = 8;        ///< Lloyd iterations on the sample
  std::size_t sample = 32768;///< rows the codebook is fitted to (at least K are used)
};

/// A fitted codebook: `codewords` (size() x dim, row-major, values exactly representable as half
/// floats) and one index per point.
struct VectorCodebook {
  int dim = 0;
  std::vector<float> codewords;
  std::vector<std::uint32_t> index;
  [[nodiscard]] std::size_t size() const noexcept { return dim > 0 ? codewords.size() / std::size_t(dim) : 0; }
};

/// index[i] = the nearest codeword of row i of x (n rows); dist2[i] (if not null) = its squared distance.
inline void assign_nearest(const float* x, std::size_t n, int dim, const std::vector<float>& codewords, std::uint32_t* index,
                           float* dist2, ThreadPool* pool) {
  using RowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const auto K = Eigen::Index(codewords.size() / std::size_t(dim));
  const Eigen::Map<const RowMatrix> C(codewords.data(), K, dim);
  const Eigen::VectorXf cn = C.rowwise().squaredNorm();
  constexpr std::size_t kBlock = 64;
  parallel_for_chunks(pool, n, 16 * kBlock, [&](std::size_t, std::size_t b, std::size_t e) {
    RowMatrix G;
    for (std::size_t s = b; s < e; s += kBlock) {
      const auto m = Eigen::Index(std::min(kBlock, e - s));
      const Eigen::Map<const RowMatrix> X(x + s * std::size_t(dim), m, dim);
      G.noalias() = X * C.transpose();
      for (Eigen::Index r = 0; r < m; ++r) {
        Eigen::Index best = 0;
        float bd = cn[0] - 2 * G(r, 0);
        for (Eigen::Index k = 1; k < K; ++k) {
          const float d = cn[k] - 2 * G(r, k);
          if (d < bd) bd = d, best = k;
        }
        index[s + std::size_t(r)] = std::uint32_t(best);
        if (dist2) dist2[s + std::size_t(r)] = std::max(0.0f, bd + X.row(r).squaredNorm());
      }
    }
  });
}

/// Rounds every value to the nearest half float.
inline void round_to_half(std::vector<float>& v) {
  for (float& f : v) f = half_to_float(float_to_half(f));
}

/// Fits a codebook to n rows of `dim` floats (see the file comment).
[[nodiscard]] inline VectorCodebook fit_vector_codebook(const std::vector<float>& x, std::size_t n, int dim,
                                                        const VectorQuantizerOptions& o, ThreadPool* pool) {
  VectorCodebook cb;
  cb.dim = dim;
  cb.index.resize(n);
  const std::size_t D = std::size_t(dim), K = std::size_t(std::max(o.codebook, 1));
  if (n <= K) {
    cb.codewords.assign(x.begin(), x.begin() + std::ptrdiff_t(n * D));
    round_to_half(cb.codewords);
    std::iota(cb.index.begin(), cb.index.end(), 0u);
    return cb;
  }
  const std::size_t S = std::min(n, std::max(o.sample, K));
  std::vector<float> sample(S * D);
  for (std::size_t j = 0; j < S; ++j) {
    const std::size_t i = j * (n / S) + j * (n % S) / S;  // floor(j n / S) without overflowing j n
    std::copy_n(x.begin() + std::ptrdiff_t(i * D), D, sample.begin() + std::ptrdiff_t(j * D));
  }
  cb.codewords.resize(K * D);
  for (std::size_t k = 0; k < K; ++k)
    std::copy_n(sample.begin() + std::ptrdiff_t((k * S / K) * D), D, cb.codewords.begin() + std::ptrdiff_t(k * D));

  std::vector<std::uint32_t> idx(S);
  std::vector<float> dist(S);
  std::vector<double> sums(K * D);
  std::vector<std::size_t> count(K), order(S);
  for (int it = 0; it < o.iterations; ++it) {
    assign_nearest(sample.data(), S, dim, cb.codewords, idx.data(), dist.data(), pool);
    std::fill(sums.begin(), sums.end(), 0.0);
    std::fill(count.begin(), count.end(), std::size_t(0));
    for (std::size_t j = 0; j < S; ++j) {
      ++count[idx[j]];
      for (std::size_t d = 0; d < D; ++d) sums[idx[j] * D + d] += double(sample[j * D + d]);
    }
    std::iota(order.begin(), order.end(), std::size_t(0));
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return dist[a] > dist[b]; });
    std::size_t next_far = 0;
    for (std::size_t k = 0; k < K; ++k) {
      float* c = cb.codewords.data() + k * D;
      if (count[k] > 0) {
        for (std::size_t d = 0; d < D; ++d) c[d] = float(sums[k * D + d] / double(count[k]));
      } else {
        std::copy_n(sample.begin() + std::ptrdiff_t(order[next_far % S] * D), D, c);
        ++next_far;
      }
    }
  }
  round_to_half(cb.codewords);
  assign_nearest(x.data(), n, dim, cb.codewords, cb.index.data(), nullptr, pool);
  return cb;
}

}  // namespace video3dgs::detail
