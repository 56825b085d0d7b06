#pragma once
/// @file
/// Seeded synthetic Gaussian scenes: `random_view_cloud` (the rasterizer benchmark scene: N Gaussians
/// filling a camera's view) and `demo_scene` + `demo_camera` (a textured object in front of a textured
/// backdrop, seen from a camera moving on an arc). Deterministic for a seed on every platform (own
/// uniform/normal mapping of a 64-bit Mersenne twister).

#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>

#include "video3dgs/core/camera.hpp"
#include "video3dgs/gaussian/activations.hpp"
#include "video3dgs/gaussian/cloud.hpp"
#include "video3dgs/sh/basis.hpp"

namespace video3dgs::synthetic {

/// Portable seeded random numbers (the std distributions are implementation-defined).
class Random {
 public:
  explicit Random(std::uint64_t seed) : rng_(seed) {}
  /// Uniform in [0, 1).
  double uniform() { return static_cast<double>(rng_() >> 11) * 0x1.0p-53; }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  /// Standard normal (Box-Muller).
  double normal() {
    const double u1 = 1.0 - uniform(), u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
  }

 private:
  std::mt19937_64 rng_;
};

struct RandomViewOptions {
  double min_depth = 2, max_depth = 6;          ///< camera depth range
  double min_sigma_px = 1, max_sigma_px = 4;    ///< projected standard deviation per axis (pixels)
  double min_opacity = 0.1, max_opacity = 0.9;
  double sh_rest_std = 0.1;                     ///< std of the non-DC SH coefficients
};

/// N Gaussians filling the view of `cam` (benchmark scene): uniform pixel position and depth, per-axis
/// scale giving the requested projected sigma, uniformly random rotation, opacity and colour.
template <class Scalar, int SHDegree>
[[nodiscard]] GaussianCloud<Scalar, SHDegree> random_view_cloud(const Camera<Scalar>& cam, std::size_t n, std::uint64_t seed,
                                                                const RandomViewOptions& o = {}) {
  Random rnd(seed);
  GaussianCloud<Scalar, SHDegree> cloud;
  cloud.reserve(n);
  Gaussian<Scalar, SHDegree> g;
  for (std::size_t i = 0; i < n; ++i) {
    const double u = rnd.uniform(0, cam.width), v = rnd.uniform(0, cam.height);
    const double z = rnd.uniform(o.min_depth, o.max_depth);
    const auto p = cam.pixel_to_world(typename Camera<Scalar>::Vec2(Scalar(u), Scalar(v)), Scalar(z));
    for (int k = 0; k < 3; ++k) g.mean[k] = p[k];
    for (int k = 0; k < 3; ++k)
      g.log_scale[k] = Scalar(std::log(rnd.uniform(o.min_sigma_px, o.max_sigma_px) * z / double(cam.fx)));
    for (int k = 0; k < 4; ++k) g.rotation[k] = Scalar(rnd.normal());
    g.opacity_logit = logit(Scalar(rnd.uniform(o.min_opacity, o.max_opacity)));
    for (auto& c : g.sh) c = Scalar(o.sh_rest_std * rnd.normal());
    g.set_rgb(Scalar(rnd.uniform(0.1, 0.9)), Scalar(rnd.uniform(0.1, 0.9)), Scalar(rnd.uniform(0.1, 0.9)));
    cloud.push_back(g);
  }
  return cloud;
}

/// The demo scene (world units, y down like the cameras): a striped sphere of radius 1 at the origin
/// made of `object_gaussians` surface Gaussians (Fibonacci lattice), in front of a checkered backdrop
/// plane at z = 4 (`backdrop_side` x 0.6 `backdrop_side` Gaussians over 20 x 12 units), SH degree 3 with a mild view-dependent
/// sheen on the sphere.
template <class Scalar>
[[nodiscard]] GaussianCloud<Scalar, 3> demo_scene(std::uint64_t seed = 1, int object_gaussians = 2500, int backdrop_side = 110) {
  Random rnd(seed);
  GaussianCloud<Scalar, 3> cloud;
  Gaussian<Scalar, 3> g;
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  const double surf = std::sqrt(4 * std::numbers::pi / object_gaussians);  // spacing on the unit sphere
  for (int i = 0; i < object_gaussians; ++i) {
    const double y = 1 - 2 * (i + 0.5) / object_gaussians, r = std::sqrt(1 - y * y), phi = golden * i;
    const double x = r * std::cos(phi), z = r * std::sin(phi);
    g.mean = {Scalar(x), Scalar(y), Scalar(z)};
    // Flat disc tangent to the sphere: rotate +z onto the normal.
    const Eigen::Matrix<double, 3, 1> nrm(x, y, z);
    const auto q = Eigen::Quaternion<double>::FromTwoVectors(Eigen::Matrix<double, 3, 1>(0, 0, 1), nrm);
    g.rotation = {Scalar(q.w()), Scalar(q.x()), Scalar(q.y()), Scalar(q.z())};
    g.log_scale = {Scalar(std::log(0.6 * surf)), Scalar(std::log(0.6 * surf)), Scalar(std::log(0.05 * surf))};
    g.opacity_logit = logit(Scalar(0.9));
    for (auto& c : g.sh) c = Scalar(0);
    const double lat = std::asin(y), lon = std::atan2(z, x);
    const bool stripe = std::fmod(std::floor(lat * 6 / std::numbers::pi) + std::floor(lon * 4 / std::numbers::pi) + 64, 2.0) < 1;
    const double jitter = 0.05 * rnd.normal();
    if (stripe) g.set_rgb(Scalar(0.9 + jitter), Scalar(0.35 + jitter), Scalar(0.1));
    else g.set_rgb(Scalar(0.15), Scalar(0.3 + jitter), Scalar(0.85 + jitter));
    for (int c = 0; c < 3; ++c) g.sh[3 * 2 + c] = Scalar(0.15);  // brighter when seen from behind (+z view)
    cloud.push_back(g);
  }
  const double bw = 20, bh = 12, step = bw / backdrop_side;
  const int rows = static_cast<int>(bh / step);
  for (int j = 0; j < rows; ++j)
    for (int i = 0; i < backdrop_side; ++i) {
      const double x = -bw / 2 + (i + 0.5) * step, y = -bh / 2 + (j + 0.5) * (bh / rows);
      g.mean = {Scalar(x), Scalar(y), Scalar(4)};
      g.rotation = {1, 0, 0, 0};
      g.log_scale = {Scalar(std::log(0.7 * step)), Scalar(std::log(0.7 * step)), Scalar(std::log(0.02 * step))};
      g.opacity_logit = logit(Scalar(0.95));
      for (auto& c : g.sh) c = Scalar(0);
      const bool check = ((static_cast<int>(std::floor(x)) + static_cast<int>(std::floor(y))) & 1) != 0;
      const double shade = 0.5 + 0.4 * (y / bh + 0.5) * (check ? 1.0 : 0.4) + 0.03 * rnd.normal();
      g.set_rgb(Scalar(shade * 0.9), Scalar(shade * 0.85), Scalar(shade * 0.7));
      cloud.push_back(g);
    }
  return cloud;
}

/// Camera of frame `frame` of `frames` for the demo scene: on an arc of +-20 degrees around the sphere
/// at distance 5, looking at the origin; 60 degree horizontal field of view.
template <class Scalar>
[[nodiscard]] Camera<Scalar> demo_camera(int width, int height, int frame, int frames) {
  auto cam = Camera<Scalar>::from_fov(width, height, Scalar(60.0 * std::numbers::pi / 180.0));
  const double t = frames > 1 ? double(frame) / double(frames - 1) : 0.5;
  const double a = (t - 0.5) * 40.0 * std::numbers::pi / 180.0;
  const typename Camera<Scalar>::Vec3 eye(Scalar(5 * std::sin(a)), Scalar(-0.6 + 0.4 * t), Scalar(-5 * std::cos(a)));
  cam.look_at(eye, Camera<Scalar>::Vec3::Zero());
  return cam;
}

}  // namespace video3dgs::synthetic
