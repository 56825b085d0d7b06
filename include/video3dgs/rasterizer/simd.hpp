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

#include "video3dgs/core/isa.hpp"

#define VIDEO3DGS_RASTER_DISPATCH VIDEO3DGS_ISA_DISPATCH

namespace video3dgs {

/// Instruction set of the compositing kernels (RasterSettings::simd): the library's `Isa`
/// (core/isa.hpp); the rasterizer has portable, AVX2 and AVX-512 copies.
using RasterSimd = Isa;

/// Stable lower-case name ("automatic", "portable", "avx2", "avx512").
[[nodiscard]] inline const char* raster_simd_name(RasterSimd s) noexcept { return isa_name(s); }

/// Whether this build and CPU can run the kernels of `s` (`automatic` and `portable` always can).
[[nodiscard]] inline bool raster_simd_supported(RasterSimd s) noexcept { return isa_supported(s); }

/// Which compositing pass a path is chosen for.
enum class RasterPass { forward, backward };

/// The path `s` runs on in `pass`: an explicit choice as is; `automatic` resolved to the widest supported
/// one for the forward pass, and to AVX2 (if supported) for the backward pass, whose per-row work is
/// too short to fill 16-lane blocks (docs/performance.md). All paths give the same bits.
[[nodiscard]] inline RasterSimd resolve_raster_simd(RasterSimd s, RasterPass pass = RasterPass::forward) noexcept {
  return pass == RasterPass::forward ? resolve_isa(s, {Isa::avx512, Isa::avx2}) : resolve_isa(s, {Isa::avx2});
}

}  // namespace video3dgs
