#pragma once
/// @file
/// Row kernels of the separable SSIM filters. Every output is a sum over the taps held in registers
/// (rather than one read-modify-write pass per tap), summed in tap order k = 0..2r starting from 0,
/// so the result does not depend on how rows are split between threads. Sources are zero-padded in
/// memory (r*C zeros left and right of a row, r zero rows above and below a map), so the kernels
/// have no border branches. NT > 0 fixes the tap count at compile time (unrolled, vectorised);
/// NT == 0 takes it at run time. The target-only maps (`SsimTarget*` kernels: y and y y, then my and
/// eyy) can be computed once and read by the `SsimShared*` kernels, which evaluate the other three
/// statistics with the same expressions, so both routes give the same bits.
///
/// Each kernel is a struct with a static `run`, called through `run_kernel<K>(avx2, args...)`: the
/// build's baseline code or, on x86-64 with GCC/Clang, a copy compiled for AVX2 (core/isa.hpp). The
/// copy is not allowed FMA, so it rounds exactly like the baseline: twice the lanes, the same bits.

#include <cstddef>

#include "video3dgs/core/isa.hpp"
#include "video3dgs/loss/detail/gaussian_window.hpp"

#if defined(__clang__)
#define VIDEO3DGS_IVDEP _Pragma("clang loop vectorize(assume_safety)")
#elif defined(__GNUC__)
#define VIDEO3DGS_IVDEP _Pragma("GCC ivdep")
#else
#define VIDEO3DGS_IVDEP
#endif

#if defined(__GNUC__) || defined(__clang__)
#define VIDEO3DGS_SSIM_INLINE inline __attribute__((always_inline))
#else
#define VIDEO3DGS_SSIM_INLINE inline
#endif

namespace video3dgs::loss::detail {

/// Tap count compiled in for the default 11x11 window.
inline constexpr int kDefaultTaps = 11;

#if VIDEO3DGS_ISA_DISPATCH
/// K::run(a...) compiled for AVX2 (K::run is always inlined, so its loops take this function's ISA).
template <class K, class... A>
__attribute__((target("avx2"))) void run_kernel_avx2(A... a) noexcept {
  K::run(a...);
}
#endif

/// K::run(a...) in the AVX2 copy when `avx2` (the caller checked that the CPU has it), else in the
/// baseline code.
template <class K, class... A>
inline void run_kernel([[maybe_unused]] bool avx2, A... a) noexcept {
#if VIDEO3DGS_ISA_DISPATCH
  if (avx2) return run_kernel_avx2<K>(a...);
#endif
  K::run(a...);
}

/// Horizontal pass of x, y, x x, y y, x y for one row. `px`, `py`: padded rows (element i's first tap
/// at index i, last at i + (nt - 1) C).
template <int NT, int C>
struct SsimHorizontalRow {
  template <class Scalar>
  VIDEO3DGS_SSIM_INLINE static void run(const Scalar* VIDEO3DGS_RESTRICT taps, int nt, std::ptrdiff_t n,
                                        const Scalar* VIDEO3DGS_RESTRICT px, const Scalar* VIDEO3DGS_RESTRICT py,
                                        Scalar* VIDEO3DGS_RESTRICT hx, Scalar* VIDEO3DGS_RESTRICT hy, Scalar* VIDEO3DGS_RESTRICT hxx,
                                        Scalar* VIDEO3DGS_RESTRICT hyy, Scalar* VIDEO3DGS_RESTRICT hxy) noexcept {
    if constexpr (NT > 0) nt = NT;
    VIDEO3DGS_IVDEP
    for (std::ptrdiff_t i = 0; i < n; ++i) {
      Scalar sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
      for (int k = 0; k < nt; ++k) {
        const Scalar w = taps[k];
        const Scalar a = px[i + k * C], b = py[i + k * C];
        sx += w * a;
        sy += w * b;
        sxx += w * (a * a);
        syy += w * (b * b);
        sxy += w * (a * b);
      }
      hx[i] = sx;
      hy[i] = sy;
      hxx[i] = sxx;
      hyy[i] = syy;
      hxy[i] = sxy;
    }
  }
};

/// Horizontal pass of three padded rows (the backward's coefficient maps).
template <int NT, int C>
struct Horizontal3Row {
  template <class Scalar>
  VIDEO3DGS_SSIM_INLINE static void run(const Scalar* VIDEO3DGS_RESTRICT taps, int nt, std::ptrdiff_t n,
                                        const Scalar* VIDEO3DGS_RESTRICT p0,
                                        const Scalar* VIDEO3DGS_RESTRICT p1, const Scalar* VIDEO3DGS_RESTRICT p2,
                                        Scalar* VIDEO3DGS_RESTRICT o0, Scalar* VIDEO3DGS_RESTRICT o1,
                                        Scalar* VIDEO3DGS_RESTRICT o2) noexcept {
    if constexpr (NT > 0) nt = NT;
    VIDEO3DGS_IVDEP
    for (std::ptrdiff_t i = 0; i < n; ++i) {
      Scalar s0 = 0, s1 = 0, s2 = 0;
      for (int k = 0; k < nt; ++k) {
        const Scalar w = taps[k];
        s0 += w * p0[i + k * C];
        s1 += w * p1[i + k * C];
        s2 += w * p2[i + k * C];
      }
      o0[i] = s0;
      o1[i] = s1;
      o2[i] = s2;
    }
  }
};

/// S and, if Grad, its coefficients dS/dmx, dS/dexx, dS/dexy at element i, from the five filtered
/// statistics (ssim.hpp's formulas). The one definition both vertical kernels use.
template <bool Grad, class Scalar>
VIDEO3DGS_SSIM_INLINE void ssim_point(Scalar ax, Scalar ay, Scalar exx, Scalar eyy, Scalar exy, Scalar c1, Scalar c2, std::ptrdiff_t i,
                                      Scalar* s_out, Scalar* dmx, Scalar* dexx, Scalar* dexy) noexcept {
  const Scalar mx2 = ax * ax, my2 = ay * ay, mxy = ax * ay;
  const Scalar A1 = Scalar(2) * mxy + c1;
  const Scalar A2 = Scalar(2) * (exy - mxy) + c2;
  const Scalar B1 = mx2 + my2 + c1;
  const Scalar B2 = (exx - mx2) + (eyy - my2) + c2;
  const Scalar D = B1 * B2;
  const Scalar S = (A1 * A2) / D;  // a division (not a reciprocal) keeps SSIM(x, x) == 1 exactly
  s_out[i] = S;
  if constexpr (Grad) {
    const Scalar inv = Scalar(1) / D;
    dmx[i] = Scalar(2) * (ay * (A2 - A1) - ax * S * (B2 - B1)) * inv;
    dexx[i] = -S / B2;
    dexy[i] = Scalar(2) * A1 * inv;
  }
}

/// Vertical pass of the five statistics for one output row, then S (into `s_out`) and, if Grad, the
/// coefficient maps. `h0..h4` point at the first tap row of each padded map; rows are `n` apart.
template <bool Grad, int NT>
struct SsimVerticalRow {
  template <class Scalar>
  VIDEO3DGS_SSIM_INLINE static void run(const Scalar* VIDEO3DGS_RESTRICT taps, int nt, std::ptrdiff_t n,
                                        const Scalar* VIDEO3DGS_RESTRICT h0,
                                        const Scalar* VIDEO3DGS_RESTRICT h1, const Scalar* VIDEO3DGS_RESTRICT h2,
                                        const Scalar* VIDEO3DGS_RESTRICT h3, const Scalar* VIDEO3DGS_RESTRICT h4, Scalar c1, Scalar c2,
                                        Scalar* VIDEO3DGS_RESTRICT s_out, Scalar* VIDEO3DGS_RESTRICT dmx, Scalar* VIDEO3DGS_RESTRICT dexx,
                                        Scalar* VIDEO3DGS_RESTRICT dexy) noexcept {
    if constexpr (NT > 0) nt = NT;
    VIDEO3DGS_IVDEP
    for (std::ptrdiff_t i = 0; i < n; ++i) {
      Scalar ax = 0, ay = 0, exx = 0, eyy = 0, exy = 0;
      for (int k = 0; k < nt; ++k) {
        const Scalar w = taps[k];
        const std::ptrdiff_t o = k * n + i;
        ax += w * h0[o];
        ay += w * h1[o];
        exx += w * h2[o];
        eyy += w * h3[o];
        exy += w * h4[o];
      }
      ssim_point<Grad>(ax, ay, exx, eyy, exy, c1, c2, i, s_out, dmx, dexx, dexy);
    }
  }
};

/// Horizontal pass of y and y y for one row (the target-only maps). `py`: a padded row.
template <int NT, int C>
struct SsimTargetHorizontalRow {
  template <class Scalar>
  VIDEO3DGS_SSIM_INLINE static void run(const Scalar* VIDEO3DGS_RESTRICT taps, int nt, std::ptrdiff_t n,
                                        const Scalar* VIDEO3DGS_RESTRICT py, Scalar* VIDEO3DGS_RESTRICT hy,
                                        Scalar* VIDEO3DGS_RESTRICT hyy) noexcept {
    if constexpr (NT > 0) nt = NT;
    VIDEO3DGS_IVDEP
    for (std::ptrdiff_t i = 0; i < n; ++i) {
      Scalar sy = 0, syy = 0;
      for (int k = 0; k < nt; ++k) {
        const Scalar w = taps[k];
        const Scalar b = py[i + k * C];
        sy += w * b;
        syy += w * (b * b);
      }
      hy[i] = sy;
      hyy[i] = syy;
    }
  }
};

/// Vertical pass of the target-only maps for one output row: my = G*y, eyy = G*(y y). `h0`, `h1`
/// point at the first tap row of the padded horizontal maps of y and y y.
template <int NT>
struct SsimTargetVerticalRow {
  template <class Scalar>
  VIDEO3DGS_SSIM_INLINE static void run(const Scalar* VIDEO3DGS_RESTRICT taps, int nt, std::ptrdiff_t n,
                                        const Scalar* VIDEO3DGS_RESTRICT h0,
                                        const Scalar* VIDEO3DGS_RESTRICT h1, Scalar* VIDEO3DGS_RESTRICT my,
                                        Scalar* VIDEO3DGS_RESTRICT eyy) noexcept {
    if constexpr (NT > 0) nt = NT;
    VIDEO3DGS_IVDEP
    for (std::ptrdiff_t i = 0; i < n; ++i) {
      Scalar ay = 0, e = 0;
      for (int k = 0; k < nt; ++k) {
        const Scalar w = taps[k];
        const std::ptrdiff_t o = k * n + i;
        ay += w * h0[o];
        e += w * h1[o];
      }
      my[i] = ay;
      eyy[i] = e;
    }
  }
};

/// Horizontal pass of x, x x, x y for one row (the target's maps come precomputed).
template <int NT, int C>
struct SsimSharedHorizontalRow {
  template <class Scalar>
  VIDEO3DGS_SSIM_INLINE static void run(const Scalar* VIDEO3DGS_RESTRICT taps, int nt, std::ptrdiff_t n,
                                        const Scalar* VIDEO3DGS_RESTRICT px, const Scalar* VIDEO3DGS_RESTRICT py,
                                        Scalar* VIDEO3DGS_RESTRICT hx, Scalar* VIDEO3DGS_RESTRICT hxx,
                                        Scalar* VIDEO3DGS_RESTRICT hxy) noexcept {
    if constexpr (NT > 0) nt = NT;
    VIDEO3DGS_IVDEP
    for (std::ptrdiff_t i = 0; i < n; ++i) {
      Scalar sx = 0, sxx = 0, sxy = 0;
      for (int k = 0; k < nt; ++k) {
        const Scalar w = taps[k];
        const Scalar a = px[i + k * C], b = py[i + k * C];
        sx += w * a;
        sxx += w * (a * a);
        sxy += w * (a * b);
      }
      hx[i] = sx;
      hxx[i] = sxx;
      hxy[i] = sxy;
    }
  }
};

/// Vertical pass of x, x x, x y for one output row, with my and eyy of that row read from the target's
/// maps, then S and, if Grad, the coefficient maps (as `SsimVerticalRow`).
template <bool Grad, int NT>
struct SsimSharedVerticalRow {
  template <class Scalar>
  VIDEO3DGS_SSIM_INLINE static void run(const Scalar* VIDEO3DGS_RESTRICT taps, int nt, std::ptrdiff_t n,
                                        const Scalar* VIDEO3DGS_RESTRICT h0,
                                        const Scalar* VIDEO3DGS_RESTRICT h1, const Scalar* VIDEO3DGS_RESTRICT h2,
                                        const Scalar* VIDEO3DGS_RESTRICT my, const Scalar* VIDEO3DGS_RESTRICT eyy, Scalar c1, Scalar c2,
                                        Scalar* VIDEO3DGS_RESTRICT s_out, Scalar* VIDEO3DGS_RESTRICT dmx, Scalar* VIDEO3DGS_RESTRICT dexx,
                                        Scalar* VIDEO3DGS_RESTRICT dexy) noexcept {
    if constexpr (NT > 0) nt = NT;
    VIDEO3DGS_IVDEP
    for (std::ptrdiff_t i = 0; i < n; ++i) {
      Scalar ax = 0, exx = 0, exy = 0;
      for (int k = 0; k < nt; ++k) {
        const Scalar w = taps[k];
        const std::ptrdiff_t o = k * n + i;
        ax += w * h0[o];
        exx += w * h1[o];
        exy += w * h2[o];
      }
      ssim_point<Grad>(ax, my[i], exx, eyy[i], exy, c1, c2, i, s_out, dmx, dexx, dexy);
    }
  }
};

/// Vertical pass of the backward's three filtered maps for one output row, then
/// out += g (G*dmx + 2 x G*dexx + y G*dexy).
template <int NT>
struct SsimBackwardVerticalRow {
  template <class Scalar>
  VIDEO3DGS_SSIM_INLINE static void run(const Scalar* VIDEO3DGS_RESTRICT taps, int nt, std::ptrdiff_t n,
                                        const Scalar* VIDEO3DGS_RESTRICT h0, const Scalar* VIDEO3DGS_RESTRICT h1,
                                        const Scalar* VIDEO3DGS_RESTRICT h2, const Scalar* VIDEO3DGS_RESTRICT x,
                                        const Scalar* VIDEO3DGS_RESTRICT y, Scalar g, Scalar* VIDEO3DGS_RESTRICT out) noexcept {
    if constexpr (NT > 0) nt = NT;
    VIDEO3DGS_IVDEP
    for (std::ptrdiff_t i = 0; i < n; ++i) {
      Scalar a0 = 0, a1 = 0, a2 = 0;
      for (int k = 0; k < nt; ++k) {
        const Scalar w = taps[k];
        const std::ptrdiff_t o = k * n + i;
        a0 += w * h0[o];
        a1 += w * h1[o];
        a2 += w * h2[o];
      }
      out[i] += g * (a0 + Scalar(2) * x[i] * a1 + y[i] * a2);
    }
  }
};

}  // namespace video3dgs::loss::detail
