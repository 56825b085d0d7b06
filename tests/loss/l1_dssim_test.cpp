#include "video3dgs/loss/l1_dssim.hpp"

#include <cmath>
#include <cstdint>
#include <random>
#include <span>
#include <utility>

#include <doctest/doctest.h>

#include "video3dgs/testing/grad_check.hpp"

#include "../test_data.hpp"

using namespace video3dgs;
using video3dgs::test::random_image;

TEST_CASE_TEMPLATE("l1_dssim: value is (1 - lambda) L1 + lambda (1 - SSIM)", Scalar, float, double) {
  const auto x = random_image<Scalar, 3>(20, 15, 1), y = random_image<Scalar, 3>(20, 15, 2);
  loss::L1DssimContext<Scalar, 3> ctx;
  const Scalar L = loss::l1_dssim_forward<Scalar, 3>(x, y, ctx);
  loss::L1Context<Scalar, 3> l1;
  loss::SsimContext<Scalar, 3> ss;
  const double l1v = loss::l1_forward<Scalar, 3>(x, y, l1);
  const double sv = loss::ssim_forward<Scalar, 3>(x, y, ss);
  CHECK(static_cast<double>(L) == doctest::Approx(0.8 * l1v + 0.2 * (1.0 - sv)).epsilon(1e-6));
  CHECK(ctx.l1_value == static_cast<Scalar>(l1v));
  CHECK(ctx.ssim_value == static_cast<Scalar>(sv));
  CHECK(loss::l1_dssim_forward<Scalar, 3>(x, x, ctx) == Scalar(0));
}

TEST_CASE("l1_dssim: backward matches central differences in double, with a (1 + 2W) weight") {
  const int w = 37, h = 23;
  auto x = random_image<double, 3>(w, h, 11);
  const auto y = random_image<double, 3>(w, h, 12);
  for (std::size_t i = 0; i < x.size(); ++i) {
    x.data()[i] = 0.5 * x.data()[i] + 0.5 * y.data()[i];
    if (std::abs(x.data()[i] - y.data()[i]) < 1e-3) x.data()[i] += 0.01;
  }
  auto weight = random_image<double, 1>(w, h, 13);
  for (auto& v : weight.storage()) v = 1.0 + 2.0 * v;
  const double M = static_cast<double>(x.size());
  for (double lambda : {0.2, 0.0, 1.0}) {
    INFO("lambda " << lambda);
    loss::L1DssimOptions opts;
    opts.lambda_dssim = lambda;
    loss::L1DssimContext<double, 3> ctx(opts), probe(opts);
    (void)loss::l1_dssim_forward<double, 3>(x, y, ctx, nullptr, weight);
    Image<double, 3> grad(w, h, 0.0);
    loss::l1_dssim_backward<double, 3>(ctx, M, grad);
    // atol: L = M (l1 + dssim) is ~M (up to ~2.5e3 pixels x channels), so with h = 1e-5 the central
    // difference carries rounding noise eps |L| / h ~ 6e-8 on every entry (measured up to 6.4e-8).
    const auto r = testing::check_gradient(
        "l1_dssim", std::span<double>(x.storage()), std::span<const double>(grad.storage()),
        [&] { return M * loss::l1_dssim_forward<double, 3>(x, y, probe, nullptr, weight); }, {.rtol = 1e-6, .atol = 2e-7}, 1e-5);
    INFO(r);
    CHECK(r.ok());
  }
}

TEST_CASE("l1_dssim: deterministic across thread counts; reused context does not reallocate") {
  const auto x = random_image<float, 3>(96, 70, 21), y = random_image<float, 3>(96, 70, 22);
  ThreadPool two(2);
  loss::L1DssimContext<float, 3> a, b;
  Image<float, 3> ga(96, 70), gb(96, 70);
  const float la = loss::l1_dssim_forward<float, 3>(x, y, a, nullptr);
  loss::l1_dssim_backward<float, 3>(a, 1.0f, ga, nullptr);
  const float lb = loss::l1_dssim_forward<float, 3>(x, y, b, &two);
  const float* scratch = b.ssim.h[0].data();
  const float* coef = b.ssim.d_mx.data();
  loss::l1_dssim_backward<float, 3>(b, 1.0f, gb, &two);
  CHECK(la == lb);
  CHECK(ga.storage() == gb.storage());
  // Second iteration on the same size: buffers are reused in place.
  (void)loss::l1_dssim_forward<float, 3>(y, x, b, &two);
  loss::l1_dssim_backward<float, 3>(b, 1.0f, gb, &two);
  CHECK(b.ssim.h[0].data() == scratch);
  CHECK(b.ssim.d_mx.data() == coef);
  for (float v : gb.storage()) REQUIRE(std::isfinite(v));
}

TEST_CASE_TEMPLATE("l1_dssim: against a shared SsimTarget, the value and gradient are the plain call's bit for bit", Scalar, float, double) {
  // The clip graph's pattern: three renders (one with a weight map) against one target, one target fill.
  ThreadPool two(2);
  for (const auto& size : {std::pair{96, 70}, std::pair{7, 5}, std::pair{33, 2}}) {
    const int w = size.first, h = size.second;  // not a binding: INFO captures them
    INFO("size " << w << "x" << h << " seeds 31-35");
    const auto y = random_image<Scalar, 3>(w, h, 31);
    const Image<Scalar, 3> xs[3] = {random_image<Scalar, 3>(w, h, 32), random_image<Scalar, 3>(w, h, 33), random_image<Scalar, 3>(w, h, 34)};
    auto weight = random_image<Scalar, 1>(w, h, 35);
    for (auto& v : weight.storage()) v = static_cast<Scalar>(1 + 2 * v);
    for (ThreadPool* pool : {static_cast<ThreadPool*>(nullptr), &two}) {
      loss::L1DssimOptions opts;
      opts.lambda_dssim = 0.4;
      loss::SsimTarget<Scalar, 3> target;
      loss::fill_ssim_target<Scalar, 3>(y, target, opts.ssim, pool);
      for (int k = 0; k < 3; ++k) {
        const ConstImageView<Scalar, 1> wk = k == 2 ? ConstImageView<Scalar, 1>(weight) : ConstImageView<Scalar, 1>();
        loss::L1DssimContext<Scalar, 3> plain(opts), shared(opts);
        CHECK(loss::l1_dssim_forward<Scalar, 3>(xs[k], y, plain, pool, wk) == loss::l1_dssim_forward<Scalar, 3>(xs[k], target, shared, pool, wk));
        CHECK(plain.l1_value == shared.l1_value);
        CHECK(plain.ssim_value == shared.ssim_value);
        Image<Scalar, 3> gp(w, h, Scalar(0.25)), gs(w, h, Scalar(0.25));
        loss::l1_dssim_backward<Scalar, 3>(plain, Scalar(1.5), gp, pool);
        loss::l1_dssim_backward<Scalar, 3>(shared, Scalar(1.5), gs, pool);
        CHECK(gp.storage() == gs.storage());
      }
    }
  }
}

TEST_CASE("l1_dssim: against a shared SsimTarget the backward matches central differences in double, with a weight") {
  const int w = 23, h = 19;
  auto x = random_image<double, 3>(w, h, 41);
  const auto y = random_image<double, 3>(w, h, 42);
  for (std::size_t i = 0; i < x.size(); ++i) {
    x.data()[i] = 0.5 * x.data()[i] + 0.5 * y.data()[i];
    if (std::abs(x.data()[i] - y.data()[i]) < 1e-3) x.data()[i] += 0.01;  // away from the L1 kink
  }
  auto weight = random_image<double, 1>(w, h, 43);
  for (auto& v : weight.storage()) v = 1.0 + 2.0 * v;
  const double M = static_cast<double>(x.size());
  loss::L1DssimOptions opts;
  opts.lambda_dssim = 0.4;
  loss::SsimTarget<double, 3> target;
  loss::fill_ssim_target<double, 3>(y, target, opts.ssim);
  loss::L1DssimContext<double, 3> ctx(opts), probe(opts);
  (void)loss::l1_dssim_forward<double, 3>(x, target, ctx, nullptr, weight);
  Image<double, 3> grad(w, h, 0.0);
  loss::l1_dssim_backward<double, 3>(ctx, M, grad);
  // atol: L = M l is ~M (~1.3e3), so with h = 1e-5 the central difference carries ~eps |L| / h ~ 3e-8.
  const auto r = testing::check_gradient(
      "l1_dssim_shared_target", std::span<double>(x.storage()), std::span<const double>(grad.storage()),
      [&] { return M * loss::l1_dssim_forward<double, 3>(x, target, probe, nullptr, weight); }, {.rtol = 1e-6, .atol = 2e-7}, 1e-5);
  INFO(r);
  CHECK(r.ok());
}
