#pragma once
/// @file
/// `RasterSettings<Scalar, Channels>`: the constants of projection and compositing (docs/method.md,
/// "Rasterizer constants"), every one with the standard 3DGS default.

#include <array>
#include <limits>
#include <string>

#include "video3dgs/core/error.hpp"
#include "video3dgs/rasterizer/simd.hpp"

namespace video3dgs {

template <class Scalar, int Channels = 3>
struct RasterSettings {
  /// Gaussians with camera depth z <= near_plane are culled (3DGS uses 0.2).
  Scalar near_plane = Scalar(0.2);
  /// Gaussians with z > far_plane are culled.
  Scalar far_plane = std::numeric_limits<Scalar>::max();
  /// EWA low-pass: 2D covariance + low_pass I (pixels²).
  Scalar low_pass = Scalar(0.3);
  /// Antialiased mode (Mip-Splatting / gsplat "antialiased"): opacity scaled by
  /// sqrt(det(cov2d) / det(cov2d + low_pass I)).
  bool antialiased = false;
  /// Jacobian clamp: x/z in [-(cx/fx + (f-1) w/2fx), (w-cx)/fx + (f-1) w/2fx], f = fov_clamp
  /// (1.3 x the half-FOV tangent for a centred principal point), same in y.
  Scalar fov_clamp = Scalar(1.3);
  /// The image the clamp's bounds come from, when the render is a window of a larger one (a training
  /// crop, graph/clip_graph.hpp): the window's origin in it and its size. clamp_frame_width 0: the
  /// render itself. With it, a window's Jacobians are the whole image's, so its pixels are the whole
  /// render's (up to rounding).
  int clamp_frame_x = 0, clamp_frame_y = 0, clamp_frame_width = 0, clamp_frame_height = 0;
  /// alpha = min(alpha_max, o exp(-power)); pixels with alpha < alpha_min are skipped (alpha_min >= 1e-20
  /// keeps footprints within the range of the float exp of the compositing loops).
  Scalar alpha_max = Scalar(0.99);
  Scalar alpha_min = Scalar(1) / Scalar(255);
  /// A pixel stops when its transmittance would fall below this; whether the Gaussian that crosses it
  /// is blended first: `blend_at_stop`.
  Scalar min_transmittance = kReferenceMinTransmittance;
  static constexpr Scalar kReferenceMinTransmittance = Scalar(1e-4);  ///< the method's stop (3DGS's)
  /// false (the method's, 3DGS's rule): the crossing Gaussian is not blended, so a stop s drops up to
  /// s alpha_max / (1 - alpha_max) of a pixel's colour (99 s), and a stop at or above 1 - alpha_max
  /// can drop a fully opaque Gaussian in front. true: it is blended and then the pixel stops, so a stop
  /// drops less than s of the colour (only what lies behind T < s), and large stops skip the pairs
  /// behind nearly opaque surfaces at a bounded cost. The backward pass is the same for both rules
  /// (it walks back from the last blended Gaussian).
  bool blend_at_stop = false;
  /// SH bands used: 0..(storage degree of the Gaussians); raised during training.
  int active_sh_degree = 3;
  /// Colour behind everything (also receives a gradient).
  std::array<Scalar, Channels> background{};
  /// Whether the forward pass accumulates the depth image (RasterContext::depth); false leaves it all
  /// zeros and saves one sum per pixel-Gaussian evaluation (training reads no depth). The backward's
  /// depth gradient does not read it, and no other output changes.
  bool depth = true;
  /// Instruction set of the compositing kernels (simd.hpp); every choice gives bit-identical results.
  RasterSimd simd = RasterSimd::automatic;

  /// Throws `option.raster` naming the field at fault.
  void validate() const {
    auto bad = [](const char* f, const char* why) { throw option_error("option.raster", f, why); };
    if (!(near_plane > Scalar(0))) bad("near_plane", "must be > 0");
    if (!(far_plane > near_plane)) bad("far_plane", "must be > near_plane");
    if (!(low_pass >= Scalar(0))) bad("low_pass", "must be >= 0");
    if (antialiased && !(low_pass > Scalar(0))) bad("low_pass", "antialiased mode needs low_pass > 0");
    if (!(fov_clamp >= Scalar(1))) bad("fov_clamp", "must be >= 1");
    if (!(alpha_max > Scalar(0) && alpha_max < Scalar(1))) bad("alpha_max", "must be in (0, 1)");
    if (!(alpha_min >= Scalar(1e-20) && alpha_min < alpha_max)) bad("alpha_min", "must be in [1e-20, alpha_max)");
    if (!(min_transmittance > Scalar(0) && min_transmittance < Scalar(1))) bad("min_transmittance", "must be in (0, 1)");
    if (active_sh_degree < 0 || active_sh_degree > 3) bad("active_sh_degree", "must be in 0..3");
    for (Scalar b : background)
      if (!(b == b) || b > std::numeric_limits<Scalar>::max() || b < -std::numeric_limits<Scalar>::max())
        bad("background", "must be finite");
    if (!raster_simd_supported(simd)) bad("simd", "this instruction set is not supported by the CPU or the build");
  }
};

}  // namespace video3dgs
