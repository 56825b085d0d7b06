#include "video3dgs/testing/grad_check.hpp"

#include <cmath>
#include <vector>

#include <doctest/doctest.h>

using namespace video3dgs::testing;

TEST_CASE("grad_check: accepts a right gradient and pinpoints a wrong entry") {
  std::vector<double> x = {0.3, -1.2, 2.0};
  auto loss = [&] { return std::sin(x[0]) * x[1] + x[2] * x[2] * x[2]; };
  std::vector<double> g = {std::cos(x[0]) * x[1], std::sin(x[0]), 3 * x[2] * x[2]};
  const auto good = check_gradient("toy", x, g, loss);
  CHECK(good.ok(1e-7));
  CHECK(x[0] == 0.3);  // restored
  g[1] += 1e-3;
  const auto bad = check_gradient("toy", x, g, loss);
  CHECK_FALSE(bad.ok(1e-7));
  CHECK(bad.worst_index == 1);
  std::vector<double> nan_grad = {NAN, 0, 0};
  CHECK_FALSE(check_gradient("nan", x, nan_grad, loss).ok(1.0));
}
