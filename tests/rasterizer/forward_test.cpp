#include "video3dgs/rasterizer/forward.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <vector>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "scene_util.hpp"
#include "video3dgs/core/resample.hpp"
#include "video3dgs/rasterizer/rasterizer.hpp"

using namespace video3dgs;

namespace {
template <class Scalar>
bool all_finite(const std::vector<Scalar>& v) {
  return std::all_of(v.begin(), v.end(), [](Scalar x) { return std::isfinite(x); });
}

/// Reference: per pixel, every visible Gaussian in (depth, index) order, no tiles, no footprints.
template <class Scalar>
Image<Scalar, 3> brute_force(const Camera<Scalar>& cam, const RasterSettings<Scalar, 3>& s, const RasterContext<Scalar, 3>& ctx) {
  Image<Scalar, 3> img(cam.width, cam.height);
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      Scalar T = 1, acc[3] = {0, 0, 0};
      for (const auto& g : ctx.sorted) {
        const Scalar dx = Scalar(x) + Scalar(0.5) - g.u, dy = Scalar(y) + Scalar(0.5) - g.v;
        const Scalar power = Scalar(0.5) * g.A * dx * dx + g.B * dy * dx + Scalar(0.5) * g.C * dy * dy;
        if (power < 0) continue;
        const Scalar alpha = std::min(s.alpha_max, g.opacity * std::exp(-power));
        if (alpha < s.alpha_min) continue;
        const bool stop = T * (1 - alpha) < s.min_transmittance;
        if (stop && !s.blend_at_stop) break;
        for (int c = 0; c < 3; ++c) acc[c] += g.color[c] * alpha * T;
        T *= 1 - alpha;
        if (stop) break;
      }
      for (int c = 0; c < 3; ++c) img(x, y, c) = acc[c] + T * s.background[c];
    }
  return img;
}
}  // namespace

TEST_CASE_TEMPLATE("rasterizer forward: matches a per-pixel brute force over all Gaussians", Scalar, float, double) {
  auto cam = test::small_camera<Scalar>(70, 45);
  auto cloud = test::random_scene<Scalar, 2>(cam, 42, 40);
  Rasterizer<Scalar, 16> r;
  r.settings.background = {Scalar(0.2), Scalar(0.3), Scalar(0.4)};
  RasterContext<Scalar, 3> ctx;
  r.forward(cam, cloud.params(), ctx);
  const auto ref = brute_force(cam, r.settings, ctx);
  double worst = 0;
  for (std::size_t i = 0; i < ref.size(); ++i) worst = std::max(worst, double(std::abs(ref.data()[i] - ctx.image.data()[i])));
  CHECK(worst < 1e-5);
  CHECK(ctx.stats.visible > 30);
  CHECK(ctx.stats.evaluations > 0);
}

TEST_CASE_TEMPLATE("rasterizer forward: blend_at_stop blends the crossing Gaussian; it drops less than the stop of a pixel's colour", Scalar, float, double) {
  auto cam = test::small_camera<Scalar>(70, 45);
  auto cloud = test::random_scene<Scalar, 2>(cam, 42, 120);
  for (auto& l : cloud.opacity_logit) l = Scalar(3);  // opacity 0.95: many pixels stop
  Rasterizer<Scalar, 16> r;
  r.settings.background = {Scalar(0.2), Scalar(0.3), Scalar(0.4)};
  r.settings.min_transmittance = Scalar(0.05);  // above 1 - alpha_max: allowed for both rules here
  RasterContext<Scalar, 3> all, drop, blend;
  {
    Rasterizer<Scalar, 16> no_stop = r;
    no_stop.settings.min_transmittance = std::numeric_limits<Scalar>::min();
    no_stop.forward(cam, cloud.params(), all);
  }
  r.forward(cam, cloud.params(), drop);
  r.settings.blend_at_stop = true;
  r.forward(cam, cloud.params(), blend);
  // Both rules match the per-pixel brute force.
  const auto ref_blend = brute_force(cam, r.settings, blend);
  r.settings.blend_at_stop = false;
  const auto ref_drop = brute_force(cam, r.settings, drop);
  double worst = 0, bound = 0;
  for (std::size_t i = 0; i < ref_blend.size(); ++i) {
    worst = std::max(worst, double(std::abs(ref_blend.data()[i] - blend.image.data()[i])));
    worst = std::max(worst, double(std::abs(ref_drop.data()[i] - drop.image.data()[i])));
  }
  CHECK(worst < 1e-5);
  for (const auto& g : blend.sorted)
    for (int c = 0; c < 3; ++c) bound = std::max(bound, double(std::abs(g.color[c])));
  for (Scalar b : r.settings.background) bound = std::max(bound, double(b));
  // Against the render without a stop: blending the crossing Gaussian leaves only what lies behind
  // T_final < 0.05 out, so every channel is within 0.05 (max |colour| + max |background|) of it; the
  // method's rule drops the crossing Gaussian too, up to 0.05 alpha_max / (1 - alpha_max) of the colour.
  std::size_t stopped = 0, differ = 0;
  double worst_blend = 0, worst_drop = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const std::size_t pix = static_cast<std::size_t>(y) * static_cast<std::size_t>(cam.width) + static_cast<std::size_t>(x);
      stopped += blend.final_T[pix] < Scalar(0.05) ? 1 : 0;
      CHECK(blend.final_T[pix] <= drop.final_T[pix]);
      CHECK(blend.last_contrib[pix] >= drop.last_contrib[pix]);
      differ += blend.last_contrib[pix] != drop.last_contrib[pix] ? 1 : 0;
      for (int c = 0; c < 3; ++c) {
        worst_blend = std::max(worst_blend, double(std::abs(blend.image(x, y, c) - all.image(x, y, c))));
        worst_drop = std::max(worst_drop, double(std::abs(drop.image(x, y, c) - all.image(x, y, c))));
      }
    }
  CHECK(stopped > 100);
  CHECK(differ > 100);
  CHECK(worst_blend <= 0.05 * 2 * bound + 1e-5);
  CHECK(worst_drop > worst_blend);
}

TEST_CASE("rasterizer forward: zero opacity renders the background; zero Gaussians; 1x1 image") {
  auto cam = test::small_camera<float>();
  auto cloud = test::random_scene<float, 1>(cam, 3, 20);
  for (auto& l : cloud.opacity_logit) l = -30.f;
  Rasterizer<float, 16> r;
  r.settings.background = {0.25f, 0.5f, 1.0f};
  RasterContext<float, 3> ctx;
  r.forward(cam, cloud.params(), ctx);
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      CHECK(ctx.image(x, y, 0) == 0.25f);
      CHECK(ctx.image(x, y, 2) == 1.0f);
      CHECK(ctx.alpha(x, y) == 0.0f);
    }
  GaussianCloud<float, 1> empty;
  r.forward(cam, empty.params(), ctx);
  CHECK(ctx.image(3, 4, 1) == 0.5f);
  Image<float, 3> dimg(cam.width, cam.height, 1.0f);
  RasterGrads<float, 3> grads;
  r.backward(ctx, dimg.cview(), {}, {}, grads);
  CHECK(grads.dL_dbackground[0] == doctest::Approx(cam.width * cam.height));
  auto tiny = test::small_camera<float>(1, 1);
  auto one = test::random_scene<float, 1>(tiny, 4, 5);
  r.forward(tiny, one.params(), ctx);
  CHECK(std::isfinite(ctx.image(0, 0, 0)));
}

TEST_CASE("rasterizer forward: accumulated alpha in [0, 1], transmittance never increases front to back") {
  auto cam = test::small_camera<double>();
  auto cloud = test::random_scene<double, 0>(cam, 9, 60);
  Rasterizer<double, 16> r;
  RasterContext<double, 3> ctx;
  r.forward(cam, cloud.params(), ctx);
  for (double a : ctx.alpha.storage()) {
    CHECK(a >= 0.0);
    CHECK(a <= 1.0);
  }
  // Render the k nearest Gaussians for growing k: the accumulated alpha of every pixel never decreases.
  std::vector<std::size_t> order(cloud.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](auto a, auto b) { return cloud.mean[3 * a + 2] < cloud.mean[3 * b + 2]; });
  std::vector<double> prev(ctx.alpha.size(), 0.0);
  for (std::size_t k = 1; k <= order.size(); k += 7) {
    GaussianCloud<double, 0> sub;
    for (std::size_t j = 0; j < k; ++j) sub.push_back(cloud.get(order[j]));
    RasterContext<double, 3> c2;
    r.forward(cam, sub.params(), c2);
    for (std::size_t i = 0; i < prev.size(); ++i) {
      CHECK(c2.alpha.data()[i] >= prev[i] - 1e-12);
      prev[i] = c2.alpha.data()[i];
    }
  }
}

TEST_CASE_TEMPLATE("rasterizer forward: images independent of tile size; thread count bit-identical", Scalar, float, double) {
  auto cam = test::small_camera<Scalar>(123, 77);
  auto cloud = test::random_scene<Scalar, 3>(cam, 17, 300);
  RasterContext<Scalar, 3> c8, c16, c32;
  Rasterizer<Scalar, 8>().forward(cam, cloud.params(), c8);
  Rasterizer<Scalar, 16>().forward(cam, cloud.params(), c16);
  Rasterizer<Scalar, 32>().forward(cam, cloud.params(), c32);
  CHECK(c8.image.storage() == c16.image.storage());
  CHECK(c32.image.storage() == c16.image.storage());
  CHECK(c8.depth.storage() == c16.depth.storage());
  CHECK(c32.alpha.storage() == c16.alpha.storage());

  // Threads: images and every gradient bit-identical.
  Image<Scalar, 3> dimg(cam.width, cam.height);
  auto rng = test::seeded_rng(5);
  std::uniform_real_distribution<double> U(-1, 1);
  for (auto& v : dimg.storage()) v = Scalar(U(rng));
  GaussianCloudGrad<Scalar, 3> g1(cloud.size());
  RasterGrads<Scalar, 3> gr1;
  gr1.gaussians = g1.grads();
  Rasterizer<Scalar, 16> r;
  r.backward(c16, dimg.cview(), c16.alpha.cview(), c16.depth.cview(), gr1);
  for (unsigned threads : {2u, 3u}) {
    ThreadPool pool(threads);
    RasterContext<Scalar, 3> cp;
    r.forward(cam, cloud.params(), cp, &pool);
    CHECK(cp.image.storage() == c16.image.storage());
    GaussianCloudGrad<Scalar, 3> g2(cloud.size());
    RasterGrads<Scalar, 3> gr2;
    gr2.gaussians = g2.grads();
    r.backward(cp, dimg.cview(), c16.alpha.cview(), c16.depth.cview(), gr2, &pool);
    CHECK(g1.dL_dmean == g2.dL_dmean);
    CHECK(g1.dL_dlog_scale == g2.dL_dlog_scale);
    CHECK(g1.dL_drotation == g2.dL_drotation);
    CHECK(g1.dL_dopacity_logit == g2.dL_dopacity_logit);
    CHECK(g1.dL_dsh == g2.dL_dsh);
    CHECK(gr1.dL_dbackground == gr2.dL_dbackground);
  }
  CHECK(all_finite(g1.dL_dmean));
}

TEST_CASE_TEMPLATE("rasterizer forward: without the depth image, every other output and every gradient is the same", Scalar, float, double) {
  auto cam = test::small_camera<Scalar>(97, 61);
  auto cloud = test::random_scene<Scalar, 3>(cam, 19, 200);
  Image<Scalar, 3> dimg(cam.width, cam.height);
  Image<Scalar, 1> dd(cam.width, cam.height), da(cam.width, cam.height);
  auto rng = test::seeded_rng(6);
  std::uniform_real_distribution<double> U(-1, 1);
  for (auto* im : {&dimg.storage(), &dd.storage(), &da.storage()})
    for (auto& v : *im) v = Scalar(U(rng));
  struct Out {
    RasterContext<Scalar, 3> ctx;
    std::vector<Scalar> grads;
  };
  auto run = [&](bool depth) {
    Rasterizer<Scalar, 16> r;
    r.settings.depth = depth;
    Out o;
    r.forward(cam, cloud.params(), o.ctx);
    GaussianCloudGrad<Scalar, 3> g(cloud.size());
    RasterGrads<Scalar, 3> gr;
    gr.gaussians = g.grads();
    r.backward(o.ctx, dimg.cview(), da.cview(), dd.cview(), gr);  // a depth gradient reads no depth image
    for (const auto* v : {&g.dL_dmean, &g.dL_dlog_scale, &g.dL_drotation, &g.dL_dopacity_logit, &g.dL_dsh})
      o.grads.insert(o.grads.end(), v->begin(), v->end());
    return o;
  };
  const Out with = run(true), without = run(false);
  CHECK(without.ctx.image.storage() == with.ctx.image.storage());
  CHECK(without.ctx.alpha.storage() == with.ctx.alpha.storage());
  CHECK(without.ctx.final_T == with.ctx.final_T);
  CHECK(without.ctx.last_contrib == with.ctx.last_contrib);
  CHECK(without.ctx.stats.evaluations == with.ctx.stats.evaluations);
  CHECK(without.grads == with.grads);
  bool all_zero = true, some_depth = false;
  for (Scalar v : without.ctx.depth.storage()) all_zero = all_zero && v == Scalar(0);
  for (Scalar v : with.ctx.depth.storage()) some_depth = some_depth || v > Scalar(0);
  CHECK(all_zero);
  CHECK(some_depth);
}

TEST_CASE("rasterizer forward: independent of the input order of the Gaussians") {
  auto cam = test::small_camera<double>(90, 60);
  auto cloud = test::random_scene<double, 1>(cam, 23, 150);
  std::vector<std::size_t> perm(cloud.size());
  std::iota(perm.begin(), perm.end(), 0);
  std::shuffle(perm.begin(), perm.end(), test::seeded_rng(24));
  GaussianCloud<double, 1> shuffled;
  for (auto i : perm) shuffled.push_back(cloud.get(i));
  Rasterizer<double, 16> r;
  RasterContext<double, 3> a, b;
  r.forward(cam, cloud.params(), a);
  r.forward(cam, shuffled.params(), b);
  double worst = 0;
  for (std::size_t i = 0; i < a.image.size(); ++i) worst = std::max(worst, std::abs(a.image.data()[i] - b.image.data()[i]));
  CHECK(worst < 1e-12);
  Image<double, 3> dimg(cam.width, cam.height, 0.5);
  GaussianCloudGrad<double, 1> ga(cloud.size()), gb(cloud.size());
  RasterGrads<double, 3> ra, rb;
  ra.gaussians = ga.grads();
  rb.gaussians = gb.grads();
  r.backward(a, dimg.cview(), {}, {}, ra);
  r.backward(b, dimg.cview(), {}, {}, rb);
  double gworst = 0;
  for (std::size_t j = 0; j < perm.size(); ++j)
    for (int k = 0; k < 3; ++k) gworst = std::max(gworst, std::abs(ga.dL_dmean[3 * perm[j] + k] - gb.dL_dmean[3 * j + k]));
  CHECK(gworst < 1e-9);
  CHECK(a.visible[perm[5]] == b.visible[5]);
  CHECK(a.radii[perm[7]] == b.radii[7]);
}

TEST_CASE("rasterizer forward: context reuse and option errors") {
  auto cam = test::small_camera<float>();
  auto cloud = test::random_scene<float, 3>(cam, 8, 30);
  Rasterizer<float, 16> r;
  RasterContext<float, 3> ctx;
  r.forward(cam, cloud.params(), ctx);
  const auto first = ctx.image.storage();
  r.forward(cam, cloud.params(), ctx);
  CHECK(ctx.image.storage() == first);
  r.settings.active_sh_degree = 0;  // lower active degree changes view-dependent colour only
  r.forward(cam, cloud.params(), ctx);
  CHECK(ctx.image.storage() != first);
  auto bad = cloud.params();
  bad.sh = bad.sh.first(bad.sh.size() - 1);
  CHECK_THROWS_AS(r.forward(cam, bad, ctx), option_error);
  r.settings.alpha_max = 2;
  CHECK_THROWS_AS(r.forward(cam, cloud.params(), ctx), option_error);
  Rasterizer<float, 16, 4> r4;
  RasterContext<float, 4> c4;
  CHECK_THROWS_AS(r4.forward(cam, cloud.params(), c4), option_error);  // 4 channels need colours
  Rasterizer<float, 8> r8;
  r.settings.alpha_max = 0.99f;
  r.forward(cam, cloud.params(), ctx);
  Image<float, 3> dimg(cam.width, cam.height);
  RasterGrads<float, 3> grads;
  CHECK_THROWS_AS(r8.backward(ctx, dimg.cview(), {}, {}, grads), option_error);  // tile size mismatch
  Image<float, 3> wrong(3, 3);
  CHECK_THROWS_AS(r.backward(ctx, wrong.cview(), {}, {}, grads), option_error);
}

TEST_CASE("rasterizer: a reused context does not reallocate (steady state)") {
  auto cam = test::small_camera<float>(100, 70);
  auto cloud = test::random_scene<float, 3>(cam, 12, 200);
  Rasterizer<float, 16> r;
  RasterContext<float, 3> ctx;
  GaussianCloudGrad<float, 3> g(cloud.size());
  RasterGrads<float, 3> grads;
  grads.gaussians = g.grads();
  Image<float, 3> dimg(cam.width, cam.height, 0.1f);
  r.forward(cam, cloud.params(), ctx);
  r.backward(ctx, dimg.cview(), {}, {}, grads);
  const void* before[] = {ctx.image.data(), ctx.sorted.data(), ctx.tile_list.data(), ctx.slot_record.data(),
                          ctx.pair_grad.data(), ctx.final_T.data(), ctx.color.data(), ctx.projected.data()};
  for (int it = 0; it < 3; ++it) {
    r.forward(cam, cloud.params(), ctx);
    r.backward(ctx, dimg.cview(), {}, {}, grads);
  }
  const void* after[] = {ctx.image.data(), ctx.sorted.data(), ctx.tile_list.data(), ctx.slot_record.data(),
                         ctx.pair_grad.data(), ctx.final_T.data(), ctx.color.data(), ctx.projected.data()};
  for (int i = 0; i < 8; ++i) CHECK(before[i] == after[i]);
}

TEST_CASE("rasterizer forward: with Camera::resized a Gaussian lands at the same place relative to the image") {
  // One isotropic Gaussian on a black background at 256x160 and at 64x40: the centroids of the
  // renders' intensity, in continuous pixel coordinates (centre of pixel x at x + 1/2), scale by 1/4,
  // and the low render is close to the area-resampled high one.
  const auto cam = test::small_camera<double>(256, 160);
  const auto low = cam.resized(64, 40);
  auto rng = test::seeded_rng(5);
  GaussianCloud<double, 0> cloud;
  auto g = test::gaussian_at<double, 0>(cam, rng, 101.3, 77.8, 3.0, 9.0, 1.0, 0.9);
  g.log_scale = {g.log_scale[0], g.log_scale[0], g.log_scale[0]};
  cloud.push_back(g);
  Rasterizer<double, 16> r;
  r.settings.background = {0, 0, 0};
  auto centroid = [&](const CameraD& c, Image<double, 3>* keep) {
    RasterContext<double, 3> ctx;
    r.forward(c, cloud.params(), ctx);
    double s = 0, sx = 0, sy = 0;
    for (int y = 0; y < c.height; ++y)
      for (int x = 0; x < c.width; ++x) {
        const double v = ctx.image(x, y, 0);
        s += v, sx += v * (x + 0.5), sy += v * (y + 0.5);
      }
    if (keep) *keep = ctx.image;
    return std::array<double, 2>{sx / s, sy / s};
  };
  Image<double, 3> high_img, low_img;
  const auto ch = centroid(cam, &high_img), cl = centroid(low, &low_img);
  CHECK(ch[0] == doctest::Approx(101.3).epsilon(2e-3));
  CHECK(ch[1] == doctest::Approx(77.8).epsilon(2e-3));
  CHECK(cl[0] == doctest::Approx(ch[0] / 4).epsilon(2e-3));
  CHECK(cl[1] == doctest::Approx(ch[1] / 4).epsilon(2e-3));
  const Image<double, 3> down = resize_area(high_img, 64, 40);
  double worst = 0;
  for (std::size_t i = 0; i < down.size(); ++i) worst = std::max(worst, std::abs(down.data()[i] - low_img.data()[i]));
  CHECK(worst < 0.1);  // point samples vs area means, and the 0.3 px^2 low-pass added at each size
}
