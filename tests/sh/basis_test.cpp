#include "video3dgs/sh/basis.hpp"

#include <cmath>
#include <random>
#include <vector>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "video3dgs/testing/grad_check.hpp"

using namespace video3dgs;

TEST_CASE("sh: basis is orthonormal on the sphere (Monte Carlo, degree 3)") {
  auto rng = test::seeded_rng(3);
  std::normal_distribution<double> N(0, 1);
  double gram[16][16] = {};
  const int samples = 200000;
  for (int s = 0; s < samples; ++s) {
    Eigen::Vector3d d(N(rng), N(rng), N(rng));
    d.normalize();
    double B[16];
    sh::basis(3, d.x(), d.y(), d.z(), B);
    for (int i = 0; i < 16; ++i)
      for (int j = 0; j < 16; ++j) gram[i][j] += B[i] * B[j];
  }
  const double area = 4 * M_PI / samples;
  for (int i = 0; i < 16; ++i)
    for (int j = 0; j < 16; ++j) CHECK(gram[i][j] * area == doctest::Approx(i == j ? 1.0 : 0.0).epsilon(0.02).scale(1));
}

TEST_CASE("sh: DC colour round trip and clamp") {
  const Eigen::Vector3f d(0, 0, 1);
  float coeffs[3] = {sh::rgb_to_dc(0.2f), sh::rgb_to_dc(0.7f), sh::rgb_to_dc(-0.5f)};
  float col[3];
  bool clamped[3];
  sh::evaluate<float, 3>(0, d, coeffs, col, clamped);
  CHECK(col[0] == doctest::Approx(0.2f));
  CHECK(col[1] == doctest::Approx(0.7f));
  CHECK(col[2] == 0.0f);
  CHECK(clamped[2]);
  CHECK_FALSE(clamped[0]);
}

TEST_CASE("sh: backward matches finite differences for every degree") {
  const std::uint64_t seed = 5;
  INFO("seed " << seed);
  auto rng = test::seeded_rng(seed);
  std::normal_distribution<double> N(0, 1);
  for (int degree = 0; degree <= 3; ++degree) {
    const int K = sh::coeff_count(degree);
    std::vector<double> mean = {N(rng), N(rng), N(rng) + 4};
    const Eigen::Vector3d centre(0.1, -0.2, 0.3);
    std::vector<double> coeffs(3 * 16);
    for (auto& c : coeffs) c = 0.3 * N(rng);
    coeffs[0] = coeffs[1] = coeffs[2] = 1.0;  // keep away from the clamp
    const double w[3] = {0.7, -1.3, 0.4};
    auto loss = [&] {
      double inv;
      const auto d = sh::view_direction(Eigen::Vector3d(mean[0], mean[1], mean[2]), centre, inv);
      double col[3];
      sh::evaluate<double, 3>(degree, d, coeffs.data(), col);
      return w[0] * col[0] + w[1] * col[1] + w[2] * col[2];
    };
    double inv;
    const auto d = sh::view_direction(Eigen::Vector3d(mean[0], mean[1], mean[2]), centre, inv);
    bool clamped[3];
    double col[3];
    sh::evaluate<double, 3>(degree, d, coeffs.data(), col, clamped);
    std::vector<double> gc(coeffs.size(), 0.0);
    const auto dd = sh::evaluate_backward<double, 3>(degree, d, coeffs.data(), clamped, w, gc.data());
    const auto dm = sh::view_direction_backward(d, inv, dd);
    std::vector<double> gm = {dm.x(), dm.y(), dm.z()};
    INFO("degree " << degree);
    const auto rc = testing::check_gradient("sh coeffs", coeffs, gc, loss, {.rtol = 1e-7});
    INFO(rc);
    CHECK(rc.ok());
    const auto rm = testing::check_gradient("sh mean", mean, gm, loss, {.rtol = 1e-7});
    INFO(rm);
    CHECK(rm.ok());
    for (std::size_t k = 3 * K; k < gc.size(); ++k) CHECK(gc[k] == 0.0);
  }
}
