#pragma once
/// @file
/// The compile-time choices of stage 1 and stage 2, as one bundle: the rasterizer's tile size and the
/// optimiser's update rule (the SH degree and the deformation field are the model's, see
/// `ClipModel<Scalar, SHDegree, Field>`). `ClipTrainer<Model, TileSize, OptimizerPolicy>` and
/// `ClipRefiner<Scalar, D, Field, TileSize, OptimizerPolicy>` pass them to the clip graph, the
/// evaluation and the renderer. Their default tile sizes differ: stage 1 trains at
/// `kTrainingTileSize` (32), stage 2 refines at 16 (`TrainingPolicy`'s default; not measured at 32).
///
/// The optimiser's hyperparameters per group come from `group_hyper`: Adam's eps where the policy has
/// one, and for the SH group (rows of 3K scalars, DC first) the rate of the higher bands relative to
/// the DC band where the policy has a per-column rate (`SplitLrAdam`); a policy without one trains
/// every band at the DC rate.

#include <cstddef>

#include "video3dgs/optim/policies.hpp"
#include "video3dgs/sh/basis.hpp"
#include "video3dgs/training/split_adam.hpp"

namespace video3dgs {

/// The rasterizer's tile size that `ClipTrainer` trains with unless told otherwise. Images do not
/// depend on the tile size; gradients are summed per (tile, Gaussian) slot in tile order, so another
/// size trains the same maths with another rounding. 32 is the fastest of 8 / 16 / 32 for training
/// at every render size measured (fewer tile pairs: less binning, per-pair set-up and slot records;
/// docs/performance.md, "The tile size in training").
inline constexpr int kTrainingTileSize = 32;

template <int TileSize = 16, class OptimizerPolicy = SplitLrAdam>
struct TrainingPolicy {
  static constexpr int tile_size = TileSize;
  using optimizer = OptimizerPolicy;
};

/// Hyperparameters of policy P for an ordinary group (`sh_degree < 0`) or for the SH group of a
/// cloud of degree `sh_degree` trained at lr_dc (DC) and lr_rest (other bands).
template <class P>
[[nodiscard]] typename P::Hyper group_hyper(double eps, int sh_degree = -1, double lr_dc = 0, double lr_rest = 0) {
  typename P::Hyper h{};
  if constexpr (requires { h.eps; }) h.eps = eps;
  if constexpr (requires { h.row_width; h.lead; h.tail_scale; }) {
    if (sh_degree >= 0) {
      h.row_width = std::size_t(3 * sh::coeff_count(sh_degree));
      h.lead = 3;
      h.tail_scale = lr_dc > 0 ? lr_rest / lr_dc : 1.0;
    }
  }
  return h;
}

}  // namespace video3dgs
