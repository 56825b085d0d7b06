#include "video3dgs/gaussian/activations.hpp"

#include <cmath>

#include <doctest/doctest.h>

#include "video3dgs/testing/grad_check.hpp"

using namespace video3dgs;

TEST_CASE_TEMPLATE("activations: sigmoid and logit are stable and inverse", Scalar, float, double) {
  for (Scalar l : {Scalar(-100), Scalar(-30), Scalar(-1), Scalar(0), Scalar(2), Scalar(30), Scalar(100)}) {
    const Scalar o = sigmoid(l);
    CHECK(std::isfinite(o));
    CHECK(o >= Scalar(0));
    CHECK(o <= Scalar(1));
  }
  CHECK(sigmoid(Scalar(0)) == Scalar(0.5));
  for (Scalar o : {Scalar(0.1), Scalar(0.5), Scalar(0.9)}) CHECK(sigmoid(logit(o)) == doctest::Approx(o).epsilon(1e-5));
  CHECK(std::isfinite(logit(Scalar(0))));
  CHECK(std::isfinite(logit(Scalar(1))));
  CHECK(std::isfinite(scale_from_log(Scalar(1e6))));
  CHECK(scale_from_log(Scalar(-1e6)) > Scalar(0));
}

TEST_CASE("activations: quaternion normalisation backward matches finite differences") {
  std::vector<double> q = {0.3, -1.2, 0.7, 2.0};
  auto loss = [&] {
    std::array<double, 4> qn{};
    double inv = 0;
    normalize_quaternion(q.data(), qn, inv);
    return 1.0 * qn[0] - 2.0 * qn[1] + 0.5 * qn[2] + 3.0 * qn[3];
  };
  std::array<double, 4> qn{};
  double inv = 0;
  REQUIRE(normalize_quaternion(q.data(), qn, inv));
  std::vector<double> g(4);
  normalize_quaternion_backward(qn, inv, {1.0, -2.0, 0.5, 3.0}, g.data());
  const auto r = testing::check_gradient("quaternion", q, g, loss, {.rtol = 1e-8});
  INFO(r);
  CHECK(r.ok());
  // Zero and huge quaternions.
  const double z[4] = {0, 0, 0, 0};
  CHECK_FALSE(normalize_quaternion(z, qn, inv));
  CHECK(qn[0] == 1.0);
  const float big[4] = {1e30f, 1e30f, 0, 0};
  std::array<float, 4> qf{};
  float invf = 0;
  REQUIRE(normalize_quaternion(big, qf, invf));
  CHECK(qf[0] == doctest::Approx(std::sqrt(0.5)));
}
