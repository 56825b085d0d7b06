#pragma once
// Random test scenes for the rasterizer tests: a small camera and Gaussians that include the hazards
// the issue names (overlapping, nearly edge-on, partially off-screen with a clamped Jacobian, near the
// near plane).
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "video3dgs/testing/grad_check.hpp"
#include "video3dgs/core/camera.hpp"
#include "video3dgs/gaussian/activations.hpp"
#include "video3dgs/gaussian/cloud.hpp"
#include "video3dgs/sh/basis.hpp"

namespace video3dgs::test {

template <class Scalar>
Camera<Scalar> small_camera(int w = 64, int h = 48) {
  Camera<Scalar> cam;
  cam.width = w;
  cam.height = h;
  cam.fx = cam.fy = Scalar(60) * Scalar(w) / Scalar(64);
  cam.cx = Scalar(w) / 2 + Scalar(0.3);
  cam.cy = Scalar(h) / 2 - Scalar(0.2);
  return cam;
}

/// Places a Gaussian at pixel (u, v) and depth z with screen sigma ~ sigma_px (anisotropy `aniso`).
template <class Scalar, int D>
Gaussian<Scalar, D> gaussian_at(const Camera<Scalar>& cam, std::mt19937_64& rng, double u, double v, double z,
                                double sigma_px, double aniso = 1.5, double opacity = 0.6) {
  std::normal_distribution<double> N(0, 1);
  std::uniform_real_distribution<double> U(0, 1);
  Gaussian<Scalar, D> g;
  const auto p = cam.pixel_to_world(typename Camera<Scalar>::Vec2(Scalar(u), Scalar(v)), Scalar(z));
  for (int k = 0; k < 3; ++k) g.mean[k] = p[k];
  const double s = sigma_px * z / double(cam.fx);
  g.log_scale = {Scalar(std::log(s)), Scalar(std::log(s / aniso)), Scalar(std::log(s * (0.5 + U(rng))))};
  g.rotation = {Scalar(N(rng)), Scalar(N(rng)), Scalar(N(rng)), Scalar(N(rng))};
  g.opacity_logit = logit(Scalar(opacity));
  for (auto& c : g.sh) c = Scalar(0.15 * N(rng));
  // The draws are sequenced (the order of a call's arguments is unspecified): last channel first.
  const double b = 0.2 + 0.6 * U(rng), gr = 0.2 + 0.6 * U(rng), r = 0.2 + 0.6 * U(rng);
  g.set_rgb(Scalar(r), Scalar(gr), Scalar(b));
  return g;
}

/// `n` random Gaussians plus the hazard cases.
template <class Scalar, int D = 3>
GaussianCloud<Scalar, D> random_scene(const Camera<Scalar>& cam, std::uint64_t seed, int n = 12, bool hazards = true) {
  auto rng = seeded_rng(seed);
  std::uniform_real_distribution<double> U(0, 1);
  GaussianCloud<Scalar, D> cloud;
  const double W = cam.width, H = cam.height;
  for (int i = 0; i < n; ++i) {
    // Sequenced draws, last argument first (a call's argument order is unspecified).
    const double opacity = 0.15 + 0.7 * U(rng), aniso = 1 + 2 * U(rng), sigma = 1.5 + 4 * U(rng), z = 2 + 3 * U(rng);
    const double v = H * (-0.05 + 1.1 * U(rng)), u = W * (-0.05 + 1.1 * U(rng));
    cloud.push_back(gaussian_at<Scalar, D>(cam, rng, u, v, z, sigma, aniso, opacity));
  }
  if (hazards) {
    // Two overlapping Gaussians at the same pixel, different depths.
    cloud.push_back(gaussian_at<Scalar, D>(cam, rng, W * 0.4, H * 0.5, 3.0, 5, 1.2, 0.7));
    cloud.push_back(gaussian_at<Scalar, D>(cam, rng, W * 0.42, H * 0.48, 3.3, 4, 1.4, 0.6));
    // Nearly edge-on: one axis 1e-3 of the others.
    auto flat = gaussian_at<Scalar, D>(cam, rng, W * 0.6, H * 0.3, 2.5, 6, 1.0, 0.5);
    flat.log_scale[2] = flat.log_scale[0] + Scalar(std::log(1e-3));
    flat.rotation = {Scalar(0.9), Scalar(0.1), Scalar(0.4), Scalar(0.05)};
    cloud.push_back(flat);
    // Partially off-screen (left) and far off-screen with a clamped Jacobian (right).
    cloud.push_back(gaussian_at<Scalar, D>(cam, rng, -3.0, H * 0.7, 3.1, 4, 1.3, 0.5));
    cloud.push_back(gaussian_at<Scalar, D>(cam, rng, W + 22.0, H * 0.4, 2.0, 9, 1.1, 0.6));
    // Near the near plane (z = 0.3 with near 0.2), small so it covers a patch.
    cloud.push_back(gaussian_at<Scalar, D>(cam, rng, W * 0.25, H * 0.25, 0.3, 3, 1.2, 0.4));
  }
  return cloud;
}

/// Finite-difference check (double) of every parameter group of `cloud` (mean, log-scale, rotation,
/// opacity logit, SH) and of the background colour against the rasterizer's gradients `g` (the cloud's
/// part) and `dL_dbackground`; `eval()` renders `cloud` with `settings` and returns the loss.
template <class Cloud, class Grad, class Settings, class Background, class Eval>
void check_raster_gradients(Cloud& cloud, const Grad& g, Settings& settings, const Background& dL_dbackground, Eval&& eval,
                            const testing::GradTolerance& tol) {
  auto check = [&](const char* name, std::vector<double>& p, const std::vector<double>& a) {
    const auto res = testing::check_gradient(name, p, a, eval, tol);
    INFO(res);
    CHECK(res.ok());
  };
  check("mean", cloud.mean, g.dL_dmean);
  check("log_scale", cloud.log_scale, g.dL_dlog_scale);
  check("rotation", cloud.rotation, g.dL_drotation);
  check("opacity_logit", cloud.opacity_logit, g.dL_dopacity_logit);
  check("sh", cloud.sh, g.dL_dsh);
  std::vector<double> bg(settings.background.begin(), settings.background.end());
  const std::vector<double> dbg(dL_dbackground.begin(), dL_dbackground.end());
  const auto rb = testing::check_gradient("background", bg, dbg, [&] {
    for (int c = 0; c < 3; ++c) settings.background[std::size_t(c)] = bg[std::size_t(c)];
    return eval();
  }, tol);
  for (int c = 0; c < 3; ++c) settings.background[std::size_t(c)] = bg[std::size_t(c)];
  INFO(rb);
  CHECK(rb.ok());
}

}  // namespace video3dgs::test
