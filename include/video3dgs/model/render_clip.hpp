#pragma once
/// @file
/// Rendering a frame of a `ClipModel`: both sets deformed to t_i, rasterized, merged by the frame's
/// alpha map, I = A I_frg + (1 - A) I_bkg (model/alpha_merge.hpp). Reuse one `ClipRenderBuffers` per
/// clip: no allocation after the first frame.
///
///     ClipRenderBuffers<float> buf;
///     render_clip_frame(model, i, buf, &pool);   // buf.frg.image, buf.bkg.image, buf.merged
///
/// A clip without foreground renders the background set only (merged = bkg, frg image black).

#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/model/alpha_merge.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/rasterizer/rasterizer.hpp"

namespace video3dgs {

template <class Scalar, class Field = DefaultDeformationField<Scalar>>
struct ClipRenderBuffers {
  RasterContext<Scalar, 3> frg, bkg;                 ///< per-set forward contexts (image, alpha, depth)
  DeformScratch<Scalar, Field> frg_scratch, bkg_scratch;
  Image<Scalar, 3> merged;
};

/// Renders clip frame i of `m` into `buf` (see the file comment). `settings` may set the background
/// colour, the active SH degree (default: all bands of the model), and the other raster constants.
template <class Scalar, int D, class Field>
void render_clip_frame(const ClipModel<Scalar, D, Field>& m, int i, ClipRenderBuffers<Scalar, Field>& buf, ThreadPool* pool = nullptr,
                       RasterSettings<Scalar, 3> settings = {}, bool all_sh_bands = true) {
  if (i < 0 || i >= m.frame_count()) throw option_error("option.frame", "frame index " + std::to_string(i), "outside the clip");
  if (all_sh_bands) settings.active_sh_degree = D;
  const Rasterizer<Scalar, 16, 3> r(settings);
  const Camera<Scalar>& cam = m.cameras[std::size_t(i)];
  r.forward(cam, m.deformed(GaussianSet::background, i, buf.bkg_scratch, pool), buf.bkg, pool);
  if (!m.has_foreground) {
    buf.frg.image.resize(cam.width, cam.height);
    buf.merged = buf.bkg.image;
    return;
  }
  r.forward(cam, m.deformed(GaussianSet::foreground, i, buf.frg_scratch, pool), buf.frg, pool);
  if (buf.merged.width() != cam.width || buf.merged.height() != cam.height) buf.merged.resize(cam.width, cam.height);
  alpha_merge_forward<Scalar, 3>(buf.frg.image, buf.bkg.image, m.alpha_logit[std::size_t(i)], buf.merged, pool);
}

}  // namespace video3dgs
