#include "video3dgs/autodiff/tape.hpp"

#include <vector>

#include <doctest/doctest.h>

#include "video3dgs/autodiff/arena.hpp"
#include "video3dgs/autodiff/ops.hpp"

#include "../count_allocations.hpp"  // to prove that a warm tape iteration allocates nothing

using namespace video3dgs;
using namespace video3dgs::autodiff;

TEST_CASE("count_allocations.hpp: the counter sees operator new and new[]") {
  const std::size_t before = video3dgs_test::allocations();
  void* volatile p = ::operator new(16);
  ::operator delete(p);
  int* volatile q = new int[4];
  delete[] q;
  CHECK(video3dgs_test::allocations() == before + 2);
}

TEST_CASE("arena: bump allocation, alignment, mark/rewind, reset merges blocks") {
  Arena a(256);
  auto* p = a.allocate_array<float>(10);
  CHECK(reinterpret_cast<std::uintptr_t>(p) % 32 == 0);
  const auto m = a.mark();
  (void)a.allocate(1000);  // overflows the first block
  CHECK(a.block_count() == 2);
  a.rewind(m);
  auto* q = a.allocate_array<float>(10);
  CHECK(q != p);
  const std::size_t cap = a.capacity();
  a.reset();
  CHECK(a.block_count() == 1);
  CHECK(a.capacity() == cap);
  const std::size_t sys = a.system_allocations();
  (void)a.allocate(1000);
  (void)a.allocate_array<double>(10);
  CHECK(a.system_allocations() == sys);  // fits the merged block
}

namespace {
/// One "training iteration": a small graph over borrowed parameters, backward, clear.
double iteration(Tape<double>& t, std::vector<double>& w, std::vector<double>& gw, const std::vector<double>& x,
                 const std::vector<int>& idx) {
  const Var W = t.leaf(w.data(), gw.data(), 4, 3);
  const Var X = t.constant(x.data(), 8, 4);
  const Var h = sigmoid(t, matmul(t, X, W));
  const Var g = gather_rows(t, h, std::span<const int>(idx));
  const Var n = normalize_rows(t, g);
  // A custom node: y = x^3 with a hand-written backward.
  const double* nv = t.value(n);
  double* ng = t.grad(n);
  const std::size_t sz = t.size(n);
  const Var cube = t.custom(t.rows(n), t.cols(n), true,
                            [=](double* out) { for (std::size_t i = 0; i < sz; ++i) out[i] = nv[i] * nv[i] * nv[i]; },
                            [=](const double*, const double* dout) {
                              for (std::size_t i = 0; i < sz; ++i) ng[i] += 3 * nv[i] * nv[i] * dout[i];
                            });
  const Var loss = sum(t, cube);
  t.backward(loss);
  const double l = t.value(loss)[0];
  t.clear();
  return l;
}
}  // namespace

TEST_CASE("tape: the arena does not grow and nothing is allocated across 1000 identical iterations") {
  Tape<double> t(512);  // deliberately small: the first iteration overflows and the blocks merge
  std::vector<double> w(12, 0.1), gw(12, 0.0), x(32);
  for (std::size_t i = 0; i < x.size(); ++i) x[i] = 0.01 * double(i) - 0.1;
  const std::vector<int> idx = {0, 3, 5, 7, 7, 2};
  const double l0 = iteration(t, w, gw, x, idx);
  (void)iteration(t, w, gw, x, idx);
  const std::size_t cap = t.arena().capacity();
  const std::size_t blocks = t.arena().block_count();
  const std::size_t before = video3dgs_test::allocations();
  double l = 0;
  for (int it = 0; it < 1000; ++it) {
    std::fill(gw.begin(), gw.end(), 0.0);
    l = iteration(t, w, gw, x, idx);
  }
  CHECK(video3dgs_test::allocations() == before);
  CHECK(t.arena().capacity() == cap);
  CHECK(t.arena().block_count() == blocks);
  CHECK(blocks == 1);
  CHECK(l == l0);
}

TEST_CASE("tape: custom node gradient, zero_grad, and backward replays in reverse") {
  Tape<double> t;
  std::vector<double> a = {1, 2, 3}, ga(3, 0.0);
  const Var A = t.leaf(a.data(), ga.data(), 3, 1);
  const Var B = square(t, A);          // recorded first
  const Var C = affine(t, B, 2.0);     // recorded second: must run first
  const Var L = sum(t, C);
  CHECK(t.step_count() == 3);
  t.backward(L);
  for (std::size_t i = 0; i < 3; ++i) CHECK(ga[i] == doctest::Approx(4 * a[i]));
  t.zero_grad();
  for (double g : ga) CHECK(g == 0.0);
  CHECK(t.grad(B)[0] == 0.0);
  // Calling backward again accumulates from zero to the same values.
  t.backward(L);
  CHECK(ga[2] == doctest::Approx(12.0));
}

TEST_CASE("tape: nested scope back-propagates its own steps and is discarded") {
  Tape<double> t;
  std::vector<double> a = {0.5, -1.0}, ga(2, 0.0);
  const Var A = t.leaf(a.data(), ga.data(), 2, 1);
  const Var outer = exp(t, A);
  const std::size_t nodes = t.node_count(), steps = t.step_count();
  {
    Tape<double>::Scope scope(t);
    const Var inner = sum(t, square(t, A));  // d/dA = 2A
    scope.backward(inner);
    CHECK(ga[0] == doctest::Approx(1.0));
    CHECK(ga[1] == doctest::Approx(-2.0));
    CHECK(t.grad(outer)[0] == 0.0);  // the outer step did not run
  }
  CHECK(t.node_count() == nodes);
  CHECK(t.step_count() == steps);
  std::fill(ga.begin(), ga.end(), 0.0);
  t.backward(sum(t, outer));
  CHECK(ga[0] == doctest::Approx(std::exp(0.5)));
}

TEST_CASE("tape: constants get no gradient and record no step") {
  Tape<float> t;
  std::vector<float> c = {1, 2};
  const Var C = t.constant(c.data(), 2, 1);
  const Var E = exp(t, C);
  CHECK_FALSE(t.requires_grad(E));
  CHECK(t.step_count() == 0);
}
