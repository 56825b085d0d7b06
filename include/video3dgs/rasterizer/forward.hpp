#pragma once
/// @file
/// Forward pass: project -> colour (SH or given) -> sort -> bin -> composite front to back.
///
/// Culled (not visible, zero gradients): what project_gaussian culls, and a Gaussian with a non-finite
/// colour or a non-finite SH coefficient among those read (the first (evaluated degree + 1)² per channel).
///
/// Per pixel (centre p), over its tile's Gaussians i in (depth, index) order:
///   power_i = (A dx² + C dy²)/2 + B dx dy,  d = p - mean2d_i;   skip power < 0
///   alpha_i = min(alpha_max, o_i exp(-power_i));                 skip alpha_i < alpha_min
///   stop once T_i (1 - alpha_i) < min_transmittance: without blending i (the method's rule), or
///   after blending it (RasterSettings::blend_at_stop)
///   colour = sum_i c_i alpha_i T_i + T_final bg,  alpha = 1 - T_final,  depth = sum_i z_i alpha_i T_i
/// with T_i = prod_{j<i} (1 - alpha_j) (depth only with RasterSettings::depth, else zeros).
///
/// CPU specifics: a tile walks its Gaussians in the outer loop and, per Gaussian, only the pixels of
/// each row inside the footprint {power <= p_max} (closed-form x-interval), instead of all pixels of the
/// tile; it stops as soon as every pixel of the tile is saturated. The skip decisions are the
/// per-pixel ones above, so the result equals the per-pixel loop exactly. The per-tile kernel runs on
/// the instruction set RasterSettings::simd names (simd.hpp, detail/kernels.inc); every path gives the
/// same bits.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <type_traits>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/gaussian/activations.hpp"
#include "video3dgs/rasterizer/binning.hpp"
#include "video3dgs/rasterizer/context.hpp"
#include "video3dgs/rasterizer/detail/kernels.hpp"
#include "video3dgs/rasterizer/project.hpp"
#include "video3dgs/sh/basis.hpp"

namespace video3dgs {
/// Runs the forward pass into `ctx` (see context.hpp for what it holds afterwards).
/// @param colors  empty: colour from SH (Channels must be 3); else N x Channels colours per Gaussian.
/// @throws option_error for an invalid camera, settings, mismatched spans, or Channels != 3 without colours.
template <int TileSize, class Scalar, int C>
void rasterize_forward(const Camera<Scalar>& cam, const RasterSettings<Scalar, C>& settings, const GaussianParams<Scalar>& params,
                       std::span<const Scalar> colors, RasterContext<Scalar, C>& ctx, ThreadPool* pool) {
  static_assert(TileSize == 8 || TileSize == 16 || TileSize == 32, "video3dgs: TileSize must be 8, 16 or 32");
  cam.validate();
  settings.validate();
  params.validate();
  const std::size_t n = params.count;
  if (!colors.empty() && colors.size() != n * C)
    throw option_error("option.gaussians", "colors", "has " + std::to_string(colors.size()) + " values, expected " + std::to_string(n * C));
  if (colors.empty() && C != 3)
    throw option_error("option.gaussians", "colors", "SH colour has 3 channels: pass per-Gaussian colours for other channel counts");
  if (n >= 0xffffffffull) throw option_error("option.gaussians", "count", "at most 2^32 - 1 Gaussians");

  ctx.camera = cam;
  ctx.settings = settings;
  ctx.params = params;
  ctx.colors = colors;
  ctx.sh_degree = std::min(settings.active_sh_degree, params.sh_degree);
  ctx.tile_size = TileSize;
  ctx.tiles_x = (cam.width + TileSize - 1) / TileSize;
  ctx.tiles_y = (cam.height + TileSize - 1) / TileSize;

  // 1. Project and colour every Gaussian.
  ctx.projected.resize(n);
  ctx.visible.resize(n);
  ctx.radii.resize(n);
  ctx.color.resize(n * C);
  ctx.color_clamped.resize(n);
  const Eigen::Matrix<Scalar, 3, 1> centre = cam.center();
  const int K = params.sh_coeffs();
  parallel_for(pool, n, [&](std::size_t i) {
    auto& pg = ctx.projected[i];
    bool ok = project_gaussian(cam, settings, &params.mean[3 * i], &params.log_scale[3 * i], &params.rotation[4 * i],
                               params.opacity_logit[i], pg);
    Scalar* col = &ctx.color[i * C];
    std::uint8_t clamp_bits = 0;
    if (ok) {
      if (!colors.empty()) {
        for (int c = 0; c < C; ++c) col[c] = colors[i * C + c];
      } else {
        // A non-finite coefficient read gives a non-finite colour (sh::evaluate never clamps it to 0),
        // culled below: clamped to 0, its backward would be inf x 0 = NaN in dL/ddir, hence dL/dmean.
        const Eigen::Matrix<Scalar, 3, 1> m(params.mean[3 * i], params.mean[3 * i + 1], params.mean[3 * i + 2]);
        Scalar inv_len;
        const auto dir = sh::view_direction(m, centre, inv_len);
        bool clamped[3];
        sh::evaluate<Scalar, 3>(ctx.sh_degree, dir, &params.sh[static_cast<std::size_t>(3 * K) * i], col, clamped);
        for (int c = 0; c < 3; ++c) clamp_bits |= clamped[c] ? std::uint8_t(1u << c) : std::uint8_t(0);
      }
      for (int c = 0; c < C; ++c) ok = ok && std::isfinite(col[c]);
    }
    ctx.visible[i] = ok ? 1 : 0;
    ctx.radii[i] = ok ? pg.radius : 0;
    ctx.color_clamped[i] = clamp_bits;
  }, 1024);

  // 2. Depth sort of the visible ones, ties by index.
  ctx.order.clear();
  ctx.keys.clear();
  for (std::size_t i = 0; i < n; ++i)
    if (ctx.visible[i]) {
      ctx.order.push_back(static_cast<std::uint32_t>(i));
      ctx.keys.push_back(detail::depth_key(ctx.projected[i].depth));
    }
  detail::radix_sort_pairs(ctx.keys, ctx.order, ctx.keys_tmp, ctx.order_tmp, ctx.radix_hist, 8 * static_cast<int>(sizeof(Scalar)));
  const std::size_t nv = ctx.order.size();
  ctx.sorted.resize(nv);
  ctx.rank.resize(n);
  parallel_for(pool, nv, [&](std::size_t s) {
    const std::uint32_t id = ctx.order[s];
    ctx.rank[id] = static_cast<std::uint32_t>(s);
    const auto& pg = ctx.projected[id];
    auto& g = ctx.sorted[s];
    g.u = pg.u, g.v = pg.v;
    g.A = pg.conic[0], g.B = pg.conic[1], g.C = pg.conic[2];
    g.opacity = pg.opacity;
    g.depth = pg.depth;
    g.p_max = pg.p_max;
    g.two_a_p = Scalar(2) * g.A * pg.p_max;
    g.det = g.A * g.C - g.B * g.B;
    g.inv_A = Scalar(1) / g.A;
    g.band_dy = std::sqrt(Scalar(2) * pg.p_max) * pg.cov[1] / std::sqrt(pg.cov[0]);
    for (int c = 0; c < C; ++c) g.color[c] = ctx.color[id * C + c];
    g.x0 = pg.x0, g.y0 = pg.y0, g.x1 = pg.x1, g.y1 = pg.y1;
    g.id = id;
  }, 2048);

  // 3. Tile lists.
  detail::bin_tiles<TileSize>(ctx, pool);

  // 4. Composite, tile by tile.
  const int W = cam.width, H = cam.height;
  const std::size_t tiles = static_cast<std::size_t>(ctx.tiles_x) * static_cast<std::size_t>(ctx.tiles_y);
  if (ctx.image.width() != W || ctx.image.height() != H) {  // every pixel is written below
    ctx.image.resize(W, H);
    ctx.alpha.resize(W, H);
    ctx.depth.resize(W, H);
  }
  ctx.final_T.resize(static_cast<std::size_t>(W) * H);
  ctx.last_contrib.resize(static_cast<std::size_t>(W) * H);
  ctx.tile_evals.assign(tiles, 0);
  const RasterSimd simd = resolve_raster_simd(settings.simd);
  parallel_for(pool, tiles, [&](std::size_t t) { detail::forward_tile<TileSize>(simd, ctx, t); }, 1);
  ctx.stats.visible = nv;
  ctx.stats.tile_pairs = ctx.tile_list.size();
  ctx.stats.evaluations = 0;
  for (std::size_t v : ctx.tile_evals) ctx.stats.evaluations += v;
}

}  // namespace video3dgs
