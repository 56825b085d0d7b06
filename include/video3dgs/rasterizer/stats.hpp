#pragma once
/// @file
/// `RasterStats`: the work counters of one forward pass of the rasterizer (`RasterContext::stats`),
/// also reported per training iteration (`IterationInfo::frg_raster` / `bkg_raster`).

#include <cstddef>

namespace video3dgs {

/// Work counters of the last forward pass.
struct RasterStats {
  std::size_t visible = 0;     ///< Gaussians that survived culling
  std::size_t tile_pairs = 0;  ///< (tile, Gaussian) pairs after binning
  /// Pixel-Gaussian evaluations of the forward pass: the pixels of each Gaussian's footprint rows
  /// (rasterizer/binning.hpp's interval) that had not stopped yet; the same count on every SIMD path.
  std::size_t evaluations = 0;
};

}  // namespace video3dgs
