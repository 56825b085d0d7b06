#pragma once
/// @file
/// Optimizer policies (`OptimizerPolicy`): per-element update rules with their moment buffers.
///
/// Adam (Kingma & Ba 2015, Alg. 1; the PyTorch form used by 3DGS), step k = 1, 2, ...:
///
///     m <- b1 m + (1 - b1) g,   v <- b2 v + (1 - b2) g^2
///     p <- p - lr (m / (1 - b1^k)) / (sqrt(v / (1 - b2^k)) + eps)
///
/// Sgd with momentum mu (heavy ball, PyTorch form): b <- mu b + g (b = g at k = 1), p <- p - lr b.

#include <array>
#include <cmath>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <string>
#include <type_traits>
#include <utility>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/isa.hpp"

#if VIDEO3DGS_ISA_DISPATCH
#include <immintrin.h>
#endif

namespace video3dgs {

namespace detail {
#if VIDEO3DGS_ISA_DISPATCH
/// Adam's update (`Adam::Step::apply`) of the first n - n % 8 floats in 8-lane AVX2 blocks, with the
/// scalar loop's operations in its order and no FMA: the same bits. Returns how many it did.
__attribute__((target("avx2"))) inline std::size_t adam_apply_avx2(float* p, const float* g, float* m1, float* m2, std::size_t n, float b1,
                                                                   float c1, float b2, float c2, float step, float inv_sqrt_bc2,
                                                                   float eps) noexcept {
  const __m256 vb1 = _mm256_set1_ps(b1), vc1 = _mm256_set1_ps(c1), vb2 = _mm256_set1_ps(b2), vc2 = _mm256_set1_ps(c2);
  const __m256 vstep = _mm256_set1_ps(step), vinv = _mm256_set1_ps(inv_sqrt_bc2), veps = _mm256_set1_ps(eps);
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    const __m256 gi = _mm256_loadu_ps(g + i);
    const __m256 a = _mm256_add_ps(_mm256_mul_ps(vb1, _mm256_loadu_ps(m1 + i)), _mm256_mul_ps(vc1, gi));
    const __m256 v = _mm256_add_ps(_mm256_mul_ps(vb2, _mm256_loadu_ps(m2 + i)), _mm256_mul_ps(_mm256_mul_ps(vc2, gi), gi));
    _mm256_storeu_ps(m1 + i, a);
    _mm256_storeu_ps(m2 + i, v);
    const __m256 den = _mm256_add_ps(_mm256_mul_ps(_mm256_sqrt_ps(v), vinv), veps);
    _mm256_storeu_ps(p + i, _mm256_sub_ps(_mm256_loadu_ps(p + i), _mm256_div_ps(_mm256_mul_ps(vstep, a), den)));
  }
  return i;
}
#endif
}  // namespace detail

/// What an optimizer policy provides: a number of moment buffers (each the size of the parameters),
/// per-group hyperparameters, and an elementwise update for one contiguous range. A policy whose rule
/// depends on the position inside the group's buffer (a learning rate per column) may instead take
/// one more argument, `first`: the index of p[0] in the group's buffer (`PositionalOptimizerPolicy`).
template <class P, class Scalar>
concept OptimizerPolicy = requires(const typename P::Hyper& h, double lr, std::uint64_t k, Scalar* p, const Scalar* g,
                                   const std::array<Scalar*, P::kMoments>& m, std::size_t n) {
  { P::kMoments } -> std::convertible_to<int>;
  { P::name } -> std::convertible_to<const char*>;
  P::template update<Scalar>(h, lr, k, p, g, m, n);
};

template <class P, class Scalar>
concept PositionalOptimizerPolicy = requires(const typename P::Hyper& h, double lr, std::uint64_t k, Scalar* p, const Scalar* g,
                                             const std::array<Scalar*, P::kMoments>& m, std::size_t n, std::size_t first) {
  { P::kMoments } -> std::convertible_to<int>;
  { P::name } -> std::convertible_to<const char*>;
  P::template update<Scalar>(h, lr, k, p, g, m, n, first);
};

/// Optional, for speed: a policy whose per-step constants cost more than a few elements' updates
/// (Adam's bias corrections: two pow) may provide `Prepared<Scalar>`, built once per group step from
/// (hyper, lr, k) and then applied to any number of ranges, `prepared(p, g, m, n, first)`, with the
/// same result as `update` on each range. The optimizer then builds it once per group segment and step.
template <class P, class Scalar>
concept PreparedOptimizerPolicy = requires(const typename P::Hyper& h, double lr, std::uint64_t k, Scalar* p, const Scalar* g,
                                           const std::array<Scalar*, P::kMoments>& m, std::size_t n, std::size_t first) {
  requires std::constructible_from<typename P::template Prepared<Scalar>, const typename P::Hyper&, double, std::uint64_t>;
  std::declval<const typename P::template Prepared<Scalar>&>()(p, g, m, n, first);
};

struct Adam {
  static constexpr int kMoments = 2;
  static constexpr const char* name = "adam";
  struct Hyper {
    double beta1 = 0.9;
    double beta2 = 0.999;
    double eps = 1e-15;  ///< the 3DGS value (PyTorch's default is 1e-8)
    /// The update's instruction set for float (core/isa.hpp): `portable` or `avx2` (`automatic`: avx2
    /// where the CPU has it). The same bits for every choice; one this CPU or build lacks is refused.
    Isa simd = Isa::automatic;
  };
  /// The constants of step k at learning rate lr, applied to any number of ranges.
  template <class Scalar>
  struct Step {
    Scalar b1, b2, step, inv_sqrt_bc2, eps;
    bool avx2 = false;  ///< float entries in AVX2 blocks (Hyper::simd)
    /// @throws option_error `option.optimizer` (`simd`) for an instruction set this CPU or build lacks
    Step(const Hyper& h, double lr, std::uint64_t k)
        : b1(Scalar(h.beta1)), b2(Scalar(h.beta2)), step(Scalar(lr / (1 - std::pow(h.beta1, double(k))))),
          inv_sqrt_bc2(Scalar(1 / std::sqrt(1 - std::pow(h.beta2, double(k))))), eps(Scalar(h.eps)) {
      if (h.simd == Isa::avx512 || !isa_supported(h.simd))
        throw option_error("option.optimizer", "simd", std::string("no ") + isa_name(h.simd) + " copy of Adam's update for this build and CPU");
      avx2 = std::is_same_v<Scalar, float> && resolve_isa(h.simd, {Isa::avx2}) == Isa::avx2;
    }
    /// The update of the file comment on n entries (m1, m2: the two moments of the same entries).
    void apply(Scalar* p, const Scalar* g, Scalar* m1, Scalar* m2, std::size_t n) const {
      std::size_t i = 0;
#if VIDEO3DGS_ISA_DISPATCH
      if constexpr (std::is_same_v<Scalar, float>)
        if (avx2) i = detail::adam_apply_avx2(p, g, m1, m2, n, b1, Scalar(1) - b1, b2, Scalar(1) - b2, step, inv_sqrt_bc2, eps);
#endif
      for (; i < n; ++i) {
        const Scalar gi = g[i];
        m1[i] = b1 * m1[i] + (Scalar(1) - b1) * gi;
        m2[i] = b2 * m2[i] + (Scalar(1) - b2) * gi * gi;
        p[i] -= step * m1[i] / (std::sqrt(m2[i]) * inv_sqrt_bc2 + eps);
      }
    }
  };
  /// `PreparedOptimizerPolicy`: the constants once, any number of ranges.
  template <class Scalar>
  struct Prepared : Step<Scalar> {
    using Step<Scalar>::Step;
    void operator()(Scalar* p, const Scalar* g, const std::array<Scalar*, kMoments>& m, std::size_t n, std::size_t) const {
      this->apply(p, g, m[0], m[1], n);
    }
  };
  /// One Adam step (k >= 1) on n entries.
  template <class Scalar>
  static void update(const Hyper& h, double lr, std::uint64_t k, Scalar* p, const Scalar* g,
                     const std::array<Scalar*, kMoments>& m, std::size_t n) {
    Step<Scalar>(h, lr, k).apply(p, g, m[0], m[1], n);
  }
};

struct Sgd {
  static constexpr int kMoments = 1;
  static constexpr const char* name = "sgd";
  struct Hyper {
    double momentum = 0;
  };
  template <class Scalar>
  static void update(const Hyper& h, double lr, std::uint64_t k, Scalar* p, const Scalar* g,
                     const std::array<Scalar*, kMoments>& m, std::size_t n) {
    const Scalar mu = Scalar(h.momentum), a = Scalar(lr);
    Scalar* b = m[0];
    for (std::size_t i = 0; i < n; ++i) {
      b[i] = k == 1 ? g[i] : mu * b[i] + g[i];
      p[i] -= a * (h.momentum != 0 ? b[i] : g[i]);
    }
  }
};

}  // namespace video3dgs
