#pragma once
/// @file
/// `HashGrid<Scalar, Dims, Levels, FeaturesPerLevel, Log2TableSize>`: a multiresolution hash encoding
/// (Mueller et al. 2022, "Instant neural graphics primitives", Sec. 3) on inputs in [0, 1]^Dims.
///
/// Level l has resolution R_l = ceil(b s^l) cells per axis (b: base resolution, s: per-level scale;
/// b = 16, s = 1.38 gives 16, 23, 31, 43, ..., 2006) and (R_l + 1) vertices per axis; an axis d with a
/// cap M_d (HashGridOptions::max_cells, 0 = none) has R_{l,d} = min(R_l, M_d) cells instead (for
/// example the time axis of a clip of n frames: M = n - 1 puts every frame on a vertex, so a level
/// holds n time slices instead of 2 per frame). Below, R_l stands for R_{l,d} on axis d. A vertex with
/// integer coordinates c is stored at
///
///     dense  (prod_d (R_{l,d} + 1) <= T):  i = sum_d c_d prod_{e<d} (R_{l,e} + 1)
///     hashed (otherwise):            i = (XOR_d c_d pi_d) mod T,  pi = (1, 2654435761, 805459861, 3674653429, ...)
///
/// (uint32 arithmetic, T = 2^Log2TableSize, or 2^HashGridOptions::log2_table_size when that is set; a
/// dense level stores only its prod_d (R_{l,d} + 1) vertices). The template's Levels is the output width
/// (Levels x FeaturesPerLevel); HashGridOptions::levels = L' < Levels keeps only levels 0..L'-1: the
/// others hold no entries, output 0 and receive no gradient, so a smaller grid keeps the same layout
/// for whatever reads its outputs (a level l < L' is bit-identical to level l of the full grid).
/// A point x (clamped to [0, 1]) maps to p = x R_l, cell c = min(floor(p), R_l - 1), f = p - c, and
///
///     y_l = sum_{k in {0,1}^Dims} (prod_d w_{k_d}(f_d)) theta_l[i(c + k)],   w_1(f) = S(f), w_0 = 1 - S(f)
///
/// with S(f) = f (linear) or S(f) = f^2 (3 - 2f) (smoothstep, C1 across cells). Output j = l F + q.
/// Table entries are initialised U(-r, r) (r = 1e-4) from a seed, independently of the thread count.
///
/// Backward (see the matching derivation in backward()):
///
///     dL/dtheta_l[i(c + k)] += w_k dL/dy_l                                    (scatter-add)
///     dL/dx_d += R_l S'(f_d) sum_k (+-1 by k_d) (prod_{e != d} w_{k_e}(f_e)) <theta_l[i(c+k)], dL/dy_l>
///
/// (dL/dx_d = 0 where x_d was clamped). The scatter-add runs level by level: a level's table is written
/// by one task that walks the points in order, so the result is bit-identical for any thread count and
/// no per-thread copy of the table is needed. The level kernels are compiled for the build's baseline
/// and, on x86 with GCC/Clang, also for AVX2, chosen at run time (HashGridOptions::simd, GridSimd);
/// neither enables FMA, so both give the same bits. Inputs are rows of Dims (row-major, N x Dims); outputs
/// are feature-major (y_j of point n at out[j N + n]) so that each level writes its own columns.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "video3dgs/core/assert.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/core/hash.hpp"
#include "video3dgs/core/isa.hpp"
#include "video3dgs/core/parallel.hpp"

/// Tells the compiler that a loop's iterations are independent (the batch arrays never alias).
#if defined(__GNUC__) && !defined(__clang__)
#define VIDEO3DGS_IVDEP _Pragma("GCC ivdep")
#elif defined(__clang__)
#define VIDEO3DGS_IVDEP _Pragma("clang loop vectorize(assume_safety)")
#else
#define VIDEO3DGS_IVDEP
#endif

/// Level kernels are force-inlined into their per-ISA wrappers (see HashGrid::forward_level_avx2).
#if defined(__GNUC__)
#define VIDEO3DGS_KERNEL_INLINE inline __attribute__((always_inline))
#define VIDEO3DGS_LAMBDA_INLINE __attribute__((always_inline))
#else
#define VIDEO3DGS_KERNEL_INLINE inline
#define VIDEO3DGS_LAMBDA_INLINE
#endif
#define VIDEO3DGS_HAS_AVX2_DISPATCH VIDEO3DGS_ISA_DISPATCH

namespace video3dgs {

/// How a hash-grid level interpolates between the vertices of a cell.
enum class GridInterpolation { linear, smoothstep };

/// Instruction set of the hash grid's level kernels (HashGridOptions::simd): the library's `Isa`
/// (core/isa.hpp); the grid has portable and AVX2 copies (`avx512` is refused). Every choice gives
/// bit-identical results: this is a speed choice only (and lets tests compare the paths).
using GridSimd = Isa;

/// Stable lower-case name ("automatic", "portable", "avx2").
[[nodiscard]] inline const char* grid_simd_name(GridSimd s) noexcept { return isa_name(s); }

struct HashGridOptions {
  double base_resolution = 16;   ///< b: cells per axis at level 0
  double per_level_scale = 1.38; ///< s: R_l = ceil(b s^l)
  GridInterpolation interpolation = GridInterpolation::linear;
  std::uint64_t seed = 0x5eed;   ///< table initialisation seed
  double init_range = 1e-4;      ///< entries ~ U(-init_range, init_range)
  GridSimd simd = GridSimd::automatic;  ///< level kernels' instruction set (same bits for every choice)
  /// log2 of the table size T of a hashed level: 0 = the grid's Log2TableSize, else in [2, 30].
  int log2_table_size = 0;
  /// Levels in use L' (the finest Levels - L' output 0): 0 = all Levels, else in [1, Levels].
  int levels = 0;
  /// Per axis d < Dims, a cap M_d on the cells of every level along it (R_{l,d} = min(R_l, M_d));
  /// 0 = none (axes >= Dims are ignored and must be 0).
  std::array<std::uint32_t, 7> max_cells{};
};

namespace detail {
#if defined(__GNUC__)
/// Two features of one table entry as a 2-lane vector (GCC/Clang vector extension).
template <class T>
struct Pair;
template <>
struct Pair<float> {
  typedef float type __attribute__((vector_size(8)));
};
template <>
struct Pair<double> {
  typedef double type __attribute__((vector_size(16)));
};
#endif
}  // namespace detail

/// Whether this build and CPU can run the level kernels of `s` (`automatic` and `portable` always can;
/// the grid has no AVX-512 copy).
[[nodiscard]] inline bool grid_simd_supported(GridSimd s) noexcept { return s != Isa::avx512 && isa_supported(s); }

template <class Scalar, int Dims, int Levels, int FeaturesPerLevel, int Log2TableSize>
class HashGrid {
  static_assert(std::is_floating_point_v<Scalar>, "video3dgs: HashGrid<Scalar, ...> needs a floating-point Scalar");
  static_assert(Dims >= 1 && Dims <= 7, "video3dgs: HashGrid supports 1 to 7 input dimensions (2^Dims corners per cell)");
  static_assert(Levels >= 1, "video3dgs: HashGrid needs at least one level");
  static_assert(FeaturesPerLevel >= 1, "video3dgs: HashGrid needs at least one feature per level");
  static_assert(Log2TableSize >= 2 && Log2TableSize <= 30, "video3dgs: HashGrid Log2TableSize must be in [2, 30]");

 public:
  using scalar_type = Scalar;
  static constexpr int kDims = Dims;
  static constexpr int kLevels = Levels;
  static constexpr int kFeatures = FeaturesPerLevel;
  static constexpr int kOutputs = Levels * FeaturesPerLevel;
  static constexpr int kCorners = 1 << Dims;
  /// The default table size (HashGridOptions::log2_table_size = 0); table_size() is the one in use.
  static constexpr std::size_t kTableSize = std::size_t(1) << Log2TableSize;
  /// The spatial-hash primes; dimension d uses kPrimes[d] (the first four are Mueller et al.'s).
  static constexpr std::array<std::uint32_t, 7> kPrimes = {1u, 2654435761u, 805459861u, 3674653429u,
                                                           2097192037u, 1434869437u, 2165219737u};

  explicit HashGrid(const HashGridOptions& options = {}) : options_(options) {
    if (!(options.base_resolution >= 1) || !std::isfinite(options.base_resolution))
      throw option_error("option.hash_grid", "base_resolution", "must be finite and >= 1");
    if (!(options.per_level_scale >= 1) || !std::isfinite(options.per_level_scale))
      throw option_error("option.hash_grid", "per_level_scale", "must be finite and >= 1");
    if (!(options.init_range >= 0) || !std::isfinite(options.init_range))
      throw option_error("option.hash_grid", "init_range", "must be finite and >= 0");
    if (!grid_simd_supported(options.simd))
      throw option_error("option.hash_grid", "simd", "this instruction set is not supported by the CPU or the build");
    if (options.log2_table_size != 0 && (options.log2_table_size < 2 || options.log2_table_size > 30))
      throw option_error("option.hash_grid", "log2_table_size",
                         "must be 0 (the grid's " + std::to_string(Log2TableSize) + ") or in [2, 30], got " +
                             std::to_string(options.log2_table_size));
    if (options.levels < 0 || options.levels > Levels)
      throw option_error("option.hash_grid", "levels",
                         "must be 0 (all " + std::to_string(Levels) + ") or in [1, " + std::to_string(Levels) + "], got " +
                             std::to_string(options.levels));
    for (int d = Dims; d < 7; ++d)
      if (options.max_cells[d] != 0)
        throw option_error("option.hash_grid", "max_cells", "axis " + std::to_string(d) + " is not an input axis (the grid has " +
                                                                std::to_string(Dims) + ")");
    table_size_ = std::size_t(1) << (options.log2_table_size == 0 ? Log2TableSize : options.log2_table_size);
    mask_ = static_cast<std::uint32_t>(table_size_ - 1);
    active_levels_ = options.levels == 0 ? Levels : options.levels;
    std::size_t offset = 0;
    for (int l = 0; l < active_levels_; ++l) {
      const double r = options.base_resolution * std::pow(options.per_level_scale, double(l));
      if (!(r < 1e9)) throw option_error("option.hash_grid", "per_level_scale", "level resolution exceeds 1e9");
      const auto res = static_cast<std::uint32_t>(std::ceil(r * (1 - 1e-12)));
      resolution_[l] = res;
      double verts = 1;
      for (int d = 0; d < Dims; ++d) {
        axis_res_[l][d] = options.max_cells[d] != 0 ? std::min(res, options.max_cells[d]) : res;
        verts *= double(axis_res_[l][d]) + 1;
      }
      dense_[l] = verts <= double(table_size_);
      level_size_[l] = dense_[l] ? static_cast<std::size_t>(verts) : table_size_;
      level_offset_[l] = offset;
      offset += level_size_[l];
    }
    for (int l = active_levels_; l < Levels; ++l) level_offset_[l] = offset;  // no entries, resolution 0
    entries_ = offset;
    if (entries_ > std::size_t(0xffffffffu)) throw option_error("option.hash_grid", "log2_table_size", "more than 2^32 table entries");
    table_.resize(entries_ * FeaturesPerLevel);
    reset_parameters(options.seed);
  }

  /// Re-draws every entry from U(-init_range, init_range) with `seed` (deterministic).
  void reset_parameters(std::uint64_t seed) {
    const double r = options_.init_range;
    for (std::size_t i = 0; i < table_.size(); ++i) {
      // splitmix64 (core/hash.hpp) is counter-based: entry i's initial value does not depend on the others.
      const double u = double(splitmix64(seed * kSplitmix64Gamma + i) >> 11) * 0x1.0p-53;  // [0, 1)
      table_[i] = Scalar((2 * u - 1) * r);
    }
  }

  [[nodiscard]] const HashGridOptions& options() const noexcept { return options_; }
  /// T: entries of a hashed level (a power of two).
  [[nodiscard]] std::size_t table_size() const noexcept { return table_size_; }
  /// L': levels in use (the others output 0).
  [[nodiscard]] int active_levels() const noexcept { return active_levels_; }
  /// R_l: cells per axis of level l (0 for a level not in use); a capped axis has resolution(l, d).
  [[nodiscard]] std::uint32_t resolution(int level) const noexcept { return resolution_[level]; }
  /// R_{l,d}: cells of level l along axis d (R_l unless max_cells caps the axis).
  [[nodiscard]] std::uint32_t resolution(int level, int axis) const noexcept { return axis_res_[level][axis]; }
  [[nodiscard]] bool dense(int level) const noexcept { return dense_[level]; }
  /// First entry of level l in the table, and its number of entries.
  [[nodiscard]] std::size_t level_offset(int level) const noexcept { return level_offset_[level]; }
  [[nodiscard]] std::size_t level_size(int level) const noexcept { return level_size_[level]; }
  /// Total entries (each FeaturesPerLevel scalars).
  [[nodiscard]] std::size_t entries() const noexcept { return entries_; }

  /// The parameters theta, entry-major: entry e, feature q at [e F + q].
  [[nodiscard]] std::span<Scalar> params() noexcept { return table_; }
  [[nodiscard]] std::span<const Scalar> params() const noexcept { return table_; }
  [[nodiscard]] std::size_t param_count() const noexcept { return table_.size(); }

  /// The raw spatial hash XOR_d c_d pi_d (uint32, before the modulo).
  [[nodiscard]] static constexpr std::uint32_t hash(const std::array<std::uint32_t, Dims>& c) noexcept {
    std::uint32_t h = 0;
    for (int d = 0; d < Dims; ++d) h ^= c[d] * kPrimes[d];
    return h;
  }
  /// Table entry (relative to the level's offset) of the vertex with integer coordinates c.
  [[nodiscard]] std::size_t vertex_index(int level, const std::array<std::uint32_t, Dims>& c) const noexcept {
    if (dense_[level]) {
      std::size_t i = 0, stride = 1;
      for (int d = 0; d < Dims; ++d) {
        i += c[d] * stride;
        stride *= axis_res_[level][d] + 1;
      }
      return i;
    }
    return hash(c) & mask_;
  }

  /// y = encode(x). inputs: n x Dims row-major; out: kOutputs x n (out[j n + i]); levels not in use
  /// write zeros.
  void forward(const Scalar* inputs, std::size_t n, Scalar* out, ThreadPool* pool = nullptr) const {
    if (active_levels_ < Levels)
      std::fill(out + std::size_t(active_levels_) * FeaturesPerLevel * n, out + std::size_t(kOutputs) * n, Scalar(0));
    parallel_for_chunks(pool, std::size_t(active_levels_), 1, [&](std::size_t l, std::size_t, std::size_t) {
      dispatch(int(l), [&]<bool Dense, bool Smooth>() {
#if VIDEO3DGS_HAS_AVX2_DISPATCH
        if (use_avx2()) return forward_level_avx2<Dense, Smooth>(int(l), inputs, n, out);
#endif
        forward_level_base<Dense, Smooth>(int(l), inputs, n, out);
      });
    });
  }

  /// Accumulates dL/dtheta into `dL_dtable` (param_count() scalars) and, if not null, dL/dx into
  /// `dL_dinputs` (n x Dims). `dL_dout` is kOutputs x n like the forward output.
  void backward(const Scalar* inputs, std::size_t n, const Scalar* dL_dout, Scalar* dL_dtable,
                Scalar* dL_dinputs = nullptr, ThreadPool* pool = nullptr) const {
    if (dL_dtable) {
      parallel_for_chunks(pool, std::size_t(active_levels_), 1, [&](std::size_t l, std::size_t, std::size_t) {
        dispatch(int(l), [&]<bool Dense, bool Smooth>() {
#if VIDEO3DGS_HAS_AVX2_DISPATCH
          if (use_avx2()) return backward_table_level_avx2<Dense, Smooth>(int(l), inputs, n, dL_dout, dL_dtable);
#endif
          backward_table_level_base<Dense, Smooth>(int(l), inputs, n, dL_dout, dL_dtable);
        });
      });
    }
    if (dL_dinputs) {
      parallel_for_chunks(pool, n, kInputGrain, [&](std::size_t, std::size_t b, std::size_t e) {
        backward_inputs(inputs, n, b, e, dL_dout, dL_dinputs);
      });
    }
  }

 private:
  static constexpr std::size_t kInputGrain = 1024;

#if VIDEO3DGS_HAS_AVX2_DISPATCH
  /// Whether the level kernels run their AVX2 copy (options().simd, validated by the constructor).
  [[nodiscard]] bool use_avx2() const noexcept {
    return resolve_isa(options_.simd, {Isa::avx2}) == Isa::avx2;
  }
#endif

  template <class F>
  void for_level(int l, F&& f) const {
    if (dense_[l])
      f(std::integral_constant<bool, true>{});
    else
      f(std::integral_constant<bool, false>{});
  }
  /// Calls f.template operator()<Dense, Smooth>() with this level's compile-time flags.
  template <class F>
  void dispatch(int l, F&& f) const {
    const bool smooth = options_.interpolation == GridInterpolation::smoothstep;
    if (dense_[l]) {
      if (smooth) f.template operator()<true, true>(); else f.template operator()<true, false>();
    } else {
      if (smooth) f.template operator()<false, true>(); else f.template operator()<false, false>();
    }
  }

  /// Per-point cell data of one level: corner indices (absolute entry), weights, and per-axis terms.
  struct Cell {
    std::array<std::uint32_t, kCorners> idx;
    std::array<Scalar, kCorners> w;
    std::array<Scalar, Dims> w1;   ///< S(f_d)
    std::array<Scalar, Dims> dw1;  ///< S'(f_d) R_{l,d} (0 where clamped)
  };

  template <bool Dense>
  inline void cell(int l, const Scalar* x, Cell& c) const {
    std::array<std::uint32_t, Dims> h0, h1;
    std::uint32_t stride = 1;
    for (int d = 0; d < Dims; ++d) {
      const std::uint32_t res = axis_res_[l][d];
      const Scalar rs = Scalar(res);
      Scalar xd = x[d];
      bool clamped = false;
      if (!(xd >= Scalar(0))) { xd = Scalar(0); clamped = true; }  // also maps NaN to 0
      if (xd > Scalar(1)) { xd = Scalar(1); clamped = true; }
      const Scalar p = xd * rs;
      std::uint32_t ci = static_cast<std::uint32_t>(p);
      if (ci >= res) ci = res - 1;
      const Scalar f = p - Scalar(ci);
      Scalar s, ds;
      if (options_.interpolation == GridInterpolation::smoothstep) {
        s = f * f * (Scalar(3) - Scalar(2) * f);
        ds = Scalar(6) * f * (Scalar(1) - f);
      } else {
        s = f;
        ds = Scalar(1);
      }
      c.w1[d] = s;
      c.dw1[d] = clamped ? Scalar(0) : ds * rs;
      if constexpr (Dense) {
        h0[d] = ci * stride;
        h1[d] = h0[d] + stride;
        stride *= res + 1;
      } else {
        h0[d] = ci * kPrimes[d];
        h1[d] = (ci + 1) * kPrimes[d];
      }
    }
    // Corner k has bit d set when it takes c_d + 1; built by doubling over the dimensions.
    c.idx[0] = 0;
    c.w[0] = Scalar(1);
    for (int d = 0; d < Dims; ++d) {
      const int half = 1 << d;
      const Scalar a1 = c.w1[d], a0 = Scalar(1) - c.w1[d];
      for (int k = 0; k < half; ++k) {
        if constexpr (Dense) {
          c.idx[k + half] = c.idx[k] + h1[d];
          c.idx[k] += h0[d];
        } else {
          c.idx[k + half] = c.idx[k] ^ h1[d];
          c.idx[k] ^= h0[d];
        }
        c.w[k + half] = c.w[k] * a1;
        c.w[k] *= a0;
      }
    }
    const auto off = static_cast<std::uint32_t>(level_offset_[l]);
    for (int k = 0; k < kCorners; ++k) {
      if constexpr (!Dense) c.idx[k] &= mask_;
      c.idx[k] += off;
    }
  }

  // Each level kernel is compiled twice: for the baseline ISA and, on x86 with GCC/Clang, for AVX2
  // (8-wide integer multiplies for the hash and wider corner arithmetic), chosen at run time. No FMA
  // is enabled, so both produce bit-identical results.
  template <bool Dense, bool Smooth>
  void forward_level_base(int l, const Scalar* inputs, std::size_t n, Scalar* out) const {
    forward_level<Dense, Smooth>(l, inputs, n, out);
  }
  template <bool Dense, bool Smooth>
  void backward_table_level_base(int l, const Scalar* inputs, std::size_t n, const Scalar* g, Scalar* t) const {
    backward_table_level<Dense, Smooth>(l, inputs, n, g, t);
  }
#if VIDEO3DGS_HAS_AVX2_DISPATCH
  template <bool Dense, bool Smooth>
  __attribute__((target("avx2"))) void forward_level_avx2(int l, const Scalar* inputs, std::size_t n, Scalar* out) const {
    forward_level<Dense, Smooth>(l, inputs, n, out);
  }
  template <bool Dense, bool Smooth>
  __attribute__((target("avx2"))) void backward_table_level_avx2(int l, const Scalar* inputs, std::size_t n, const Scalar* g,
                                                                 Scalar* t) const {
    backward_table_level<Dense, Smooth>(l, inputs, n, g, t);
  }
#endif

  /// Corner indices and weights of one level for a batch of up to kBatch points, structure-of-arrays
  /// (idx[k][p], w[k][p]) so that the per-dimension arithmetic vectorises; the table is then read or
  /// written in a tight scalar loop. Keeps the batch in L1.
  ///
  /// Corners whose weight is exactly 0 for every point of the batch are left out: when an axis has
  /// S(f_d) = 0 at every point (all on a vertex, as the time axis usually is for every frame when it is
  /// capped at frames - 1 cells: t = i / (n - 1) times n - 1 rounds back to i for most i and n) or
  /// S(f_d) = 1 at every point (x_d = 1), only the corners on that side are built (2^(Dims - 1) per
  /// such axis), the others (weight 0 x entry) add nothing. The kept corners keep their order (k
  /// ascending) and their weights are the same products (a dropped axis contributes a factor of
  /// exactly 1), so outputs and table gradients are bit-identical to evaluating all 2^Dims corners for
  /// finite table entries and gradients and a gradient buffer without -0 entries (0 x Inf or 0 x NaN
  /// is no longer formed, and -0 + 0 is no longer turned into +0).
  static constexpr std::size_t kBatch = 64;
  struct Batch {
    alignas(64) std::uint32_t idx[kCorners][kBatch];
    alignas(64) Scalar w[kCorners][kBatch];
    int corners = kCorners;  ///< corners built (the first `corners` rows)
  };
  /// Calls f.template operator()<KC>() with KC = the batch's corner count when it is 2^Dims or
  /// 2^(Dims - 1) (compile-time loop bounds for the common cases), else KC = 0 (read b.corners).
  template <class F>
  VIDEO3DGS_KERNEL_INLINE static void with_corners(int corners, F&& f) {
    if (corners == kCorners)
      f.template operator()<kCorners>();
    else if (corners == kCorners / 2)
      f.template operator()<kCorners / 2>();
    else
      f.template operator()<0>();
  }

  template <bool Dense, bool Smooth>
  VIDEO3DGS_KERNEL_INLINE void batch_cells(int l, const Scalar* inputs, std::size_t count, Batch& b) const {
    std::uint32_t stride = 1;
    for (std::size_t p = 0; p < count; ++p) {
      b.idx[0][p] = 0;
      b.w[0][p] = Scalar(1);
    }
    int corners = 1;
    for (int d = 0; d < Dims; ++d) {
      const std::uint32_t res = axis_res_[l][d];
      const Scalar rs = Scalar(res);
      const auto ires = static_cast<std::int32_t>(res);
      const std::uint32_t mult = Dense ? stride : kPrimes[d];
      alignas(64) std::uint32_t h0[kBatch], h1[kBatch];
      alignas(64) Scalar a0[kBatch], a1[kBatch];
      alignas(64) Scalar xs[kBatch];
      for (std::size_t p = 0; p < count; ++p) {  // gather one coordinate and clamp it (NaN -> 0)
        const Scalar v = inputs[p * Dims + d];
        xs[p] = v > Scalar(0) ? (v < Scalar(1) ? v : Scalar(1)) : Scalar(0);
      }
      int low = 1, high = 1;  // every point has S(f_d) = 0 (low) / = 1 (high)
      VIDEO3DGS_IVDEP
      for (std::size_t p = 0; p < count; ++p) {
        const Scalar pos = xs[p] * rs;
        const auto c0 = static_cast<std::int32_t>(pos);         // floor (pos >= 0)
        const std::int32_t ci = c0 - std::int32_t(c0 >= ires);  // x = 1 falls in the last cell, f = 1
        const Scalar f = pos - Scalar(ci);
        const Scalar sw = Smooth ? f * f * (Scalar(3) - Scalar(2) * f) : f;
        a1[p] = sw;
        a0[p] = Scalar(1) - sw;
        low &= int(sw == Scalar(0));
        high &= int(sw == Scalar(1));
        h0[p] = static_cast<std::uint32_t>(ci) * mult;
        h1[p] = h0[p] + mult;
      }
      if (low || high) {  // one side only; its factor is exactly 1 (1 - 0, or 1)
        const std::uint32_t* __restrict hk = low ? h0 : h1;
        for (int k = 0; k < corners; ++k) {
          std::uint32_t* __restrict ik = b.idx[k];
          VIDEO3DGS_IVDEP
          for (std::size_t p = 0; p < count; ++p) {
            if constexpr (Dense)
              ik[p] += hk[p];
            else
              ik[p] ^= hk[p];
          }
        }
      } else {
        for (int k = 0; k < corners; ++k) {
          std::uint32_t* __restrict lo = b.idx[k];
          std::uint32_t* __restrict hi = b.idx[k + corners];
          Scalar* __restrict wl = b.w[k];
          Scalar* __restrict wh = b.w[k + corners];
          VIDEO3DGS_IVDEP
          for (std::size_t p = 0; p < count; ++p) {
            if constexpr (Dense) {
              hi[p] = lo[p] + h1[p];
              lo[p] += h0[p];
            } else {
              hi[p] = lo[p] ^ h1[p];
              lo[p] ^= h0[p];
            }
            wh[p] = wl[p] * a1[p];
            wl[p] *= a0[p];
          }
        }
        corners *= 2;
      }
      if constexpr (Dense) stride *= res + 1;
    }
    const auto off = static_cast<std::uint32_t>(level_offset_[l]);
    const std::uint32_t mask = mask_;
    for (int k = 0; k < corners; ++k) {
      std::uint32_t* __restrict ik = b.idx[k];
      VIDEO3DGS_IVDEP
      for (std::size_t p = 0; p < count; ++p) {
        if constexpr (Dense)
          ik[p] += off;
        else
          ik[p] = (ik[p] & mask) + off;
      }
    }
    b.corners = corners;
  }

#if defined(__GNUC__)
  static constexpr bool kPairLanes =
      FeaturesPerLevel == 2 && (std::is_same_v<Scalar, float> || std::is_same_v<Scalar, double>);
#endif

  /// Large levels miss the cache on nearly every corner: touch the lines of point p + kPrefetch while
  /// point p is processed, so the misses overlap (docs/performance.md has the measurement).
  /// Levels whose table is larger than this (bytes) are prefetched (smaller ones stay in L2).
  static constexpr std::size_t kPrefetch = 4;
  static constexpr std::size_t kPrefetchBytes = std::size_t(512) << 10;
  [[nodiscard]] bool wants_prefetch(int l) const noexcept {
    return level_size_[l] * FeaturesPerLevel * sizeof(Scalar) > kPrefetchBytes;
  }
  VIDEO3DGS_KERNEL_INLINE static void prefetch_points(const Batch& b, const Scalar* base, std::size_t from, std::size_t to,
                                                      bool write) {
#if defined(__GNUC__)
    for (std::size_t p = from; p < to; ++p)
      for (int k = 0; k < b.corners; ++k) {
        const Scalar* e = base + std::size_t(b.idx[k][p]) * FeaturesPerLevel;
        if (write)
          __builtin_prefetch(e, 1, 3);
        else
          __builtin_prefetch(e, 0, 3);
      }
#else
    (void)b; (void)base; (void)from; (void)to; (void)write;
#endif
  }

  template <bool Dense, bool Smooth>
  VIDEO3DGS_KERNEL_INLINE void forward_level(int l, const Scalar* inputs, std::size_t n, Scalar* out) const {
    constexpr int F = FeaturesPerLevel;
    const Scalar* table = table_.data();
    Scalar* o = out + std::size_t(l) * F * n;
    const bool prefetch = wants_prefetch(l);
    Batch b;
    for (std::size_t i0 = 0; i0 < n; i0 += kBatch) {
      const std::size_t count = std::min(kBatch, n - i0);
      batch_cells<Dense, Smooth>(l, inputs + i0 * Dims, count, b);
      with_corners(b.corners, [&]<int KC>() VIDEO3DGS_LAMBDA_INLINE {
        const int nc = KC ? KC : b.corners;
        if (prefetch) prefetch_points(b, table, 0, std::min(kPrefetch, count), false);
        for (std::size_t p = 0; p < count; ++p) {
          if (prefetch && p + kPrefetch < count) prefetch_points(b, table, p + kPrefetch, p + kPrefetch + 1, false);
#if defined(__GNUC__)
          if constexpr (kPairLanes) {  // one 2-lane load / multiply / add per corner (same IEEE ops per lane)
            using V2 = typename detail::Pair<Scalar>::type;
            V2 acc = {Scalar(0), Scalar(0)};
            for (int k = 0; k < nc; ++k) {
              V2 e;
              std::memcpy(&e, table + std::size_t(b.idx[k][p]) * 2, sizeof(V2));
              acc += b.w[k][p] * e;
            }
            o[i0 + p] = acc[0];
            o[n + i0 + p] = acc[1];
            continue;
          }
#endif
          std::array<Scalar, F> acc{};
          for (int k = 0; k < nc; ++k) {
            const Scalar* e = table + std::size_t(b.idx[k][p]) * F;
            const Scalar w = b.w[k][p];
            for (int q = 0; q < F; ++q) acc[q] += w * e[q];
          }
          for (int q = 0; q < F; ++q) o[std::size_t(q) * n + i0 + p] = acc[q];
        }
      });
    }
  }

  template <bool Dense, bool Smooth>
  VIDEO3DGS_KERNEL_INLINE void backward_table_level(int l, const Scalar* inputs, std::size_t n, const Scalar* dL_dout, Scalar* dL_dtable) const {
    constexpr int F = FeaturesPerLevel;
    const Scalar* g = dL_dout + std::size_t(l) * F * n;
    const bool prefetch = wants_prefetch(l);
    Batch b;
    for (std::size_t i0 = 0; i0 < n; i0 += kBatch) {
      const std::size_t count = std::min(kBatch, n - i0);
      batch_cells<Dense, Smooth>(l, inputs + i0 * Dims, count, b);
      with_corners(b.corners, [&]<int KC>() VIDEO3DGS_LAMBDA_INLINE {
        const int nc = KC ? KC : b.corners;
        if (prefetch) prefetch_points(b, dL_dtable, 0, std::min(kPrefetch, count), true);
        for (std::size_t p = 0; p < count; ++p) {
          if (prefetch && p + kPrefetch < count) prefetch_points(b, dL_dtable, p + kPrefetch, p + kPrefetch + 1, true);
#if defined(__GNUC__)
          if constexpr (kPairLanes) {
            using V2 = typename detail::Pair<Scalar>::type;
            const V2 gv = {g[i0 + p], g[n + i0 + p]};
            for (int k = 0; k < nc; ++k) {
              Scalar* ep = dL_dtable + std::size_t(b.idx[k][p]) * 2;
              V2 e;
              std::memcpy(&e, ep, sizeof(V2));
              e += b.w[k][p] * gv;
              std::memcpy(ep, &e, sizeof(V2));
            }
            continue;
          }
#endif
          std::array<Scalar, F> gi;
          for (int q = 0; q < F; ++q) gi[q] = g[std::size_t(q) * n + i0 + p];
          for (int k = 0; k < nc; ++k) {
            Scalar* e = dL_dtable + std::size_t(b.idx[k][p]) * F;
            const Scalar w = b.w[k][p];
            for (int q = 0; q < F; ++q) e[q] += w * gi[q];
          }
        }
      });
    }
  }

  void backward_inputs(const Scalar* inputs, std::size_t n, std::size_t b, std::size_t e, const Scalar* dL_dout,
                       Scalar* dL_dinputs) const {
    constexpr int F = FeaturesPerLevel;
    const Scalar* table = table_.data();
    Cell c;
    for (std::size_t i = b; i < e; ++i) {
      std::array<Scalar, Dims> gx{};
      for (int l = 0; l < active_levels_; ++l) {
        std::array<Scalar, F> gi;
        for (int q = 0; q < F; ++q) gi[q] = dL_dout[(std::size_t(l) * F + q) * n + i];
        for_level(l, [&]<bool Dense>(std::integral_constant<bool, Dense>) { cell<Dense>(l, inputs + i * Dims, c); });
        // v_k = <theta[i(c + k)], dL/dy_l>
        std::array<Scalar, kCorners> v;
        for (int k = 0; k < kCorners; ++k) {
          const Scalar* t = table + std::size_t(c.idx[k]) * F;
          Scalar s = 0;
          for (int q = 0; q < F; ++q) s += t[q] * gi[q];
          v[k] = s;
        }
        for (int d = 0; d < Dims; ++d) {
          if (c.dw1[d] == Scalar(0)) continue;
          Scalar acc = 0;
          for (int k = 0; k < kCorners; ++k) {
            Scalar p = (k >> d) & 1 ? Scalar(1) : Scalar(-1);
            for (int o = 0; o < Dims; ++o)
              if (o != d) p *= (k >> o) & 1 ? c.w1[o] : Scalar(1) - c.w1[o];
            acc += p * v[k];
          }
          gx[d] += acc * c.dw1[d];
        }
      }
      for (int d = 0; d < Dims; ++d) dL_dinputs[i * Dims + d] += gx[d];
    }
  }

  HashGridOptions options_;
  std::array<std::uint32_t, Levels> resolution_{};
  std::array<std::array<std::uint32_t, Dims>, Levels> axis_res_{};  ///< R_{l,d}
  std::array<bool, Levels> dense_{};
  std::array<std::size_t, Levels> level_size_{};
  std::array<std::size_t, Levels> level_offset_{};
  std::size_t entries_ = 0;
  std::size_t table_size_ = kTableSize;
  std::uint32_t mask_ = static_cast<std::uint32_t>(kTableSize - 1);
  int active_levels_ = Levels;
  std::vector<Scalar> table_;
};

/// The deformation field's grid (docs/method.md): (x, y, z, t), 16 levels x 2 features, 2^19 entries.
template <class Scalar, int Log2TableSize = 19>
using HashGrid4D = HashGrid<Scalar, 4, 16, 2, Log2TableSize>;

}  // namespace video3dgs
