// densify_and_prune (clone / split / prune and the optimizer-row edit it reports), SplitLrAdam, and
// the detail weight map.
#include <cmath>
#include <random>

#include <doctest/doctest.h>

#include "video3dgs/optim/optimizer.hpp"
#include "video3dgs/training/densify.hpp"
#include "video3dgs/training/detail_weight.hpp"
#include "video3dgs/training/split_adam.hpp"

using namespace video3dgs;

TEST_CASE_TEMPLATE("densify_and_prune: clone small, split large, prune transparent; moments follow", Scalar, float, double) {
  GaussianCloud<Scalar, 1> c(4);
  // 0: small, high gradient -> clone; 1: large, high gradient -> split; 2: low gradient; 3: transparent -> prune.
  for (int i = 0; i < 4; ++i) {
    c.mean[3 * i] = Scalar(i);
    c.opacity_logit[i] = logit(Scalar(0.5));
    c.sh[12 * i] = Scalar(i);
  }
  for (int k = 0; k < 3; ++k) c.log_scale[k] = std::log(Scalar(0.001)), c.log_scale[3 + k] = std::log(Scalar(0.5));
  c.opacity_logit[3] = logit(Scalar(0.001));
  const std::vector<Scalar> accum{Scalar(1e-2), Scalar(1e-2), Scalar(1e-5), Scalar(1e-2)};
  const std::vector<Scalar> count{Scalar(10), Scalar(10), Scalar(10), Scalar(0)};
  Optimizer<Scalar> opt;
  std::vector<Scalar> grad(12);
  opt.add_group({"mean", LrSchedule::constant(0.1), {}, 3}, c.mean, grad);
  for (std::size_t i = 0; i < 12; ++i) opt.group("mean").moment(0)[i] = Scalar(i + 1);
  DensifyOptions o;
  o.dense_scale = 0.01;
  std::mt19937_64 rng(5);
  const auto r = densify_and_prune(c, std::span<const Scalar>(accum), std::span<const Scalar>(count), o, rng,
                                   [&](std::span<const std::size_t> src, std::span<const std::uint8_t> keep) {
                                     opt.append_rows("mean", src, RowMoments::zero);
                                     opt.keep_rows("mean", keep);
                                   });
  CHECK(r.cloned == 1);
  CHECK(r.split == 1);
  CHECK(r.pruned == 1);
  // Kept: 0, 2, clone of 0, two children of 1.
  REQUIRE(c.size() == 5);
  CHECK(c.mean[0] == Scalar(0));
  CHECK(c.mean[3] == Scalar(2));
  CHECK(c.mean[6] == Scalar(0));
  CHECK(c.sh[12 * 2] == Scalar(0));
  for (int j : {3, 4}) {
    CHECK(c.sh[12 * j] == Scalar(1));
    CHECK(std::exp(c.log_scale[3 * j]) == doctest::Approx(0.5 / 1.6));
    CHECK(std::abs(c.mean[3 * j] - Scalar(1)) < Scalar(3));
  }
  CHECK(c.mean[9] != c.mean[12]);  // children sampled apart
  const auto m = opt.group("mean").moment(0);
  REQUIRE(m.size() == 15);
  CHECK(m[0] == Scalar(1));
  CHECK(m[3] == Scalar(7));   // row 2's moments
  CHECK(m[6] == Scalar(0));   // new rows start at zero
  CHECK(m[14] == Scalar(0));
  grad.assign(15, Scalar(0));
  opt.bind("mean", c.mean, grad);
  opt.step(0);
}

TEST_CASE("densify_and_prune: a binding budget takes the largest gradients first; the prune frees room") {
  // 6 Gaussians, all small (clones): gradients 1..6 over one view; row 5 (gradient 6) is transparent.
  GaussianCloud<float, 0> c(6);
  for (int i = 0; i < 6; ++i) c.mean[3 * i] = float(i), c.log_scale[3 * i] = c.log_scale[3 * i + 1] = c.log_scale[3 * i + 2] = -9;
  c.opacity_logit[5] = -20;
  const std::vector<float> accum{1, 2, 3, 4, 5, 6}, count{1, 1, 1, 1, 1, 1};
  DensifyOptions o;
  o.grad_threshold = 0.5;
  o.max_count = 8;  // 5 survivors of the prune: room for 3 clones, the transparent row 5 is not one of them
  std::mt19937_64 rng(1);
  std::vector<std::size_t> sources;
  const auto r = densify_and_prune(c, std::span<const float>(accum), std::span<const float>(count), o, rng,
                                   [&](std::span<const std::size_t> src, auto) { sources.assign(src.begin(), src.end()); });
  CHECK(r.cloned == 3);
  CHECK(r.split == 0);
  CHECK(r.pruned == 1);
  CHECK(c.size() == 8);
  CHECK(sources == std::vector<std::size_t>{2, 3, 4});  // the three largest gradients, in index order
  CHECK(c.mean[3 * 5] == 2.0f);                         // the clones follow the kept originals 0..4
  CHECK(c.mean[3 * 7] == 4.0f);
}

TEST_CASE("densify_and_prune: a split costs children - 1 rows; a cheaper candidate still fits") {
  // Row 0: large (split into 3, net +2), gradient 9; row 1: small (clone, +1), gradient 1. Room 1.
  GaussianCloud<float, 0> c(2);
  for (int k = 0; k < 3; ++k) c.log_scale[k] = 0, c.log_scale[3 + k] = -9;
  const std::vector<float> accum{9, 1}, count{1, 1};
  DensifyOptions o;
  o.grad_threshold = 0.5;
  o.children = 3;
  o.max_count = 3;
  std::mt19937_64 rng(1);
  const auto r = densify_and_prune(c, std::span<const float>(accum), std::span<const float>(count), o, rng, [](auto, auto) {});
  CHECK(r.split == 0);
  CHECK(r.cloned == 1);
  CHECK(c.size() == 3);
  o.max_count = 4;  // now the split fits (2 - 1 + 3 = 4) and the clone does not
  GaussianCloud<float, 0> d(2);
  for (int k = 0; k < 3; ++k) d.log_scale[k] = 0, d.log_scale[3 + k] = -9;
  const auto r2 = densify_and_prune(d, std::span<const float>(accum), std::span<const float>(count), o, rng, [](auto, auto) {});
  CHECK(r2.split == 1);
  CHECK(r2.cloned == 0);
  CHECK(d.size() == 4);
}

TEST_CASE("densify_and_prune: a cloud above its budget loses its most transparent rows; never empty") {
  GaussianCloud<float, 0> c(5);
  const float logits[5] = {0.5f, -1.0f, 2.0f, -1.0f, 1.0f};
  for (int i = 0; i < 5; ++i) c.opacity_logit[i] = logits[i], c.mean[3 * i] = float(i);
  const std::vector<float> zero(5, 0.0f);
  DensifyOptions o;
  o.prune_opacity = 0;
  o.max_count = 3;
  std::mt19937_64 rng(1);
  std::vector<std::uint8_t> keep;
  const auto r = densify_and_prune(c, std::span<const float>(zero), std::span<const float>(zero), o, rng,
                                   [&](auto, std::span<const std::uint8_t> k) { keep.assign(k.begin(), k.end()); });
  CHECK(r.pruned == 2);
  CHECK(keep == std::vector<std::uint8_t>{1, 0, 1, 0, 1});  // both -1.0 rows go (ties: higher index first)
  CHECK(c.size() == 3);
  // Every row transparent: the prune keeps the most opaque one (ties: lower index).
  GaussianCloud<float, 0> t(4);
  for (int i = 0; i < 4; ++i) t.opacity_logit[i] = i == 2 ? -15.0f : -20.0f, t.mean[3 * i] = float(i);
  DensifyOptions p;
  const std::vector<float> z4(4, 0.0f);
  const auto rt = densify_and_prune(t, std::span<const float>(z4), std::span<const float>(z4), p, rng, [](auto, auto) {});
  CHECK(rt.pruned == 3);
  REQUIRE(t.size() == 1);
  CHECK(t.mean[0] == 2.0f);
}

TEST_CASE("densify_and_prune: random clouds, gradients and budgets: never above the budget, never empty") {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int trial = 0; trial < 300; ++trial) {
    const std::size_t n = 1 + rng() % 40;
    GaussianCloud<float, 0> c(n);
    std::vector<float> accum(n), count(n);
    for (std::size_t i = 0; i < n; ++i) {
      for (int k = 0; k < 3; ++k) c.log_scale[3 * i + k] = u(rng) < 0.5f ? -9.0f : 0.0f;
      c.opacity_logit[i] = 12.0f * u(rng) - 8.0f;  // some below logit(0.005) = -5.3
      count[i] = float(rng() % 3);
      accum[i] = count[i] * u(rng);
    }
    DensifyOptions o;
    o.grad_threshold = 0.3;
    o.children = 1 + int(rng() % 3);
    o.max_count = 1 + rng() % 60;
    const auto r = densify_and_prune(c, std::span<const float>(accum), std::span<const float>(count), o, rng, [](auto, auto) {});
    CHECK(c.size() >= 1);
    CHECK(c.size() <= o.max_count);
    CHECK(c.size() == n + r.cloned + r.split * std::size_t(o.children) - r.split - r.pruned);
  }
}

TEST_CASE("SplitLrAdam: plain Adam without a base; the tail columns at lr x tail_scale") {
  std::vector<float> p1(12, 1.0f), p2(12, 1.0f), g(12, 0.5f);
  Optimizer<float, Adam> a;
  a.add_group({"x", LrSchedule::constant(0.1), {}, 6}, p1, g);
  Optimizer<float, SplitLrAdam> b;
  SplitLrAdam::Hyper h;
  h.eps = 1e-15;
  b.add_group({"x", LrSchedule::constant(0.1), h, 6}, p2, g);
  a.step(0);
  b.step(0);
  CHECK(p1 == p2);
  std::vector<float> p3(12, 1.0f);
  Optimizer<float, SplitLrAdam> c;
  h.row_width = 6;
  h.lead = 3;
  h.tail_scale = 0.05;
  c.add_group({"x", LrSchedule::constant(0.1), h, 6}, p3, g);
  c.step(0);
  for (int i = 0; i < 12; ++i) CHECK(1.0f - p3[i] == doctest::Approx((i % 6) < 3 ? 0.1 : 0.005).epsilon(1e-4));
  // The column follows the position in the group's buffer, also across segments (4 + 8 entries, rows
  // of 6): entries 4..11 are columns 4, 5, 0, 1, 2, 3, 4, 5.
  std::vector<float> q1(4, 1.0f), q2(8, 1.0f), g1(4, 0.5f), g2(8, 0.5f);
  Optimizer<float, SplitLrAdam> d;
  d.add_group({"x", LrSchedule::constant(0.1), h, 6}, std::vector<ParamSegment<float>>{{q1, g1}, {q2, g2}});
  d.step(0);
  for (int i = 0; i < 12; ++i) {
    const float v = i < 4 ? q1[std::size_t(i)] : q2[std::size_t(i - 4)];
    CHECK(v == p3[std::size_t(i)]);  // bit-identical to the single-segment group
  }
}

TEST_CASE("detail_weight_map: 1 on flat images, largest at edges, in [1, 1 + gain]") {
  Image<float, 3> flat(16, 12, 0.3f);
  const auto w = detail_weight_map<float>(flat, 2.0);
  for (std::size_t i = 0; i < w.size(); ++i) CHECK(w.data()[i] == 1.0f);
  // Left half flat, right half a fine checker of amplitude 0.05 (detail the bilateral filter removes).
  Image<float, 3> step(16, 12, 0.5f);
  for (int y = 0; y < 12; ++y)
    for (int x = 8; x < 16; ++x)
      for (int c = 0; c < 3; ++c) step(x, y, c) = ((x + y) & 1) ? 0.55f : 0.45f;
  ThreadPool pool(2);
  const auto e = detail_weight_map<float>(step, 2.0, &pool);
  const auto e1 = detail_weight_map<float>(step, 2.0);
  CHECK(e.storage() == e1.storage());
  float mx = 0;
  for (std::size_t i = 0; i < e.size(); ++i) {
    CHECK(e.data()[i] >= 1.0f);
    CHECK(e.data()[i] <= 3.0f + 1e-6f);
    mx = std::max(mx, e.data()[i]);
  }
  CHECK(mx == doctest::Approx(3.0f));
  CHECK(e(12, 5) > e(3, 5));
  CHECK(e(3, 5) == 1.0f);
}
