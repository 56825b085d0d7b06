#include "video3dgs/metrics/psnr.hpp"

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>

#include <doctest/doctest.h>

#include "video3dgs/metrics/ssim.hpp"

using namespace video3dgs;

TEST_CASE_TEMPLATE("psnr: closed form for known noise", Scalar, float, double) {
  const int w = 37, h = 23;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> base(0.2, 0.8);
  Image<Scalar, 3> x(w, h), y(w, h);
  // y = x +- d with a random sign: MSE = d^2, PSNR = -20 log10(d).
  const double d = 0.05;
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double v = base(rng);
    x.data()[i] = static_cast<Scalar>(v);
    y.data()[i] = static_cast<Scalar>(v + ((rng() & 1) ? d : -d));
  }
  const double tol = std::is_same_v<Scalar, double> ? 1e-9 : 1e-4;
  CHECK(metrics::mse(x, y) == doctest::Approx(d * d).epsilon(tol));
  CHECK(metrics::psnr(x, y) == doctest::Approx(-20.0 * std::log10(d)).epsilon(tol));
  // Data range 255 scales the peak: +20 log10(255).
  CHECK(metrics::psnr(x, y, nullptr, 255.0) == doctest::Approx(-20.0 * std::log10(d) + 20.0 * std::log10(255.0)).epsilon(tol));

  // Uniform noise in [-a, a]: E[MSE] = a^2 / 3 (statistical tolerance).
  const double a = 0.1;
  std::uniform_real_distribution<double> noise(-a, a);
  Image<Scalar, 3> big(256, 256), noisy(256, 256);
  for (std::size_t i = 0; i < big.size(); ++i) {
    const double v = base(rng);
    big.data()[i] = static_cast<Scalar>(v);
    noisy.data()[i] = static_cast<Scalar>(v + noise(rng));
  }
  CHECK(metrics::psnr(big, noisy) == doctest::Approx(10.0 * std::log10(3.0 / (a * a))).epsilon(2e-3));

  CHECK(metrics::psnr(x, x) == std::numeric_limits<double>::infinity());
  ThreadPool two(2);
  CHECK(metrics::psnr(big, noisy, &two) == metrics::psnr(big, noisy, nullptr));
}

TEST_CASE("metrics::ssim: float inputs are evaluated in double and equal 1 on identical images") {
  Image<float, 3> x(40, 30);
  std::mt19937_64 rng(9);
  for (auto& v : x.storage()) v = static_cast<float>(rng() % 256) / 255.0f;
  auto y = x;
  for (auto& v : y.storage()) v = 0.9f * v;
  CHECK(metrics::ssim(x, x) == 1.0);
  const double s = metrics::ssim(x, y);
  CHECK(s == metrics::ssim(x.cast<double>(), y.cast<double>()));
  CHECK(s > 0.9);
  CHECK(s < 1.0);
}
