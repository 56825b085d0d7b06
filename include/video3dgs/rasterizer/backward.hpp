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
/// Per (tile, Gaussian) slot the pixel sums are written to a slot record; each Gaussian then sums its
/// slots in tile order (fixed order: bit-identical for any thread count) and runs the projection
/// (project.hpp) and SH (sh/basis.hpp) backward passes.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <string>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/rasterizer/context.hpp"
#include "video3dgs/rasterizer/detail/lanes.hpp"
#include "video3dgs/rasterizer/forward.hpp"
#include "video3dgs/rasterizer/project.hpp"
#include "video3dgs/sh/basis.hpp"

namespace video3dgs {

/// Backward of `rasterize_forward` for the context it filled.
/// @param dL_dimage  W x H x Channels (required)
/// @param dL_dalpha  W x H or empty; @param dL_ddepth W x H or empty
/// @throws option_error if an image size does not match the forward pass, or the context is empty;
///         numeric_error (`numeric.nonfinite`) if an output gradient is NaN or infinite.
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

  constexpr int R = 7 + C;  // slot record: u, v, A, B, C, opacity, depth, colour[C]
  const std::size_t tiles = static_cast<std::size_t>(ctx.tiles_x) * static_cast<std::size_t>(ctx.tiles_y);
  ctx.pair_grad.resize(ctx.tile_list.size() * R);
  ctx.slot_live.resize(ctx.tile_list.size());
  ctx.tile_bg_grad.resize(tiles * C);
  const Scalar amax = ctx.settings.alpha_max, amin = ctx.settings.alpha_min;
  const auto& bg = ctx.settings.background;

  // 1. Per tile: walk each pixel back to front, write per-slot sums.
  using LN = detail::Lanes<Scalar>;
  using V = typename LN::V;
  using I = typename LN::I;
  using Idx = typename LN::index_type;
  constexpr int NL = LN::n;
  parallel_for(pool, tiles, [&](std::size_t t) {
    // Planar per-pixel state, padded by one lane block (see forward.hpp).
    constexpr int P = TileSize * TileSize + NL;
    alignas(64) Scalar T[P], X[C][P], Y[P], Z[P], gC[C][P], gA[P], gD[P];
    alignas(64) Idx last[P];
    const int tx = static_cast<int>(t % ctx.tiles_x), ty = static_cast<int>(t / ctx.tiles_x);
    const int px0 = tx * TileSize, py0 = ty * TileSize;
    const int px1 = std::min(px0 + TileSize, W), py1 = std::min(py0 + TileSize, H);
    Idx max_last = 0;
    Idx row_last[TileSize];  // per row: max last contributor (rows a Gaussian cannot affect are skipped)
    for (int y = 0; y < TileSize; ++y) row_last[y] = 0;
    Scalar bg_grad[C];
    for (int c = 0; c < C; ++c) bg_grad[c] = Scalar(0);
    for (int p = 0; p < P; ++p) {
      last[p] = 0, T[p] = Scalar(1), Y[p] = Z[p] = gA[p] = gD[p] = Scalar(0);
      for (int c = 0; c < C; ++c) X[c][p] = gC[c][p] = Scalar(0);
    }
    for (int y = py0; y < py1; ++y)
      for (int x = px0; x < px1; ++x) {
        const int p = (y - py0) * TileSize + (x - px0);
        const std::size_t pix = static_cast<std::size_t>(y) * W + x;
        T[p] = ctx.final_T[pix];
        last[p] = static_cast<Idx>(ctx.last_contrib[pix]);
        max_last = std::max(max_last, last[p]);
        row_last[y - py0] = std::max(row_last[y - py0], last[p]);
        const Scalar* gi = dL_dimage.pixel(x, y);
        bool finite = true;
        for (int c = 0; c < C; ++c) finite = finite && std::isfinite(gi[c]);
        if (has_alpha) finite = finite && std::isfinite(dL_dalpha(x, y));
        if (has_depth) finite = finite && std::isfinite(dL_ddepth(x, y));
        if (!finite)
          throw numeric_error("numeric.nonfinite", "dL_doutputs",
                              "non-finite output gradient at pixel (" + std::to_string(x) + ", " + std::to_string(y) + ")");
        for (int c = 0; c < C; ++c) {
          gC[c][p] = gi[c];
          X[c][p] = bg[c];
          bg_grad[c] += T[p] * gi[c];
        }
        gA[p] = has_alpha ? dL_dalpha(x, y) : Scalar(0);
        gD[p] = has_depth ? dL_ddepth(x, y) : Scalar(0);
      }
    for (int c = 0; c < C; ++c) ctx.tile_bg_grad[t * C + c] = bg_grad[c];
    const std::uint32_t b = ctx.tile_begin[t], e = ctx.tile_begin[t + 1];
    // Slots past the tile's last contributor carry no gradient: flag them instead of writing zeros.
    for (std::uint32_t j = b; j < e; ++j) ctx.slot_live[j] = j - b < static_cast<std::uint32_t>(max_last) ? 1 : 0;
    const I lane = LN::iota();
    for (Idx k = max_last; k-- > 0;) {
      if (k >= detail::kPrefetch) detail::prefetch(&ctx.sorted[ctx.tile_list[b + static_cast<std::uint32_t>(k - detail::kPrefetch)]]);
      const auto& g = ctx.sorted[ctx.tile_list[b + static_cast<std::uint32_t>(k)]];
      // Per-lane partial sums, reduced lane by lane at the end (fixed order).
      V du{}, dv{}, dA{}, dB{}, dCc{}, dop{}, dz{}, dcol[C];
      for (int c = 0; c < C; ++c) dcol[c] = V{};
      const int ya = std::max(g.y0, py0), yb = std::min(g.y1, py1);
      const int cx0 = std::max(g.x0, px0), cx1 = std::min(g.x1, px1);
      const Scalar half_a = Scalar(0.5) * g.A;
      for (int y = ya; y < yb; ++y) {
        if (k >= row_last[y - py0]) continue;
        const Scalar dy = Scalar(y) + Scalar(0.5) - g.v;
        int xa, xb;
        if (!detail::footprint_pixels(g, dy, cx0, cx1, xa, xb)) continue;
        const Scalar hc = Scalar(0.5) * g.C * dy * dy, bdy = g.B * dy;
        const Scalar half_dy2 = Scalar(0.5) * dy * dy;
        const int row = (y - py0) * TileSize - px0;
        for (int x0 = xa; x0 < xb; x0 += NL) {
          const int p0 = row + x0;
          const I live = (lane < static_cast<Idx>(xb - x0)) & (k < detail::load<I>(last + p0));
          if (detail::none(live)) continue;
          const V dx = __builtin_convertvector(lane + static_cast<Idx>(x0), V) + Scalar(0.5) - g.u;
          const V power = (half_a * dx) * dx + bdy * dx + hc;
          const V Gv = detail::exp_neg(power);
          const V raw = g.opacity * Gv;
          const V alpha = raw < amax ? raw : V{} + amax;
          const I valid = live & (power >= Scalar(0)) & (alpha >= amin);
          const V one_m = Scalar(1) - alpha;
          const V Tv = detail::load<V>(T + p0);
          const V Ti = Tv / one_m;
          const V w = alpha * Ti;
          V dL_dalpha{};
          for (int c = 0; c < C; ++c) {
            const V gc = detail::load<V>(gC[c] + p0), Xc = detail::load<V>(X[c] + p0);
            dcol[c] += valid ? w * gc : V{};
            dL_dalpha += (g.color[c] - Xc) * gc;
            detail::store(X[c] + p0, valid ? alpha * g.color[c] + one_m * Xc : Xc);
          }
          const V gd = detail::load<V>(gD + p0), Yv = detail::load<V>(Y + p0), Zv = detail::load<V>(Z + p0);
          dz += valid ? w * gd : V{};
          dL_dalpha += (g.depth - Yv) * gd + (Scalar(1) - Zv) * detail::load<V>(gA + p0);
          dL_dalpha *= Ti;
          detail::store(Y + p0, valid ? alpha * g.depth + one_m * Yv : Yv);
          detail::store(Z + p0, valid ? alpha + one_m * Zv : Zv);
          detail::store(T + p0, valid ? Ti : Tv);
          const I unclamped = valid & (raw < amax);
          dop += unclamped ? Gv * dL_dalpha : V{};
          const V dpow = unclamped ? -alpha * dL_dalpha : V{};
          dA += (Scalar(0.5) * dx * dx) * dpow;
          dB += (dx * dy) * dpow;
          dCc += half_dy2 * dpow;
          du -= (g.A * dx + g.B * dy) * dpow;
          dv -= (g.C * dy + g.B * dx) * dpow;
        }
      }
      Scalar* rec = &ctx.pair_grad[static_cast<std::size_t>(b + static_cast<std::uint32_t>(k)) * R];
      for (int r = 0; r < R; ++r) rec[r] = Scalar(0);
      for (int l = 0; l < NL; ++l) {
        rec[0] += du[l], rec[1] += dv[l], rec[2] += dA[l], rec[3] += dB[l], rec[4] += dCc[l], rec[5] += dop[l], rec[6] += dz[l];
        for (int c = 0; c < C; ++c) rec[7 + c] += dcol[c][l];
      }
    }
  }, 1);

  // 2. Culled Gaussians get zero gradients (visible ones are overwritten in step 3).
  auto zero = [](std::span<Scalar> s, std::size_t i, std::size_t n) {
    if (!s.empty()) std::fill_n(s.begin() + static_cast<std::ptrdiff_t>(i * n), n, Scalar(0));
  };
  parallel_for(pool, n, [&](std::size_t i) {
    if (ctx.visible[i]) return;
    zero(G.dL_dmean, i, 3), zero(G.dL_dlog_scale, i, 3), zero(G.dL_drotation, i, 4), zero(G.dL_dopacity_logit, i, 1);
    zero(G.dL_dsh, i, static_cast<std::size_t>(3 * K)), zero(grads.dL_dcolors, i, C), zero(grads.dL_dmean2d, i, 2);
  }, 4096);
  for (int c = 0; c < C; ++c) {
    Scalar s = 0;
    for (std::size_t t = 0; t < tiles; ++t) s += ctx.tile_bg_grad[t * C + c];
    grads.dL_dbackground[c] = s;
  }

  // 3. Per visible Gaussian: reduce its slots in tile order, then projection + SH backward.
  const Eigen::Matrix<Scalar, 3, 1> centre = ctx.camera.center();
  const auto& P = ctx.params;
  parallel_for(pool, ctx.sorted.size(), [&](std::size_t s) {
    Scalar acc[R];
    for (int r = 0; r < R; ++r) acc[r] = Scalar(0);
    for (std::uint32_t j = ctx.gauss_begin[s]; j < ctx.gauss_begin[s + 1]; ++j) {
      if (!ctx.slot_live[ctx.gauss_slots[j]]) continue;
      const Scalar* rec = &ctx.pair_grad[static_cast<std::size_t>(ctx.gauss_slots[j]) * R];
      for (int r = 0; r < R; ++r) acc[r] += rec[r];
    }
    const std::size_t i = ctx.sorted[s].id;
    bool any = false;
    for (int r = 0; r < R; ++r) any = any || acc[r] != Scalar(0);
    if (!any) {  // hidden everywhere: every gradient is exactly zero (all are linear in acc)
      zero(G.dL_dmean, i, 3), zero(G.dL_dlog_scale, i, 3), zero(G.dL_drotation, i, 4), zero(G.dL_dopacity_logit, i, 1);
      zero(G.dL_dsh, i, static_cast<std::size_t>(3 * K)), zero(grads.dL_dcolors, i, C), zero(grads.dL_dmean2d, i, 2);
      return;
    }
    if (!grads.dL_dmean2d.empty()) grads.dL_dmean2d[2 * i] = acc[0], grads.dL_dmean2d[2 * i + 1] = acc[1];
    Scalar dmean[3] = {0, 0, 0}, dls[3], drot[4], dlogit;
    if (!G.dL_dsh.empty() && (!ctx.colors.empty() || C != 3)) zero(G.dL_dsh, i, static_cast<std::size_t>(3 * K));
    if (!grads.dL_dcolors.empty())
      for (int c = 0; c < C; ++c) grads.dL_dcolors[i * C + c] = acc[7 + c];
    if constexpr (C == 3) {
      if (ctx.colors.empty()) {
        const Eigen::Matrix<Scalar, 3, 1> m(P.mean[3 * i], P.mean[3 * i + 1], P.mean[3 * i + 2]);
        Scalar inv_len;
        const auto dir = sh::view_direction(m, centre, inv_len);
        bool clamped[3];
        for (int c = 0; c < 3; ++c) clamped[c] = (ctx.color_clamped[i] >> c) & 1u;
        Scalar dsh_local[48];
        Scalar* dsh = G.dL_dsh.empty() ? dsh_local : &G.dL_dsh[static_cast<std::size_t>(3 * K) * i];
        std::fill(dsh, dsh + 3 * K, Scalar(0));
        const auto ddir = sh::evaluate_backward<Scalar, 3>(ctx.sh_degree, dir, &P.sh[static_cast<std::size_t>(3 * K) * i], clamped,
                                                           &acc[7], dsh);
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
      for (int k = 0; k < 3; ++k) G.dL_dmean[3 * i + k] = dmean[k];
    if (!G.dL_dlog_scale.empty())
      for (int k = 0; k < 3; ++k) G.dL_dlog_scale[3 * i + k] = dls[k];
    if (!G.dL_drotation.empty())
      for (int k = 0; k < 4; ++k) G.dL_drotation[4 * i + k] = drot[k];
    if (!G.dL_dopacity_logit.empty()) G.dL_dopacity_logit[i] = dlogit;
  }, 512);
}

}  // namespace video3dgs
