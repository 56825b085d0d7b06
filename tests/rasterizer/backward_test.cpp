#include "video3dgs/rasterizer/backward.hpp"

#include <cmath>
#include <limits>
#include <tuple>
#include <random>
#include <vector>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "scene_util.hpp"
#include "video3dgs/rasterizer/rasterizer.hpp"
#include "video3dgs/testing/grad_check.hpp"

using namespace video3dgs;

namespace {

/// L = <Wc, image> + <Wa, alpha> + <Wd, depth> with random weights.
struct RandomLoss {
  Image<double, 3> wc;
  Image<double, 1> wa, wd;
  RandomLoss(int w, int h, std::uint64_t seed, bool use_alpha = true, bool use_depth = true)
      : wc(w, h), wa(w, h), wd(w, h) {
    auto rng = test::seeded_rng(seed);
    std::uniform_real_distribution<double> U(-1, 1);
    for (auto& v : wc.storage()) v = U(rng);
    for (auto& v : wa.storage()) v = use_alpha ? U(rng) : 0.0;
    for (auto& v : wd.storage()) v = use_depth ? 0.3 * U(rng) : 0.0;
  }
  double operator()(const RasterContext<double, 3>& ctx) const {
    double L = 0;
    for (std::size_t i = 0; i < wc.size(); ++i) L += wc.data()[i] * ctx.image.data()[i];
    for (std::size_t i = 0; i < wa.size(); ++i) L += wa.data()[i] * ctx.alpha.data()[i] + wd.data()[i] * ctx.depth.data()[i];
    return L;
  }
};

template <int Tile>
void check_all_gradients(std::uint64_t seed, bool antialiased, int active_sh) {
  INFO("seed " << seed << " tile " << Tile << " antialiased " << antialiased << " sh " << active_sh);
  auto cam = test::small_camera<double>();
  auto cloud = test::random_scene<double, 3>(cam, seed);
  Rasterizer<double, Tile> r;
  r.settings.antialiased = antialiased;
  r.settings.active_sh_degree = active_sh;
  r.settings.background = {0.1, 0.5, 0.9};
  RasterContext<double, 3> ctx;
  RandomLoss loss(cam.width, cam.height, seed + 1000);
  auto eval = [&] {
    RasterContext<double, 3> c2;
    r.forward(cam, cloud.params(), c2);
    return loss(c2);
  };
  r.forward(cam, cloud.params(), ctx);
  std::size_t visible = 0;
  for (auto v : ctx.visible) visible += v;
  CHECK(visible >= cloud.size() - 1);  // the far off-screen one may be culled
  GaussianCloudGrad<double, 3> g(cloud.size());
  RasterGrads<double, 3> grads;
  grads.gaussians = g.grads();
  r.backward(ctx, loss.wc.cview(), loss.wa.cview(), loss.wd.cview(), grads);
  // atol: L sums ~1.5e4 pixel terms, each composited through a few Gaussians, and is accurate to
  // ~1e-13 only, so the central difference carries noise ~1e-13 / h = 1e-7 on every entry (measured
  // up to 1.9e-7; e.g. the flat Gaussian's thin-axis log-scale gradient is ~1e-6 with a few % of noise).
  // rtol: was 2e-5 relative to max(1, |g|); every entry well above atol now meets 1e-5 of its own size.
  const testing::GradTolerance tol{.rtol = 1e-5, .atol = 3e-7};
  test::check_raster_gradients(cloud, g, r.settings, grads.dL_dbackground, eval, tol);
}

}  // namespace

TEST_CASE("rasterizer backward: every input matches finite differences (double)") {
  for (std::uint64_t seed : {1u, 2u, 3u}) check_all_gradients<16>(seed, false, 3);
  check_all_gradients<8>(4, false, 1);
  check_all_gradients<32>(5, true, 2);
  check_all_gradients<16>(6, true, 0);
}

TEST_CASE("rasterizer backward: dL/dmean2d is the gradient w.r.t. the 2D means (pixels)") {
  // Shifting cx moves every 2D mean by the same amount and nothing else (no Gaussian is clamped here),
  // so dL/dcx = sum_i dL/du_i.
  auto cam = test::small_camera<double>();
  auto cloud = test::random_scene<double, 3>(cam, 21, 10, false);
  Rasterizer<double, 16> r;
  r.settings.fov_clamp = 10;  // no clamping anywhere
  RasterContext<double, 3> ctx;
  RandomLoss loss(cam.width, cam.height, 77);
  r.forward(cam, cloud.params(), ctx);
  std::vector<double> m2d(2 * cloud.size());
  RasterGrads<double, 3> grads;
  grads.dL_dmean2d = m2d;
  r.backward(ctx, loss.wc.cview(), loss.wa.cview(), loss.wd.cview(), grads);
  double su = 0, sv = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) su += m2d[2 * i], sv += m2d[2 * i + 1];
  std::vector<double> c = {cam.cx, cam.cy};
  const std::vector<double> a = {su, sv};
  const auto res = testing::check_gradient("cx,cy", c, a, [&] {
    auto cam2 = cam;
    cam2.cx = c[0];
    cam2.cy = c[1];
    RasterContext<double, 3> c2;
    r.forward(cam2, cloud.params(), c2);
    return loss(c2);
  }, {.rtol = 1e-5});
  INFO(res);
  CHECK(res.ok());
  CHECK(std::abs(su) + std::abs(sv) > 0);
}

TEST_CASE("rasterizer backward: precomputed colours with 2 channels") {
  auto cam = test::small_camera<double>(40, 30);
  auto cloud = test::random_scene<double, 0>(cam, 31, 8, false);
  std::vector<double> colors(2 * cloud.size());
  auto rng = test::seeded_rng(32);
  std::uniform_real_distribution<double> U(0, 1);
  for (auto& c : colors) c = U(rng);
  Rasterizer<double, 8, 2> r;
  r.settings.background = {0.25, 0.75};
  Image<double, 2> w(cam.width, cam.height);
  for (auto& v : w.storage()) v = U(rng) - 0.5;
  auto eval = [&] {
    RasterContext<double, 2> c2;
    r.forward(cam, cloud.params(), c2, nullptr, colors);
    double L = 0;
    for (std::size_t i = 0; i < w.size(); ++i) L += w.data()[i] * c2.image.data()[i];
    return L;
  };
  RasterContext<double, 2> ctx;
  r.forward(cam, cloud.params(), ctx, nullptr, colors);
  std::vector<double> dcol(colors.size()), dmean(cloud.mean.size());
  RasterGrads<double, 2> grads;
  grads.dL_dcolors = dcol;
  grads.gaussians.dL_dmean = dmean;
  r.backward(ctx, w.cview(), {}, {}, grads);
  auto rc = testing::check_gradient("colors", colors, dcol, eval, {.rtol = 1e-6});
  INFO(rc);
  CHECK(rc.ok());
  auto rm = testing::check_gradient("mean", cloud.mean, dmean, eval, {.rtol = 1e-5});
  INFO(rm);
  CHECK(rm.ok());
}

TEST_CASE("rasterizer backward: overwrites its outputs; dL/dcolors with SH colour is dL/dDC / C0") {
  auto cam = test::small_camera<float>();
  auto cloud = test::random_scene<float, 2>(cam, 41, 15);
  cloud.mean[0] = std::numeric_limits<float>::quiet_NaN();  // one culled Gaussian
  Rasterizer<float, 16> r;
  RasterContext<float, 3> ctx;
  r.forward(cam, cloud.params(), ctx);
  RandomLoss loss(cam.width, cam.height, 42);
  const auto wc = loss.wc.cast<float>();
  auto run = [&](float fill) {
    GaussianCloudGrad<float, 2> g(cloud.size());
    for (auto* v : {&g.dL_dmean, &g.dL_dlog_scale, &g.dL_drotation, &g.dL_dopacity_logit, &g.dL_dsh}) std::fill(v->begin(), v->end(), fill);
    std::vector<float> dcol(3 * cloud.size(), fill), m2d(2 * cloud.size(), fill);
    RasterGrads<float, 3> grads;
    grads.gaussians = g.grads();
    grads.dL_dcolors = dcol;
    grads.dL_dmean2d = m2d;
    r.backward(ctx, wc.cview(), {}, {}, grads);
    return std::make_tuple(g, dcol, m2d);
  };
  const auto [g0, c0, m0] = run(0.f);
  const auto [g1, c1, m1] = run(123.f);
  CHECK(g0.dL_dmean == g1.dL_dmean);
  CHECK(g0.dL_dsh == g1.dL_dsh);
  CHECK(g0.dL_dopacity_logit == g1.dL_dopacity_logit);
  CHECK(c0 == c1);
  CHECK(m0 == m1);
  CHECK(g1.dL_dmean[0] == 0.f);
  const int K = sh::coeff_count(2);
  int checked = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i)
    for (int c = 0; c < 3; ++c)
      if (ctx.visible[i] && !((ctx.color_clamped[i] >> c) & 1u)) {
        CHECK(g0.dL_dsh[3 * K * i + c] == doctest::Approx(float(sh::kC0) * c0[3 * i + c]).epsilon(1e-5));
        ++checked;
      }
  CHECK(checked > 20);
}

TEST_CASE("rasterizer backward: accumulate mode adds exactly the overwrite-mode gradients") {
  auto cam = test::small_camera<float>();
  auto cloud = test::random_scene<float, 2>(cam, 43, 15);
  cloud.mean[0] = std::numeric_limits<float>::quiet_NaN();  // one culled Gaussian keeps its prior value
  Rasterizer<float, 16> r;
  RasterContext<float, 3> ctx;
  r.forward(cam, cloud.params(), ctx);
  RandomLoss loss(cam.width, cam.height, 44);
  const auto wc = loss.wc.cast<float>();
  auto run = [&](bool accumulate, float fill) {
    GaussianCloudGrad<float, 2> g(cloud.size());
    for (auto* v : {&g.dL_dmean, &g.dL_dlog_scale, &g.dL_drotation, &g.dL_dopacity_logit, &g.dL_dsh}) std::fill(v->begin(), v->end(), fill);
    std::vector<float> dcol(3 * cloud.size(), fill), m2d(2 * cloud.size(), fill);
    RasterGrads<float, 3> grads;
    grads.gaussians = g.grads();
    grads.dL_dcolors = dcol;
    grads.dL_dmean2d = m2d;
    grads.accumulate = accumulate;
    r.backward(ctx, wc.cview(), {}, {}, grads);
    std::vector<float> all;
    for (const auto* v : {&g.dL_dmean, &g.dL_dlog_scale, &g.dL_drotation, &g.dL_dopacity_logit, &g.dL_dsh, &dcol, &m2d})
      all.insert(all.end(), v->begin(), v->end());
    return all;
  };
  const auto over = run(false, 0.f);
  // Into zeros: the same bits as overwriting (the tape relies on this for bit-identical training).
  CHECK(run(true, 0.f) == over);
  // Into 0.25: every entry is 0.25 + the overwrite-mode value (exact for these magnitudes is not
  // guaranteed, so compare with the float sum computed the same way).
  const auto acc = run(true, 0.25f);
  REQUIRE(acc.size() == over.size());
  std::size_t bad = 0, nonzero = 0;
  for (std::size_t i = 0; i < acc.size(); ++i) {
    bad += acc[i] != 0.25f + over[i];
    nonzero += over[i] != 0.f;
  }
  CHECK(bad == 0);
  CHECK(nonzero > 100);
}

TEST_CASE_TEMPLATE("rasterizer backward: asking for the blend weights changes no gradient; tiles 16 and 32 agree to rounding", Scalar, float, double) {
  // The kernels skip the weights' sums when they are not asked for, and compute each pair's column
  // terms only for the columns its footprint reaches: neither may change a bit of any gradient.
  auto cam = test::small_camera<Scalar>(101, 67);
  auto cloud = test::random_scene<Scalar, 2>(cam, 45, 120);
  RandomLoss loss(cam.width, cam.height, 46);
  const auto wc = loss.wc.template cast<Scalar>();
  Image<Scalar, 1> da(cam.width, cam.height);
  auto rng = test::seeded_rng(47);
  std::uniform_real_distribution<double> U(-1, 1);
  for (auto& v : da.storage()) v = Scalar(U(rng));
  auto run = [&]<int Tile>(bool weights, bool with_alpha) {
    Rasterizer<Scalar, Tile> r;
    RasterContext<Scalar, 3> ctx;
    r.forward(cam, cloud.params(), ctx);
    GaussianCloudGrad<Scalar, 2> g(cloud.size());
    std::vector<Scalar> m2d(2 * cloud.size()), w(weights ? cloud.size() : 0);
    RasterGrads<Scalar, 3> grads;
    grads.gaussians = g.grads();
    grads.dL_dmean2d = m2d;
    grads.blend_weight = w;
    r.backward(ctx, wc.cview(), with_alpha ? da.cview() : ConstImageView<Scalar, 1>{}, {}, grads);
    std::vector<Scalar> all;
    for (const auto* v : {&g.dL_dmean, &g.dL_dlog_scale, &g.dL_drotation, &g.dL_dopacity_logit, &g.dL_dsh, &m2d})
      all.insert(all.end(), v->begin(), v->end());
    for (Scalar b : grads.dL_dbackground) all.push_back(b);
    return std::pair{all, w};
  };
  for (bool with_alpha : {false, true}) {
    CAPTURE(with_alpha);
    const auto plain16 = run.template operator()<16>(false, with_alpha).first;
    const auto [weighted16, w16] = run.template operator()<16>(true, with_alpha);
    CHECK(weighted16 == plain16);
    const auto plain32 = run.template operator()<32>(false, with_alpha).first;
    const auto [weighted32, w32] = run.template operator()<32>(true, with_alpha);
    CHECK(weighted32 == plain32);
    // Tile 32 sums each Gaussian's pixels in other groups (per tile): the same values to rounding.
    REQUIRE(plain32.size() == plain16.size());
    double worst = 0, scale = 0;
    for (std::size_t i = 0; i < plain16.size(); ++i) {
      worst = std::max(worst, std::abs(double(plain32[i]) - double(plain16[i])));
      scale = std::max(scale, std::abs(double(plain16[i])));
    }
    CHECK(scale > 0);
    CHECK(worst <= 1e-4 * scale);
    REQUIRE(w32.size() == w16.size());
    std::size_t positive = 0;
    for (std::size_t i = 0; i < w16.size(); ++i) {
      CHECK(double(w32[i]) == doctest::Approx(double(w16[i])).epsilon(1e-4).scale(1e-6));
      positive += w16[i] > Scalar(0);
    }
    CHECK(positive > w16.size() / 2);  // the weights were summed
  }
}

TEST_CASE_TEMPLATE("rasterizer backward: evaluations count each Gaussian's footprint pixels in front of the pixel's last blend", Scalar, float, double) {
  auto cam = test::small_camera<Scalar>(70, 45);
  auto cloud = test::random_scene<Scalar, 2>(cam, 43, 60);
  cloud.mean[0] = std::numeric_limits<Scalar>::quiet_NaN();  // culled: no evaluation
  Rasterizer<Scalar, 16> r;
  RasterContext<Scalar, 3> ctx;
  r.forward(cam, cloud.params(), ctx);
  const std::size_t n = cloud.size();
  // Reference, per pixel in (depth, index) order: the last Gaussian the forward's rules blend, then
  // every Gaussian up to it whose footprint {power <= p_max} (p_max = two_a_p / 2A) holds the pixel;
  // and, apart, the pixels each Gaussian was blended at (a subset).
  std::vector<double> ref(n, 0.0), blended(n, 0.0), weight(n, 0.0);
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      double T = 1;
      std::size_t last = 0;  // 1 + position in `sorted` of the last blended Gaussian
      std::vector<double> power(ctx.sorted.size());
      for (std::size_t j = 0; j < ctx.sorted.size(); ++j) {
        const auto& g = ctx.sorted[j];
        const double dx = x + 0.5 - double(g.u), dy = y + 0.5 - double(g.v);
        power[j] = 0.5 * double(g.A) * dx * dx + double(g.B) * dy * dx + 0.5 * double(g.C) * dy * dy;
        if (power[j] < 0) continue;
        const double alpha = std::min(double(r.settings.alpha_max), double(g.opacity) * std::exp(-power[j]));
        if (alpha < double(r.settings.alpha_min)) continue;
        if (T * (1 - alpha) < double(r.settings.min_transmittance)) break;
        blended[g.id] += 1;
        weight[g.id] += alpha * T;
        T *= 1 - alpha;
        last = j + 1;
      }
      for (std::size_t j = 0; j < last; ++j) {
        const auto& g = ctx.sorted[j];
        if (power[j] <= double(g.two_a_p) / (2 * double(g.A))) ref[g.id] += 1;
      }
    }
  auto evaluations = [&](ThreadPool* pool, bool with_weights) {
    std::vector<Scalar> e(n, Scalar(-1)), w(with_weights ? n : 0);
    Image<Scalar, 3> dimg(cam.width, cam.height, Scalar(0));
    RasterGrads<Scalar, 3> grads;
    grads.blend_evals = e;
    grads.blend_weight = w;
    r.backward(ctx, dimg.cview(), {}, {}, grads, pool);
    return std::pair{e, w};
  };
  const auto [e, w] = evaluations(nullptr, true);
  double total = 0, total_ref = 0;
  std::size_t positive = 0;
  for (std::size_t i = 0; i < n; ++i) {
    CAPTURE(i);
    CHECK(double(e[i]) == std::floor(double(e[i])));  // a count
    CHECK(double(e[i]) >= blended[i]);                // every blended pixel was evaluated
    CHECK(double(w[i]) <= double(e[i]) * double(r.settings.alpha_max) + 1e-3);  // weight <= alpha_max per evaluation
    // The kernels' footprint rows carry a 0.01-pixel margin and their own rounding: a pixel at a
    // row's end may differ.
    CHECK(std::abs(double(e[i]) - ref[i]) <= 0.05 * ref[i] + 2);
    total += double(e[i]), total_ref += ref[i];
    positive += e[i] > Scalar(0);
  }
  CHECK(e[0] == Scalar(0));
  CHECK(positive > n / 2);
  CHECK(total == doctest::Approx(total_ref).epsilon(0.01));
  ThreadPool pool(3);
  CHECK(evaluations(&pool, true).first == e);  // any thread count
  CHECK(evaluations(nullptr, false).first == e);  // without the weights
  // Not with a depth gradient.
  Image<Scalar, 3> dimg(cam.width, cam.height, Scalar(0));
  Image<Scalar, 1> dd(cam.width, cam.height, Scalar(1));
  std::vector<Scalar> e2(n);
  RasterGrads<Scalar, 3> g2;
  g2.blend_evals = e2;
  CHECK_THROWS_AS(r.backward(ctx, dimg.cview(), {}, dd.cview(), g2), option_error);
}

TEST_CASE_TEMPLATE("rasterizer backward: blend weights are sum_p alpha T per Gaussian; they sum to the alpha image", Scalar, float, double) {
  auto cam = test::small_camera<Scalar>(70, 45);
  auto cloud = test::random_scene<Scalar, 2>(cam, 42, 40);
  cloud.mean[0] = std::numeric_limits<Scalar>::quiet_NaN();  // culled: weight 0
  Rasterizer<Scalar, 16> r;
  RasterContext<Scalar, 3> ctx;
  r.forward(cam, cloud.params(), ctx);
  const std::size_t n = cloud.size();
  // Reference: per pixel, every visible Gaussian in (depth, index) order (the forward's rules).
  std::vector<double> ref(n, 0.0);
  double alpha_sum = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      double T = 1;
      for (const auto& g : ctx.sorted) {
        const double dx = x + 0.5 - double(g.u), dy = y + 0.5 - double(g.v);
        const double power = 0.5 * double(g.A) * dx * dx + double(g.B) * dy * dx + 0.5 * double(g.C) * dy * dy;
        if (power < 0) continue;
        const double alpha = std::min(double(r.settings.alpha_max), double(g.opacity) * std::exp(-power));
        if (alpha < double(r.settings.alpha_min)) continue;
        if (T * (1 - alpha) < double(r.settings.min_transmittance)) break;
        ref[g.id] += alpha * T;
        T *= 1 - alpha;
      }
      alpha_sum += double(ctx.alpha(x, y));
    }
  Image<Scalar, 3> dimg(cam.width, cam.height, Scalar(0));  // no gradient at all: the weights still come out
  auto weights = [&](ThreadPool* pool) {
    std::vector<Scalar> w(n, Scalar(-1));
    RasterGrads<Scalar, 3> grads;
    grads.blend_weight = w;
    r.backward(ctx, dimg.cview(), {}, {}, grads, pool);
    return w;
  };
  const auto w = weights(nullptr);
  double total = 0;
  std::size_t positive = 0;
  for (std::size_t i = 0; i < n; ++i) {
    CHECK(double(w[i]) == doctest::Approx(ref[i]).epsilon(1e-4).scale(1));
    total += double(w[i]);
    positive += w[i] > Scalar(0);
  }
  CHECK(w[0] == Scalar(0));
  CHECK(positive > n / 2);
  CHECK(total == doctest::Approx(alpha_sum).epsilon(1e-5));
  ThreadPool pool(3);
  CHECK(weights(&pool) == w);  // bit-identical for any thread count
  // Not with a depth gradient (its record entry carries the depth sums).
  Image<Scalar, 1> dd(cam.width, cam.height, Scalar(1));
  std::vector<Scalar> w2(n);
  RasterGrads<Scalar, 3> g2;
  g2.blend_weight = w2;
  CHECK_THROWS_AS(r.backward(ctx, dimg.cview(), {}, dd.cview(), g2), option_error);
}
