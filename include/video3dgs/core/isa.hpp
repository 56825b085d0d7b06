#pragma once
/// @file
/// The one run-time instruction-set dispatch of the library: every kernel family with per-ISA copies
/// (the rasterizer's compositing kernels, the hash grid's level kernels, the SSIM filters, Adam's
/// float update) takes an `Isa` in its options, asks `isa_supported` (the CPU is queried once) and
/// resolves `automatic` with `resolve_isa` against the ISAs it has kernels for. Copies are compiled with function-level target
/// attributes (GCC/Clang on x86-64), so one binary runs everywhere; every copy rounds exactly like the
/// portable one (no FMA contraction, sums in a fixed order), so the choice changes speed, never bits.
/// Elsewhere (other architectures or compilers, or with VIDEO3DGS_NO_ISA_DISPATCH defined) only
/// `portable` exists.
///
/// Why not Highway: its dynamic dispatch re-includes a translation unit once per target, which does
/// not fit a header-only template library, and its operations would have to be pinned against FMA
/// contraction to keep the bit-identical guarantee; target attributes give both for two ISAs.

#include <initializer_list>

#if (defined(__GNUC__) || defined(__clang__)) && defined(__x86_64__) && !defined(VIDEO3DGS_NO_ISA_DISPATCH)
#define VIDEO3DGS_ISA_DISPATCH 1
#else
#define VIDEO3DGS_ISA_DISPATCH 0
#endif

namespace video3dgs {

/// An instruction set a kernel copy is compiled for.
enum class Isa {
  automatic,  ///< the fastest one the kernel family has and the CPU supports
  portable,   ///< the build's baseline (always available)
  avx2,       ///< x86-64 AVX2 (32-byte blocks)
  avx512      ///< x86-64 AVX-512 F/VL/DQ/BW (64-byte blocks)
};

/// Stable lower-case name ("automatic", "portable", "avx2", "avx512").
[[nodiscard]] inline const char* isa_name(Isa s) noexcept {
  switch (s) {
    case Isa::portable: return "portable";
    case Isa::avx2: return "avx2";
    case Isa::avx512: return "avx512";
    default: return "automatic";
  }
}

/// Whether this build and CPU can run code for `s` (`automatic` and `portable` always can).
[[nodiscard]] inline bool isa_supported(Isa s) noexcept {
#if VIDEO3DGS_ISA_DISPATCH
  static const bool avx2 = __builtin_cpu_supports("avx2");
  static const bool avx512 = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
                             __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512bw");
  if (s == Isa::avx2) return avx2;
  if (s == Isa::avx512) return avx512;
  return true;
#else
  return s == Isa::automatic || s == Isa::portable;
#endif
}

/// `requested` as is, or for `automatic` the first of `preference` (fastest first) that the CPU
/// supports, else `portable`.
[[nodiscard]] inline Isa resolve_isa(Isa requested, std::initializer_list<Isa> preference) noexcept {
  if (requested != Isa::automatic) return requested;
  for (Isa s : preference)
    if (isa_supported(s)) return s;
  return Isa::portable;
}

}  // namespace video3dgs
