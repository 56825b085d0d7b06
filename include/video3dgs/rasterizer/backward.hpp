#pragma once
/// @file
/// Backward pass of the rasterizer, hand-derived.
///
/// Compositing (per pixel, Gaussians i = 0..n-1 front to back, T_0 = 1, T_{i+1} = T_i (1 - alpha_i)):
///   C = sum_i c_i alpha_i T_i + T_n bg,   D = sum_i z_i alpha_i T_i,   A = 1 - T_n.
/// Let X_i be the normalised colour behind i (background included):
///   X_{n-1} = bg,  X_{i-1} = alpha_i c_i + (1 - alpha_i) X_i   (so C = sum_{j<i} ... + T_i (alpha_i c_i + (1 - alpha_i) X_i)).
/// Then, walking back to front with T_i = T_{i+1} / (1 - alpha_i):
///   dC/dc_i = alpha_i T_i,   dC/dalpha_i = T_i (c_i - X_i),   dC/dbg = T_n
///   dD/dz_i = alpha_i T_i,   dD/dalpha_i = T_i (z_i - Y_i)    (Y: same recursion, Y_{n-1} = 0)
///   dA/dalpha_i = T_i (1 - Z_i)                               (Z: same recursion with colour 1, Z_{n-1} = 0)
/// alpha = o G (unless clamped at alpha_max: no gradient), G = exp(-power):
///   dalpha/do = G,  dalpha/dpower = -alpha,
///   dpower/dA = dx²/2, dpower/dB = dx dy, dpower/dC = dy²/2,
///   dpower/du = -(A dx + B dy), dpower/dv = -(C dy + B dx)        (d = pixel centre - (u, v)).
/// Blend weight: W_i = sum_p alpha_i T_i over the pixels where i was blended (its share of the
/// composite; sum_i W_i = sum_p (1 - T_final(p)), the alpha image's sum), a by-product of the walk.
/// Evaluations: E_i = #{p in i's footprint rows : i is in front of p's last blended Gaussian}, the
/// pixel terms the walk computes for i (W_i / E_i: the weight it buys per unit of compositing work).
/// Per (tile, Gaussian) slot the pixel sums are written to a slot record (summed over 8 "virtual lanes"
/// row by row, then the lanes folded pairwise in a fixed order: the same bits for every SIMD path,
/// detail/kernels.inc), stored Gaussian-major (binning.hpp); each Gaussian then sums its records in
/// tile order (fixed order: bit-identical for any thread count), reading consecutive memory, and runs
/// the projection (project.hpp) and SH (sh/basis.hpp) backward passes.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <string>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/rasterizer/context.hpp"
#include "video3dgs/rasterizer/detail/kernels.hpp"
#include "video3dgs/rasterizer/forward.hpp"
#include "video3dgs/rasterizer/project.hpp"
#include "video3dgs/sh/basis.hpp"

namespace video3dgs {

/// Backward of `rasterize_forward` for the context it filled.
/// @param dL_dimage  W x H x Channels (required)
/// @param dL_dalpha  W x H or empty; @param dL_ddepth W x H or empty
/// @throws option_error if an image size does not match the forward pass, or the context is empty;
///         numeric_error (`numeric.non_finite`) if an output gradient is NaN or infinite.
template <int TileSize, class Scalar, int C>
void rasterize_backward(RasterContext<Scalar, C>& ctx, ConstImageView<Scalar, C> dL_dimage, ConstImageView<Scalar, 1> dL_dalpha,
                        ConstImageView<Scalar, 1> dL_ddepth, RasterGrads<Scalar, C>& grads, ThreadPool* pool) {
  const int W = ctx.camera.width, H = ctx.camera.height;
  if (ctx.tile_size != TileSize)
    throw option_error("option.raster", "backward", "context was made by a forward pass with another tile size (or none)");
  auto check_size = [&](int w, int h, const char* what) {
    if (w != W || h != H) throw option_error("option.raster", what, "size does not match the forward pass");
  };
  check_size(dL_dimage.width(), dL_dimage.height(), "dL_dimage");
  const bool has_alpha = !dL_dalpha.empty(), has_depth = !dL_ddepth.empty();
  if (has_alpha) check_size(dL_dalpha.width(), dL_dalpha.height(), "dL_dalpha");
  if (has_depth) check_size(dL_ddepth.width(), dL_ddepth.height(), "dL_ddepth");
  const std::size_t n = ctx.params.count;
  const auto& G = grads.gaussians;
  auto check_span = [&](std::size_t got, std::size_t want, const char* what) {
    if (got != 0 && got != want) throw option_error("option.raster", what, "gradient span has the wrong size");
  };
  const int K = ctx.params.sh_coeffs();
  check_span(G.dL_dmean.size(), 3 * n, "dL_dmean");
  check_span(G.dL_dlog_scale.size(), 3 * n, "dL_dlog_scale");
  check_span(G.dL_drotation.size(), 4 * n, "dL_drotation");
  check_span(G.dL_dopacity_logit.size(), n, "dL_dopacity_logit");
  check_span(G.dL_dsh.size(), static_cast<std::size_t>(3 * K) * n, "dL_dsh");
  check_span(grads.dL_dcolors.size(), n * C, "dL_dcolors");
  check_span(grads.dL_dmean2d.size(), 2 * n, "dL_dmean2d");
  check_span(grads.blend_weight.size(), n, "blend_weight");
  check_span(grads.blend_evals.size(), n, "blend_evals");
  if (!grads.blend_weight.empty() && has_depth)
    throw option_error("option.raster", "blend_weight", "is computed only without a depth gradient (its record entry holds the depth sums)");
  if (!grads.blend_evals.empty() && has_depth)
    throw option_error("option.raster", "blend_evals", "is computed only without a depth gradient (with the blend weights)");
  const bool blend_stats = !grads.blend_weight.empty() || !grads.blend_evals.empty();

  constexpr int R = 7 + C;  // slot record: u, v, A, B, C, opacity, depth, colour[C]
  const std::size_t tiles = static_cast<std::size_t>(ctx.tiles_x) * static_cast<std::size_t>(ctx.tiles_y);
  ctx.pair_grad.resize(ctx.tile_list.size() * R);
  ctx.tile_bg_grad.resize(tiles * C);
  if (blend_stats) ctx.pair_evals.resize(ctx.tile_list.size());

  // 1. Per tile: walk each pixel back to front, write per-slot sums (detail/kernels.inc).
  const RasterSimd simd = resolve_raster_simd(ctx.settings.simd, RasterPass::backward);
  parallel_for(pool, tiles, [&](std::size_t t) { detail::backward_tile<TileSize>(simd, ctx, dL_dimage, dL_dalpha, dL_ddepth, t, blend_stats); }, 1);

  const bool acc_mode = grads.accumulate;
  auto zero = [acc_mode](std::span<Scalar> s, std::size_t i, std::size_t n) {
    if (!s.empty() && !acc_mode) std::fill_n(s.begin() + static_cast<std::ptrdiff_t>(i * n), n, Scalar(0));
  };
  // Writes v into s[i] (overwrite mode) or adds it (accumulate mode).
  auto put = [acc_mode](std::span<Scalar> s, std::size_t i, Scalar v) {
    if (acc_mode)
      s[i] += v;
    else
      s[i] = v;
  };
  // 2. Background.
  for (int c = 0; c < C; ++c) {
    Scalar s = 0;
    for (std::size_t t = 0; t < tiles; ++t) s += ctx.tile_bg_grad[t * C + c];
    grads.dL_dbackground[c] = s;
  }

  // 3. Per Gaussian, in input order (parameters and gradients are read and written sequentially):
  //    culled ones get zero gradients; visible ones reduce their slots in tile order, then run the
  //    projection + SH backward.
  const Eigen::Matrix<Scalar, 3, 1> centre = ctx.camera.center();
  const auto& P = ctx.params;
  parallel_for(pool, n, [&](std::size_t i) {
    if (!ctx.visible[i]) {
      zero(grads.blend_weight, i, 1);
      zero(grads.blend_evals, i, 1);
      zero(G.dL_dmean, i, 3), zero(G.dL_dlog_scale, i, 3), zero(G.dL_drotation, i, 4), zero(G.dL_dopacity_logit, i, 1);
      zero(G.dL_dsh, i, static_cast<std::size_t>(3 * K)), zero(grads.dL_dcolors, i, C), zero(grads.dL_dmean2d, i, 2);
      return;
    }
    Scalar acc[R];
    for (int r = 0; r < R; ++r) acc[r] = Scalar(0);
    for (std::uint32_t j = ctx.gauss_begin[i]; j < ctx.gauss_begin[i + 1]; ++j) {
      const Scalar* rec = &ctx.pair_grad[static_cast<std::size_t>(j) * R];
      for (int r = 0; r < R; ++r) acc[r] += rec[r];
    }
    if (!has_depth) {  // entry 6 is the blend weight (detail/kernels.inc), not a depth gradient
      if (!grads.blend_weight.empty()) put(grads.blend_weight, i, acc[6]);
      acc[6] = Scalar(0);
    }
    if (!grads.blend_evals.empty()) {  // integers: exact in any order
      std::uint64_t evals = 0;
      for (std::uint32_t j = ctx.gauss_begin[i]; j < ctx.gauss_begin[i + 1]; ++j) evals += ctx.pair_evals[j];
      put(grads.blend_evals, i, static_cast<Scalar>(evals));
    }
    bool any = false;
    for (int r = 0; r < R; ++r) any = any || acc[r] != Scalar(0);
    if (!any) {  // hidden everywhere: every gradient is exactly zero (all are linear in acc)
      zero(G.dL_dmean, i, 3), zero(G.dL_dlog_scale, i, 3), zero(G.dL_drotation, i, 4), zero(G.dL_dopacity_logit, i, 1);
      zero(G.dL_dsh, i, static_cast<std::size_t>(3 * K)), zero(grads.dL_dcolors, i, C), zero(grads.dL_dmean2d, i, 2);
      return;
    }
    if (!grads.dL_dmean2d.empty()) put(grads.dL_dmean2d, 2 * i, acc[0]), put(grads.dL_dmean2d, 2 * i + 1, acc[1]);
    Scalar dmean[3] = {0, 0, 0}, dls[3], drot[4], dlogit;
    if (!G.dL_dsh.empty() && (!ctx.colors.empty() || C != 3)) zero(G.dL_dsh, i, static_cast<std::size_t>(3 * K));
    if (!grads.dL_dcolors.empty())
      for (int c = 0; c < C; ++c) put(grads.dL_dcolors, i * C + c, acc[7 + c]);
    if constexpr (C == 3) {
      if (ctx.colors.empty()) {
        const Eigen::Matrix<Scalar, 3, 1> m(P.mean[3 * i], P.mean[3 * i + 1], P.mean[3 * i + 2]);
        Scalar inv_len;
        const auto dir = sh::view_direction(m, centre, inv_len);
        bool clamped[3];
        for (int c = 0; c < 3; ++c) clamped[c] = (ctx.color_clamped[i] >> c) & 1u;
        Scalar dsh_local[48];
        Scalar* dsh = G.dL_dsh.empty() || acc_mode ? dsh_local : &G.dL_dsh[static_cast<std::size_t>(3 * K) * i];
        std::fill(dsh, dsh + 3 * K, Scalar(0));
        const auto ddir = sh::evaluate_backward<Scalar, 3>(ctx.sh_degree, dir, &P.sh[static_cast<std::size_t>(3 * K) * i], clamped,
                                                           &acc[7], dsh);
        if (acc_mode && !G.dL_dsh.empty())
          for (int k = 0; k < 3 * K; ++k) G.dL_dsh[static_cast<std::size_t>(3 * K) * i + std::size_t(k)] += dsh_local[k];
        const auto dm = sh::view_direction_backward(dir, inv_len, ddir);
        for (int k = 0; k < 3; ++k) dmean[k] += dm[k];
      }
    }
    ProjectedGaussianGrad<Scalar> pgrad;
    pgrad.u = acc[0], pgrad.v = acc[1];
    pgrad.conic[0] = acc[2], pgrad.conic[1] = acc[3], pgrad.conic[2] = acc[4];
    pgrad.opacity = acc[5];
    pgrad.depth = acc[6];
    project_gaussian_backward(ctx.camera, ctx.settings, &P.mean[3 * i], &P.log_scale[3 * i], &P.rotation[4 * i],
                              P.opacity_logit[i], pgrad, dmean, dls, drot, &dlogit);
    if (!G.dL_dmean.empty())
      for (std::size_t k = 0; k < 3; ++k) put(G.dL_dmean, 3 * i + k, dmean[k]);
    if (!G.dL_dlog_scale.empty())
      for (std::size_t k = 0; k < 3; ++k) put(G.dL_dlog_scale, 3 * i + k, dls[k]);
    if (!G.dL_drotation.empty())
      for (std::size_t k = 0; k < 4; ++k) put(G.dL_drotation, 4 * i + k, drot[k]);
    if (!G.dL_dopacity_logit.empty()) put(G.dL_dopacity_logit, i, dlogit);
  }, 512);
}

}  // namespace video3dgs
