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

TEST_CASE("densify_and_prune: growth beyond max_count is skipped, pruning still runs") {
  GaussianCloud<float, 0> c(3);
  c.opacity_logit[2] = -20;
  const std::vector<float> accum{1, 1, 1}, count{1, 1, 1};
  DensifyOptions o;
  o.max_count = 4;
  std::mt19937_64 rng(1);
  const auto r = densify_and_prune(c, std::span<const float>(accum), std::span<const float>(count), o, rng,
                                   [](auto, auto) {});
  CHECK(r.cloned + r.split == 0);
  CHECK(r.pruned == 1);
  CHECK(c.size() == 2);
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
