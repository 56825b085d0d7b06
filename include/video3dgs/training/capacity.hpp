#pragma once
/// @file
/// Capacity that follows the clip: `plan_capacity` sizes a clip's model from what the clip holds, its
/// pixel samples W x H x F, its SfM points and the spread of its viewpoints, instead of one size for
/// every clip.
///
///     ClipShape s = clip_shape(width, height, cameras, sfm_points);   // or fill it by hand
///     CapacityPlan p = plan_capacity(s);   // p.frg_grid / p.bkg_grid, p.gaussians_per_pixel, p.max_sh_degree
///
/// The rules (each anchored on measurements: docs/performance.md, "Capacity that follows the clip"),
/// with P the clip's SfM points, which stand for its textured, trackable structure:
///
///   hash tables   2^T entries per level, T = round(log2(max(W H F / pixels_per_entry,
///                 entries_per_point x P))) clamped to [min_log2_table, max_log2_table]. At
///                 max_log2_table the fields keep the library's default grid (2^16 entries, 16 levels
///                 up to 2006 cells). Below it the finest level has 128 x 4^(T - 14) cells per axis
///                 (at least the base resolution, 16) and the levels grow by ~level_growth each:
///                 L = 1 + round(ln(finest / 16) / ln(level_growth)); 2^14 gets 8 levels up to 128
///                 cells. Both fields get the same size (a static background keeps its 4-entry grid).
///   budget        below the default table, each set is capped at gaussians_per_point x max(P, 1)
///                 Gaussians, the foreground's share fixed at 1 (on whole-frame cameras the
///                 foreground set models the whole frame); at the default table there is no cap.
///   SH degree     0 when the largest angle between two frames' viewing directions of the scene
///                 centre (`view_spread`) is below min_view_spread: every frame then sees each
///                 Gaussian from (almost) the same direction and the rest bands can only repeat the DC
///                 colour; otherwise 3.
///
/// Monotone: a clip with fewer pixels, frames or SfM points, or a narrower spread, never gets a larger
/// table, more levels, a finer grid, a larger budget or a higher SH degree.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "video3dgs/core/camera.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/scheduling/sfm_result.hpp"

namespace video3dgs {

/// What a plan reads of a clip.
struct ClipShape {
  int width = 0, height = 0;  ///< the training size
  int frames = 0;
  double view_spread = 0;     ///< radians (`view_spread`)
  std::size_t points = 0;     ///< SfM points
};

/// The rules' constants (see the file comment).
struct CapacityRules {
  double pixels_per_entry = 12;
  double entries_per_point = 64;
  int min_log2_table = 12;
  int max_log2_table = 16;          ///< the default table: from here on the default grid, no budget
  double level_growth = 1.35;
  double gaussians_per_point = 165;
  double min_view_spread = 0.5 * 3.14159265358979323846 / 180;  ///< 0.5 degrees

  /// @throws option_error `option.capacity` naming the field.
  void validate() const {
    auto bad = [](const char* f, const char* why) { throw option_error("option.capacity", f, why); };
    if (!(pixels_per_entry > 0) || !std::isfinite(pixels_per_entry)) bad("pixels_per_entry", "must be finite and > 0");
    if (!(entries_per_point >= 0) || !std::isfinite(entries_per_point)) bad("entries_per_point", "must be finite and >= 0");
    if (min_log2_table < 4 || min_log2_table > max_log2_table || max_log2_table > 24) bad("min_log2_table", "need 4 <= min <= max <= 24");
    if (!(level_growth > 1) || !std::isfinite(level_growth)) bad("level_growth", "must be finite and > 1");
    if (!(gaussians_per_point > 0) || !std::isfinite(gaussians_per_point)) bad("gaussians_per_point", "must be finite and > 0");
    if (!(min_view_spread >= 0) || !std::isfinite(min_view_spread)) bad("min_view_spread", "must be finite and >= 0");
  }
};

/// A clip's sizes. `frg_grid` / `bkg_grid` leave `time_cells` at the default (one slice per frame);
/// an unresized GridSize (all 0) means the library's default grid.
struct CapacityPlan {
  int log2_table = 0;             ///< T (see the file comment), also when the grids are the default
  GridSize frg_grid{}, bkg_grid{};
  /// TrainOptions::gaussians_per_pixel (0: no cap; else gaussians_per_point x P per set, as a rate per
  /// pixel of the clip), foreground share 1
  double gaussians_per_pixel = 0;
  int max_sh_degree = 3;          ///< TrainOptions::max_sh_degree
  friend bool operator==(const CapacityPlan&, const CapacityPlan&) = default;
};

/// The largest angle (radians, in [0, pi]) between two of the directions from `centre` to the cameras'
/// centres: 0 for one camera, a still camera or one that only turns.
template <class Scalar>
[[nodiscard]] double view_spread(std::span<const Camera<Scalar>> cameras, const Eigen::Vector3d& centre) {
  std::vector<Eigen::Vector3d> dirs;
  for (const auto& c : cameras) {
    const Eigen::Vector3d d = c.center().template cast<double>() - centre;
    if (d.norm() > 0 && std::isfinite(d.norm())) dirs.push_back(d.normalized());
  }
  double widest = 0;
  for (std::size_t i = 0; i < dirs.size(); ++i)
    for (std::size_t j = i + 1; j < dirs.size(); ++j)
      widest = std::max(widest, std::atan2(dirs[i].cross(dirs[j]).norm(), dirs[i].dot(dirs[j])));  // stable at small angles
  return widest;
}

/// The scene centre of a clip: the per-axis median of its SfM points (the origin without points).
template <class S>
[[nodiscard]] Eigen::Vector3d scene_centre(std::span<const SfmPoint<S>> points) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  if (points.empty()) return c;
  std::vector<double> v(points.size());
  for (int a = 0; a < 3; ++a) {
    for (std::size_t i = 0; i < points.size(); ++i) v[i] = double(points[i].xyz(a));
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(v.size() / 2), v.end());
    c(a) = v[v.size() / 2];
  }
  return c;
}

/// The plan of a clip (see the file comment). @throws option_error `option.capacity` on bad rules or an
/// empty clip.
[[nodiscard]] inline CapacityPlan plan_capacity(const ClipShape& s, const CapacityRules& r = {}) {
  r.validate();
  if (s.width < 1 || s.height < 1 || s.frames < 1) throw option_error("option.capacity", "clip", "needs a size and frames");
  CapacityPlan p;
  const double samples = double(s.width) * double(s.height) * double(s.frames);
  const double entries = std::max({samples / r.pixels_per_entry, r.entries_per_point * double(s.points), 1.0});
  const int T = static_cast<int>(std::lround(std::log2(entries)));
  p.log2_table = std::clamp(T, r.min_log2_table, r.max_log2_table);
  if (p.log2_table < r.max_log2_table) {
    GridSize g;
    g.log2_table_size = p.log2_table;
    g.finest = std::max(16.0, 128.0 * std::pow(4.0, double(p.log2_table - 14)));
    g.levels = std::clamp(1 + static_cast<int>(std::lround(std::log(g.finest / 16.0) / std::log(r.level_growth))), 1, 16);
    p.frg_grid = p.bkg_grid = g;
    // The count N = floor(gaussians_per_point P) (at least 1) as a per-pixel rate whose
    // TrainOptions::gaussian_budget, ceil(rate W H), is N itself for any W x H (the half keeps rounding
    // away from the integer), capped at TrainOptions' 1e6 per pixel.
    const double count = std::max(1.0, std::floor(r.gaussians_per_point * double(std::max<std::size_t>(s.points, 1))));
    p.gaussians_per_pixel = std::min((count - 0.5) / (double(s.width) * double(s.height)), 1e6);
  }
  p.max_sh_degree = s.view_spread < r.min_view_spread ? 0 : 3;
  return p;
}

/// The shape of a clip trained at width x height from these cameras and SfM points.
template <class Scalar, class S>
[[nodiscard]] ClipShape clip_shape(int width, int height, std::span<const Camera<Scalar>> cameras, std::span<const SfmPoint<S>> points) {
  return {width, height, static_cast<int>(cameras.size()), view_spread(cameras, scene_centre(points)), points.size()};
}

}  // namespace video3dgs
