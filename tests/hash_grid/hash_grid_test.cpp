#include "video3dgs/hash_grid/hash_grid.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <random>
#include <utility>
#include <vector>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "video3dgs/testing/grad_check.hpp"

using namespace video3dgs;

TEST_CASE("hash grid: golden level resolutions for base 16, scale 1.38") {
  HashGrid<float, 4, 16, 2, 19> grid;
  const std::array<std::uint32_t, 16> expected = {16, 23, 31, 43, 59, 81, 111, 153, 211, 291, 401, 554, 764, 1054, 1454, 2006};
  for (int l = 0; l < 16; ++l) CHECK(grid.resolution(l) == expected[std::size_t(l)]);
  // (R+1)^4 vertices: 17^4 = 83521 and 24^4 = 331776 fit 2^19 = 524288, 32^4 does not.
  CHECK(grid.dense(0));
  CHECK(grid.dense(1));
  for (int l = 2; l < 16; ++l) CHECK_FALSE(grid.dense(l));
  CHECK(grid.level_size(0) == 83521);
  CHECK(grid.level_size(1) == 331776);
  CHECK(grid.level_size(2) == (std::size_t(1) << 19));
  CHECK(grid.level_offset(2) == 83521 + 331776);
  CHECK(grid.param_count() == grid.entries() * 2);
  // Entries initialised in U(-1e-4, 1e-4), not all equal.
  const auto p = grid.params();
  float lo = 1, hi = -1;
  for (float v : p) { lo = std::min(lo, v); hi = std::max(hi, v); }
  CHECK(lo >= -1e-4f);
  CHECK(hi <= 1e-4f);
  CHECK(hi - lo > 1.9e-4f);
}

TEST_CASE("hash grid: spatial hash of hand-computed corners") {
  using G4 = HashGrid<double, 4, 16, 2, 19>;
  // 1*1 ^ 2*2654435761 ^ 3*805459861 ^ 4*3674653429 (mod 2^32), computed by hand (Python).
  CHECK(G4::hash({1, 2, 3, 4}) == 3228761608u);
  CHECK(G4::hash({0, 0, 0, 1}) == 3674653429u);
  CHECK(G4::hash({17, 5, 100, 2005}) == 3154886281u);
  CHECK(G4::hash({2006, 2006, 2006, 2006}) == 2987554144u);
  G4 grid;
  CHECK(grid.vertex_index(2, {1, 2, 3, 4}) == 196104u);          // 3228761608 mod 2^19
  CHECK(grid.vertex_index(15, {17, 5, 100, 2005}) == 245385u);
  CHECK(grid.vertex_index(0, {1, 2, 3, 4}) == 1 + 2 * 17 + 3 * 17 * 17 + 4 * 17 * 17 * 17);  // dense
  using G2 = HashGrid<double, 2, 4, 2, 14>;
  CHECK(G2::hash({7, 9}) == 2415085374u);
}

TEST_CASE("hash grid: forward reproduces hand-computed interpolation") {
  // One dense 2D level, R = 4: the value at a point is the bilinear blend of 4 table entries.
  HashGridOptions o;
  o.base_resolution = 4;
  HashGrid<double, 2, 1, 1, 10> grid(o);
  auto p = grid.params();
  for (std::size_t i = 0; i < p.size(); ++i) p[i] = double(i) * 0.25 + 0.1 * double(i % 3);
  const double x[2] = {0.30, 0.60};  // p = (1.2, 2.4): cell (1, 2), f = (0.2, 0.4)
  double y = 0;
  grid.forward(x, 1, &y);
  auto e = [&](int cx, int cy) { return p[std::size_t(cx + 5 * cy)]; };
  const double expect = 0.8 * 0.6 * e(1, 2) + 0.2 * 0.6 * e(2, 2) + 0.8 * 0.4 * e(1, 3) + 0.2 * 0.4 * e(2, 3);
  CHECK(y == doctest::Approx(expect).epsilon(1e-14));
  // The domain edges map to the corner vertices exactly.
  const double corner[2] = {1.0, 1.0};
  grid.forward(corner, 1, &y);
  CHECK(y == doctest::Approx(e(4, 4)).epsilon(1e-14));
  const double origin[2] = {0.0, 0.0};
  grid.forward(origin, 1, &y);
  CHECK(y == doctest::Approx(e(0, 0)).epsilon(1e-14));
}

namespace {

/// A small grid of the given dimension with dense and hashed levels, in double, for gradient checks.
template <int D>
struct SmallGrid {
  using Grid = HashGrid<double, D, 4, 2, (D == 2 ? 8 : 10)>;
  static HashGridOptions options(GridInterpolation interp) {
    HashGridOptions o;
    o.base_resolution = 3;
    o.per_level_scale = 2.1;
    o.interpolation = interp;
    o.init_range = 0.5;  // large values so the input gradient is well above rounding
    o.seed = 99;
    return o;
  }
};

/// x ~ U(0, 1) and g ~ U(-0.5, 0.5) from test::seeded_rng(seed) (inputs and output gradients).
void random_points(std::uint64_t seed, std::vector<float>& x, std::vector<float>& g) {
  auto rng = test::seeded_rng(seed);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  for (auto& v : x) v = u(rng);
  for (auto& v : g) v = u(rng) - 0.5f;
}

/// L = sum_{j,n} c_{j,n} y_{j,n}(x, theta); returns L.
template <class Grid>
double linear_loss(const Grid& g, const std::vector<double>& x, const std::vector<double>& c) {
  const std::size_t n = x.size() / Grid::kDims;
  std::vector<double> y(Grid::kOutputs * n);
  g.forward(x.data(), n, y.data());
  double l = 0;
  for (std::size_t i = 0; i < y.size(); ++i) l += c[i] * y[i];
  return l;
}

/// `log2_table` / `levels`: HashGridOptions' runtime sizes (0 = the template's); `last_axis_cells`:
/// max_cells of the last axis (0 = none).
template <int D>
void check_grid_gradients(GridInterpolation interp, int log2_table = 0, int levels = 0, std::uint32_t last_axis_cells = 0) {
  using Grid = typename SmallGrid<D>::Grid;
  HashGridOptions o = SmallGrid<D>::options(interp);
  o.log2_table_size = log2_table;
  o.levels = levels;
  o.max_cells[D - 1] = last_axis_cells;
  Grid grid(o);
  const std::uint64_t seed = 1234 + D;
  INFO("seed " << seed << " dims " << D << " smooth " << (interp == GridInterpolation::smoothstep) << " log2 table "
                << log2_table << " levels " << levels << " last axis cells " << last_axis_cells);
  auto rng = test::seeded_rng(seed);
  std::uniform_real_distribution<double> u(0.02, 0.98), uc(-1, 1);
  const std::size_t n = 6;
  std::vector<double> x(n * D);
  for (auto& v : x) v = u(rng);
  std::vector<double> c(Grid::kOutputs * n);
  for (auto& v : c) v = uc(rng);

  std::vector<double> gt(grid.param_count(), 0.0), gx(n * D, 0.0);
  grid.backward(x.data(), n, c.data(), gt.data(), gx.data());

  // Table: only entries touched by the points matter; check them plus a few untouched ones.
  std::vector<std::size_t> idx;
  for (std::size_t i = 0; i < gt.size(); ++i)
    if (gt[i] != 0 || i % 997 == 0) idx.push_back(i);
  std::vector<double> sub(idx.size()), an(idx.size());
  auto params = grid.params();
  for (std::size_t k = 0; k < idx.size(); ++k) { sub[k] = params[idx[k]]; an[k] = gt[idx[k]]; }
  auto r = testing::check_gradient("table", sub, an, [&] {
    for (std::size_t k = 0; k < idx.size(); ++k) params[idx[k]] = sub[k];
    return linear_loss(grid, x, c);
  }, {.rtol = 1e-7});
  for (std::size_t k = 0; k < idx.size(); ++k) params[idx[k]] = sub[k];
  INFO(r);
  CHECK(r.ok());
  CHECK(idx.size() > std::size_t(Grid::kCorners));

  auto rx = testing::check_gradient("inputs", x, gx, [&] { return linear_loss(grid, x, c); }, {.rtol = 1e-6});
  INFO(rx);
  CHECK(rx.ok());
}

}  // namespace

TEST_CASE("hash grid: table and input gradients (2D, 3D, 4D; linear and smoothstep)") {
  check_grid_gradients<2>(GridInterpolation::linear);
  check_grid_gradients<3>(GridInterpolation::linear);
  check_grid_gradients<4>(GridInterpolation::linear);
  check_grid_gradients<2>(GridInterpolation::smoothstep);
  check_grid_gradients<3>(GridInterpolation::smoothstep);
  check_grid_gradients<4>(GridInterpolation::smoothstep);
}

TEST_CASE("hash grid: gradients with a runtime table size and fewer levels") {
  check_grid_gradients<3>(GridInterpolation::linear, 5, 3);    // 32-entry tables: many collisions
  check_grid_gradients<4>(GridInterpolation::smoothstep, 7, 2);
  check_grid_gradients<2>(GridInterpolation::linear, 0, 1);
}

TEST_CASE("hash grid: gradients with the last axis capped (max_cells)") {
  check_grid_gradients<4>(GridInterpolation::linear, 0, 0, 2);   // time: 2 cells on every level
  check_grid_gradients<4>(GridInterpolation::smoothstep, 7, 0, 5);
  check_grid_gradients<2>(GridInterpolation::linear, 0, 0, 1);   // one cell: linear along the axis
}

TEST_CASE("hash grid: a capped axis has min(R_l, M) cells, a dense layout with its own stride, and hand-computed values") {
  // 2D, levels R = 4 and 8, the second axis capped at 2 cells: both levels dense, (R + 1) x 3 vertices.
  HashGridOptions o;
  o.base_resolution = 4;
  o.per_level_scale = 2;
  o.max_cells[1] = 2;
  HashGrid<double, 2, 2, 1, 10> grid(o);
  CHECK(grid.resolution(0) == 4);
  CHECK(grid.resolution(1) == 8);
  CHECK(grid.resolution(0, 0) == 4);
  CHECK(grid.resolution(0, 1) == 2);
  CHECK(grid.resolution(1, 1) == 2);
  REQUIRE(grid.dense(1));
  CHECK(grid.level_size(0) == 5 * 3);
  CHECK(grid.level_size(1) == 9 * 3);
  auto p = grid.params();
  for (std::size_t i = 0; i < p.size(); ++i) p[i] = std::sin(double(i) * 0.7) + 0.01 * double(i);
  const double x[2] = {0.30, 0.60};  // level 1: p = (2.4, 1.2): cell (2, 1), f = (0.4, 0.2)
  double y[2];
  grid.forward(x, 1, y);
  auto e = [&](int cx, int cy) { return p[grid.level_offset(1) + std::size_t(cx + 9 * cy)]; };
  CHECK(y[1] == doctest::Approx(0.6 * 0.8 * e(2, 1) + 0.4 * 0.8 * e(3, 1) + 0.6 * 0.2 * e(2, 2) + 0.4 * 0.2 * e(3, 2)).epsilon(1e-14));
  // Points on the capped axis's vertices read one slice: t = 1/2 is vertex 1 whatever the level.
  const double on[2] = {0.30, 0.5};
  grid.forward(on, 1, y);
  CHECK(y[1] == doctest::Approx(0.6 * e(2, 1) + 0.4 * e(3, 1)).epsilon(1e-14));
}

TEST_CASE("hash grid: a cap at or above every level's resolution changes nothing, bit for bit") {
  using Grid = HashGrid<float, 4, 6, 2, 12>;
  HashGridOptions a;
  a.init_range = 0.3;
  HashGridOptions b = a;
  b.max_cells[3] = 10000;
  Grid ga(a), gb(b);
  REQUIRE(ga.entries() == gb.entries());
  std::vector<float> x(4 * 300), g(Grid::kOutputs * 300);
  random_points(17, x, g);
  std::vector<float> ya(g.size()), yb(g.size()), ta(ga.param_count()), tb(gb.param_count()), xa(x.size()), xb(x.size());
  ga.forward(x.data(), 300, ya.data());
  gb.forward(x.data(), 300, yb.data());
  ga.backward(x.data(), 300, g.data(), ta.data(), xa.data());
  gb.backward(x.data(), 300, g.data(), tb.data(), xb.data());
  CHECK(ya == yb);
  CHECK(ta == tb);
  CHECK(xa == xb);
  // A real cap changes the cells along the axis (every level here is hashed) and the outputs.
  b.max_cells[3] = 3;
  Grid gc(b);
  for (int l = 0; l < Grid::kLevels; ++l) CHECK(gc.resolution(l, 3) == 3);
  std::vector<float> yc(g.size());
  gc.forward(x.data(), 300, yc.data());
  CHECK(yc != ya);
}

TEST_CASE("hash grid: a runtime table size and level count match the compile-time grid bit for bit") {
  using Small = HashGrid<float, 4, 16, 2, 12>;
  using Large = HashGrid<float, 4, 16, 2, 16>;
  HashGridOptions o;
  o.log2_table_size = 12;
  const Small a;
  const Large b(o);
  CHECK(b.table_size() == 4096);
  CHECK(b.active_levels() == 16);
  REQUIRE(a.param_count() == b.param_count());
  CHECK(std::equal(a.params().begin(), a.params().end(), b.params().begin()));
  INFO("seed 91");
  const std::size_t n = 700;
  std::vector<float> x(n * 4), g(Small::kOutputs * n);
  random_points(91, x, g);
  std::vector<float> ya(Small::kOutputs * n), yb(Small::kOutputs * n);
  std::vector<float> ta(a.param_count(), 0.f), tb(b.param_count(), 0.f), xa(n * 4, 0.f), xb(n * 4, 0.f);
  a.forward(x.data(), n, ya.data());
  b.forward(x.data(), n, yb.data());
  a.backward(x.data(), n, g.data(), ta.data(), xa.data());
  b.backward(x.data(), n, g.data(), tb.data(), xb.data());
  CHECK(ya == yb);
  CHECK(ta == tb);
  CHECK(xa == xb);

  // 8 of 16 levels: the first 8 levels are those of the full grid (same entries, outputs and table
  // gradient); the last 8 hold no entries, output 0 over whatever the buffer held and add nothing to
  // the input gradient.
  o.levels = 8;
  const Large c(o);
  CHECK(c.active_levels() == 8);
  const std::size_t kept = c.param_count();
  CHECK(kept == b.level_offset(8) * 2);
  CHECK(std::equal(c.params().begin(), c.params().end(), b.params().begin()));
  for (int l = 8; l < 16; ++l) {
    CHECK(c.resolution(l) == 0);
    CHECK(c.level_size(l) == 0);
  }
  std::vector<float> yc(Small::kOutputs * n, 7.f), tc(kept, 0.f), xc(n * 4, 0.f);
  c.forward(x.data(), n, yc.data());
  const std::size_t half = 8 * 2 * n;
  CHECK(std::equal(yc.begin(), yc.begin() + std::ptrdiff_t(half), yb.begin()));
  CHECK(std::all_of(yc.begin() + std::ptrdiff_t(half), yc.end(), [](float v) { return v == 0.f; }));
  c.backward(x.data(), n, g.data(), tc.data(), xc.data());
  CHECK(std::equal(tc.begin(), tc.end(), tb.begin()));
  std::vector<float> g8 = g, t8(b.param_count(), 0.f), x8(n * 4, 0.f);
  std::fill(g8.begin() + std::ptrdiff_t(half), g8.end(), 0.f);
  b.backward(x.data(), n, g8.data(), t8.data(), x8.data());
  CHECK(xc == x8);
}

TEST_CASE("hash grid: input gradient on cell borders and at the domain edges") {
  // Linear interpolation is linear along each axis inside a cell, so one-sided differences are exact:
  // on a border the analytic derivative is the one of the cell the point is assigned to (the upper
  // cell, p = c), at x = 1 the last cell (left derivative), and at x = 0 the first (right derivative).
  using Grid = HashGrid<double, 3, 1, 2, 12>;
  HashGridOptions o;
  o.base_resolution = 4;  // borders at multiples of 1/4: exact in binary
  o.init_range = 0.5;
  for (auto interp : {GridInterpolation::linear, GridInterpolation::smoothstep}) {
    o.interpolation = interp;
    Grid grid(o);
    const std::vector<double> c = {0.7, -1.3};
    // Points: interior borders (x = 2/4, 3/4), the edges 0 and 1, and mixed.
    const std::vector<std::array<double, 3>> pts = {
        {0.5, 0.5, 0.13}, {0.0, 0.37, 0.61}, {1.0, 0.2, 0.9}, {0.75, 1.0, 0.0}, {0.8, 0.8, 0.8}};
    for (const auto& pt : pts) {
      std::vector<double> x(pt.begin(), pt.end());
      std::vector<double> gx(3, 0.0), gt(grid.param_count(), 0.0);
      grid.backward(x.data(), 1, c.data(), gt.data(), gx.data());
      for (int d = 0; d < 3; ++d) {
        const double h = 1e-7;
        const double x0 = x[std::size_t(d)];
        const bool at_top = x0 >= 1.0;
        double numeric;
        if (interp == GridInterpolation::smoothstep && x0 > 0 && x0 < 1) {
          x[std::size_t(d)] = x0 + h;
          const double lp = linear_loss(grid, x, c);
          x[std::size_t(d)] = x0 - h;
          const double lm = linear_loss(grid, x, c);
          numeric = (lp - lm) / (2 * h);
        } else {
          const double l0 = linear_loss(grid, x, c);
          x[std::size_t(d)] = at_top ? x0 - h : x0 + h;
          const double l1 = linear_loss(grid, x, c);
          numeric = at_top ? (l0 - l1) / h : (l1 - l0) / h;
        }
        x[std::size_t(d)] = x0;
        INFO("point (" << pt[0] << ", " << pt[1] << ", " << pt[2] << ") dim " << d << " analytic " << gx[std::size_t(d)]
                       << " numeric " << numeric);
        CHECK(std::isfinite(gx[std::size_t(d)]));
        // atol (smoothstep): on a border or an edge S'(f) = 0 and S(f) ~ 3 f^2 on each side, so the
        // difference carries a truncation error ~ 3 h R^2 |theta| / 2 ~ 2e-6 (h = 1e-7, R = 4) on an
        // exact zero. Linear interpolation is linear in each cell: its differences are exact up to rounding.
        const testing::GradTolerance tol{.rtol = 1e-5, .atol = interp == GridInterpolation::smoothstep ? 1e-5 : 1e-9};
        CHECK(testing::within(gx[std::size_t(d)], numeric, tol));
      }
    }
  }
}

TEST_CASE("hash grid: inputs outside [0, 1] and NaN are clamped, with zero gradient") {
  using Grid = HashGrid<double, 2, 3, 2, 10>;
  HashGridOptions o;
  o.init_range = 0.5;
  Grid grid(o);
  const double x[6] = {-0.5, 0.3, 1.7, 0.3, std::nan(""), 0.3};
  std::vector<double> y(Grid::kOutputs * 3);
  grid.forward(x, 3, y.data());
  for (double v : y) CHECK(std::isfinite(v));
  const double edge[4] = {0.0, 0.3, 1.0, 0.3};
  std::vector<double> ye(Grid::kOutputs * 2);
  grid.forward(edge, 2, ye.data());
  for (int j = 0; j < Grid::kOutputs; ++j) {
    CHECK(y[std::size_t(j) * 3 + 0] == ye[std::size_t(j) * 2 + 0]);  // -0.5 -> 0
    CHECK(y[std::size_t(j) * 3 + 1] == ye[std::size_t(j) * 2 + 1]);  // 1.7 -> 1
    CHECK(y[std::size_t(j) * 3 + 2] == ye[std::size_t(j) * 2 + 0]);  // NaN -> 0
  }
  std::vector<double> g(Grid::kOutputs * 3, 1.0), gt(grid.param_count(), 0.0), gx(6, 0.0);
  grid.backward(x, 3, g.data(), gt.data(), gx.data());
  CHECK(gx[0] == 0.0);
  CHECK(gx[2] == 0.0);
  CHECK(gx[4] == 0.0);
  CHECK(gx[1] != 0.0);
  for (double v : gt) CHECK(std::isfinite(v));
}

TEST_CASE("hash grid: forward and backward are bit-identical for 1 and 2 threads") {
  using Grid = HashGrid<float, 4, 16, 2, 14>;
  Grid grid;
  INFO("seed 77");
  const std::size_t n = 5000;
  std::vector<float> x(n * 4), g(Grid::kOutputs * n);
  random_points(77, x, g);
  // Many points share table entries at the coarse levels: the scatter-add order matters.
  std::vector<float> y1(Grid::kOutputs * n);
  std::vector<float> y2(Grid::kOutputs * n);
  std::vector<float> t1, t2;
  t1.assign(grid.param_count(), 0.f);
  t2.assign(grid.param_count(), 0.f);
  std::vector<float> x1(n * 4, 0.f);
  std::vector<float> x2(n * 4, 0.f);
  grid.forward(x.data(), n, y1.data(), nullptr);
  grid.backward(x.data(), n, g.data(), t1.data(), x1.data(), nullptr);
  ThreadPool pool(2);
  grid.forward(x.data(), n, y2.data(), &pool);
  grid.backward(x.data(), n, g.data(), t2.data(), x2.data(), &pool);
  CHECK(std::memcmp(y1.data(), y2.data(), y1.size() * sizeof(float)) == 0);
  CHECK(std::memcmp(t1.data(), t2.data(), t1.size() * sizeof(float)) == 0);
  CHECK(std::memcmp(x1.data(), x2.data(), x1.size() * sizeof(float)) == 0);
}

TEST_CASE("hash grid: same seed gives the same table, another seed a different one") {
  HashGridOptions o;
  HashGrid<float, 3, 2, 2, 10> a(o), b(o);
  CHECK(std::equal(a.params().begin(), a.params().end(), b.params().begin()));
  o.seed += 1;
  HashGrid<float, 3, 2, 2, 10> c(o);
  CHECK_FALSE(std::equal(a.params().begin(), a.params().end(), c.params().begin()));
}

TEST_CASE("hash grid: bad options throw option.hash_grid") {
  for (const auto& bad : {std::pair{1, 0}, std::pair{31, 0}, std::pair{-3, 0}, std::pair{0, -1}, std::pair{0, 3}}) {
    const int log2 = bad.first, levels = bad.second;  // not a binding: INFO captures them
    HashGridOptions o;
    o.log2_table_size = log2;
    o.levels = levels;
    INFO("log2 " << log2 << " levels " << levels);
    try {
      HashGrid<float, 2, 2, 2, 8> g(o);
      FAIL("expected a throw");
    } catch (const error& e) {
      CHECK(e.id() == "option.hash_grid");
    }
  }
  HashGridOptions o;
  o.max_cells[2] = 4;  // a 2D grid has no axis 2
  try {
    HashGrid<float, 2, 2, 2, 8> g(o);
    FAIL("expected a throw");
  } catch (const error& e) {
    CHECK(e.id() == "option.hash_grid");
    CHECK(std::string(e.what()).find("max_cells") != std::string::npos);
  }
  o = {};
  o.per_level_scale = 0.5;
  CHECK_THROWS_AS((HashGrid<float, 2, 2, 2, 8>(o)), option_error);
  o = {};
  o.base_resolution = std::nan("");
  try {
    HashGrid<float, 2, 2, 2, 8> g(o);
    FAIL("expected a throw");
  } catch (const error& e) {
    CHECK(e.id() == "option.hash_grid");
  }
}

TEST_CASE_TEMPLATE("hash grid: batched forward and backward match a naive per-corner reference", Scalar, float, double) {
  // 3D, levels dense and hashed, 200 points (several batches and a partial one), smoothstep.
  using Grid = HashGrid<Scalar, 3, 5, 2, 11>;
  HashGridOptions o;
  o.base_resolution = 4;
  o.per_level_scale = 1.9;
  o.interpolation = GridInterpolation::smoothstep;
  o.init_range = 0.5;
  for (const std::uint32_t cap : {0u, 6u}) {  // axis 1 capped at 6 cells on levels 2..4
    CAPTURE(cap);
    o.max_cells[1] = cap;
    Grid grid(o);
    auto rng = test::seeded_rng(5);
    INFO("seed 5");
    std::uniform_real_distribution<double> u(-0.05, 1.05);  // some points outside [0, 1]
    const std::size_t n = 200;
    std::vector<Scalar> x(n * 3), g(Grid::kOutputs * n);
    for (auto& v : x) v = Scalar(u(rng));
    for (auto& v : g) v = Scalar(u(rng) - 0.5);
    std::vector<Scalar> y(Grid::kOutputs * n);
    grid.forward(x.data(), n, y.data());
    std::vector<Scalar> gt(grid.param_count(), Scalar(0));
    grid.backward(x.data(), n, g.data(), gt.data());
    std::vector<double> ref_gt(grid.param_count(), 0.0);
    const auto p = grid.params();
    double worst = 0, worst_g = 0;
    for (std::size_t i = 0; i < n; ++i)
      for (int l = 0; l < Grid::kLevels; ++l) {
        std::array<std::uint32_t, 3> c0{};
        std::array<double, 3> s{};
        for (int d = 0; d < 3; ++d) {
          const double r = cap != 0 && d == 1 ? std::min<double>(grid.resolution(l), cap) : grid.resolution(l);
          const double xd = std::clamp(double(x[i * 3 + std::size_t(d)]), 0.0, 1.0);
          double cell = std::floor(xd * r);
          if (cell > r - 1) cell = r - 1;
          const double f = xd * r - cell;
          c0[std::size_t(d)] = std::uint32_t(cell);
          s[std::size_t(d)] = f * f * (3 - 2 * f);
        }
        double acc[2] = {0, 0};
        for (int k = 0; k < 8; ++k) {
          std::array<std::uint32_t, 3> c = c0;
          double w = 1;
          for (int d = 0; d < 3; ++d) {
            const bool up = (k >> d) & 1;
            c[std::size_t(d)] += up ? 1u : 0u;
            w *= up ? s[std::size_t(d)] : 1 - s[std::size_t(d)];
          }
          const std::size_t e = grid.level_offset(l) + grid.vertex_index(l, c);
          for (int q = 0; q < 2; ++q) {
            acc[q] += w * double(p[e * 2 + std::size_t(q)]);
            ref_gt[e * 2 + std::size_t(q)] += w * double(g[(std::size_t(l) * 2 + std::size_t(q)) * n + i]);
          }
        }
        for (int q = 0; q < 2; ++q)
          worst = std::max(worst, std::abs(acc[q] - double(y[(std::size_t(l) * 2 + std::size_t(q)) * n + i])));
      }
    for (std::size_t e = 0; e < gt.size(); ++e) worst_g = std::max(worst_g, std::abs(ref_gt[e] - double(gt[e])));
    const double tol = std::is_same_v<Scalar, float> ? 1e-5 : 1e-13;
    CHECK(worst < tol);
    CHECK(worst_g < tol * 100);
  }
}

TEST_CASE_TEMPLATE("hash grid: corners of zero weight are left out without changing a bit", Scalar, float, double) {
  // A batch whose points all sit on a vertex of an axis (or at x = 1) builds only the corners of nonzero
  // weight. The
  // same points in batches that also hold one point off the vertex (so every corner is built; its
  // upstream gradient is 0, so it adds nothing) must give the same outputs and table gradient, bit for
  // bit. The time axis of a clip (capped at 8 cells), a middle axis (y on a vertex of some levels),
  // both (4 corners) and every axis (1 corner).
  using Grid = HashGrid<Scalar, 4, 6, 2, 12>;
  constexpr std::size_t kB = 64;  // the grid's batch: the test relies on it to place the extra point
  for (const auto interp : {GridInterpolation::linear, GridInterpolation::smoothstep})
    for (const int axes : {0b1000, 0b0010, 0b1010, 0b1111})  // time; y; time and y (4 corners); all (1 corner)
      for (const double on : {0.0, 0.25, 0.5, 1.0}) {
        CAPTURE(int(interp));
        CAPTURE(axes);
        CAPTURE(on);
        HashGridOptions o;
        o.base_resolution = 4;
        o.per_level_scale = 1.9;  // 4, 8, 15, 28, 53, 100 cells: dense and hashed levels
        o.interpolation = interp;
        o.init_range = 0.5;
        o.max_cells[3] = 8;
        const Grid grid(o);
        auto rng = test::seeded_rng(13);
        INFO("seed 13");
        std::uniform_real_distribution<double> u(0.0, 1.0);
        const std::size_t n = 150;  // three batches, the last partial
        std::vector<Scalar> x(n * 4), g(Grid::kOutputs * n);
        for (std::size_t i = 0; i < n; ++i)
          for (int d = 0; d < 4; ++d) x[i * 4 + std::size_t(d)] = (axes >> d) & 1 ? Scalar(on) : Scalar(u(rng));
        for (auto& v : g) v = Scalar(u(rng) - 0.5);
        std::vector<Scalar> y(Grid::kOutputs * n), gt(grid.param_count(), Scalar(0));
        grid.forward(x.data(), n, y.data());
        grid.backward(x.data(), n, g.data(), gt.data());

        // The same points, kB - 1 per batch after one point off the vertex of every level (0.3737 R_l
        // is no integer for R_l = 4, 8, 15, 28, 53, 100; gradient 0).
        const std::size_t batches = (n + kB - 2) / (kB - 1), m = n + batches;
        std::vector<Scalar> x2(m * 4), g2(Grid::kOutputs * m, Scalar(0));
        std::vector<std::size_t> where(n);
        for (std::size_t j = 0, i = 0; j < m; ++j) {
          if (j % kB == 0) {
            for (int d = 0; d < 4; ++d) x2[j * 4 + std::size_t(d)] = (axes >> d) & 1 ? Scalar(0.3737) : Scalar(0.5);
            continue;
          }
          for (int d = 0; d < 4; ++d) x2[j * 4 + std::size_t(d)] = x[i * 4 + std::size_t(d)];
          for (int k = 0; k < Grid::kOutputs; ++k) g2[std::size_t(k) * m + j] = g[std::size_t(k) * n + i];
          where[i++] = j;
        }
        std::vector<Scalar> y2(Grid::kOutputs * m), gt2(grid.param_count(), Scalar(0));
        grid.forward(x2.data(), m, y2.data());
        grid.backward(x2.data(), m, g2.data(), gt2.data());
        std::size_t differ = 0;
        for (std::size_t i = 0; i < n; ++i)
          for (int k = 0; k < Grid::kOutputs; ++k)
            differ += std::memcmp(&y[std::size_t(k) * n + i], &y2[std::size_t(k) * m + where[i]], sizeof(Scalar)) != 0;
        CHECK(differ == 0);
        CHECK(std::memcmp(gt.data(), gt2.data(), gt.size() * sizeof(Scalar)) == 0);
      }
}
