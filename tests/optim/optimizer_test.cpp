#include "video3dgs/optim/optimizer.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <vector>

#include "video3dgs/training/split_adam.hpp"

#include <doctest/doctest.h>

#include "../test_data.hpp"

using namespace video3dgs;

TEST_CASE_TEMPLATE("Adam matches closed-form values for its first steps", Scalar, float, double) {
  Optimizer<Scalar, Adam> opt;
  std::vector<Scalar> p = {Scalar(1), Scalar(-2), Scalar(0.5)}, g(3);
  Adam::Hyper hyper;  // 0.9, 0.999, 1e-15
  opt.add_group({"xyz", LrSchedule::constant(0.1), hyper, 3}, p, g);
  // Gradients g1 = (1, -3, 0.5), g2 = (2, 1, 0.5) (chosen by hand).
  const std::vector<double> g1 = {1, -3, 0.5}, g2 = {2, 1, 0.5};
  std::vector<double> ref = {1, -2, 0.5};
  // Step 1: m = 0.1 g, v = 0.001 g^2, mhat = g, vhat = g^2: p -= lr g / (|g| + eps) = lr sign(g).
  for (int i = 0; i < 3; ++i) g[std::size_t(i)] = Scalar(g1[std::size_t(i)]);
  opt.step(0);
  for (int i = 0; i < 3; ++i) ref[std::size_t(i)] -= 0.1 * (g1[std::size_t(i)] > 0 ? 1 : -1);
  for (int i = 0; i < 3; ++i) CHECK(double(p[std::size_t(i)]) == doctest::Approx(ref[std::size_t(i)]).epsilon(1e-6));
  // Step 2: m = 0.09 g1 + 0.1 g2, v = 0.000999 g1^2 + 0.001 g2^2, bias corrections 0.19 and 0.001999.
  for (int i = 0; i < 3; ++i) g[std::size_t(i)] = Scalar(g2[std::size_t(i)]);
  opt.step(1);
  for (int i = 0; i < 3; ++i) {
    const double m = 0.09 * g1[std::size_t(i)] + 0.1 * g2[std::size_t(i)];
    const double v = 0.000999 * g1[std::size_t(i)] * g1[std::size_t(i)] + 0.001 * g2[std::size_t(i)] * g2[std::size_t(i)];
    ref[std::size_t(i)] -= 0.1 * (m / 0.19) / std::sqrt(v / (1 - 0.999 * 0.999));
    CHECK(double(p[std::size_t(i)]) == doctest::Approx(ref[std::size_t(i)]).epsilon(1e-5));
  }
  // For entry 2 (equal gradients) the update is exactly lr again.
  CHECK(double(p[2]) == doctest::Approx(0.5 - 0.2).epsilon(1e-5));
  CHECK(opt.group("xyz").step_count() == 2);
  CHECK(double(opt.group("xyz").moment(0)[0]) == doctest::Approx(0.09 + 0.2));
}

TEST_CASE("optimizer: a frozen group never changes, unfreeze resumes") {
  Optimizer<float, Adam> opt;
  std::vector<float> a = {1, 2}, ga = {1, 1}, b = {3, 4}, gb = {1, 1};
  opt.add_group({"deformation", LrSchedule::constant(0.01), {}, 1}, a, ga);
  opt.add_group({"opacity", LrSchedule::constant(0.01), {}, 1}, b, gb);
  opt.freeze("deformation");
  for (int k = 0; k < 10; ++k) opt.step(k);
  CHECK(a[0] == 1.0f);
  CHECK(a[1] == 2.0f);
  CHECK(opt.group("deformation").step_count() == 0);
  CHECK(opt.group("deformation").moment(0)[0] == 0.0f);
  CHECK(b[0] < 3.0f);
  opt.unfreeze("deformation");
  opt.step(10);
  CHECK(a[0] < 1.0f);
  CHECK(opt.group("deformation").step_count() == 1);
}

TEST_CASE("optimizer: moments follow clone, split and prune of rows") {
  Optimizer<double, Adam> opt;
  // 3 Gaussians, rows of 3.
  std::vector<double> p = {0, 0, 0, 1, 1, 1, 2, 2, 2}, g = {1, 1, 1, 2, 2, 2, 3, 3, 3};
  opt.add_group({"xyz", LrSchedule::constant(0.01), {}, 3}, p, g);
  opt.step(0);
  auto& grp = opt.group("xyz");
  const std::vector<double> m_before(grp.moment(0).begin(), grp.moment(0).end());
  const std::vector<double> v_before(grp.moment(1).begin(), grp.moment(1).end());
  // Clone row 1 (copy its moments) and split row 2 into two children (zero moments), then prune the parent.
  const std::size_t clone_src[] = {1};
  opt.append_rows("xyz", clone_src, RowMoments::copy);
  const std::size_t split_src[] = {2, 2};
  opt.append_rows("xyz", split_src, RowMoments::zero);
  CHECK(grp.rows() == 6);
  for (int c = 0; c < 3; ++c) {
    CHECK(grp.moment(0)[9 + std::size_t(c)] == m_before[3 + std::size_t(c)]);
    CHECK(grp.moment(1)[9 + std::size_t(c)] == v_before[3 + std::size_t(c)]);
    CHECK(grp.moment(0)[12 + std::size_t(c)] == 0.0);
    CHECK(grp.moment(1)[15 + std::size_t(c)] == 0.0);
  }
  // step() refuses stale buffers.
  CHECK_THROWS_AS(opt.step(1), option_error);
  const std::uint8_t keep[] = {1, 1, 0, 1, 1, 1};  // prune the split parent (row 2)
  opt.keep_rows("xyz", keep);
  CHECK(grp.rows() == 5);
  // Rows now: 0, 1, clone of 1, child, child.
  for (int c = 0; c < 3; ++c) {
    CHECK(grp.moment(0)[std::size_t(c)] == m_before[std::size_t(c)]);
    CHECK(grp.moment(0)[3 + std::size_t(c)] == m_before[3 + std::size_t(c)]);
    CHECK(grp.moment(0)[6 + std::size_t(c)] == m_before[3 + std::size_t(c)]);
    CHECK(grp.moment(0)[9 + std::size_t(c)] == 0.0);
  }
  std::vector<double> p2(15, 0.0), g2(15, 1.0);
  opt.bind("xyz", p2, g2);
  opt.step(1);
  CHECK(grp.step_count() == 2);
  // A zero-moment child moves by lr * (0.1 / 0.19) / sqrt(0.001 / 0.001999): not the clone's update.
  CHECK(std::isfinite(p2[9]));
  CHECK(p2[9] != p2[6]);
  std::vector<double> wrong(14), wrong_g(14);
  CHECK_THROWS_AS(opt.bind("xyz", wrong, wrong_g), option_error);
  const std::uint8_t short_mask[] = {1};
  CHECK_THROWS_AS(opt.keep_rows("xyz", short_mask), option_error);
  const std::size_t bad_src[] = {99};
  CHECK_THROWS_AS(opt.append_rows("xyz", bad_src), option_error);
}

TEST_CASE("optimizer: groups, names and errors") {
  Optimizer<float, Adam> opt;
  std::vector<float> a(4), ga(4), b(6), gb(6);
  opt.add_group({"f_dc", LrSchedule::constant(2.5e-3), {}, 1}, a, ga);
  CHECK_THROWS_AS(opt.add_group({"f_dc", LrSchedule::constant(1), {}, 1}, b, gb), option_error);
  CHECK_THROWS_AS(opt.add_group({"rot", LrSchedule::constant(1), {}, 4}, b, gb), option_error);  // 6 % 4
  CHECK_THROWS_AS((void)opt.group("nope"), option_error);
  // Multi-segment group (a network): step works, row edits are refused.
  std::vector<ParamSegment<float>> segs = {{a, ga}, {b, gb}};
  std::vector<float> a2(4), ga2(4, 1.f), b2(6), gb2(6, 1.f);
  opt.add_group({"deformation", LrSchedule::constant(1e-3), {}, 1}, {{a2, ga2}, {b2, gb2}});
  opt.step(0);
  CHECK(a2[0] < 0.f);
  CHECK(b2[5] < 0.f);
  const std::size_t src[] = {0};
  CHECK_THROWS_AS(opt.append_rows("deformation", src), option_error);
  CHECK(opt.groups().size() == 2);
  opt.zero_grad();
  CHECK(ga2[0] == 0.f);
}

TEST_CASE("schedules: constant and 3DGS log-linear decay with delay") {
  const auto c = LrSchedule::constant(0.05);
  CHECK(c(0) == 0.05);
  CHECK(c(100000) == 0.05);
  // Position lr of 3DGS: 1.6e-4 -> 1.6e-6 over 30k steps.
  const auto e = LrSchedule::exponential(1.6e-4, 1.6e-6, 30000);
  CHECK(e(0) == doctest::Approx(1.6e-4));
  CHECK(e(15000) == doctest::Approx(1.6e-5));  // geometric midpoint
  CHECK(e(30000) == doctest::Approx(1.6e-6));
  CHECK(e(60000) == doctest::Approx(1.6e-6));
  CHECK(e(-1) == 0.0);
  const auto d = LrSchedule::exponential(1e-2, 1e-4, 1000, 100, 0.01);
  CHECK(d(0) == doctest::Approx(1e-4));  // delay_mult * lr_init
  CHECK(d(100) == doctest::Approx(std::exp(std::log(1e-2) * 0.9 + std::log(1e-4) * 0.1)));
  CHECK(d(50) == doctest::Approx((0.01 + 0.99 * std::sin(0.25 * 3.14159265358979)) * std::exp(std::log(1e-2) * 0.95 + std::log(1e-4) * 0.05)));
  CHECK_THROWS_AS((void)LrSchedule::exponential(1e-2, 0, 10), option_error);
  CHECK_THROWS_AS((void)LrSchedule::exponential(1e-2, 1e-3, 0), option_error);
  CHECK_THROWS_AS((void)LrSchedule::constant(-1), option_error);
  // The optimizer uses the group's schedule at the given iteration.
  Optimizer<double, Adam> opt;
  std::vector<double> p(1), g(1, 1.0);
  opt.add_group({"xyz", e, {}, 1}, p, g);
  opt.step(15000);
  CHECK(opt.group("xyz").last_lr() == doctest::Approx(1.6e-5));
  CHECK(p[0] == doctest::Approx(-1.6e-5));
}

TEST_CASE("schedules: one step multiplies the rate from its iteration on") {
  const auto c = LrSchedule::constant(0.05).with_step(2000, 0.5);
  CHECK(c(0) == 0.05);
  CHECK(c(1999) == 0.05);
  CHECK(c(2000) == 0.025);
  CHECK(c(100000) == 0.025);
  const auto e = LrSchedule::exponential(1.6e-4, 1.6e-6, 30000);
  const auto es = e.with_step(15000, 0.25);  // the decay goes on; the step scales it
  CHECK(es(14999) == e(14999));
  CHECK(es(15000) == doctest::Approx(0.25 * 1.6e-5));
  CHECK(es(30000) == doctest::Approx(0.25 * 1.6e-6));
  CHECK(es(-1) == 0.0);
  CHECK(e.with_step(0, 1.0)(700) == e(700));  // factor 1: the schedule unchanged
  CHECK(LrSchedule::constant(0.05).with_step(0, 0.0)(0) == 0.0);
  CHECK_THROWS_AS((void)c.with_step(-1, 0.5), option_error);
  CHECK_THROWS_AS((void)c.with_step(10, -0.5), option_error);
  CHECK_THROWS_AS((void)c.with_step(10, std::numeric_limits<double>::infinity()), option_error);
  // The optimizer steps at the stepped rate.
  Optimizer<double, Sgd> opt;
  std::vector<double> p(1), g(1, 1.0);
  opt.add_group({"opacity", LrSchedule::constant(0.1).with_step(3, 0.5), {}, 1}, p, g);
  opt.step(2);
  CHECK(opt.group("opacity").last_lr() == 0.1);
  opt.step(3);
  CHECK(opt.group("opacity").last_lr() == 0.05);
  CHECK(p[0] == doctest::Approx(-0.15));  // plain SGD: -0.1 x 1, then -0.05 x 1
}

TEST_CASE("schedules: an anneal falls log-linearly to its factor and stays there") {
  const auto c = LrSchedule::constant(0.08).with_step(2000, 8.0);
  const auto a = c.with_anneal(2500, 3000, 0.1);
  for (int k : {0, 1999, 2000, 2499}) CHECK(a(k) == c(k));  // the same bits before the anneal
  CHECK(a(2500) == c(2500));                                // factor^0 = 1 exactly
  CHECK(a(2750) == doctest::Approx(0.64 * std::sqrt(0.1)));   // half way: sqrt(factor)
  CHECK(a(3000) == doctest::Approx(0.064));
  CHECK(a(4000) == doctest::Approx(0.064));                 // after `until`: the factor
  for (int k = 2500; k < 3000; ++k) CHECK(a(k + 1) < a(k));  // strictly falling
  const auto e = LrSchedule::exponential(1.6e-4, 1.6e-6, 30000).with_anneal(1000, 2000, 0.5);
  const auto plain = LrSchedule::exponential(1.6e-4, 1.6e-6, 30000);
  CHECK(e(999) == plain(999));
  CHECK(e(1500) == doctest::Approx(plain(1500) * std::sqrt(0.5)));  // on top of the decay
  CHECK(e(-1) == 0.0);
  CHECK_THROWS_AS((void)c.with_anneal(-1, 10, 0.5), option_error);
  CHECK_THROWS_AS((void)c.with_anneal(10, 10, 0.5), option_error);
  CHECK_THROWS_AS((void)c.with_anneal(10, 20, 0.0), option_error);
  CHECK_THROWS_AS((void)c.with_anneal(10, 20, std::numeric_limits<double>::quiet_NaN()), option_error);
  // The optimizer steps at the annealed rate.
  Optimizer<double, Sgd> opt;
  std::vector<double> p(1), g(1, 1.0);
  opt.add_group({"opacity", LrSchedule::constant(0.1).with_anneal(1, 3, 0.25), {}, 1}, p, g);
  opt.step(1);
  CHECK(opt.group("opacity").last_lr() == 0.1);
  opt.step(2);
  CHECK(opt.group("opacity").last_lr() == doctest::Approx(0.05));
  opt.step(3);
  CHECK(opt.group("opacity").last_lr() == doctest::Approx(0.025));
}

TEST_CASE("Sgd policy slots into the optimizer") {
  Optimizer<double, Sgd> plain;
  std::vector<double> p = {1.0}, g = {2.0};
  plain.add_group({"w", LrSchedule::constant(0.1), {}, 1}, p, g);
  plain.step(0);
  CHECK(p[0] == doctest::Approx(0.8));
  Optimizer<double, Sgd> mom;
  std::vector<double> q = {1.0}, gq = {2.0};
  mom.add_group({"w", LrSchedule::constant(0.1), Sgd::Hyper{0.9}, 1}, q, gq);
  mom.step(0);  // b = 2
  mom.step(1);  // b = 0.9 * 2 + 2 = 3.8
  CHECK(q[0] == doctest::Approx(1.0 - 0.2 - 0.38));
}

namespace {

/// Deterministic values in [-1, 1).
std::vector<float> noise(std::size_t n, unsigned seed) {
  std::vector<float> v(n);
  std::uint32_t x = seed * 2654435761u + 1;
  for (auto& e : v) {
    x = x * 1664525u + 1013904223u;
    e = float(x >> 8) / float(1u << 23) - 1.0f;
  }
  return v;
}

}  // namespace

TEST_CASE_TEMPLATE("optimizer: a lazy group leaves untouched rows alone and steps touched rows as a dense step does", Policy, Adam,
                   SplitLrAdam) {
  // 20000 rows of 48 scalars (an SH group of degree 3), so that chunks of the pool split the rows.
  const std::size_t w = 48, rows = 20000;
  typename Policy::Hyper hyper{};
  if constexpr (requires { hyper.tail_scale; }) hyper.row_width = w, hyper.lead = 3, hyper.tail_scale = 1.0 / 20;
  auto make = [&](std::vector<float>& p, std::vector<float>& g, bool lazy) {
    auto o = std::make_unique<Optimizer<float, Policy>>();
    o->add_group({"sh", LrSchedule::constant(0.01), hyper, w, lazy}, p, g);
    return o;
  };
  std::vector<float> p_dense = noise(rows * w, 1), g_dense(rows * w), p_lazy = p_dense, g_lazy(rows * w), p_pool = p_dense, g_pool(rows * w);
  auto dense = make(p_dense, g_dense, false);
  auto lazy = make(p_lazy, g_lazy, true);
  auto pooled = make(p_pool, g_pool, true);
  ThreadPool pool(3);
  // Two dense-like steps first (every row touched: lazy == dense), so the moments are not zero.
  for (int k = 0; k < 2; ++k) {
    const auto g = noise(rows * w, 10 + unsigned(k));
    g_dense = g_lazy = g_pool = g;
    dense->step(k);
    lazy->step(k);
    pooled->step(k, &pool);
  }
  CHECK(p_lazy == p_dense);
  // Step 3: every third row untouched (gradient exactly zero, -0.0 included), one touched row with a
  // single non-zero column.
  auto g = noise(rows * w, 20);
  for (std::size_t r = 0; r < rows; r += 3)
    for (std::size_t j = 0; j < w; ++j) g[r * w + j] = (j % 2) ? 0.0f : -0.0f;
  for (std::size_t j = 0; j < w; ++j) g[1 * w + j] = j == 17 ? 0.5f : 0.0f;
  const std::vector<float> before = p_lazy;
  const std::vector<float> m0 = {lazy->group("sh").moment(0).begin(), lazy->group("sh").moment(0).end()};
  const std::vector<float> m1 = {lazy->group("sh").moment(1).begin(), lazy->group("sh").moment(1).end()};
  g_dense = g_lazy = g_pool = g;
  dense->step(2);
  lazy->step(2);
  pooled->step(2, &pool);
  CHECK(lazy->group("sh").step_count() == 3);
  std::size_t untouched_ok = 0, touched_ok = 0, touched = 0;
  for (std::size_t r = 0; r < rows; ++r) {
    const bool t = r % 3 != 0;
    touched += t;
    bool same_as_before = true, same_as_dense = true;
    for (std::size_t j = 0; j < w; ++j) {
      const std::size_t i = r * w + j;
      same_as_before = same_as_before && p_lazy[i] == before[i] && lazy->group("sh").moment(0)[i] == m0[i] && lazy->group("sh").moment(1)[i] == m1[i];
      same_as_dense = same_as_dense && p_lazy[i] == p_dense[i] && lazy->group("sh").moment(0)[i] == dense->group("sh").moment(0)[i] &&
                      lazy->group("sh").moment(1)[i] == dense->group("sh").moment(1)[i];
    }
    untouched_ok += !t && same_as_before;
    touched_ok += t && same_as_dense;
  }
  CHECK(untouched_ok == rows - touched);
  CHECK(touched_ok == touched);
  CHECK(p_dense != p_lazy);  // the dense step moved the untouched rows along their momentum
  CHECK(p_pool == p_lazy);   // any thread count, same bits
  CHECK(std::vector<float>(pooled->group("sh").moment(1).begin(), pooled->group("sh").moment(1).end()) ==
        std::vector<float>(lazy->group("sh").moment(1).begin(), lazy->group("sh").moment(1).end()));
}

TEST_CASE("optimizer: a lazy group of several segments (hash table + head) steps entry by entry") {
  std::vector<float> table = {1, 2, 3, 4, 5, 6}, gt = {0, 0.5f, 0, 0, -1, 0}, head = {7, 8}, gh = {0.25f, 0};
  Optimizer<float, Adam> opt;
  opt.add_group({"deformation", LrSchedule::constant(0.1), {}, 1, true}, {{table, gt}, {head, gh}});
  opt.step(0);
  // Adam's first step moves a touched entry by lr sign(g); the others keep value and zero moments.
  const std::vector<float> want_table = {1, 2 - 0.1f, 3, 4, 5 + 0.1f, 6}, want_head = {7 - 0.1f, 8};
  for (std::size_t i = 0; i < table.size(); ++i) CHECK(table[i] == doctest::Approx(want_table[i]));
  for (std::size_t i = 0; i < head.size(); ++i) CHECK(head[i] == doctest::Approx(want_head[i]));
  CHECK(opt.group("deformation").moment(1)[0] == 0.0f);
  CHECK(opt.group("deformation").moment(1)[7] == 0.0f);
  CHECK(opt.group("deformation").moment(1)[6] > 0.0f);
  // Segments that do not hold whole rows are refused before anything changes.
  std::vector<float> a(5), ga(5, 1.0f), b(1), gb(1, 1.0f);
  Optimizer<float, Adam> bad;
  bad.add_group({"rows", LrSchedule::constant(0.1), {}, 3, true}, {{a, ga}, {b, gb}});
  CHECK_THROWS_WITH_AS(bad.step(0), doctest::Contains("[option.optimizer]"), option_error);
  CHECK(a == std::vector<float>(5, 0.0f));
}

TEST_CASE("optimizer: a lazy SplitLrAdam group of several segments steps touched rows as the dense step does, columns by position") {
  static_assert(PreparedOptimizerPolicy<Adam, float> && PreparedOptimizerPolicy<SplitLrAdam, double>);
  static_assert(!PreparedOptimizerPolicy<Sgd, float>);  // stepped run by run through update()
  // Two segments of rows of 4 (lead 1 at lr, 3 at lr / 10): rows 0-2 in the first, 3-4 in the second.
  SplitLrAdam::Hyper h;
  h.row_width = 4, h.lead = 1, h.tail_scale = 0.1;
  auto run = [&](bool lazy) {
    std::vector<float> a = noise(12, 3), ga(12), b = noise(8, 4), gb(8);
    Optimizer<float, SplitLrAdam> opt;
    opt.add_group({"sh", LrSchedule::constant(0.05), h, 4, lazy}, {{a, ga}, {b, gb}});
    const auto g1 = noise(20, 5), g2 = noise(20, 6);
    std::copy_n(g1.begin(), 12, ga.begin()), std::copy_n(g1.begin() + 12, 8, gb.begin());
    opt.step(0);
    std::copy_n(g2.begin(), 12, ga.begin()), std::copy_n(g2.begin() + 12, 8, gb.begin());
    std::fill_n(ga.begin() + 4, 4, 0.0f);  // row 1 untouched
    std::fill_n(gb.begin(), 4, 0.0f);      // row 3 (the second segment's first) untouched
    const std::vector<float> a1 = a, b1 = b;
    opt.step(1);
    return std::array<std::vector<float>, 4>{a1, b1, a, b};
  };
  const auto dense = run(false), lazy = run(true);
  for (std::size_t i = 0; i < 12; ++i) {
    INFO(i);
    CHECK(lazy[2][i] == (i / 4 == 1 ? lazy[0][i] : dense[2][i]));
  }
  for (std::size_t i = 0; i < 8; ++i) {
    INFO(i);
    CHECK(lazy[3][i] == (i / 4 == 0 ? lazy[1][i] : dense[3][i]));
  }
  CHECK(dense[3][1] != dense[1][1]);  // the dense step moved the untouched row along its momentum
}

TEST_CASE("SplitLrAdam: columns past `active` are left alone; with zero gradients and moments that is the dense step, bit for bit") {
  // Rows of 6 (lead 1 at lr, 5 at lr / 10), as SH rows with bands not yet active: columns 3-5 get a
  // zero gradient for the first steps, then become active.
  for (const double tail : {0.1, 1.0}) {
    for (const bool lazy : {false, true}) {
      INFO("tail_scale " << tail << (lazy ? ", lazy" : ""));
      SplitLrAdam::Hyper h;
      h.row_width = 6, h.lead = 1, h.tail_scale = tail;
      auto run = [&](std::size_t active_first) {
        std::vector<float> p = noise(24, 7), g(24);
        Optimizer<float, SplitLrAdam> opt;
        opt.add_group({"sh", LrSchedule::constant(0.05), h, 6, lazy}, p, g);
        for (int k = 0; k < 5; ++k) {
          const auto gk = noise(24, 20 + unsigned(k));
          std::copy(gk.begin(), gk.end(), g.begin());
          if (k < 3)
            for (std::size_t i = 0; i < 24; ++i)
              if (i % 6 >= 3) g[i] = 0;
          opt.group("sh").options().hyper.active = k < 3 ? active_first : 0;
          opt.step(k);
        }
        std::vector<float> m0(opt.group("sh").moment(0).begin(), opt.group("sh").moment(0).end());
        std::vector<float> m1(opt.group("sh").moment(1).begin(), opt.group("sh").moment(1).end());
        return std::array<std::vector<float>, 3>{p, m0, m1};
      };
      const auto dense = run(0), skipping = run(3);
      for (int b = 0; b < 3; ++b)
        for (std::size_t i = 0; i < 24; ++i) {
          INFO(b << " " << i);
          CHECK(std::memcmp(&skipping[std::size_t(b)][i], &dense[std::size_t(b)][i], sizeof(float)) == 0);
        }
    }
  }
  // A skipped column is not read or written, whatever its gradient.
  SplitLrAdam::Hyper h;
  h.row_width = 4, h.lead = 1, h.tail_scale = 0.1, h.active = 2;
  std::vector<float> p = noise(8, 3), g = noise(8, 4);
  const std::vector<float> p0 = p;
  Optimizer<float, SplitLrAdam> opt;
  opt.add_group({"sh", LrSchedule::constant(0.05), h, 4}, p, g);
  opt.step(0);
  for (std::size_t i = 0; i < 8; ++i) {
    INFO(i);
    CHECK((i % 4 >= 2) == (p[i] == p0[i]));
    CHECK((i % 4 >= 2) == (opt.group("sh").moment(0)[i] == 0.0f));
  }
}

TEST_CASE("Adam: the AVX2 update gives the portable bits (float, ragged lengths, SplitLrAdam's columns)") {
  Adam::Hyper bad;
  bad.simd = Isa::avx512;  // no such copy
  CHECK_THROWS_WITH_AS((Adam::Step<float>(bad, 0.1, 1)), doctest::Contains("simd"), option_error);
  if (!isa_supported(Isa::avx2)) {
    Adam::Hyper avx2;
    avx2.simd = Isa::avx2;
    CHECK_THROWS_AS((Adam::Step<float>(avx2, 0.1, 1)), option_error);
    test::skip("this CPU has no AVX2: only the portable update runs");
    return;
  }
  std::mt19937_64 rng(5);
  std::normal_distribution<float> nd(0.f, 1.f);
  for (std::size_t n : {std::size_t(1), std::size_t(7), std::size_t(8), std::size_t(1003), std::size_t(48 * 37)}) {
    INFO("n " << n);
    std::vector<float> p0(n), g(n);
    for (auto& v : p0) v = nd(rng);
    std::array<std::vector<float>, 2> p{p0, p0}, m1{std::vector<float>(n, 0.f), std::vector<float>(n, 0.f)}, m2 = m1;
    for (int k = 1; k <= 5; ++k) {
      for (auto& v : g) v = k == 3 ? 0.f : 1e-3f * nd(rng);  // one step with zero gradients
      for (int path = 0; path < 2; ++path) {
        Adam::Hyper h;
        h.simd = path == 0 ? Isa::portable : Isa::avx2;
        Adam::Step<float>(h, 0.01, std::uint64_t(k)).apply(p[path].data(), g.data(), m1[path].data(), m2[path].data(), n);
      }
    }
    CHECK(std::memcmp(p[0].data(), p[1].data(), n * sizeof(float)) == 0);
    CHECK(std::memcmp(m1[0].data(), m1[1].data(), n * sizeof(float)) == 0);
    CHECK(std::memcmp(m2[0].data(), m2[1].data(), n * sizeof(float)) == 0);
    CHECK(p[0] != p0);  // the steps moved the parameters
  }
  // SplitLrAdam's runs (lead at lr, tail at lr * 0.05, `active` columns) on both paths.
  const std::size_t rows = 301, w = 48;
  std::vector<float> g(rows * w);
  for (auto& v : g) v = 1e-3f * nd(rng);
  std::array<std::vector<float>, 2> p, m1, m2;
  for (int path = 0; path < 2; ++path) {
    p[path].assign(rows * w, 0.5f);
    m1[path].assign(rows * w, 0.f);
    m2[path].assign(rows * w, 0.f);
    SplitLrAdam::Hyper h;
    h.row_width = w, h.lead = 3, h.tail_scale = 0.05, h.active = 12;
    h.simd = path == 0 ? Isa::portable : Isa::avx2;
    for (std::uint64_t k = 1; k <= 3; ++k)
      SplitLrAdam::update<float>(h, 0.01, k, p[path].data(), g.data(), {m1[path].data(), m2[path].data()}, rows * w - 5, 5);
  }
  CHECK(p[0] == p[1]);
  CHECK(m1[0] == m1[1]);
  CHECK(m2[0] == m2[1]);
}
