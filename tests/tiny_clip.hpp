#pragma once
// Shared by the end-to-end gradient tests of tests/training and tests/refine: a 2-frame 32x24
// synthetic clip in double with a small field (4 levels, 2^10 entries, 8 hidden units), so that one
// forward is cheap enough to take hundreds of them; the graph is the same as with the default field.
#include <span>
#include <vector>

#include <doctest/doctest.h>

#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/synthetic/clip.hpp"

namespace video3dgs::test {

using TinyField = DeformationField<double, HashGrid<double, 4, 4, 2, 10>, 8>;
using TinyModel = ClipModel<double, 3, TinyField>;

struct TinyClip {
  TinyModel model;
  std::vector<Image<double, 3>> frames;
};

/// The clip (generator seed `seed`) and its initial model; `foreground = false` empties the masks
/// (background set only); `input_gradient` is the fields' `grid_input_gradient`.
inline TinyClip make_tiny_clip(bool foreground, bool input_gradient, std::uint64_t seed) {
  synthetic::SyntheticClipOptions so;
  so.frames = 2;
  so.width = 32;
  so.height = 24;
  so.object_gaussians = 60;
  so.background_gaussians = 150;
  so.foreground_points = 40;
  so.seed = seed;
  auto clip = synthetic::make_synthetic_clip<double>(so);
  ClipModelOptions mo;
  mo.background.points_per_shell = 60;
  mo.deformation.grid_input_gradient = input_gradient;
  std::vector<Image<double, 1>> masks = clip.masks;
  if (!foreground)
    for (auto& m : masks) m.fill(0.0);
  TinyClip t{make_clip_model<double, 3, TinyField>(clip.sfm_result(), mo, std::span<const Image<double, 1>>(masks)),
             std::move(clip.frames)};
  REQUIRE(t.model.has_foreground == foreground);
  return t;
}

}  // namespace video3dgs::test
