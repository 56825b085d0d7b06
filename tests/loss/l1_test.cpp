#include "video3dgs/loss/l1.hpp"

#include <cmath>
#include <cstdint>
#include <random>
#include <span>

#include <doctest/doctest.h>

#include "video3dgs/testing/grad_check.hpp"

#include "../test_data.hpp"

using namespace video3dgs;
using video3dgs::test::random_image;

TEST_CASE_TEMPLATE("l1: value, weights and the sign of the gradient", Scalar, float, double) {
  Image<Scalar, 1> x(2, 1), y(2, 1), w(2, 1);
  x(0, 0) = Scalar(0.75);
  y(0, 0) = Scalar(0.25);
  x(1, 0) = Scalar(0.5);
  y(1, 0) = Scalar(0.5);  // equal: gradient 0
  loss::L1Context<Scalar, 1> ctx;
  CHECK(loss::l1_forward<Scalar, 1>(x, y, ctx) == Scalar(0.25));
  w(0, 0) = Scalar(3);
  w(1, 0) = Scalar(1);
  CHECK(loss::l1_forward<Scalar, 1>(x, y, ctx, nullptr, w) == Scalar(0.75));
  Image<Scalar, 1> g(2, 1, Scalar(0));
  loss::l1_backward<Scalar, 1>(ctx, Scalar(2), g);
  CHECK(g(0, 0) == Scalar(3));  // 2 * 3 * sign(+) / 2
  CHECK(g(1, 0) == Scalar(0));
}

TEST_CASE("l1: backward matches central differences in double (weighted and unweighted)") {
  const int w = 37, h = 23;
  auto x = random_image<double, 3>(w, h, 1);
  const auto y = random_image<double, 3>(w, h, 2);
  // Keep every |x - y| away from the kink at 0 by more than the step.
  for (std::size_t i = 0; i < x.size(); ++i)
    if (std::abs(x.data()[i] - y.data()[i]) < 1e-3) x.data()[i] += 0.01;
  const auto weight = random_image<double, 1>(w, h, 3, 1.0, 3.0);
  const double M = static_cast<double>(x.size());
  for (bool weighted : {false, true}) {
    INFO("weighted " << weighted);
    const ConstImageView<double, 1> wv = weighted ? weight.view() : ConstImageView<double, 1>{};
    loss::L1Context<double, 3> ctx, probe;
    (void)loss::l1_forward<double, 3>(x, y, ctx, nullptr, wv);
    Image<double, 3> grad(w, h, 0.0);
    loss::l1_backward<double, 3>(ctx, M, grad);
    const auto r = testing::check_gradient(
        "l1", std::span<double>(x.storage()), std::span<const double>(grad.storage()),
        [&] { return M * loss::l1_forward<double, 3>(x, y, probe, nullptr, wv); }, {.rtol = 1e-6}, 1e-5);
    INFO(r);
    CHECK(r.ok());
  }
}

TEST_CASE_TEMPLATE("l1: bit-identical for any thread count", Scalar, float, double) {
  const auto x = random_image<Scalar, 3>(64, 45, 4), y = random_image<Scalar, 3>(64, 45, 5);
  ThreadPool two(2);
  loss::L1Context<Scalar, 3> a, b;
  CHECK(loss::l1_forward<Scalar, 3>(x, y, a, nullptr) == loss::l1_forward<Scalar, 3>(x, y, b, &two));
  Image<Scalar, 3> ga(64, 45), gb(64, 45);
  loss::l1_backward<Scalar, 3>(a, Scalar(1), ga, nullptr);
  loss::l1_backward<Scalar, 3>(b, Scalar(1), gb, &two);
  CHECK(ga.storage() == gb.storage());
  const Image<Scalar, 3> small(3, 3);
  auto mismatched = [&] { (void)loss::l1_forward<Scalar, 3>(x, small, a); };
  CHECK_THROWS_WITH_AS(mismatched(), doctest::Contains("[option.size] l1: images differ in size (64x45 vs 3x3)"), option_error);
}
