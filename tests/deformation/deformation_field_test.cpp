// Eigen's own heap check (EIGEN_RUNTIME_NO_MALLOC) must stay active in Release: route eigen_assert
// to an exception in this executable (its only translation unit that includes Eigen).
#include <stdexcept>
#define EIGEN_RUNTIME_NO_MALLOC
#define eigen_assert(x) \
  do {                  \
    if (!(x)) throw std::runtime_error("Eigen assertion failed: " #x); \
  } while (false)

#include "video3dgs/deformation/deformation_field.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <span>
#include <string>
#include <random>
#include <vector>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "video3dgs/autodiff/ops.hpp"
#include "video3dgs/testing/grad_check.hpp"

// Count operator new in this program (Eigen's mallocs are checked by EIGEN_RUNTIME_NO_MALLOC).
#include "../count_allocations.hpp"

using namespace video3dgs;

namespace {

using SmallGrid = HashGrid<double, 4, 4, 2, 10>;

DeformationOptions test_options(DeformationMode mode, bool grid_inputs) {
  DeformationOptions o;
  o.grid.base_resolution = 3;
  o.grid.per_level_scale = 2.0;
  o.grid.init_range = 0.3;  // large enough that every path carries a visible gradient
  o.head_init = HeadInitOptions{HeadInit::uniform_fan_in, 1e-3, 5};
  o.mode = mode;
  o.grid_input_gradient = grid_inputs;
  // The extreme points sit at margin / (1 + 2 margin) in normalised coordinates: with 0.1 that is
  // 1/12, a cell border of the R = 12 and 24 levels, where linear interpolation has a kink and central
  // differences are not the (one-sided) derivative. 0.137 keeps every point off the borders.
  o.box_margin = 0.137;
  return o;
}

struct Cloud {
  std::vector<double> mean, log_scale, rotation;
  std::size_t n = 0;
};

Cloud random_cloud(std::size_t n, std::uint64_t seed) {
  auto rng = test::seeded_rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  Cloud c;
  c.n = n;
  c.mean.resize(n * 3);
  c.log_scale.resize(n * 3);
  c.rotation.resize(n * 4);
  for (auto& v : c.mean) v = 2 * u(rng);
  for (auto& v : c.log_scale) v = -2 + 0.5 * u(rng);
  for (auto& v : c.rotation) v = u(rng);
  c.rotation[0] += 2;  // away from zero norm
  return c;
}

template <class Field>
struct Harness {
  Field& field;
  Cloud& cloud;
  double time;
  std::vector<double> c_mean, c_scale, c_rot;  // loss weights

  double loss() {
    typename Field::Context ctx;
    std::vector<double> m(cloud.n * 3), s(cloud.n * 3), q(cloud.n * 4);
    field.forward({cloud.mean.data(), cloud.log_scale.data(), cloud.rotation.data(), cloud.n, time},
                  {m.data(), s.data(), q.data()}, ctx);
    double l = 0;
    for (std::size_t i = 0; i < m.size(); ++i) l += c_mean[i] * m[i] + c_scale[i] * s[i];
    for (std::size_t i = 0; i < q.size(); ++i) l += c_rot[i] * q[i];
    return l;
  }
};

template <int HiddenLayers>
void check_field(DeformationMode mode, bool grid_inputs) {
  using Field = DeformationField<double, SmallGrid, 6, HiddenLayers, Softplus>;
  INFO("mode " << (mode == DeformationMode::stable ? "stable" : "reference") << " grid_inputs " << grid_inputs
               << " hidden layers " << HiddenLayers);
  Cloud cloud = random_cloud(6, 21);
  Field field(cloud.mean, test_options(mode, grid_inputs));
  auto rng = test::seeded_rng(12);
  std::uniform_real_distribution<double> u(-1, 1);
  Harness<Field> h{field, cloud, 0.37, {}, {}, {}};
  h.c_mean.resize(cloud.n * 3);
  h.c_scale.resize(cloud.n * 3);
  h.c_rot.resize(cloud.n * 4);
  for (auto& v : h.c_mean) v = u(rng);
  for (auto& v : h.c_scale) v = u(rng);
  for (auto& v : h.c_rot) v = u(rng);

  typename Field::Context ctx;
  std::vector<double> m(cloud.n * 3), s(cloud.n * 3), q(cloud.n * 4);
  field.forward({cloud.mean.data(), cloud.log_scale.data(), cloud.rotation.data(), cloud.n, h.time}, {m.data(), s.data(), q.data()}, ctx);
  std::vector<double> gm(cloud.n * 3, 0.0), gs(cloud.n * 3, 0.0), gq(cloud.n * 4, 0.0);
  field.zero_grad();
  field.backward(ctx, h.c_mean.data(), h.c_scale.data(), h.c_rot.data(), {gm.data(), gs.data(), gq.data()});
  {
    // The field held constant: the canonical gradients alone, the same bits, the field's own untouched.
    std::vector<double> cm(cloud.n * 3, 0.0), cs(cloud.n * 3, 0.0), cq(cloud.n * 4, 0.0), before, after;
    for (const auto& seg : field.segments()) before.insert(before.end(), seg.grad.begin(), seg.grad.end());
    if (grid_inputs) {
      CHECK_THROWS_WITH_AS(field.backward_canonical(ctx, h.c_mean.data(), h.c_scale.data(), h.c_rot.data(), {cm.data(), cs.data(), cq.data()}),
                           doctest::Contains("grid_input_gradient"), option_error);
      // Without the means' gradient nothing runs through the grid.
      field.backward_canonical(ctx, h.c_mean.data(), h.c_scale.data(), h.c_rot.data(), {nullptr, cs.data(), cq.data()});
    } else {
      field.backward_canonical(ctx, h.c_mean.data(), h.c_scale.data(), h.c_rot.data(), {cm.data(), cs.data(), cq.data()});
      CHECK(cm == gm);
    }
    CHECK(cs == gs);
    CHECK(cq == gq);
    for (const auto& seg : field.segments()) after.insert(after.end(), seg.grad.begin(), seg.grad.end());
    CHECK(after == before);
  }

  auto loss = [&] { return h.loss(); };
  // atol: L sums 60 weighted outputs through the grid and heads; the central difference carries a
  // rounding + truncation noise of a few 1e-9 on every entry (measured up to 5e-9), above the default
  // 1e-9 on the many table entries whose gradient is ~1e-4. A 100% error on a 1e-5 entry still fails.
  const testing::GradTolerance tol{.rtol = 1e-6, .atol = 1e-8};
  auto r1 = testing::check_gradient("log_scale", cloud.log_scale, gs, loss, tol);
  INFO(r1);
  CHECK(r1.ok());
  auto r2 = testing::check_gradient("rotation", cloud.rotation, gq, loss, tol);
  INFO(r2);
  CHECK(r2.ok());
  if (grid_inputs && mode == DeformationMode::stable) {
    // With the grid input gradient the means' gradient is complete (the box is fixed).
    auto r3 = testing::check_gradient("mean", cloud.mean, gm, loss, tol);
    INFO(r3);
    CHECK(r3.ok());
  } else if (!grid_inputs) {
    for (std::size_t i = 0; i < gm.size(); ++i) CHECK(gm[i] == h.c_mean[i]);  // only the direct path
  }
  auto segs = field.segments();
  for (std::size_t k = 0; k < segs.size(); ++k) {
    // The grid table: check the touched entries (and a sample of the rest); heads: every parameter.
    std::vector<std::size_t> idx;
    for (std::size_t i = 0; i < segs[k].value.size(); ++i)
      if (k > 0 || segs[k].grad[i] != 0 || i % 1511 == 0) idx.push_back(i);
    std::vector<double> sub(idx.size()), an(idx.size());
    for (std::size_t i = 0; i < idx.size(); ++i) { sub[i] = segs[k].value[idx[i]]; an[i] = segs[k].grad[idx[i]]; }
    auto r = testing::check_gradient("segment " + std::to_string(k), sub, an, [&] {
      for (std::size_t i = 0; i < idx.size(); ++i) segs[k].value[idx[i]] = sub[i];
      return loss();
    }, tol);
    for (std::size_t i = 0; i < idx.size(); ++i) segs[k].value[idx[i]] = sub[i];
    INFO(r);
    CHECK(r.ok());
    CHECK(idx.size() > 0);
  }
}

}  // namespace

TEST_CASE("deformation field: end-to-end finite differences (stable and reference, linear and MLP heads)") {
  check_field<0>(DeformationMode::stable, true);
  check_field<0>(DeformationMode::stable, false);
  check_field<0>(DeformationMode::reference, false);
  check_field<1>(DeformationMode::stable, true);
  check_field<1>(DeformationMode::reference, true);
}

TEST_CASE_TEMPLATE("deformation field: zero heads are the identity deformation", Scalar, float, double) {
  using Field = DeformationField<Scalar, HashGrid<Scalar, 4, 4, 2, 10>>;
  std::vector<Scalar> mean = {0, 0, 0, 1, 2, 3}, ls = {-1, -2, -3, 0, 0, 0}, rot = {2, 0, 0, 0, 0.5, 0.5, 0.5, 0.5};
  DeformationOptions o;
  o.head_init.init = HeadInit::zero;
  Field field(mean, o);
  typename Field::Context ctx;
  std::vector<Scalar> m(6), s(6), q(8);
  field.forward({mean.data(), ls.data(), rot.data(), 2, Scalar(0.5)}, {m.data(), s.data(), q.data()}, ctx);
  for (int i = 0; i < 6; ++i) CHECK(m[std::size_t(i)] == mean[std::size_t(i)]);
  for (int i = 0; i < 6; ++i) CHECK(s[std::size_t(i)] == ls[std::size_t(i)]);
  CHECK(q[0] == Scalar(1));
  for (int i = 4; i < 8; ++i) CHECK(q[std::size_t(i)] == doctest::Approx(0.5));
}

TEST_CASE("deformation field: the box is fixed at construction (stable) and follows the points (reference)") {
  using Field = DeformationField<double, SmallGrid>;
  Cloud cloud = random_cloud(20, 3);
  DeformationOptions o;
  Field stable(cloud.mean, o);
  o.mode = DeformationMode::reference;
  Field ref(cloud.mean, o);
  auto run = [&](Field& f, const std::vector<double>& means) {
    typename Field::Context ctx;
    std::vector<double> m(cloud.n * 3), s(cloud.n * 3), q(cloud.n * 4);
    f.forward({means.data(), cloud.log_scale.data(), cloud.rotation.data(), cloud.n, 0.5}, {m.data(), s.data(), q.data()}, ctx);
    return m;
  };
  // Move one point far away: in stable mode the others deform exactly as before.
  std::vector<double> moved = cloud.mean;
  moved[0] += 100;
  const auto a = run(stable, cloud.mean), b = run(stable, moved);
  for (std::size_t i = 3; i < a.size(); ++i) CHECK(a[i] - cloud.mean[i] == doctest::Approx(b[i] - moved[i]).epsilon(1e-12));
  const auto c = run(ref, cloud.mean), d = run(ref, moved);
  double diff = 0;
  for (std::size_t i = 3; i < c.size(); ++i) diff = std::max(diff, std::abs((c[i] - cloud.mean[i]) - (d[i] - moved[i])));
  CHECK(diff > 0);  // the reference re-normalises, so every point's offset changes
  // The stable box holds every canonical mean (and a moved point does not move it).
  const auto lo = stable.box_lo(), ext = stable.box_extent();
  for (int d2 = 0; d2 < 3; ++d2) {
    CHECK(ext[std::size_t(d2)] > 0);
    for (std::size_t i = 0; i < cloud.n; ++i) {
      const double v = cloud.mean[3 * i + std::size_t(d2)];
      CHECK(lo[std::size_t(d2)] <= v);
      CHECK(v <= lo[std::size_t(d2)] + ext[std::size_t(d2)]);
    }
  }
}

TEST_CASE("deformation field: extremes stay finite, stable scales stay positive") {
  using Field = DeformationField<double, SmallGrid>;
  Cloud cloud = random_cloud(4, 5);
  for (auto mode : {DeformationMode::stable, DeformationMode::reference}) {
    DeformationOptions o;
    o.mode = mode;
    Field field(cloud.mean, o);
    // A large negative scale head bias drives exp(s) + dscale below zero in the reference.
    auto& b = field.head_scale().first();
    b.bias().setConstant(-10.0);
    // A rotation head bias that cancels the quaternion: v = u + drot = 0 for the identity.
    field.head_rotation().first().bias() << -1, 0, 0, 0;
    cloud.rotation = {1, 0, 0, 0, 0, 0, 0, 1e-30, 1e30, 0, 0, 0, 0, 1, 0, 0};
    typename Field::Context ctx;
    std::vector<double> m(12), s(12), q(16);
    field.forward({cloud.mean.data(), cloud.log_scale.data(), cloud.rotation.data(), 4, 2.0 /* clamped */},
                  {m.data(), s.data(), q.data()}, ctx);
    for (double v : m) CHECK(std::isfinite(v));
    for (double v : s) CHECK(std::isfinite(v));
    for (double v : q) CHECK(std::isfinite(v));
    std::vector<double> g(16, 1.0), gm(12, 0.0), gs(12, 0.0), gq(16, 0.0);
    field.backward(ctx, g.data(), g.data(), g.data(), {gm.data(), gs.data(), gq.data()});
    for (double v : gs) CHECK(std::isfinite(v));
    for (double v : gq) CHECK(std::isfinite(v));
    for (const auto& seg : field.segments())
      for (double v : seg.grad) CHECK(std::isfinite(v));
  }
  std::vector<double> bad = {0, 0, std::nan("")};
  CHECK_THROWS_AS((Field(bad)), numeric_error);
}

TEST_CASE("deformation field as one tape node: deformation -> toy loss, checked end to end") {
  using Field = DeformationField<double, SmallGrid, 6, 0>;
  using namespace video3dgs::autodiff;
  Cloud cloud = random_cloud(6, 21);
  Field field(cloud.mean, test_options(DeformationMode::stable, true));
  std::vector<double> target(cloud.n * 10);
  for (std::size_t i = 0; i < target.size(); ++i) target[i] = 0.1 * std::sin(double(i));
  const double time = 0.8;

  // Forward through the tape: the field is ONE custom node producing [mean' | log-scale' | q'] (N x 10).
  auto run = [&](std::vector<double>* gmean, std::vector<double>* gscale, std::vector<double>* grot) {
    Tape<double> t;
    typename Field::Context ctx;
    const std::size_t n = cloud.n;
    const bool rg = gmean != nullptr;
    const Var out = t.custom(
        n, 10, rg,
        [&](double* o) {
          std::vector<double> m(n * 3), s(n * 3), q(n * 4);
          field.forward({cloud.mean.data(), cloud.log_scale.data(), cloud.rotation.data(), n, time}, {m.data(), s.data(), q.data()}, ctx);
          for (std::size_t i = 0; i < n; ++i) {
            for (int d = 0; d < 3; ++d) o[i * 10 + std::size_t(d)] = m[i * 3 + std::size_t(d)];
            for (int d = 0; d < 3; ++d) o[i * 10 + 3 + std::size_t(d)] = s[i * 3 + std::size_t(d)];
            for (int d = 0; d < 4; ++d) o[i * 10 + 6 + std::size_t(d)] = q[i * 4 + std::size_t(d)];
          }
        },
        [&](const double*, const double* dout) {
          std::vector<double> gm(n * 3), gs(n * 3), gq(n * 4);
          for (std::size_t i = 0; i < n; ++i) {
            for (int d = 0; d < 3; ++d) gm[i * 3 + std::size_t(d)] = dout[i * 10 + std::size_t(d)];
            for (int d = 0; d < 3; ++d) gs[i * 3 + std::size_t(d)] = dout[i * 10 + 3 + std::size_t(d)];
            for (int d = 0; d < 4; ++d) gq[i * 4 + std::size_t(d)] = dout[i * 10 + 6 + std::size_t(d)];
          }
          field.backward(ctx, gm.data(), gs.data(), gq.data(), {gmean->data(), gscale->data(), grot->data()});
        });
    // Toy loss: sum((out - target)^2) + sum(sigmoid(out)).
    const Var tv = t.constant(target.data(), n, 10);
    const Var loss = add(t, sum(t, square(t, sub(t, out, tv))), sum(t, sigmoid(t, out)));
    if (rg) t.backward(loss);
    return t.value(loss)[0];
  };
  std::vector<double> gm(cloud.n * 3, 0.0), gs(cloud.n * 3, 0.0), gq(cloud.n * 4, 0.0);
  field.zero_grad();
  run(&gm, &gs, &gq);
  auto loss = [&] { return run(nullptr, nullptr, nullptr); };
  // atol: |L| (squares and sigmoids of 60 outputs) is ~10, so the central difference carries rounding
  // noise ~ eps |L| / h ~ 2e-9 and more through the quaternion normalisation (measured up to 1.5e-8).
  const testing::GradTolerance tol{.rtol = 1e-6, .atol = 3e-8};
  auto r1 = testing::check_gradient("mean", cloud.mean, gm, loss, tol);
  INFO(r1);
  CHECK(r1.ok());
  auto r2 = testing::check_gradient("log_scale", cloud.log_scale, gs, loss, tol);
  INFO(r2);
  CHECK(r2.ok());
  auto r3 = testing::check_gradient("rotation", cloud.rotation, gq, loss, tol);
  INFO(r3);
  CHECK(r3.ok());
  auto segs = field.segments();
  auto head = segs.back();
  std::vector<double> hv(head.value.begin(), head.value.end()), hg(head.grad.begin(), head.grad.end());
  auto r4 = testing::check_gradient("scale head", hv, hg, [&] {
    std::copy(hv.begin(), hv.end(), head.value.begin());
    return loss();
  }, tol);
  std::copy(hv.begin(), hv.end(), head.value.begin());
  INFO(r4);
  CHECK(r4.ok());
}

TEST_CASE("deformation field: a warm forward + backward allocates nothing") {
  using Field = DeformationField<float, HashGrid<float, 4, 16, 2, 12>>;
  const std::size_t n = 3000;
  auto rng = test::seeded_rng(9);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  std::vector<float> mean(n * 3), ls(n * 3), rot(n * 4);
  for (auto& v : mean) v = u(rng);
  for (auto& v : ls) v = u(rng) - 3.f;
  for (auto& v : rot) v = u(rng);
  Field field(mean);
  typename Field::Context ctx;
  ThreadPool pool(2);
  std::vector<float> m(n * 3), s(n * 3), q(n * 4), gm(n * 3), gs(n * 3), gq(n * 4), d3(n * 3, 0.1f), d4(n * 4, 0.2f);
  auto iteration = [&](float t) {
    field.zero_grad();
    field.forward({mean.data(), ls.data(), rot.data(), n, t}, {m.data(), s.data(), q.data()}, ctx, &pool);
    field.backward(ctx, d3.data(), d3.data(), d4.data(), {gm.data(), gs.data(), gq.data()}, &pool);
  };
  iteration(0.1f);  // sizes the context
  const std::size_t before = video3dgs_test::allocations();
  Eigen::internal::set_is_malloc_allowed(false);
  bool threw = false;
  try {
    for (int it = 0; it < 5; ++it) iteration(0.2f * float(it));
  } catch (const std::exception& e) {
    threw = true;
    MESSAGE(std::string(e.what()));
  }
  Eigen::internal::set_is_malloc_allowed(true);
  CHECK_FALSE(threw);
  CHECK(video3dgs_test::allocations() == before);
}

TEST_CASE("deformation field: single-layer heads run together with the bits of each head run alone") {
  // The field walks the blocks of h once for its three linear heads (forward and backward); each
  // head's outputs, parameter gradients and its share of dL/dh must be the bits of that head's own
  // Mlp::forward / backward run one after the other, for any thread count. 70,000 rows: 32 parts of
  // 2,188 rows, two blocks of Linear::kRowBlock each.
  using Field = DeformationField<float, HashGrid<float, 4, 16, 2, 12>>;
  static_assert(Field::HeadXyz::kHiddenLayers == 0);
  const std::size_t n = 70000;
  const auto N = Eigen::Index(n);
  auto rng = test::seeded_rng(31);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  std::vector<float> mean(n * 3), ls(n * 3), rot(n * 4), d3a(n * 3), d3b(n * 3), d4(n * 4);
  for (auto& v : mean) v = u(rng);
  for (auto& v : ls) v = u(rng) - 3.f;
  for (auto& v : rot) v = u(rng);
  for (auto* buf : {&d3a, &d3b, &d4})
    for (auto& v : *buf) v = u(rng);
  DeformationOptions o;
  o.head_init = HeadInitOptions{HeadInit::uniform_fan_in, 1e-3, 5};  // heads with weights of every size
  for (unsigned threads : {1u, 2u, 3u}) {
    INFO("threads " << threads);
    ThreadPool pool(threads);
    Field field(mean, o);
    typename Field::Context ctx;
    std::vector<float> m(n * 3), s(n * 3), q(n * 4), gm(n * 3, 0.f), gs(n * 3, 0.f), gq(n * 4, 0.f);
    field.zero_grad();
    field.forward({mean.data(), ls.data(), rot.data(), n, 0.4f}, {m.data(), s.data(), q.data()}, ctx, &pool);
    // Each head alone on the same input.
    typename Field::Matrix yx, yr, ys;
    typename Field::HeadXyz::Context cx;
    typename Field::HeadRot::Context cr;
    typename Field::HeadScale::Context cs;
    field.head_xyz().forward(ctx.h, yx, cx, &pool);
    field.head_rotation().forward(ctx.h, yr, cr, &pool);
    field.head_scale().forward(ctx.h, ys, cs, &pool);
    CHECK(std::memcmp(yx.data(), ctx.dxyz.data(), sizeof(float) * n * 3) == 0);
    CHECK(std::memcmp(yr.data(), ctx.drot.data(), sizeof(float) * n * 4) == 0);
    CHECK(std::memcmp(ys.data(), ctx.dscale.data(), sizeof(float) * n * 3) == 0);

    field.backward(ctx, d3a.data(), d3b.data(), d4.data(), {gm.data(), gs.data(), gq.data()}, &pool);
    // The heads' backwards in turn, from the output gradients the field handed them (ctx.g_*).
    typename Field::Matrix dh;
    dh.setZero(N, Field::kFeatures);
    std::vector<float> wx(Field::HeadXyz::kParams, 0.f), wr(Field::HeadRot::kParams, 0.f), ws(Field::HeadScale::kParams, 0.f);
    const std::span<float> sx[1] = {wx}, sr[1] = {wr}, ss[1] = {ws};
    field.head_xyz().backward(ctx.h, ctx.g_xyz, cx, std::span<const std::span<float>>(sx), &dh, &pool);
    field.head_rotation().backward(ctx.h, ctx.g_rot, cr, std::span<const std::span<float>>(sr), &dh, &pool);
    field.head_scale().backward(ctx.h, ctx.g_scale, cs, std::span<const std::span<float>>(ss), &dh, &pool);
    const auto segs = field.segments();  // the grid table, then the heads' layers (xyz, rot, scale)
    REQUIRE(segs.size() == 4);
    CHECK(std::vector<float>(segs[1].grad.begin(), segs[1].grad.end()) == wx);
    CHECK(std::vector<float>(segs[2].grad.begin(), segs[2].grad.end()) == wr);
    CHECK(std::vector<float>(segs[3].grad.begin(), segs[3].grad.end()) == ws);
    CHECK(std::memcmp(dh.data(), ctx.dh.data(), sizeof(float) * n * Field::kFeatures) == 0);
    float largest = 0;
    for (float v : wx) largest = std::max(largest, std::abs(v));
    CHECK(largest > 0.f);  // the comparison saw real gradients
  }
}
