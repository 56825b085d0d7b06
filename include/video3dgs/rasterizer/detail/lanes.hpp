#pragma once
/// @file
/// Fixed-width lane blocks for the compositing loops (GCC/Clang vector extensions). `Lanes<Scalar,
/// Bytes>` is a block of Bytes / sizeof(Scalar) lanes; the kernels (kernels.hpp) use 16 bytes (SSE2 on
/// any x86-64, NEON on AArch64, wider when the build enables AVX / AVX-512) in the portable path and 32
/// / 64 bytes in the run-time dispatched AVX2 / AVX-512 paths. A block covers consecutive pixels of one
/// tile row; lanes outside a footprint row are masked and leave the state unchanged. Every lane
/// computes exactly the scalar expression, so images do not depend on the block width or the tile size.

#include <cstdint>

namespace video3dgs::detail {

#if defined(__AVX512F__)
inline constexpr int kLaneBytes = 64;  // builds for AVX-512 (e.g. -march=native)
#elif defined(__AVX__)
inline constexpr int kLaneBytes = 32;  // builds for AVX (e.g. -march=native): 8 floats / 4 doubles
#else
inline constexpr int kLaneBytes = 16;  // portable default: SSE2 / NEON
#endif

template <class Scalar, int Bytes>
struct Lanes;

template <int Bytes>
struct Lanes<float, Bytes> {
  static constexpr int n = Bytes / 4;
  typedef float V __attribute__((vector_size(Bytes)));
  typedef std::int32_t I __attribute__((vector_size(Bytes)));
  using index_type = std::int32_t;
};

template <int Bytes>
struct Lanes<double, Bytes> {
  static constexpr int n = Bytes / 8;
  typedef double V __attribute__((vector_size(Bytes)));
  typedef std::int64_t I __attribute__((vector_size(Bytes)));
  using index_type = std::int64_t;
};

/// Block width (bytes) for tiles of TileSize pixels per row on a path with `Bytes`-wide registers:
/// a block never spans two rows, so it is at most one tile row.
template <class Scalar, int Bytes, int TileSize>
inline constexpr int kBlockBytes = Bytes < TileSize * static_cast<int>(sizeof(Scalar)) ? Bytes : TileSize * static_cast<int>(sizeof(Scalar));

/// How many tile-list entries ahead the compositing loops prefetch (records are visited in depth order,
/// scattered in memory).
inline constexpr int kPrefetch = 4;
/// Prefetches the (up to two) cache lines of a record.
template <class T>
inline void prefetch(const T* p) noexcept {
  __builtin_prefetch(p);
  __builtin_prefetch(reinterpret_cast<const char*>(p) + sizeof(T) - 1);
}

}  // namespace video3dgs::detail
