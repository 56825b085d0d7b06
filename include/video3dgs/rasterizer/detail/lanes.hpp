#pragma once
/// @file
/// Fixed-width lane blocks for the compositing loops (GCC/Clang vector extensions): 16 bytes (SSE2 on
/// any x86-64, NEON on AArch64), 32 bytes when compiled for AVX (opt-in VIDEO3DGS_NATIVE). A block covers kLanes consecutive
/// pixels of a footprint row; lanes past the row end are masked and leave the state unchanged.
/// Every lane computes exactly the scalar expression, so results do not depend on block alignment
/// (hence not on the tile size).

#include <cmath>
#include <cstdint>
#include <cstring>

namespace video3dgs::detail {

template <class Scalar>
struct Lanes;

#if defined(__AVX__)
inline constexpr int kLaneBytes = 32;  // AVX builds (e.g. -march=native): 8 floats / 4 doubles
#else
inline constexpr int kLaneBytes = 16;  // portable default: SSE2 / NEON
#endif

template <>
struct Lanes<float> {
  static constexpr int n = kLaneBytes / 4;
  typedef float V __attribute__((vector_size(kLaneBytes)));
  typedef std::int32_t I __attribute__((vector_size(kLaneBytes)));
  using index_type = std::int32_t;
  static constexpr I iota() {
    I v{};
    for (int l = 0; l < n; ++l) v[l] = l;
    return v;
  }
};

template <>
struct Lanes<double> {
  static constexpr int n = kLaneBytes / 8;
  typedef double V __attribute__((vector_size(kLaneBytes)));
  typedef std::int64_t I __attribute__((vector_size(kLaneBytes)));
  using index_type = std::int64_t;
  static constexpr I iota() {
    I v{};
    for (int l = 0; l < n; ++l) v[l] = l;
    return v;
  }
};

template <class Vec, class T>
[[nodiscard]] inline Vec load(const T* p) noexcept {
  Vec v;
  std::memcpy(&v, p, sizeof(Vec));
  return v;
}
template <class Vec, class T>
inline void store(T* p, const Vec& v) noexcept {
  std::memcpy(p, &v, sizeof(Vec));
}

/// exp(-x) on a block. float: range reduction 2^(-x/ln2) = 2^-i 2^-f (|f| <= 1/2) and a degree-6
/// polynomial (relative error < 3e-7, no libm call, vectorises); valid for x in [-0.3, 87], which
/// holds for every lane the compositing loops use (lanes outside a footprint are masked out, so their
/// value does not matter). double: std::exp per lane. Forward and backward call exactly this.
[[nodiscard]] inline Lanes<float>::V exp_neg(Lanes<float>::V x) noexcept {
  using V = Lanes<float>::V;
  using I = Lanes<float>::I;
  const V t = x * 1.44269504088896341f;  // x / ln 2
  const I i = __builtin_convertvector(t + 0.5f, I);
  const V z = (__builtin_convertvector(i, V) - t) * 0.693147180559945309f;  // in [-ln2/2, ln2/2]
  V p = V{} + 1.0f / 720.0f;
  p = p * z + 1.0f / 120.0f;
  p = p * z + 1.0f / 24.0f;
  p = p * z + 1.0f / 6.0f;
  p = p * z + 0.5f;
  p = p * z + 1.0f;
  p = p * z + 1.0f;
  const I bits = (127 - i) << 23;
  V scale;
  std::memcpy(&scale, &bits, sizeof(V));
  return p * scale;
}
[[nodiscard]] inline Lanes<double>::V exp_neg(Lanes<double>::V x) noexcept {
  Lanes<double>::V r;
  for (int l = 0; l < Lanes<double>::n; ++l) r[l] = std::exp(-x[l]);
  return r;
}

/// How many tile-list entries ahead the compositing loops prefetch (records are visited in depth order,
/// scattered in memory).
inline constexpr int kPrefetch = 4;
/// Prefetches the (up to two) cache lines of a record.
template <class T>
inline void prefetch(const T* p) noexcept {
  __builtin_prefetch(p);
  __builtin_prefetch(reinterpret_cast<const char*>(p) + sizeof(T) - 1);
}

/// True if no lane of a mask is set.
template <class I>
[[nodiscard]] inline bool none(const I& mask) noexcept {
  constexpr int words = static_cast<int>(sizeof(I) / 8);
  std::uint64_t w[words];
  std::memcpy(w, &mask, sizeof(I));
  std::uint64_t any = 0;
  for (int k = 0; k < words; ++k) any |= w[k];
  return any == 0;
}

/// Number of set lanes of a mask (-1 = set).
template <class I>
[[nodiscard]] inline int count(const I& mask, int n) noexcept {
  int c = 0;
  for (int l = 0; l < n; ++l) c += mask[l] != 0;
  return c;
}

}  // namespace video3dgs::detail
