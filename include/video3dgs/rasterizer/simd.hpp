#pragma once
/// @file
/// Which instruction set the compositing kernels of the rasterizer use (chosen at run time).
///
/// The kernels (detail/kernels.hpp) are compiled three times on x86-64 with GCC or Clang: for the
/// baseline of the build (`portable`: 16-byte SSE2 blocks by default, wider under -march=native), and
/// with function-level target attributes for AVX2 (32-byte blocks) and AVX-512 (64-byte blocks,
/// AVX512F/VL/DQ/BW). `automatic` takes the fastest one the CPU supports (resolve_raster_simd). Every path rounds every
/// expression exactly like the portable one (no FMA contraction, gradient sums in a fixed order
/// independent of the block width), so images and gradients are bit-identical across paths.
/// Elsewhere (other architectures or compilers, or with VIDEO3DGS_NO_ISA_DISPATCH defined) only
/// `portable` exists.

#include <string>

#if (defined(__GNUC__) || defined(__clang__)) && defined(__x86_64__) && !defined(VIDEO3DGS_NO_ISA_DISPATCH)
#define VIDEO3DGS_RASTER_DISPATCH 1
#else
#define VIDEO3DGS_RASTER_DISPATCH 0
#endif

namespace video3dgs {

/// Instruction set of the compositing kernels (RasterSettings::simd).
enum class RasterSimd {
  automatic,  ///< the widest supported: avx512, else avx2, else portable
  portable,   ///< the build's baseline (always available)
  avx2,       ///< x86-64 AVX2, 32-byte blocks
  avx512      ///< x86-64 AVX-512 F/VL/DQ/BW, 64-byte blocks
};

/// Stable lower-case name ("automatic", "portable", "avx2", "avx512").
[[nodiscard]] inline const char* raster_simd_name(RasterSimd s) noexcept {
  switch (s) {
    case RasterSimd::portable: return "portable";
    case RasterSimd::avx2: return "avx2";
    case RasterSimd::avx512: return "avx512";
    default: return "automatic";
  }
}

/// Whether this build and CPU can run the kernels of `s` (queried once; `automatic` and `portable`
/// always can).
[[nodiscard]] inline bool raster_simd_supported(RasterSimd s) noexcept {
#if VIDEO3DGS_RASTER_DISPATCH
  static const bool avx2 = __builtin_cpu_supports("avx2");
  static const bool avx512 = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
                             __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512bw");
  if (s == RasterSimd::avx2) return avx2;
  if (s == RasterSimd::avx512) return avx512;
  return true;
#else
  return s == RasterSimd::automatic || s == RasterSimd::portable;
#endif
}

/// Which compositing pass a path is chosen for.
enum class RasterPass { forward, backward };

/// The path `s` runs on in `pass`: an explicit choice as is; `automatic` resolved to the widest supported
/// one for the forward pass, and to AVX2 (if supported) for the backward pass: its 16-lane AVX-512
/// blocks cover whole 16-pixel tile rows, and with footprint rows of ~7 pixels the wasted lanes made it
/// ~7% slower than 8-lane AVX2 blocks on the AMD EPYC (Zen 4, 512-bit operations split in two halves)
/// we measured on. All paths give the same bits, so this is a speed choice only.
[[nodiscard]] inline RasterSimd resolve_raster_simd(RasterSimd s, RasterPass pass = RasterPass::forward) noexcept {
  if (s != RasterSimd::automatic) return s;
  if (pass == RasterPass::forward && raster_simd_supported(RasterSimd::avx512)) return RasterSimd::avx512;
  if (raster_simd_supported(RasterSimd::avx2)) return RasterSimd::avx2;
  return RasterSimd::portable;
}

}  // namespace video3dgs
