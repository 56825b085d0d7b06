#pragma once
/// @file
/// `RasterContext<Scalar, Channels>`: everything a forward pass produces and its backward needs (the
/// outputs, the projected and depth-sorted Gaussians, the tile lists, per-pixel final transmittance and
/// last contributor), and `RasterGrads`: where a backward pass writes. A context is reused across
/// iterations: buffers only grow, so a steady-state loop does not allocate.

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "video3dgs/core/camera.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/gaussian/cloud.hpp"
#include "video3dgs/rasterizer/project.hpp"
#include "video3dgs/rasterizer/settings.hpp"
#include "video3dgs/rasterizer/stats.hpp"

namespace video3dgs {

/// A projected Gaussian in depth order, packed for the compositing loops.
template <class Scalar, int Channels>
struct SortedGaussian {
  Scalar u, v;          ///< 2D mean (pixels)
  Scalar A, B, C;       ///< conic
  Scalar opacity;       ///< effective opacity
  Scalar depth;         ///< camera z
  Scalar p_max;         ///< footprint: power <= p_max
  Scalar two_a_p;       ///< 2 A p_max (row-interval test)
  Scalar det;           ///< AC - B² of the conic
  Scalar inv_A;         ///< 1 / A
  Scalar band_dy;       ///< sqrt(2 p_max) b / sqrt(a): dy of the footprint's rightmost point (binning)
  Scalar color[Channels];
  std::int32_t x0, y0, x1, y1;  ///< pixel footprint box [x0, x1) x [y0, y1)
  std::uint32_t id;     ///< index of the Gaussian in the input
};

template <class Scalar, int Channels>
struct RasterContext {
  // ---- outputs of the forward pass ----
  Image<Scalar, Channels> image;  ///< composited colour (background included)
  Image<Scalar, 1> alpha;         ///< accumulated alpha = 1 - final transmittance, in [0, 1]
  Image<Scalar, 1> depth;         ///< accumulated depth sum_i alpha_i T_i z_i (divide by alpha for the mean); zeros unless settings.depth
  std::vector<std::uint8_t> visible;  ///< per input Gaussian: 1 if it survived culling
  std::vector<std::int32_t> radii;    ///< per input Gaussian: screen radius ceil(3 sqrt(lambda_max)), 0 if culled
  RasterStats stats;

  // ---- saved for the backward pass ----
  Camera<Scalar> camera;
  RasterSettings<Scalar, Channels> settings;
  GaussianParams<Scalar> params;       ///< views: the caller keeps the storage alive until backward
  std::span<const Scalar> colors;      ///< precomputed colours (N x Channels) or empty (SH colour)
  int sh_degree = 0;                   ///< SH degree actually evaluated
  int tile_size = 0;
  int tiles_x = 0, tiles_y = 0;
  std::vector<Scalar> color;           ///< N x Channels: colour of each visible Gaussian
  std::vector<std::uint8_t> color_clamped;  ///< N: bit c set if channel c hit the max(., 0) clamp
  std::vector<SortedGaussian<Scalar, Channels>> sorted;  ///< visible Gaussians, by (depth, index)
  std::vector<std::uint32_t> rank;            ///< per input Gaussian: its position in `sorted` (if visible)
  std::vector<std::uint32_t> tile_begin;      ///< tiles + 1 offsets into tile_list
  std::vector<std::uint32_t> tile_list;       ///< sorted positions, per tile in depth order
  std::vector<std::uint32_t> gauss_begin;     ///< input + 1 offsets: Gaussian i's slot records are [gauss_begin[i], gauss_begin[i + 1])
  std::vector<std::uint32_t> slot_record;     ///< per tile_list slot: its record in Gaussian-major order (input index, then tile)
  std::vector<Scalar> final_T;                ///< per pixel transmittance after the last blended Gaussian
  std::vector<std::uint32_t> last_contrib;    ///< per pixel: 1 + local index of its last blended Gaussian

  // ---- scratch (reused) ----
  std::vector<ProjectedGaussian<Scalar>> projected;
  std::vector<std::uint32_t> order, order_tmp, chunk_counts, radix_hist;
  std::vector<std::uint64_t> keys, keys_tmp;
  std::vector<Scalar> pair_grad;           ///< per slot gradient record, Gaussian-major (slot_record; backward)
  std::vector<Scalar> tile_bg_grad;        ///< per tile background gradient (backward)
  std::vector<std::uint32_t> pair_evals;   ///< per slot record: its evaluations (backward, with blend statistics)
  std::vector<std::size_t> tile_evals;     ///< per tile evaluation counts (forward)
};

/// Where `Rasterizer::backward` writes. Every non-empty span is overwritten (not accumulated).
template <class Scalar, int Channels>
struct RasterGrads {
  GaussianGrads<Scalar> gaussians;       ///< mirrors GaussianParams (any field may be empty = not wanted)
  std::span<Scalar> dL_dcolors;          ///< N x Channels: gradient w.r.t. each Gaussian's colour (given or from SH)
  std::span<Scalar> dL_dmean2d;          ///< N x 2, gradient w.r.t. the 2D mean in pixels (densification)
  /// N: each Gaussian's blend weight sum_p alpha_i T_i in this render (backward.hpp; pruning by
  /// contribution). Only without a depth gradient.
  std::span<Scalar> blend_weight;
  /// N: each Gaussian's evaluations in this backward, the pixels whose term sum_p alpha_i T_i's walk
  /// computed (inside its footprint rows, in front of the pixel's last blended Gaussian): what it cost
  /// to composite. blend_weight / blend_evals is its weight per evaluation (pruning by efficiency).
  /// Only without a depth gradient.
  std::span<Scalar> blend_evals;
  std::array<Scalar, Channels> dL_dbackground{};
  /// false: `backward` overwrites every non-empty span; true: it adds into them (the autodiff tape's
  /// convention, so that several consumers of one buffer sum their contributions). dL_dbackground
  /// is always overwritten.
  bool accumulate = false;
};

}  // namespace video3dgs
