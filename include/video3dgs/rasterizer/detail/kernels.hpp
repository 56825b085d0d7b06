#pragma once
/// @file
/// The per-tile compositing kernels (forward_tile, backward_tile) in one copy per instruction set, and
/// the run-time choice between them (simd.hpp). The kernels live in kernels.inc, included here once
/// per instruction set with its target attribute: portable (the build's baseline) everywhere, AVX2 and
/// AVX-512 on x86-64 with GCC or Clang. See kernels.inc for how every copy rounds alike.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/rasterizer/context.hpp"
#include "video3dgs/rasterizer/detail/lanes.hpp"
#include "video3dgs/rasterizer/simd.hpp"

#if defined(__x86_64__)
#include <immintrin.h>
#endif

#if defined(__GNUC__) || defined(__clang__)
#define VIDEO3DGS_RASTER_INLINE inline __attribute__((always_inline))
#else
#define VIDEO3DGS_RASTER_INLINE inline
#endif
#if defined(__clang__)
#define VIDEO3DGS_RASTER_NO_CONTRACT _Pragma("clang fp contract(off)")
#else
#define VIDEO3DGS_RASTER_NO_CONTRACT
#endif

#define VIDEO3DGS_RASTER_ISA isa_portable
#define VIDEO3DGS_RASTER_ISA_TARGET
#define VIDEO3DGS_RASTER_ISA_BYTES ::video3dgs::detail::kLaneBytes
#include "video3dgs/rasterizer/detail/kernels.inc"
#undef VIDEO3DGS_RASTER_ISA
#undef VIDEO3DGS_RASTER_ISA_TARGET
#undef VIDEO3DGS_RASTER_ISA_BYTES

#if VIDEO3DGS_RASTER_DISPATCH
// AVX2 without FMA: nothing to contract.
#define VIDEO3DGS_RASTER_ISA isa_avx2
#define VIDEO3DGS_RASTER_ISA_TARGET __attribute__((target("avx2")))
#define VIDEO3DGS_RASTER_ISA_BYTES 32
#include "video3dgs/rasterizer/detail/kernels.inc"
#undef VIDEO3DGS_RASTER_ISA
#undef VIDEO3DGS_RASTER_ISA_TARGET
#undef VIDEO3DGS_RASTER_ISA_BYTES

// AVX-512 (implies FMA instructions: kernels.inc pins every product).
#define VIDEO3DGS_RASTER_ISA isa_avx512
#define VIDEO3DGS_RASTER_ISA_TARGET __attribute__((target("avx512f,avx512vl,avx512dq,avx512bw")))
#ifndef VIDEO3DGS_RASTER_AVX512_BYTES
#define VIDEO3DGS_RASTER_AVX512_BYTES 64
#endif
#define VIDEO3DGS_RASTER_ISA_BYTES VIDEO3DGS_RASTER_AVX512_BYTES
#include "video3dgs/rasterizer/detail/kernels.inc"
#undef VIDEO3DGS_RASTER_ISA
#undef VIDEO3DGS_RASTER_ISA_TARGET
#undef VIDEO3DGS_RASTER_ISA_BYTES
#endif

namespace video3dgs::detail {

/// Forward compositing of tile t on the path `simd` (already resolved and supported); the depth image
/// is accumulated if ctx.settings.depth.
template <int TileSize, class Scalar, int C>
inline void forward_tile(RasterSimd simd, RasterContext<Scalar, C>& ctx, std::size_t t) {
  auto run = [&](auto tile) { ctx.settings.depth ? tile.template operator()<true>() : tile.template operator()<false>(); };
#if VIDEO3DGS_RASTER_DISPATCH
  if (simd == RasterSimd::avx512) return run([&]<bool D>() { isa_avx512::forward_tile<TileSize, Scalar, C, D>(ctx, t); });
  if (simd == RasterSimd::avx2) return run([&]<bool D>() { isa_avx2::forward_tile<TileSize, Scalar, C, D>(ctx, t); });
#endif
  (void)simd;
  run([&]<bool D>() { isa_portable::forward_tile<TileSize, Scalar, C, D>(ctx, t); });
}

/// Backward compositing of tile t on the path `simd` (already resolved and supported). `weights`: record
/// entry 6 sums the blend weights (only without dL/ddepth; otherwise that entry holds the depth sums).
template <int TileSize, class Scalar, int C>
inline void backward_tile(RasterSimd simd, RasterContext<Scalar, C>& ctx, const ConstImageView<Scalar, C>& dL_dimage,
                          const ConstImageView<Scalar, 1>& dL_dalpha, const ConstImageView<Scalar, 1>& dL_ddepth, std::size_t t,
                          bool weights) {
  const bool has_alpha = !dL_dalpha.empty(), has_depth = !dL_ddepth.empty();
  auto run = [&](auto tile) {
    if (has_alpha && has_depth) tile.template operator()<true, true, false>();
    else if (has_depth) tile.template operator()<false, true, false>();
    else if (has_alpha) weights ? tile.template operator()<true, false, true>() : tile.template operator()<true, false, false>();
    else weights ? tile.template operator()<false, false, true>() : tile.template operator()<false, false, false>();
  };
#if VIDEO3DGS_RASTER_DISPATCH
  if (simd == RasterSimd::avx512)
    return run([&]<bool A, bool D, bool W>() { isa_avx512::backward_tile<TileSize, Scalar, C, A, D, W>(ctx, dL_dimage, dL_dalpha, dL_ddepth, t); });
  if (simd == RasterSimd::avx2)
    return run([&]<bool A, bool D, bool W>() { isa_avx2::backward_tile<TileSize, Scalar, C, A, D, W>(ctx, dL_dimage, dL_dalpha, dL_ddepth, t); });
#endif
  (void)simd;
  run([&]<bool A, bool D, bool W>() { isa_portable::backward_tile<TileSize, Scalar, C, A, D, W>(ctx, dL_dimage, dL_dalpha, dL_ddepth, t); });
}

}  // namespace video3dgs::detail
