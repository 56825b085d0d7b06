#pragma once
/// @file
/// Point sets that initialise a clip's Gaussians (docs/method.md):
/// - `fibonacci_sphere`: n nearly uniform points on a sphere (golden-angle lattice);
/// - `background_shell_points`: the background set, points on concentric spheres centred on the
///   foreground points' bounding box, radii proportional to the box's largest side;
/// - `knn_mean_sq_distance`: per point, the mean squared distance to its k nearest neighbours, from
///   which the isotropic initial scale sqrt(max(d2, 1e-7)) is taken.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "video3dgs/core/parallel.hpp"

namespace video3dgs {

/// n points on the sphere of the given centre and radius. Point i has height
/// z_i = 1 - (2i + 1)/n and azimuth i * pi (3 - sqrt 5) (the golden angle).
template <class Scalar>
[[nodiscard]] std::vector<Eigen::Matrix<Scalar, 3, 1>> fibonacci_sphere(std::size_t n, const Eigen::Matrix<Scalar, 3, 1>& centre,
                                                                        Scalar radius) {
  std::vector<Eigen::Matrix<Scalar, 3, 1>> pts(n);
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  for (std::size_t i = 0; i < n; ++i) {
    const double z = 1.0 - (2.0 * double(i) + 1.0) / double(n);
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const double phi = golden * double(i);
    pts[i] = centre + radius * Eigen::Matrix<Scalar, 3, 1>(Scalar(r * std::cos(phi)), Scalar(r * std::sin(phi)), Scalar(z));
  }
  return pts;
}

struct BackgroundShellOptions {
  std::size_t points_per_shell = 30000;          ///< reference: 30k per sphere, 60k in all
  std::vector<double> radius_factors{1.0, 3.0};  ///< radii as multiples of the box's largest side
  double min_extent = 1e-3;                      ///< floor for the box side (a single point, no box)
};

/// Background points: `points_per_shell` points on each sphere centred at the centre of the
/// bounding box of `foreground`, with radius `factor * max(largest side, min_extent)`. With no
/// foreground points the box is the unit cube around the origin (`fallback_centre`).
template <class Scalar>
[[nodiscard]] std::vector<Eigen::Matrix<Scalar, 3, 1>> background_shell_points(
    const std::vector<Eigen::Matrix<Scalar, 3, 1>>& foreground, const BackgroundShellOptions& opt = {},
    const Eigen::Matrix<Scalar, 3, 1>& fallback_centre = Eigen::Matrix<Scalar, 3, 1>::Zero()) {
  using V3 = Eigen::Matrix<Scalar, 3, 1>;
  V3 lo = V3::Constant(std::numeric_limits<Scalar>::max()), hi = -lo;
  for (const V3& p : foreground) {
    if (!p.allFinite()) continue;
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  V3 centre = fallback_centre;
  Scalar side = Scalar(1);
  if ((hi - lo).minCoeff() >= Scalar(0)) {
    centre = Scalar(0.5) * (lo + hi);
    side = (hi - lo).maxCoeff();
  }
  side = std::max(side, Scalar(opt.min_extent));
  std::vector<V3> out;
  out.reserve(opt.points_per_shell * opt.radius_factors.size());
  for (double f : opt.radius_factors) {
    const auto shell = fibonacci_sphere<Scalar>(opt.points_per_shell, centre, Scalar(f) * side);
    out.insert(out.end(), shell.begin(), shell.end());
  }
  return out;
}

/// For each point, the mean squared distance to its k nearest other points (exact, via a uniform
/// grid). Points without k neighbours use the ones they have; a lone point gets 0. Deterministic
/// and independent of the thread count (each point is computed on its own).
template <class Scalar>
[[nodiscard]] std::vector<Scalar> knn_mean_sq_distance(const std::vector<Eigen::Matrix<Scalar, 3, 1>>& pts, int k = 3,
                                                       ThreadPool* pool = nullptr) {
  using V3 = Eigen::Matrix<Scalar, 3, 1>;
  const std::size_t n = pts.size();
  std::vector<Scalar> out(n, Scalar(0));
  if (n < 2 || k < 1) return out;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::max()), hi = -lo;
  for (const V3& p : pts) {
    lo = lo.cwiseMin(p.template cast<double>());
    hi = hi.cwiseMax(p.template cast<double>());
  }
  // About 2 points per cell on average.
  const Eigen::Vector3d ext = (hi - lo).cwiseMax(1e-12);
  const double volume = ext.x() * ext.y() * ext.z();
  double cell = std::cbrt(std::max(volume, 1e-300) * 2.0 / double(n));
  cell = std::max({cell, ext.maxCoeff() / 1024.0, 1e-12});
  auto coord = [&](const V3& p) {
    return std::array<std::int64_t, 3>{static_cast<std::int64_t>(std::floor((double(p.x()) - lo.x()) / cell)),
                                       static_cast<std::int64_t>(std::floor((double(p.y()) - lo.y()) / cell)),
                                       static_cast<std::int64_t>(std::floor((double(p.z()) - lo.z()) / cell))};
  };
  auto key = [](std::int64_t x, std::int64_t y, std::int64_t z) {
    return (static_cast<std::uint64_t>(x) * 73856093ull) ^ (static_cast<std::uint64_t>(y) * 19349663ull) ^
           (static_cast<std::uint64_t>(z) * 83492791ull);
  };
  std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> grid;
  grid.reserve(n);
  std::array<std::int64_t, 3> max_c{0, 0, 0};
  for (std::size_t i = 0; i < n; ++i) {
    const auto c = coord(pts[i]);
    for (int d = 0; d < 3; ++d) max_c[d] = std::max(max_c[d], c[d]);
    grid[key(c[0], c[1], c[2])].push_back(static_cast<std::uint32_t>(i));
  }
  const std::int64_t max_ring = std::max({max_c[0], max_c[1], max_c[2]}) + 1;
  const std::size_t want = std::min<std::size_t>(static_cast<std::size_t>(k), n - 1);
  constexpr std::int64_t kMaxRing = 4;

  parallel_for(pool, n, [&](std::size_t i) {
    const auto c = coord(pts[i]);
    std::vector<double> best;  // sorted ascending, at most `want` entries
    best.reserve(want + 1);
    auto consider = [&](double d2) {
      if (best.size() < want || d2 < best.back()) {
        best.insert(std::upper_bound(best.begin(), best.end(), d2), d2);
        if (best.size() > want) best.pop_back();
      }
    };
    bool done = false;
    for (std::int64_t ring = 0; ring <= max_ring && !done; ++ring) {
      // Rings 0..ring-1 are done; a point in a cell of ring >= `ring` is at least (ring - 1) cells away.
      const double reach = double(std::max<std::int64_t>(ring - 1, 0)) * cell;
      if (best.size() == want && best.back() <= reach * reach) break;
      if (ring > kMaxRing) {  // an isolated point: a direct scan is cheaper than ever larger shells
        best.clear();
        for (std::size_t j = 0; j < n; ++j)
          if (j != i) consider((pts[j].template cast<double>() - pts[i].template cast<double>()).squaredNorm());
        done = true;
        break;
      }
      for (std::int64_t dx = -ring; dx <= ring; ++dx)
        for (std::int64_t dy = -ring; dy <= ring; ++dy)
          for (std::int64_t dz = -ring; dz <= ring; ++dz) {
            if (std::max({std::abs(dx), std::abs(dy), std::abs(dz)}) != ring) continue;  // shell only
            auto it = grid.find(key(c[0] + dx, c[1] + dy, c[2] + dz));
            if (it == grid.end()) continue;
            for (std::uint32_t j : it->second) {
              if (j == i) continue;
              const auto q = coord(pts[j]);
              if (q[0] != c[0] + dx || q[1] != c[1] + dy || q[2] != c[2] + dz) continue;  // hash collision
              consider((pts[j].template cast<double>() - pts[i].template cast<double>()).squaredNorm());
            }
          }
    }
    double s = 0;
    for (double d : best) s += d;
    out[i] = best.empty() ? Scalar(0) : Scalar(s / double(best.size()));
  }, 64);
  return out;
}

}  // namespace video3dgs
