// Finite-difference checks of the rasterizer where compositing saturates, and float against double.
//
// The random scenes of backward_test.cpp rarely reach the two non-smooth rules of the compositing loop:
// the clamp alpha = min(alpha_max, o G) (no opacity or position gradient where it binds) and the early
// stop (a pixel stops once T (1 - alpha) < min_transmittance, without blending that Gaussian, or after
// blending it under RasterSettings::blend_at_stop: both rules are checked). Here
// stacks of opacity-0.999 Gaussians make both happen on many pixels; the test counts them (by walking
// every pixel through the forward pass's sorted Gaussians with the per-pixel rules) and checks that no
// decision is close enough to its threshold for a finite difference to cross it, then checks every
// parameter group, and dL/dmean2d of every Gaussian entry by entry, against central differences.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "scene_util.hpp"
#include "video3dgs/rasterizer/rasterizer.hpp"
#include "video3dgs/synthetic.hpp"
#include "video3dgs/testing/grad_check.hpp"

using namespace video3dgs;

namespace {

/// L = <Wc, image> + <Wa, alpha> + <Wd, depth> with random weights.
struct LinearLoss {
  Image<double, 3> wc;
  Image<double, 1> wa, wd;
  LinearLoss(int w, int h, std::uint64_t seed) : wc(w, h), wa(w, h), wd(w, h) {
    auto rng = test::seeded_rng(seed);
    std::uniform_real_distribution<double> U(-1, 1);
    for (auto& v : wc.storage()) v = U(rng);
    for (auto& v : wa.storage()) v = U(rng);
    for (auto& v : wd.storage()) v = 0.3 * U(rng);
  }
  double operator()(const RasterContext<double, 3>& ctx) const {
    double L = 0;
    for (std::size_t i = 0; i < wc.size(); ++i) L += wc.data()[i] * ctx.image.data()[i];
    for (std::size_t i = 0; i < wa.size(); ++i) L += wa.data()[i] * ctx.alpha.data()[i] + wd.data()[i] * ctx.depth.data()[i];
    return L;
  }
};

/// Four stacks of four near-opaque (0.999) Gaussians, each stack covering the same pixels at
/// increasing depths, plus a few translucent ones around them.
GaussianCloud<double, 3> saturated_scene(const Camera<double>& cam, std::uint64_t seed) {
  auto rng = test::seeded_rng(seed);
  std::uniform_real_distribution<double> U(0, 1);
  GaussianCloud<double, 3> cloud;
  const double W = cam.width, H = cam.height;
  const double centres[4][2] = {{0.27, 0.3}, {0.7, 0.33}, {0.3, 0.72}, {0.74, 0.7}};
  // The draws are sequenced, last argument first (a call's argument order is unspecified).
  for (const auto& c : centres)
    for (int k = 0; k < 4; ++k) {
      const double aniso = 1 + 0.5 * U(rng), sigma = 5 + 3 * U(rng), z = 2.0 + 0.4 * k + 0.2 * U(rng);
      const double v = H * c[1] + 3 * (U(rng) - 0.5), u = W * c[0] + 3 * (U(rng) - 0.5);
      cloud.push_back(test::gaussian_at<double, 3>(cam, rng, u, v, z, sigma, aniso, 0.999));
    }
  for (int i = 0; i < 8; ++i) {
    const double opacity = 0.3 + 0.6 * U(rng), aniso = 1 + U(rng), sigma = 2 + 4 * U(rng), z = 1.5 + 4 * U(rng);
    const double v = H * U(rng), u = W * U(rng);
    cloud.push_back(test::gaussian_at<double, 3>(cam, rng, u, v, z, sigma, aniso, opacity));
  }
  return cloud;
}

/// What the per-pixel rules of forward.hpp decide on a scene (walked over ctx.sorted, no tiles).
struct Saturation {
  std::size_t clamped = 0;   ///< (pixel, Gaussian) pairs blended (or stopping the pixel) with o G >= alpha_max
  std::size_t clamped_pixels = 0;  ///< pixels with at least one such pair
  std::size_t stopped = 0;   ///< pixels that stopped early (T (1 - alpha) < min_transmittance)
  std::size_t blended = 0;   ///< (pixel, Gaussian) pairs blended
  /// Closest relative distance |value / threshold - 1| of a decision to its threshold: o G to alpha_max
  /// (clamp), alpha to alpha_min (skip), T (1 - alpha) to min_transmittance (stop).
  double clamp_margin = std::numeric_limits<double>::infinity();
  double skip_margin = std::numeric_limits<double>::infinity();
  double stop_margin = std::numeric_limits<double>::infinity();
  double final_T_error = 0;  ///< max |T_final - ctx.final_T| (the walk reproduces the forward pass)
};

Saturation walk(const RasterContext<double, 3>& ctx) {
  const auto& s = ctx.settings;
  Saturation out;
  auto near = [](double& margin, double value, double threshold) { margin = std::min(margin, std::abs(value / threshold - 1)); };
  for (int y = 0; y < ctx.camera.height; ++y)
    for (int x = 0; x < ctx.camera.width; ++x) {
      double T = 1;
      bool clamped_here = false;
      for (const auto& g : ctx.sorted) {
        const double dx = x + 0.5 - g.u, dy = y + 0.5 - g.v;
        const double power = 0.5 * g.A * dx * dx + g.B * dx * dy + 0.5 * g.C * dy * dy;
        if (power < 0) continue;
        const double oe = g.opacity * std::exp(-power);
        const double alpha = std::min(s.alpha_max, oe);
        near(out.skip_margin, alpha, s.alpha_min);
        if (alpha < s.alpha_min) continue;
        near(out.clamp_margin, oe, s.alpha_max);
        const double next = T * (1 - alpha);
        near(out.stop_margin, next, s.min_transmittance);
        if (oe >= s.alpha_max) ++out.clamped, clamped_here = true;
        if (next < s.min_transmittance) {
          ++out.stopped;
          if (s.blend_at_stop) ++out.blended, T = next;
          break;
        }
        ++out.blended;
        T = next;
      }
      out.clamped_pixels += clamped_here ? 1 : 0;
      const std::size_t pix = static_cast<std::size_t>(y) * static_cast<std::size_t>(ctx.camera.width) + static_cast<std::size_t>(x);
      out.final_T_error = std::max(out.final_T_error, std::abs(T - ctx.final_T[pix]));
    }
  return out;
}

template <int Tile>
void check_saturated(std::uint64_t seed, bool blend_at_stop) {
  INFO("seed " << seed << " tile " << Tile << " blend_at_stop " << blend_at_stop);
  const auto cam = test::small_camera<double>(64, 48);
  auto cloud = saturated_scene(cam, seed);
  Rasterizer<double, Tile> r;
  r.settings.background = {0.3, 0.6, 0.2};
  r.settings.blend_at_stop = blend_at_stop;
  const LinearLoss loss(cam.width, cam.height, seed + 500);
  RasterContext<double, 3> ctx;
  r.forward(cam, cloud.params(), ctx);
  REQUIRE(ctx.stats.visible == cloud.size());

  // The scene does what it is for, and no decision is within reach of a finite difference: a step of
  // 1e-6 moves o G, alpha and T by a relative few 1e-6 here (a seed with a skip margin of 8e-6 had one
  // pixel cross alpha_min and a log-scale difference off by 1e2); 1e-4 leaves a factor ~30. Seeds are
  // chosen for their margins (seed 4 even has two clamped alphas stop a pixel at exactly 0.01^2 = 1e-4).
  const Saturation sat = walk(ctx);
  MESSAGE("saturated scene seed " << seed << ": " << sat.clamped << " clamped pairs on " << sat.clamped_pixels << " pixels, "
                                  << sat.stopped << " early stops, " << sat.blended << " blended pairs; margins: clamp " << sat.clamp_margin
                                  << ", skip " << sat.skip_margin << ", stop " << sat.stop_margin);
  CHECK(sat.final_T_error < 1e-12);
  CHECK(sat.clamped >= 20);
  CHECK(sat.clamped_pixels >= 20);
  CHECK(sat.stopped >= 20);
  CHECK(sat.clamp_margin > 1e-4);
  CHECK(sat.skip_margin > 1e-4);
  CHECK(sat.stop_margin > 1e-4);

  GaussianCloudGrad<double, 3> g(cloud.size());
  std::vector<double> m2d(2 * cloud.size());
  RasterGrads<double, 3> grads;
  grads.gaussians = g.grads();
  grads.dL_dmean2d = m2d;
  r.backward(ctx, loss.wc.cview(), loss.wa.cview(), loss.wd.cview(), grads);

  auto eval = [&] {
    RasterContext<double, 3> c2;
    r.forward(cam, cloud.params(), c2);
    return loss(c2);
  };
  // Everything in double. atol: on saturated pixels 1 - alpha ~ 1e-2 and T down to 1e-4 cost two to
  // four digits, so L (~1.5e4 terms) is only accurate to ~2e-13 and the central difference carries
  // noise ~2e-13 / h = 2e-7 on every entry (measured up to 2.7e-7; it scales as 1/h: 2.6e-6 at h = 1e-7,
  // 2e-8 at h = 1e-5). rtol 1e-6 holds for every entry well above that.
  const testing::GradTolerance tol{.rtol = 1e-6, .atol = 5e-7};
  test::check_raster_gradients(cloud, g, r.settings, grads.dL_dbackground, eval, tol);

  // dL/dmean2d, per Gaussian: move the 2D mean (u, v) the forward pass saved for the compositor and
  // composite again (the compositing of every tile, nothing else: projection, colours and tile lists
  // stay; a 1e-6 pixel shift cannot change a footprint, whose edges are where alpha < alpha_min).
  std::vector<double> uv(2 * cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const auto& sg = ctx.sorted[ctx.rank[i]];
    REQUIRE(sg.id == i);
    uv[2 * i] = sg.u, uv[2 * i + 1] = sg.v;
  }
  RasterContext<double, 3> work = ctx;
  const std::size_t tiles = static_cast<std::size_t>(ctx.tiles_x) * static_cast<std::size_t>(ctx.tiles_y);
  auto composite = [&] {
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      auto& sg = work.sorted[work.rank[i]];
      sg.u = uv[2 * i], sg.v = uv[2 * i + 1];
    }
    for (std::size_t t = 0; t < tiles; ++t) detail::forward_tile<Tile>(resolve_raster_simd(r.settings.simd), work, t);
    return loss(work);
  };
  REQUIRE(composite() == loss(ctx));  // unperturbed: the same image bit for bit
  const auto rm = testing::check_gradient("mean2d", uv, m2d, composite, tol);
  INFO(rm);
  CHECK(rm.ok());
  std::size_t nonzero = 0;
  for (double v : m2d) nonzero += v != 0 ? 1 : 0;
  CHECK(nonzero == m2d.size());
}

}  // namespace

TEST_CASE("rasterizer backward: saturated pixels (alpha clamp, early stop) match finite differences (double)") {
  const auto t0 = std::chrono::steady_clock::now();
  for (bool blend_at_stop : {false, true}) {
    check_saturated<16>(1, blend_at_stop);
    check_saturated<8>(7, blend_at_stop);
  }
  MESSAGE("saturated FD checks took "
          << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() << " s");
}
