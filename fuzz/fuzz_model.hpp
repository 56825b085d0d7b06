#pragma once
// The clip model the model and checkpoint fuzz targets read: a small deformation field (2 levels of
// 2^6 entries, 4 hidden units) so that a whole model file is a few kilobytes; the reader runs the same
// code for every field type (the field's layout only sets how many parameters a segment holds).
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "video3dgs/model/clip_model.hpp"

namespace video3dgs::fuzz {

using FuzzField = DeformationField<float, HashGrid<float, 4, 2, 2, 6>, 4>;
using FuzzModel = ClipModel<float, 1, FuzzField>;
inline constexpr int kFuzzWidth = 12, kFuzzHeight = 9;

/// A model of frames r.first..r.last (12x9 cameras circling the origin, 20 foreground points).
inline FuzzModel make_fuzz_model(FrameRange r, std::uint64_t seed = 1) {
  std::vector<Camera<float>> cams;
  for (int f = r.first; f <= r.last; ++f) {
    auto c = Camera<float>::from_fov(kFuzzWidth, kFuzzHeight, 1.0f);
    const float a = 0.1f * float(f);
    c.look_at({4 * std::sin(a), 0, -4 * std::cos(a)}, {0, 0, 0});
    cams.push_back(c);
  }
  std::vector<SfmPoint<double>> pts;
  for (int i = 0; i < 20; ++i) {
    SfmPoint<double> p;
    p.xyz = {0.05 * (i % 5) - 0.1, 0.05 * (i / 5) - 0.1, 0.01 * double(seed)};
    p.rgb = {std::uint8_t(40 * (i % 6)), 120, std::uint8_t(200 - 5 * i)};
    pts.push_back(p);
  }
  ClipModelOptions o;
  o.background.points_per_shell = 6;
  o.seed = seed;
  return make_clip_model<float, 1, FuzzField>(r, std::span<const Camera<float>>(cams), std::span<const SfmPoint<double>>(pts), o);
}

}  // namespace video3dgs::fuzz
