#pragma once
/// @file
/// Rendering a frame of a `ClipModel`: the forward pass of the clip graph (graph/clip_graph.hpp)
/// without targets: both sets deformed to t_i, rasterized, merged by the frame's alpha map,
/// I = A I_frg + (1 - A) I_bkg. Reuse one `ClipRenderBuffers` (a `ClipGraphContext`) per clip: no
/// allocation after the first frame.
///
///     ClipRenderBuffers<float> buf;
///     render_clip_frame(model, i, buf, &pool);   // buf.frg.image, buf.bkg.image, buf.merged
///
/// A clip without foreground renders the background set only (merged = bkg, frg image black).

#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/graph/clip_graph.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/rasterizer/rasterizer.hpp"

namespace video3dgs {

/// Renders clip frame i of `m` into `buf` (see the file comment). `settings` may set the background
/// colour, the active SH degree (default: all bands of the model), and the other raster constants;
/// the stop rule is the model's own (ClipModel::min_transmittance, blend_at_stop).
/// `TileSize` is the rasterizer's (images do not depend on it).
template <int TileSize = 16, class Scalar, int D, class Field>
void render_clip_frame(const ClipModel<Scalar, D, Field>& m, int i, ClipRenderBuffers<Scalar, Field>& buf, ThreadPool* pool = nullptr,
                       RasterSettings<Scalar, 3> settings = {}, bool all_sh_bands = true) {
  if (all_sh_bands) settings.active_sh_degree = D;
  const ClipGraph<Scalar, D, Field, TileSize> graph(settings);
  (void)graph.forward(m, i, {}, buf, {}, {}, pool);
}

}  // namespace video3dgs
