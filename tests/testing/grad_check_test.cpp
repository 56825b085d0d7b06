#include "video3dgs/testing/grad_check.hpp"

#include <cmath>
#include <sstream>
#include <vector>

#include <doctest/doctest.h>

using namespace video3dgs::testing;

TEST_CASE("grad_check: accepts a right gradient and pinpoints a wrong entry") {
  std::vector<double> x = {0.3, -1.2, 2.0};
  auto loss = [&] { return std::sin(x[0]) * x[1] + x[2] * x[2] * x[2]; };
  std::vector<double> g = {std::cos(x[0]) * x[1], std::sin(x[0]), 3 * x[2] * x[2]};
  const auto good = check_gradient("toy", x, g, loss, {.rtol = 1e-7});
  INFO(good);
  CHECK(good.ok());
  CHECK(good.failures == 0);
  CHECK(good.max_error <= 1);
  CHECK(x[0] == 0.3);  // restored
  g[1] += 1e-3;
  const auto bad = check_gradient("toy", x, g, loss, {.rtol = 1e-7});
  CHECK_FALSE(bad.ok());
  CHECK(bad.worst_index == 1);
  CHECK(bad.failures == 1);
  CHECK(bad.passed(0));
  CHECK_FALSE(bad.passed(1));
  CHECK(bad.passed(2));
  std::vector<double> nan_grad = {NAN, 0, 0};
  const auto nan = check_gradient("nan", x, nan_grad, loss, {.rtol = 1.0, .atol = 1.0});
  CHECK_FALSE(nan.ok());
  CHECK_FALSE(nan.finite);
  CHECK(nan.worst_index == 0);
  std::vector<double> short_grad = {0, 0};
  CHECK_FALSE(check_gradient("size", x, short_grad, loss, {.rtol = 1.0, .atol = 1.0}).ok());
}

TEST_CASE("grad_check: a 100% error on a 1e-5-sized gradient fails (it passed the old max(1, |g|) norm)") {
  // L = 1e-5 sin(x0) + x1²: the first entry's gradient is ~1e-5. Under the old error
  // |g - g_fd| / max(1, |g_fd|) a gradient twice too large (or zero) had error ~1e-5 and passed a
  // tolerance of 2e-5; now it is judged relative to its own size.
  std::vector<double> x = {0.4, 0.7};
  auto loss = [&] { return 1e-5 * std::sin(x[0]) + x[1] * x[1]; };
  const double g0 = 1e-5 * std::cos(x[0]);
  for (double wrong : {2 * g0, 0.0, -g0}) {
    CAPTURE(wrong);
    const std::vector<double> g = {wrong, 2 * x[1]};
    const auto r = check_gradient("small", x, g, loss, {.rtol = 2e-5});
    INFO(r);
    CHECK_FALSE(r.ok());
    CHECK(r.worst_index == 0);
    CHECK(r.failures == 1);
    CHECK_FALSE(r.passed(0));
    CHECK(r.passed(1));
    CHECK(r.max_error > 10);
  }
  // The right small gradient passes at a tight rtol: FD noise (~1e-10 |L| / h-ish) is far below it.
  const std::vector<double> right = {g0, 2 * x[1]};
  const auto ok = check_gradient("small", x, right, loss, {.rtol = 1e-6});
  INFO(ok);
  CHECK(ok.ok());
}

TEST_CASE("grad_check: atol absorbs the FD noise of zero entries, and only that") {
  // L does not depend on x1: its central difference is exactly 0, an analytic 1e-12 passes under the
  // default atol (1e-9), an analytic 1e-6 does not.
  std::vector<double> x = {0.4, 0.7};
  auto loss = [&] { return x[0] * x[0]; };
  CHECK(check_gradient("zero", x, std::vector<double>{0.8, 1e-12}, loss, {.rtol = 1e-6}).ok());
  const auto r = check_gradient("zero", x, std::vector<double>{0.8, 1e-6}, loss, {.rtol = 1e-6});
  CHECK_FALSE(r.ok());
  CHECK(r.worst_index == 1);
  CHECK(r.max_error == doctest::Approx(1e-6 / 1e-9));
  // The per-entry test itself.
  CHECK(within(1.0 + 0.9e-6, 1.0, {.rtol = 1e-6, .atol = 0}));
  CHECK_FALSE(within(1.0 + 1.1e-6, 1.0, {.rtol = 1e-6, .atol = 0}));
  CHECK(within(2e-9, 0.0, {.rtol = 1e-6, .atol = 2e-9}));
  CHECK_FALSE(within(NAN, 0.0, {.rtol = 1, .atol = 1}));
  CHECK(normalised_error(1.5, 1.0, {.rtol = 0.25, .atol = 0.25}) == doctest::Approx(1.0));
}

TEST_CASE("grad_check: the report names the tolerance, the failing entries and the worst one") {
  std::vector<double> x = {1.0, 2.0, 3.0};
  auto loss = [&] { return x[0] + x[1] + x[2]; };
  const auto r = check_gradient("sum", x, std::vector<double>{1.0, 1.5, 0.0}, loss, {.rtol = 1e-6});
  std::ostringstream os;
  os << r;
  const std::string s = os.str();
  CHECK(s.find("sum") != std::string::npos);
  CHECK(s.find("2 fail") != std::string::npos);
  CHECK(s.find("[1] 1.5 vs 1") != std::string::npos);
  CHECK(s.find("[2] 0 vs 1") != std::string::npos);
  CHECK(s.find("worst [2]") != std::string::npos);
}

TEST_CASE("grad_check: a jump of the loss next to an entry is re-measured at smaller steps or checked one-sidedly as a kink; wrong gradients still fail") {
  // L = sum x_i^2 + J [x_0 > c0] + J [x_1 > c1]: entry 0 has a jump 5e-7 above it (inside +-h at
  // h = 1e-6, outside at h/10): re-measured, passes. Entry 1 has one 3e-9 above it (inside at h/100
  // too): the central difference grows as 1/h, a kink. Entries 2 and 3 are smooth.
  std::vector<double> x = {0.5, -0.25, 1.5, 0.75};
  const double J = 3e-6, c0 = 0.5 + 5e-7, c1 = -0.25 + 3e-9;
  auto loss = [&] { return x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3] + (x[0] > c0 ? J : 0.0) + (x[1] > c1 ? J : 0.0); };
  std::vector<double> g = {2 * x[0], 2 * x[1], 2 * x[2], 2 * x[3]};
  const auto r = check_gradient("jumps", x, g, loss, {.rtol = 1e-6});
  INFO(r);
  CHECK(r.ok());
  CHECK(r.kinks == 1);
  CHECK(r.kink[1] == 1);
  CHECK(r.kink[0] == 0);
  CHECK(r.numeric[0] == doctest::Approx(1.0).epsilon(1e-6));  // the value measured at h/10
  CHECK(r.numeric[1] == doctest::Approx(-0.5).epsilon(1e-5));  // the one-sided difference below the jump
  CHECK(x[0] == 0.5);                                          // restored
  // A wrong gradient on the smooth entry still fails.
  g[2] *= 1.01;
  CHECK_FALSE(check_gradient("jumps", x, g, loss, {.rtol = 1e-6}).ok());
  // A wrong gradient on the re-measured entry fails too (the smaller steps measure the derivative).
  g = {2 * x[0] * 1.01, 2 * x[1], 2 * x[2], 2 * x[3]};
  CHECK_FALSE(check_gradient("jumps", x, g, loss, {.rtol = 1e-6}).ok());
  // A wrong gradient on the kink entry fails: the side away from the jump measures the derivative.
  g = {2 * x[0], 2 * x[1] * 1.01, 2 * x[2], 2 * x[3]};
  const auto wrong_kink = check_gradient("jumps", x, g, loss, {.rtol = 1e-6});
  CHECK_FALSE(wrong_kink.ok());
  CHECK(wrong_kink.kinks == 0);
  // A check that is mostly kinks: not ok.
  std::vector<double> y = {-0.25};
  auto only_jump = [&] { return y[0] * y[0] + (y[0] > c1 ? J : 0.0); };
  const std::vector<double> gy = {2 * y[0]};
  const auto k = check_gradient("kink", y, gy, only_jump, {.rtol = 1e-6});
  CHECK(k.kinks == 1);
  CHECK_FALSE(k.ok());
}
