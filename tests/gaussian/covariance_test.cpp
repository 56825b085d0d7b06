#include "video3dgs/gaussian/covariance.hpp"

#include <cmath>
#include <random>
#include <vector>

#include <Eigen/LU>
#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "video3dgs/testing/grad_check.hpp"

using namespace video3dgs;

TEST_CASE_TEMPLATE("covariance: isotropic and axis-aligned cases", Scalar, float, double) {
  const Scalar ls[3] = {Scalar(std::log(2.0)), Scalar(std::log(3.0)), Scalar(0)};
  const Scalar q[4] = {Scalar(5), 0, 0, 0};  // unnormalised identity
  const auto S = covariance_3d(ls, q);
  CHECK(S(0, 0) == doctest::Approx(4.0).epsilon(1e-5));
  CHECK(S(1, 1) == doctest::Approx(9.0).epsilon(1e-5));
  CHECK(S(2, 2) == doctest::Approx(1.0).epsilon(1e-5));
  CHECK(std::abs(S(0, 1)) < 1e-6);
  // 90 degrees about z swaps x and y.
  const Scalar qz[4] = {Scalar(std::sqrt(0.5)), 0, 0, Scalar(std::sqrt(0.5))};
  const auto Sz = covariance_3d(ls, qz);
  CHECK(Sz(0, 0) == doctest::Approx(9.0).epsilon(1e-5));
  CHECK(Sz(1, 1) == doctest::Approx(4.0).epsilon(1e-5));
}

TEST_CASE("covariance: rotation matrix is orthonormal with det 1 for random quaternions") {
  auto rng = test::seeded_rng(7);
  std::normal_distribution<double> N(0, 1);
  for (int it = 0; it < 100; ++it) {
    const double q[4] = {N(rng), N(rng), N(rng), N(rng)};
    std::array<double, 4> qn{};
    double inv = 0;
    REQUIRE(normalize_quaternion(q, qn, inv));
    const auto R = rotation_from_unit_quaternion(qn);
    CHECK((R * R.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-12);
    CHECK(R.determinant() == doctest::Approx(1.0));
  }
}

TEST_CASE("covariance: backward matches finite differences") {
  const std::uint64_t seed = 11;
  INFO("seed " << seed);
  auto rng = test::seeded_rng(seed);
  std::normal_distribution<double> N(0, 1);
  for (int it = 0; it < 20; ++it) {
    std::vector<double> p(7);  // log_scale (3), q (4)
    for (auto& v : p) v = N(rng);
    Eigen::Matrix3d Wt;
    for (int i = 0; i < 9; ++i) Wt.data()[i] = N(rng);  // non-symmetric weights: L = <Wt, Sigma>
    auto loss = [&] { return (Wt.array() * covariance_3d(&p[0], &p[3]).array()).sum(); };
    std::vector<double> g(7);
    covariance_3d_backward(&p[0], &p[3], Wt, &g[0], &g[3]);
    // atol: log-scales ~ N(0, 1) make Sigma ~ e^{2s} and |L| = |<Wt, Sigma>| up to ~1e2, so the central
    // difference carries rounding noise ~ eps |L| / h ~ 1e-8 on every entry, small ones included.
    const auto r = testing::check_gradient("covariance", p, g, loss, {.rtol = 1e-7, .atol = 1e-8});
    INFO(r);
    CHECK(r.ok());
  }
}

TEST_CASE("covariance: extremes stay finite") {
  const double qs[][4] = {{0, 0, 0, 0}, {1e30, 2e30, -1e30, 0}, {1e-30, 0, 0, 1e-30}, {NAN, 0, 0, 0}};
  const double ls[][3] = {{std::log(1e-8), 0, 0}, {std::log(1e4), std::log(1e4), std::log(1e4)}, {1e3, -1e3, 0}};
  for (const auto& q : qs)
    for (const auto& l : ls) {
      const auto S = covariance_3d(l, q);
      CHECK(S.allFinite());
      const float qf[4] = {float(q[0]), float(q[1]), float(q[2]), float(q[3])};
      const float lf[3] = {float(l[0]), float(l[1]), float(l[2])};
      CHECK(covariance_3d(lf, qf).allFinite());
      double dls[3], dq[4];
      covariance_3d_backward(l, q, Eigen::Matrix3d(Eigen::Matrix3d::Ones()), dls, dq);
      for (double v : dls) CHECK(std::isfinite(v));
      for (double v : dq) CHECK(std::isfinite(v));
    }
}
