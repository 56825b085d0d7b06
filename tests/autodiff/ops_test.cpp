#include "video3dgs/autodiff/ops.hpp"

#include <cmath>
#include <random>
#include <vector>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "video3dgs/autodiff/dual.hpp"
#include "video3dgs/testing/grad_check.hpp"

using namespace video3dgs;
using namespace video3dgs::autodiff;

namespace {

struct Input {
  std::vector<double> value;
  std::size_t rows, cols;
};

/// Builds the graph `build(tape, vars)` on leaves over `inputs`, takes L = sum(c . out) with random c,
/// runs backward and compares every input's gradient with central differences.
template <class Build>
void check_op(const char* name, std::vector<Input> inputs, Build build, double tol = 1e-7) {
  INFO("op " << name);
  auto rng = test::seeded_rng(42);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> c;
  auto run = [&](bool with_grad, std::vector<std::vector<double>>* grads) {
    Tape<double> t;
    std::vector<Var> vars;
    if (grads) grads->assign(inputs.size(), {});
    for (std::size_t k = 0; k < inputs.size(); ++k) {
      if (with_grad) {
        (*grads)[k].assign(inputs[k].value.size(), 0.0);
        vars.push_back(t.leaf(inputs[k].value.data(), (*grads)[k].data(), inputs[k].rows, inputs[k].cols));
      } else {
        vars.push_back(t.constant(inputs[k].value.data(), inputs[k].rows, inputs[k].cols));
      }
    }
    const Var out = build(t, vars);
    if (c.empty()) {
      c.resize(t.size(out));
      for (auto& v : c) v = u(rng);
    }
    const Var cv = t.constant(c.data(), t.rows(out), t.cols(out));
    const Var loss = sum(t, mul(t, out, cv));
    CHECK(t.rows(loss) == 1);
    if (with_grad) t.backward(loss);
    return t.value(loss)[0];
  };
  std::vector<std::vector<double>> grads;
  run(true, &grads);
  for (std::size_t k = 0; k < inputs.size(); ++k) {
    auto r = testing::check_gradient(std::string(name) + " input " + std::to_string(k), inputs[k].value, grads[k],
                                     [&] { return run(false, nullptr); }, {.rtol = tol});
    INFO(r);
    CHECK(r.ok());
  }
}

std::vector<double> random_values(std::size_t n, std::uint64_t seed, double lo = -1, double hi = 1) {
  auto rng = test::seeded_rng(seed);
  std::uniform_real_distribution<double> u(lo, hi);
  std::vector<double> v(n);
  for (auto& x : v) x = u(rng);
  return v;
}

}  // namespace

TEST_CASE("autodiff ops: finite-difference checks") {
  const std::size_t r = 4, k = 3;
  auto in = [](std::uint64_t seed, std::size_t rows = 4, std::size_t cols = 3, double lo = -1, double hi = 1) {
    return Input{random_values(rows * cols, seed, lo, hi), rows, cols};
  };
  check_op("add", {in(1), in(2)}, [](Tape<double>& t, std::vector<Var>& v) { return add(t, v[0], v[1]); });
  check_op("sub", {in(1), in(2)}, [](Tape<double>& t, std::vector<Var>& v) { return sub(t, v[0], v[1]); });
  check_op("mul", {in(1), in(2)}, [](Tape<double>& t, std::vector<Var>& v) { return mul(t, v[0], v[1]); });
  check_op("affine", {in(1)}, [](Tape<double>& t, std::vector<Var>& v) { return affine(t, v[0], 2.5, -0.3); });
  check_op("square", {in(1)}, [](Tape<double>& t, std::vector<Var>& v) { return square(t, v[0]); });
  check_op("abs", {in(1, r, k, 0.1, 1.0)}, [](Tape<double>& t, std::vector<Var>& v) { return abs(t, affine(t, v[0], -1.0)); });
  check_op("exp", {in(3)}, [](Tape<double>& t, std::vector<Var>& v) { return exp(t, v[0]); });
  check_op("log", {in(3, r, k, 0.2, 3.0)}, [](Tape<double>& t, std::vector<Var>& v) { return log(t, v[0]); });
  check_op("sigmoid", {in(4, r, k, -8, 8)}, [](Tape<double>& t, std::vector<Var>& v) { return sigmoid(t, v[0]); });
  check_op("relu", {in(5, r, k, 0.05, 1)}, [](Tape<double>& t, std::vector<Var>& v) {
    return relu(t, mul(t, v[0], v[0]));
  });
  check_op("sum", {in(6)}, [](Tape<double>& t, std::vector<Var>& v) { return sum(t, square(t, v[0])); });
  check_op("mean", {in(6)}, [](Tape<double>& t, std::vector<Var>& v) { return mean(t, exp(t, v[0])); });
  check_op("add_row", {in(7), in(8, 1, k)}, [](Tape<double>& t, std::vector<Var>& v) { return add_row(t, v[0], v[1]); });
  check_op("matmul", {in(9, 5, 3), in(10, 3, 2)}, [](Tape<double>& t, std::vector<Var>& v) { return matmul(t, v[0], v[1]); });
  check_op("normalize_rows", {in(11, 5, 4)}, [](Tape<double>& t, std::vector<Var>& v) { return normalize_rows(t, v[0]); });
  static const std::vector<int> idx = {2, 0, 2, 3, 1, 2};
  check_op("gather_rows", {in(12)}, [](Tape<double>& t, std::vector<Var>& v) { return gather_rows(t, v[0], std::span<const int>(idx)); });
  check_op("scatter_add_rows", {in(13, 6, 2)}, [](Tape<double>& t, std::vector<Var>& v) {
    return scatter_add_rows(t, v[0], std::span<const int>(idx), 4);
  });
  check_op("composite", {in(14, 3, 4), in(15, 4, 4), in(16, 1, 4)}, [](Tape<double>& t, std::vector<Var>& v) {
    const Var h = sigmoid(t, add_row(t, matmul(t, v[0], v[1]), v[2]));
    return normalize_rows(t, mul(t, h, exp(t, v[0])));
  });
}

TEST_CASE("autodiff ops: extremes stay finite") {
  Tape<double> t;
  std::vector<double> big = {-800, -50, 0, 50, 800}, g(5, 0.0);
  const Var x = t.leaf(big.data(), g.data(), 5, 1);
  const Var s = sigmoid(t, x);
  for (std::size_t i = 0; i < 5; ++i) CHECK(std::isfinite(t.value(s)[i]));
  CHECK(t.value(s)[0] == 0.0);
  CHECK(t.value(s)[4] == 1.0);
  t.backward(sum(t, s));
  for (double v : g) CHECK(std::isfinite(v));
  // A zero row normalises to zero with a finite gradient.
  std::vector<double> zero(4, 0.0), gz(4, 0.0);
  const Var z = t.leaf(zero.data(), gz.data(), 1, 4);
  const Var n = normalize_rows(t, z);
  for (std::size_t i = 0; i < 4; ++i) CHECK(t.value(n)[i] == 0.0);
  t.backward(sum(t, n));
  for (double v : gz) CHECK(std::isfinite(v));
}

TEST_CASE_TEMPLATE("autodiff: Dual directional derivative matches the tape gradient", Scalar, float, double) {
  // f(x) = sum_i sigmoid(x_i y_i) + exp(x_i) / (1 + x_i^2), y fixed.
  const std::vector<Scalar> xs = {Scalar(0.3), Scalar(-1.2), Scalar(0.8)}, ys = {Scalar(2), Scalar(0.5), Scalar(-1)};
  const std::vector<Scalar> dir = {Scalar(1), Scalar(-2), Scalar(0.5)};
  Dual<Scalar> f = 0;
  for (std::size_t i = 0; i < 3; ++i) {
    const Dual<Scalar> x(xs[i], dir[i]);
    f += sigmoid(x * Dual<Scalar>(ys[i])) + exp(x) / (Dual<Scalar>(1) + x * x);
  }
  Tape<Scalar> t;
  std::vector<Scalar> xv = xs, g(3, Scalar(0));
  const Var x = t.leaf(xv.data(), g.data(), 3, 1);
  const Var y = t.constant(ys.data(), 3, 1);
  std::vector<Scalar> one(3, Scalar(1));
  const Var den = add(t, t.constant(one.data(), 3, 1), square(t, x));
  // exp(x) / den via exp(x - log(den))
  const Var term = exp(t, sub(t, x, log(t, den)));
  const Var loss = sum(t, add(t, sigmoid(t, mul(t, x, y)), term));
  t.backward(loss);
  Scalar jv = 0;
  for (std::size_t i = 0; i < 3; ++i) jv += g[i] * dir[i];
  CHECK(double(t.value(loss)[0]) == doctest::Approx(double(f.v)).epsilon(double(scalar_traits<Scalar>::test_tolerance)));
  CHECK(double(jv) == doctest::Approx(double(f.d)).epsilon(double(scalar_traits<Scalar>::test_tolerance) * 10));
}
