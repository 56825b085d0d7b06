#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "video3dgs/heads.hpp"
#include "video3dgs/testing/grad_check.hpp"

using namespace video3dgs;

namespace {
BatchMatrix<double> random_matrix(Eigen::Index r, Eigen::Index c, std::uint64_t seed) {
  auto rng = test::seeded_rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  BatchMatrix<double> m(r, c);
  for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = u(rng);
  return m;
}

/// FD check of params (all segments) and inputs for L = sum(C . head(X)).
template <class Head>
void check_head(Head& head, std::uint64_t seed) {
  INFO("seed " << seed);
  const Eigen::Index n = 7;
  BatchMatrix<double> X = random_matrix(n, Head::kIn, seed);
  const BatchMatrix<double> C = random_matrix(n, Head::kOut, seed + 1);
  typename Head::Context ctx;
  auto loss = [&] {
    BatchMatrix<double> Y;
    typename Head::Context c2;
    head.forward(X, Y, c2);
    return (Y.array() * C.array()).sum();
  };
  BatchMatrix<double> Y;
  head.forward(X, Y, ctx);
  std::vector<std::vector<double>> grads(Head::segment_count());
  std::vector<std::span<double>> spans;
  for (std::size_t i = 0; i < grads.size(); ++i) {
    grads[i].assign(head.segment_size(i), 0.0);
    spans.push_back(grads[i]);
  }
  BatchMatrix<double> dX = BatchMatrix<double>::Zero(n, Head::kIn);
  head.backward(X, C, ctx, std::span<const std::span<double>>(spans), &dX);
  for (std::size_t s = 0; s < grads.size(); ++s) {
    auto seg = head.segment(s);
    auto r = testing::check_gradient("segment " + std::to_string(s), seg, std::span<const double>(grads[s]), loss, {.rtol = 1e-7});
    INFO(r);
    CHECK(r.ok());
  }
  auto r = testing::check_gradient("inputs", std::span<double>(X.data(), std::size_t(X.size())),
                                   std::span<const double>(dX.data(), std::size_t(dX.size())), loss, {.rtol = 1e-7});
  INFO(r);
  CHECK(r.ok());
}
}  // namespace

TEST_CASE("heads: Linear forward matches X W^T + b and its gradients match finite differences") {
  Linear<double, 5, 3> lin;
  const BatchMatrix<double> X = random_matrix(4, 5, 3);
  BatchMatrix<double> Y;
  lin.forward(X, Y);
  for (Eigen::Index i = 0; i < 4; ++i)
    for (int o = 0; o < 3; ++o) {
      double s = lin.bias()(o);
      for (int j = 0; j < 5; ++j) s += lin.weight()(o, j) * X(i, j);
      CHECK(Y(i, o) == doctest::Approx(s).epsilon(1e-14));
    }
  Mlp<double, 5, 3, 8, 0> as_mlp;  // HiddenLayers = 0 is one Linear
  check_head(as_mlp, 10);
}

TEST_CASE("heads: Mlp gradients (1 and 2 hidden layers, ReLU and softplus)") {
  Mlp<double, 6, 4, 8, 1, Softplus> a;
  check_head(a, 20);
  Mlp<double, 6, 3, 5, 2, Softplus> b;
  check_head(b, 30);
  Mlp<double, 4, 2, 6, 2, Relu> c;
  check_head(c, 40);
}

TEST_CASE_TEMPLATE("heads: initialisation options", Scalar, float, double) {
  HeadInitOptions zero{HeadInit::zero};
  Linear<Scalar, 36, 3> z(zero);
  for (Scalar v : z.params()) CHECK(v == Scalar(0));
  Linear<Scalar, 36, 3> ref;  // uniform fan-in: |w| <= 1/sqrt(36)
  Scalar mx = 0;
  for (Scalar v : ref.params()) mx = std::max(mx, std::abs(v));
  CHECK(mx <= Scalar(1.0 / 6.0));
  CHECK(mx > Scalar(0.1));
  HeadInitOptions small{HeadInit::small, 1e-3};
  Linear<Scalar, 36, 3> s(small);
  Scalar ms = 0;
  for (Scalar v : s.params()) ms = std::max(ms, std::abs(v));
  CHECK(ms <= Scalar(1e-3 / 6.0 * 1.0001));
  CHECK(ms > Scalar(0));
  // Zero output layer: the MLP starts at exactly zero output whatever the input.
  Mlp<Scalar, 4, 3, 8, 1> m(HeadInitOptions{}, zero);
  BatchMatrix<Scalar> X = BatchMatrix<Scalar>::Random(5, 4), Y;
  typename Mlp<Scalar, 4, 3, 8, 1>::Context ctx;
  m.forward(X, Y, ctx);
  CHECK(Y.cwiseAbs().maxCoeff() == Scalar(0));
}

TEST_CASE_TEMPLATE("heads: few-output Linear in row blocks and on a pool gives the bits of one row at a time", Scalar, float, double) {
  // Out <= kSmallOut: y = b + w_0 x_0 + w_1 x_1 + ... and dx_j = sum_o w_oj dy_o, each in that order
  // per element whatever the blocking; dW entries are sums over fixed row parts, the same on a pool.
  using L = Linear<Scalar, 36, 4>;
  static_assert(L::kOut <= L::kSmallOut);
  L lin(HeadInitOptions{HeadInit::uniform_fan_in, 1e-3, 3});
  for (const Eigen::Index n : {Eigen::Index(0), Eigen::Index(5), Eigen::Index(2 * L::kRowBlock + 77),
                               Eigen::Index(L::kBackwardParts * L::kRowBlock + 3 * L::kRowBlock + 11)}) {  // several blocks per part
    CAPTURE(n);
    auto rng = test::seeded_rng(21);
    INFO("seed 21");
    std::normal_distribution<double> N01;
    BatchMatrix<Scalar> X(n, 36), dY(n, 4);
    for (Eigen::Index i = 0; i < X.size(); ++i) X.data()[i] = Scalar(N01(rng));
    for (Eigen::Index i = 0; i < dY.size(); ++i) dY.data()[i] = Scalar(N01(rng));
    BatchMatrix<Scalar> Y1, Y2;
    lin.forward(X, Y1);
    ThreadPool pool(2);
    lin.forward(X, Y2, &pool);
    std::size_t differ = 0;
    for (Eigen::Index r = 0; r < n; ++r)
      for (int o = 0; o < 4; ++o) {
        Scalar y = lin.bias()(o);
        for (int j = 0; j < 36; ++j) y = y + lin.weight()(o, j) * X(r, j);
        differ += (y != Y1(r, o)) + (y != Y2(r, o));
      }
    CHECK(differ == 0);

    std::vector<Scalar> g1(L::kParams, Scalar(0)), g2(L::kParams, Scalar(0));
    BatchMatrix<Scalar> dX1 = BatchMatrix<Scalar>::Zero(n, 36), dX2 = BatchMatrix<Scalar>::Zero(n, 36);
    lin.backward(X, dY, g1, &dX1);
    lin.backward(X, dY, g2, &dX2, &pool);
    differ = 0;
    for (Eigen::Index r = 0; r < n; ++r)
      for (int j = 0; j < 36; ++j) {
        Scalar d = 0;
        for (int o = 0; o < 4; ++o) d = d + lin.weight()(o, j) * dY(r, o);
        differ += (d != dX1(r, j)) + (d != dX2(r, j));
      }
    CHECK(differ == 0);
    // dW, db: kBackwardParts fixed row parts, each the sum of its kRowBlock blocks' dots (Eigen's), the
    // parts added in order; close to the exact sums (in double).
    const std::size_t part = (std::size_t(n) + L::kBackwardParts - 1) / L::kBackwardParts;
    double worst = 0;
    for (int o = 0; o < 4; ++o)
      for (int j = 0; j <= 36; ++j) {
        Scalar sum = 0;
        for (std::size_t k = 0; k < L::kBackwardParts; ++k) {
          const std::size_t pb = std::min(std::size_t(n), k * part), pe = std::min(std::size_t(n), pb + part);
          Scalar acc = 0;
          for (std::size_t b = pb; b < pe; b += L::kRowBlock) {
            const auto r0 = Eigen::Index(b), len = Eigen::Index(std::min(pe, b + L::kRowBlock) - b);
            acc += j < 36 ? dY.col(o).segment(r0, len).dot(X.col(j).segment(r0, len)) : dY.col(o).segment(r0, len).sum();
          }
          sum += acc;
        }
        const Scalar got = j < 36 ? g1[std::size_t(o * 36 + j)] : g1[std::size_t(4 * 36 + o)];
        differ += got != sum;
        double exact = 0;
        for (Eigen::Index r = 0; r < n; ++r) exact += double(dY(r, o)) * (j < 36 ? double(X(r, j)) : 1.0);
        worst = std::max(worst, std::abs(double(got) - exact));
      }
    CHECK(differ == 0);
    CHECK(worst < (sizeof(Scalar) == 4 ? 5e-3 : 1e-9));
    CHECK(std::memcmp(g1.data(), g2.data(), g1.size() * sizeof(Scalar)) == 0);
  }
}
