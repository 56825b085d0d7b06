#pragma once
/// @file
/// Depth sort and tile binning.
///
/// 1. Visible Gaussians are sorted by (depth, input index) with a stable LSD radix sort on the IEEE
///    bits of the (positive) depth: deterministic, ties broken by input index.
/// 2. Each Gaussian's footprint {power <= p_max} (the set where alpha can reach alpha_min) is intersected
///    with the tile grid row by row of tiles (exact ellipse x-range over each band, not just its bounding
///    box). Lists are filled in depth order, so every tile's list comes out sorted.
/// 3. The transpose: each slot's position in a Gaussian-major order (input index, then tile order).
///    The backward pass writes each slot's gradient record there, so every Gaussian then sums its
///    records from consecutive memory, in input order and in a fixed order (gradients do not depend
///    on the thread count).
///
/// Because the footprint, not the tile, decides which pixels a Gaussian reaches, the image does not
/// depend on the tile size (bit-identical).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/rasterizer/context.hpp"

namespace video3dgs::detail {

/// Monotone unsigned key of a positive float/double.
template <class Scalar>
[[nodiscard]] inline std::uint64_t depth_key(Scalar z) noexcept {
  if constexpr (sizeof(Scalar) == 4) {
    std::uint32_t b;
    std::memcpy(&b, &z, 4);
    return b;
  } else {
    std::uint64_t b;
    std::memcpy(&b, &z, 8);
    return b;
  }
}

/// Stable LSD radix sort of `vals` by `keys` (11-bit digits; passes whose digit is constant are skipped).
inline void radix_sort_pairs(std::vector<std::uint64_t>& keys, std::vector<std::uint32_t>& vals,
                             std::vector<std::uint64_t>& keys_tmp, std::vector<std::uint32_t>& vals_tmp,
                             std::vector<std::uint32_t>& hist, int key_bits) {
  const std::size_t n = keys.size();
  keys_tmp.resize(n);
  vals_tmp.resize(n);
  constexpr int kBits = 11, kBuckets = 1 << kBits;
  const int passes = (key_bits + kBits - 1) / kBits;
  hist.assign(static_cast<std::size_t>(passes) * kBuckets, 0);
  for (std::size_t i = 0; i < n; ++i)
    for (int p = 0; p < passes; ++p) ++hist[p * kBuckets + ((keys[i] >> (p * kBits)) & (kBuckets - 1))];
  for (int p = 0; p < passes; ++p) {
    std::uint32_t* h = &hist[p * kBuckets];
    if (n == 0 || h[(keys[0] >> (p * kBits)) & (kBuckets - 1)] == n) continue;  // constant digit
    std::uint32_t sum = 0;
    for (int b = 0; b < kBuckets; ++b) {
      const std::uint32_t c = h[b];
      h[b] = sum;
      sum += c;
    }
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint32_t dst = h[(keys[i] >> (p * kBits)) & (kBuckets - 1)]++;
      keys_tmp[dst] = keys[i];
      vals_tmp[dst] = vals[i];
    }
    keys.swap(keys_tmp);
    vals.swap(vals_tmp);
  }
}

/// x-interval [lo, hi] (pixel coordinates) of the footprint on the horizontal line v + dy.
template <class Scalar, int C>
inline bool footprint_row(const SortedGaussian<Scalar, C>& g, Scalar dy, Scalar& lo, Scalar& hi) noexcept {
  const Scalar disc = g.two_a_p - g.det * dy * dy;
  if (disc < Scalar(0)) return false;
  const Scalar half = std::sqrt(disc) * g.inv_A;
  const Scalar xc = g.u - g.B * dy * g.inv_A;
  lo = xc - half;
  hi = xc + half;
  return true;
}

/// x-interval of the footprint over the band of pixel rows [ya, yb] (inclusive): the ellipse's
/// rightmost/leftmost points are at dy = +- sqrt(2p) b / sqrt(a) (2D covariance [[a, b], [b, c]],
/// precomputed as g.band_dy); clamp them into the band.
template <class Scalar, int C>
inline bool footprint_band(const SortedGaussian<Scalar, C>& g, int ya, int yb, Scalar& lo, Scalar& hi) noexcept {
  const Scalar da = Scalar(ya) + Scalar(0.5) - g.v, db = Scalar(yb) + Scalar(0.5) - g.v;
  const Scalar dr = g.band_dy;
  auto eval = [&](Scalar dy, Scalar& l, Scalar& h) {
    const Scalar disc = std::max(Scalar(0), g.two_a_p - g.det * dy * dy);
    const Scalar half = std::sqrt(disc) * g.inv_A;
    const Scalar xc = g.u - g.B * dy * g.inv_A;
    l = xc - half;
    h = xc + half;
  };
  Scalar l1, h1, l2, h2;
  eval(std::clamp(-dr, da, db), l1, h1);  // leftmost
  eval(std::clamp(dr, da, db), l2, h2);   // rightmost
  lo = std::min(l1, l2);
  hi = std::max(h1, h2);
  return std::isfinite(lo) && std::isfinite(hi);
}

/// Tile columns [tx0, tx1) a Gaussian covers in tile row ty.
template <int TileSize, class Scalar, int C>
inline void tile_columns(const SortedGaussian<Scalar, C>& g, int ty, int& tx0, int& tx1) noexcept {
  const int ya = std::max(g.y0, ty * TileSize), yb = std::min(g.y1, (ty + 1) * TileSize) - 1;
  Scalar lo, hi;
  tx0 = tx1 = 0;
  if (ya > yb || !footprint_band(g, ya, yb, lo, hi)) return;
  const Scalar margin = Scalar(0.02);
  const Scalar px0 = std::ceil(lo - margin - Scalar(0.5)), px1 = std::floor(hi + margin - Scalar(0.5)) + 1;
  const int x0 = static_cast<int>(std::max(px0, Scalar(g.x0))), x1 = static_cast<int>(std::min(px1, Scalar(g.x1)));
  if (x0 >= x1) return;
  tx0 = x0 / TileSize;
  tx1 = (x1 - 1) / TileSize + 1;
}

/// Builds ctx.tile_begin / tile_list / gauss_begin / slot_record from ctx.sorted.
template <int TileSize, class Scalar, int C>
void bin_tiles(RasterContext<Scalar, C>& ctx, ThreadPool* pool) {
  const std::size_t n = ctx.sorted.size();
  const int tiles_x = ctx.tiles_x, tiles_y = ctx.tiles_y;
  const std::size_t tiles = static_cast<std::size_t>(tiles_x) * static_cast<std::size_t>(tiles_y);
  constexpr std::size_t kGrain = 4096;
  const std::size_t chunks = chunk_count(n, kGrain);
  auto& counts = ctx.chunk_counts;  // chunks x tiles histogram
  counts.assign(chunks * tiles, 0);
  // gauss_begin is indexed by input index (culled Gaussians get empty ranges).
  const std::size_t n_in = ctx.visible.size();
  ctx.gauss_begin.assign(n_in + 1, 0);
  // Pass 1: per-Gaussian and per-(chunk, tile) counts.
  parallel_for_chunks(pool, n, kGrain, [&](std::size_t k, std::size_t b, std::size_t e) {
    std::uint32_t* h = &counts[k * tiles];
    for (std::size_t s = b; s < e; ++s) {
      const auto& g = ctx.sorted[s];
      const int ty0 = g.y0 / TileSize, ty1 = (g.y1 - 1) / TileSize + 1;
      std::uint32_t cnt = 0;
      for (int ty = ty0; ty < ty1; ++ty) {
        int tx0, tx1;
        tile_columns<TileSize>(g, ty, tx0, tx1);
        for (int tx = tx0; tx < tx1; ++tx) ++h[static_cast<std::size_t>(ty) * tiles_x + tx];
        cnt += static_cast<std::uint32_t>(tx1 - tx0);
      }
      ctx.gauss_begin[g.id + 1] = cnt;
    }
  });
  // Prefix sums (serial, O(chunks x tiles + n)).
  std::uint64_t total = 0;
  for (std::size_t i = 0; i < n_in; ++i) {
    total += ctx.gauss_begin[i + 1];
    if (total > 0xffffffffull) throw numeric_error("numeric.overflow", "rasterizer", "more than 2^32 tile-Gaussian pairs");
    ctx.gauss_begin[i + 1] = static_cast<std::uint32_t>(total);
  }
  ctx.tile_begin.assign(tiles + 1, 0);
  std::uint32_t running = 0;
  for (std::size_t t = 0; t < tiles; ++t) {
    ctx.tile_begin[t] = running;
    for (std::size_t k = 0; k < chunks; ++k) {
      const std::uint32_t c = counts[k * tiles + t];
      counts[k * tiles + t] = running;  // becomes chunk k's write cursor in tile t
      running += c;
    }
  }
  ctx.tile_begin[tiles] = running;
  ctx.tile_list.resize(running);
  ctx.slot_record.resize(running);
  // Pass 2: fill (chunk k writes only its own ranges).
  parallel_for_chunks(pool, n, kGrain, [&](std::size_t k, std::size_t b, std::size_t e) {
    std::uint32_t* cursor = &counts[k * tiles];
    for (std::size_t s = b; s < e; ++s) {
      const auto& g = ctx.sorted[s];
      const int ty0 = g.y0 / TileSize, ty1 = (g.y1 - 1) / TileSize + 1;
      std::uint32_t out = ctx.gauss_begin[g.id];
      for (int ty = ty0; ty < ty1; ++ty) {
        int tx0, tx1;
        tile_columns<TileSize>(g, ty, tx0, tx1);
        for (int tx = tx0; tx < tx1; ++tx) {
          const std::uint32_t slot = cursor[static_cast<std::size_t>(ty) * tiles_x + tx]++;
          ctx.tile_list[slot] = static_cast<std::uint32_t>(s);
          ctx.slot_record[slot] = out++;
        }
      }
    }
  });
}

}  // namespace video3dgs::detail
