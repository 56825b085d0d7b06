#pragma once
/// @file
/// `Rasterizer<Scalar, TileSize, Channels>`: the differentiable tile rasterizer for 3D Gaussians as one
/// forward(inputs, ctx&) / backward(ctx, dL_doutputs, grads&) pair.
///
///     Rasterizer<float, 16> r;                  // settings: r.settings (RasterSettings)
///     RasterContext<float, 3> ctx;              // reuse across iterations: no steady-state allocation
///     r.forward(camera, cloud.params(), ctx, &pool);      // ctx.image, ctx.alpha, ctx.depth, ctx.radii
///     r.backward(ctx, dL_dimage, {}, {}, grads, &pool);   // grads.gaussians.dL_dmean, ...
///
/// Results are bit-identical for any thread count, independent of the Gaussians' input order up to
/// the (depth, index) tie-break, and (images) independent of the tile size.

#include <span>

#include "video3dgs/core/camera.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/gaussian/cloud.hpp"
#include "video3dgs/rasterizer/backward.hpp"
#include "video3dgs/rasterizer/context.hpp"
#include "video3dgs/rasterizer/forward.hpp"
#include "video3dgs/rasterizer/settings.hpp"

namespace video3dgs {

template <class Scalar, int TileSize = 16, int Channels = 3>
class Rasterizer {
  static_assert(std::is_floating_point_v<Scalar>, "video3dgs: Rasterizer<Scalar, ...> needs Scalar = float or double");
  static_assert(TileSize == 8 || TileSize == 16 || TileSize == 32, "video3dgs: Rasterizer TileSize must be 8, 16 or 32");
  static_assert(Channels >= 1 && Channels <= 16, "video3dgs: Rasterizer Channels must be in 1..16");

 public:
  using scalar_type = Scalar;
  static constexpr int tile_size = TileSize;
  static constexpr int channels = Channels;
  using Settings = RasterSettings<Scalar, Channels>;
  using Context = RasterContext<Scalar, Channels>;
  using Grads = RasterGrads<Scalar, Channels>;

  Settings settings;

  Rasterizer() = default;
  explicit Rasterizer(const Settings& s) : settings(s) {}

  /// Renders `gaussians` seen by `camera` into ctx (image, alpha, depth if settings.depth, visible, radii, stats).
  /// @param colors optional N x Channels colours replacing the SH colour (required if Channels != 3).
  /// @throws option_error on invalid camera / settings / span sizes.
  void forward(const Camera<Scalar>& camera, const GaussianParams<Scalar>& gaussians, Context& ctx, ThreadPool* pool = nullptr,
               std::span<const Scalar> colors = {}) const {
    rasterize_forward<TileSize>(camera, settings, gaussians, colors, ctx, pool);
  }

  /// Gradients of L given dL/dimage (required), dL/dalpha and dL/ddepth (empty views = zero).
  /// Overwrites every non-empty span of `grads` (or adds into them if `grads.accumulate`) and
  /// grads.dL_dbackground.
  void backward(Context& ctx, ConstImageView<Scalar, Channels> dL_dimage, ConstImageView<Scalar, 1> dL_dalpha,
                ConstImageView<Scalar, 1> dL_ddepth, Grads& grads, ThreadPool* pool = nullptr) const {
    rasterize_backward<TileSize>(ctx, dL_dimage, dL_dalpha, dL_ddepth, grads, pool);
  }
};

template <int TileSize = 16>
using RasterizerF = Rasterizer<float, TileSize, 3>;
template <int TileSize = 16>
using RasterizerD = Rasterizer<double, TileSize, 3>;

}  // namespace video3dgs
