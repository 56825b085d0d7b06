// Extremes: nothing may produce NaN/Inf in the image or any gradient; non-finite inputs are culled.
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "scene_util.hpp"
#include "video3dgs/rasterizer/rasterizer.hpp"

using namespace video3dgs;

namespace {
template <class Scalar>
bool finite(const std::vector<Scalar>& v) {
  for (Scalar x : v)
    if (!std::isfinite(x)) return false;
  return true;
}

/// Forward + backward with random output gradients; checks every output is finite. Returns visible count.
template <class Scalar, int D>
std::size_t render_checked(const Camera<Scalar>& cam, const GaussianCloud<Scalar, D>& cloud, bool antialiased = false,
                           unsigned threads = 1) {
  Rasterizer<Scalar, 16> r;
  r.settings.antialiased = antialiased;
  r.settings.background = {Scalar(0.1), Scalar(0.2), Scalar(0.3)};
  RasterContext<Scalar, 3> ctx;
  ThreadPool pool(threads);
  r.forward(cam, cloud.params(), ctx, &pool);
  CHECK(finite(ctx.image.storage()));
  CHECK(finite(ctx.alpha.storage()));
  CHECK(finite(ctx.depth.storage()));
  for (Scalar a : ctx.alpha.storage()) {
    CHECK(a >= Scalar(0));
    CHECK(a <= Scalar(1));
  }
  Image<Scalar, 3> dimg(cam.width, cam.height);
  Image<Scalar, 1> da(cam.width, cam.height), dd(cam.width, cam.height);
  auto rng = test::seeded_rng(99);
  std::uniform_real_distribution<double> U(-1, 1);
  for (auto& v : dimg.storage()) v = Scalar(U(rng));
  for (auto& v : da.storage()) v = Scalar(U(rng));
  for (auto& v : dd.storage()) v = Scalar(U(rng));
  GaussianCloudGrad<Scalar, D> g(cloud.size());
  std::vector<Scalar> m2d(2 * cloud.size());
  RasterGrads<Scalar, 3> grads;
  grads.gaussians = g.grads();
  grads.dL_dmean2d = m2d;
  r.backward(ctx, dimg.cview(), da.cview(), dd.cview(), grads, &pool);
  CHECK(finite(g.dL_dmean));
  CHECK(finite(g.dL_dlog_scale));
  CHECK(finite(g.dL_drotation));
  CHECK(finite(g.dL_dopacity_logit));
  CHECK(finite(g.dL_dsh));
  CHECK(finite(m2d));
  for (Scalar b : grads.dL_dbackground) CHECK(std::isfinite(b));
  // Culled Gaussians get exactly zero gradients.
  for (std::size_t i = 0; i < cloud.size(); ++i)
    if (!ctx.visible[i]) {
      CHECK(g.dL_dopacity_logit[i] == Scalar(0));
      CHECK(g.dL_dmean[3 * i] == Scalar(0));
    }
  return ctx.stats.visible;
}
}  // namespace

TEST_CASE_TEMPLATE("extremes: scales, opacities, quaternions", Scalar, float, double) {
  auto cam = test::small_camera<Scalar>();
  for (bool aa : {false, true}) {
    auto cloud = test::random_scene<Scalar, 3>(cam, 61, 10);
    const std::size_t n = cloud.size();
    for (std::size_t i = 0; i < n; ++i) {
      const int kind = int(i % 8);
      if (kind == 0) cloud.log_scale[3 * i] = cloud.log_scale[3 * i + 1] = cloud.log_scale[3 * i + 2] = Scalar(std::log(1e-8));
      if (kind == 1) cloud.log_scale[3 * i] = cloud.log_scale[3 * i + 1] = cloud.log_scale[3 * i + 2] = Scalar(std::log(1e4));
      if (kind == 2) cloud.opacity_logit[i] = Scalar(30);
      if (kind == 3) cloud.opacity_logit[i] = Scalar(-30);
      if (kind == 4) cloud.rotation[4 * i] = cloud.rotation[4 * i + 1] = cloud.rotation[4 * i + 2] = cloud.rotation[4 * i + 3] = 0;
      if (kind == 5) cloud.rotation[4 * i] = Scalar(1e30), cloud.rotation[4 * i + 2] = Scalar(-3e29);
      if (kind == 6) cloud.log_scale[3 * i + 1] = Scalar(std::log(1e-8));  // edge-on
      if (kind == 7) cloud.opacity_logit[i] = Scalar(30), cloud.log_scale[3 * i] = Scalar(std::log(1e4));
    }
    render_checked(cam, cloud, aa);
  }
}

TEST_CASE_TEMPLATE("extremes: behind the camera, on the near plane, at 1e6 depth", Scalar, float, double) {
  auto cam = test::small_camera<Scalar>();
  auto cloud = test::random_scene<Scalar, 3>(cam, 62, 6, false);
  auto rng = test::seeded_rng(63);
  cloud.push_back(test::gaussian_at<Scalar, 3>(cam, rng, 30, 20, -2.0, 4));     // behind
  cloud.push_back(test::gaussian_at<Scalar, 3>(cam, rng, 30, 20, 0.2, 4));      // exactly on the near plane
  cloud.push_back(test::gaussian_at<Scalar, 3>(cam, rng, 30, 20, 0.2000001, 4)); // just in front of it
  cloud.push_back(test::gaussian_at<Scalar, 3>(cam, rng, 30, 20, 1e6, 4));      // far away
  auto huge = test::gaussian_at<Scalar, 3>(cam, rng, 30, 20, 1e6, 4);
  huge.log_scale = {Scalar(std::log(1e4)), Scalar(std::log(1e4)), Scalar(std::log(1e4))};
  cloud.push_back(huge);
  const std::size_t visible = render_checked(cam, cloud);
  CHECK(visible >= 6);
  CHECK(visible <= cloud.size() - 2);  // behind and on the near plane are culled
}

TEST_CASE("extremes: a scene offset by 1e5 in float") {
  auto cam = test::small_camera<float>();
  const Eigen::Vector3f offset(1e5f, -1e5f, 1e5f);
  cam.look_at(offset + Eigen::Vector3f(0, 0, -4), offset);
  GaussianCloud<float, 3> cloud;
  auto rng = test::seeded_rng(64);
  std::uniform_real_distribution<float> U(-1, 1);
  for (int i = 0; i < 50; ++i) {
    Gaussian<float, 3> g;
    g.mean = {offset.x() + U(rng), offset.y() + U(rng), offset.z() + U(rng)};
    g.log_scale = {std::log(0.05f), std::log(0.08f), std::log(0.03f)};
    g.rotation = {U(rng), U(rng), U(rng), U(rng)};
    g.set_rgb(0.5f + 0.4f * U(rng), 0.5f, 0.5f);
    cloud.push_back(g);
  }
  CHECK(render_checked(cam, cloud) > 20);
}

TEST_CASE_TEMPLATE("extremes: non-finite inputs are culled, never propagated", Scalar, float, double) {
  auto cam = test::small_camera<Scalar>();
  auto cloud = test::random_scene<Scalar, 3>(cam, 65, 12, false);
  const Scalar nan = std::numeric_limits<Scalar>::quiet_NaN(), inf = std::numeric_limits<Scalar>::infinity();
  cloud.mean[0] = nan;
  cloud.log_scale[3 * 1 + 2] = inf;
  cloud.rotation[4 * 2 + 1] = nan;
  cloud.opacity_logit[3] = nan;
  cloud.sh[cloud.sh_coeffs * 3 * 4 + 5] = inf;
  cloud.mean[3 * 5 + 2] = -inf;
  cloud.rotation[4 * 6] = inf;
  const std::size_t visible = render_checked(cam, cloud);
  CHECK(visible <= 12 - 6);
  // Non-finite output gradients are rejected.
  Rasterizer<Scalar, 16> r;
  RasterContext<Scalar, 3> ctx;
  r.forward(cam, cloud.params(), ctx);
  Image<Scalar, 3> dimg(cam.width, cam.height);
  dimg(3, 3, 1) = nan;
  RasterGrads<Scalar, 3> grads;
  CHECK_THROWS_AS(r.backward(ctx, dimg.cview(), {}, {}, grads), numeric_error);
  // Non-finite camera or background is an option error.
  auto bad_cam = cam;
  bad_cam.t.x() = nan;
  CHECK_THROWS_AS(r.forward(bad_cam, cloud.params(), ctx), option_error);
  r.settings.background[0] = inf;
  CHECK_THROWS_AS(r.forward(cam, cloud.params(), ctx), option_error);
}

// An infinite SH coefficient times a basis function of either sign sums to +inf (a non-finite colour)
// or to -inf (clamped to the finite colour 0; its backward has inf x 0 = NaN in dL/ddir, so dL/dmean).
// Either, and NaN, culls the Gaussian: each Gaussian of the scene in turn, one coefficient of each of
// the bands 1..3.
TEST_CASE_TEMPLATE("extremes: a non-finite SH coefficient culls its Gaussian, whatever the basis function's sign", Scalar,
                   float, double) {
  auto cam = test::small_camera<Scalar>();
  const auto clean = test::random_scene<Scalar, 3>(cam, 65, 12, false);
  Rasterizer<Scalar, 16> r;
  RasterContext<Scalar, 3> ctx;
  r.forward(cam, clean.params(), ctx);
  const std::vector<std::uint8_t> visible(ctx.visible.begin(), ctx.visible.end());
  const std::size_t n_visible = ctx.stats.visible;
  REQUIRE(n_visible >= 6);
  const Scalar nan = std::numeric_limits<Scalar>::quiet_NaN(), inf = std::numeric_limits<Scalar>::infinity();
  const std::size_t K = std::size_t(clean.sh_coeffs);
  for (std::size_t i = 0; i < clean.size(); ++i)
    for (std::size_t k : {1, 6, 11})
      for (Scalar bad : {inf, -inf, nan}) {
        auto cloud = clean;
        cloud.sh[3 * (K * i + k) + i % 3] = bad;
        INFO("Gaussian " << i << ", coefficient " << k << ", channel " << i % 3 << ": " << bad);
        CHECK(render_checked(cam, cloud) == n_visible - visible[i]);
      }
}

TEST_CASE_TEMPLATE("extremes: zero Gaussians and a 1x1 image, forward and backward", Scalar, float, double) {
  GaussianCloud<Scalar, 3> empty;
  render_checked(test::small_camera<Scalar>(), empty);
  auto cam1 = test::small_camera<Scalar>(1, 1);
  auto cloud = test::random_scene<Scalar, 3>(cam1, 66, 20);
  render_checked(cam1, cloud, false, 2);
  render_checked(cam1, empty);
}

TEST_CASE_TEMPLATE("extremes: a huge opaque Gaussian in front covers the whole image", Scalar, float, double) {
  auto cam = test::small_camera<Scalar>();
  for (double log_s : {std::log(1e4), 20.0, 23.0}) {
    INFO("log scale " << log_s);
    GaussianCloud<Scalar, 0> cloud(1);
    cloud.mean = {Scalar(0.1), Scalar(-0.2), Scalar(3)};
    cloud.log_scale = {Scalar(log_s), Scalar(log_s - 1), Scalar(log_s)};
    cloud.rotation = {Scalar(0.9), Scalar(0.3), Scalar(0.2), Scalar(0.1)};
    cloud.opacity_logit = {logit(Scalar(0.9))};
    Rasterizer<Scalar, 16> r;
    RasterContext<Scalar, 3> ctx;
    r.forward(cam, cloud.params(), ctx);
    REQUIRE(ctx.stats.visible == 1);
    for (Scalar a : ctx.alpha.storage()) CHECK(a == doctest::Approx(0.9).epsilon(1e-3));
    render_checked(cam, cloud);
  }
}
