// Tests of include/video3dgs/metrics/warp_ssim.hpp: identical frames give 1, a known shift with its
// exact flow gives ~1, flicker lowers it, masked SSIM agrees with the plain SSIM, errors.
#include <cmath>
#include <cstdio>
#include <vector>

#include <doctest/doctest.h>

#include "video3dgs/metrics/ssim.hpp"
#include "video3dgs/metrics/warp_ssim.hpp"

using namespace video3dgs;

namespace {
double tex(double x, double y, int c) {
  return 0.5 + 0.15 * std::sin(0.31 * x + 0.19 * y + c) + 0.1 * std::sin(-0.23 * x + 0.41 * y + 1.0) + 0.08 * std::cos(0.6 * x - 0.5 * y);
}
/// Frame t of a texture translating by (dx, dy) px per frame.
Image<float, 3> moving(int w, int h, int t, double dx, double dy) {
  Image<float, 3> img(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) img(x, y, c) = float(tex(x - dx * t, y - dy * t, c));
  return img;
}
metrics::VideoFlows exact_flows(int w, int h, int n, double dx, double dy) {
  metrics::VideoFlows f;
  for (int t = 0; t + 1 < n; ++t) {
    flow::FlowFieldF fw(w, h), bw(w, h);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        fw(x, y, 0) = float(dx), fw(x, y, 1) = float(dy);
        bw(x, y, 0) = float(-dx), bw(x, y, 1) = float(-dy);
      }
    f.forward.push_back(fw);
    f.backward.push_back(bw);
  }
  return f;
}
}  // namespace

TEST_CASE("WarpSSIM: identical frames give exactly 1 (zero flow)") {
  std::vector<Image<float, 3>> v(4, moving(40, 32, 0, 0, 0));
  const auto r = metrics::warp_ssim(v, exact_flows(40, 32, 4, 0, 0));
  CHECK(r.value == doctest::Approx(1.0).epsilon(1e-12));
  CHECK(r.skipped_pairs == 0);
  for (double f : r.visible_fraction) CHECK(f == 1.0);
}

TEST_CASE("WarpSSIM: a known integer and sub-pixel shift with its exact flow gives ~1; flicker lowers it") {
  for (double d : {2.0, 1.5}) {
    std::vector<Image<float, 3>> v;
    for (int t = 0; t < 4; ++t) v.push_back(moving(64, 48, t, d, -0.5 * d));
    const auto flows = exact_flows(64, 48, 4, d, -0.5 * d);
    const auto r = metrics::warp_ssim(v, flows);
    std::printf("{\"warp_ssim_shift\":%.2f,\"value\":%.6f,\"visible\":%.3f}\n", d, r.value, r.visible_fraction[0]);
    CHECK(r.value > (d == 2.0 ? 0.9999 : 0.99));
    CHECK(r.visible_fraction[0] < 1.0);  // the entering border is excluded
    CHECK(r.visible_fraction[0] > 0.9);
    // flicker: brightness alternates between frames
    auto fl = v;
    for (std::size_t t = 0; t < fl.size(); ++t)
      for (float& x : fl[t].storage()) x = x * (t % 2 ? 0.7f : 1.0f) + (t % 2 ? 0.1f : 0.f);
    const auto rf = metrics::warp_ssim(fl, flows);
    CHECK(rf.value < r.value - 0.01);
    // zero flow on moving content is worse than the exact flow
    const auto r0 = metrics::warp_ssim(v, exact_flows(64, 48, 4, 0, 0));
    CHECK(r0.value < r.value - 0.05);
  }
}

TEST_CASE("WarpSSIM: built-in flow estimate gives a value close to the exact-flow one") {
  std::vector<Image<float, 3>> v;
  for (int t = 0; t < 3; ++t) v.push_back(moving(64, 48, t, 1.25, 0.75));
  ThreadPool pool(2);
  const auto est = metrics::estimate_video_flows(v, {}, &pool);
  const auto r_est = metrics::warp_ssim(v, est, {}, &pool);
  const auto r_ex = metrics::warp_ssim(v, exact_flows(64, 48, 3, 1.25, 0.75));
  std::printf("{\"warp_ssim_estimated_flow\":%.6f,\"warp_ssim_exact_flow\":%.6f}\n", r_est.value, r_ex.value);
  CHECK(r_est.value > 0.97);
  CHECK(std::fabs(r_est.value - r_ex.value) < 0.03);
  const auto r1 = metrics::warp_ssim(v, est, {}, nullptr);
  CHECK(r1.value == r_est.value);
}

TEST_CASE("masked_ssim with a full mask equals the SSIM metric") {
  const auto a = moving(30, 20, 0, 0, 0);
  const auto b = moving(30, 20, 1, 0.7, 0.2);
  Image<float, 1> all(30, 20, 1.f), none(30, 20, 0.f);
  const double m = metrics::masked_ssim<float, 3>(a.view(), b.view(), all.view());
  CHECK(m == doctest::Approx(metrics::ssim<float, 3>(a, b)).epsilon(1e-9));
  CHECK(std::isnan(metrics::masked_ssim<float, 3>(a.view(), b.view(), none.view())));
}

TEST_CASE("WarpSSIM: errors") {
  std::vector<Image<float, 3>> one(1, moving(8, 8, 0, 0, 0));
  CHECK_THROWS_AS((void)metrics::warp_ssim(one, {}), option_error);
  std::vector<Image<float, 3>> two(2, moving(8, 8, 0, 0, 0));
  CHECK_THROWS_AS((void)metrics::warp_ssim(two, exact_flows(8, 8, 3, 0, 0)), option_error);
  CHECK_THROWS_AS((void)metrics::warp_ssim(two, exact_flows(9, 8, 2, 0, 0)), option_error);
  CHECK_THROWS_AS((void)metrics::estimate_video_flows(one), option_error);
}
