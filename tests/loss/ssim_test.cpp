#include "video3dgs/loss/ssim.hpp"

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <span>
#include <stdexcept>
#include <tuple>
#include <utility>
#include <vector>

#include <doctest/doctest.h>

#include "video3dgs/testing/grad_check.hpp"

#include "../test_data.hpp"

using namespace video3dgs;
using video3dgs::test::random_image;

namespace {


/// Independent reference: the 2-D window evaluated directly (no separable passes), double precision,
/// zero padding, mean over pixels and channels.
template <class Scalar, int C>
double ssim_direct(const Image<Scalar, C>& x, const Image<Scalar, C>& y, int r = 5, double sigma = 1.5) {
  constexpr double c1 = 1e-4, c2 = 9e-4;
  std::vector<std::vector<double>> win(2 * r + 1, std::vector<double>(2 * r + 1));
  double wsum = 0;
  for (int j = -r; j <= r; ++j)
    for (int k = -r; k <= r; ++k) wsum += win[j + r][k + r] = std::exp(-(j * j + k * k) / (2 * sigma * sigma));
  double total = 0;
  for (int py = 0; py < x.height(); ++py)
    for (int px = 0; px < x.width(); ++px)
      for (int c = 0; c < C; ++c) {
        double mx = 0, my = 0, exx = 0, eyy = 0, exy = 0;
        for (int j = -r; j <= r; ++j)
          for (int k = -r; k <= r; ++k) {
            const int qx = px + k, qy = py + j;
            if (qx < 0 || qy < 0 || qx >= x.width() || qy >= x.height()) continue;
            const double w = win[j + r][k + r] / wsum;
            const double a = x(qx, qy, c), b = y(qx, qy, c);
            mx += w * a;
            my += w * b;
            exx += w * a * a;
            eyy += w * b * b;
            exy += w * a * b;
          }
        const double sxx = exx - mx * mx, syy = eyy - my * my, sxy = exy - mx * my;
        total += ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx * mx + my * my + c1) * (sxx + syy + c2));
      }
  return total / (static_cast<double>(x.pixel_count()) * C);
}

}  // namespace

TEST_CASE_TEMPLATE("ssim: matches a direct 2-D double loop (odd sizes, smaller than the window)", Scalar, float, double) {
  const double tol = std::is_same_v<Scalar, double> ? 1e-12 : 2e-6;
  for (const auto& size : {std::pair{37, 23}, std::pair{4, 3}, std::pair{1, 1}, std::pair{12, 29}}) {
    const int w = size.first, h = size.second;  // not a binding: INFO captures them
    INFO("size " << w << "x" << h << " seed 42");
    const auto x = random_image<Scalar, 3>(w, h, 42);
    const auto y = random_image<Scalar, 3>(w, h, 43);
    loss::SsimContext<Scalar, 3> ctx;
    const double s = loss::ssim_forward<Scalar, 3>(x, y, ctx);
    const double ref = ssim_direct(x, y);
    CHECK(std::abs(s - ref) < tol);
    CHECK(std::abs(loss::ssim_value<Scalar, 3>(x, y, ctx) - s) == 0.0);
    // Correlated images (SSIM well inside (0, 1)) and one channel.
    auto z = x;
    for (auto& v : z.storage()) v = static_cast<Scalar>(0.7 * v + 0.1);
    CHECK(std::abs(loss::ssim_forward<Scalar, 3>(x, z, ctx) - ssim_direct(x, z)) < tol);
    const auto x1 = random_image<Scalar, 1>(w, h, 5), y1 = random_image<Scalar, 1>(w, h, 6);
    loss::SsimContext<Scalar, 1> ctx1;
    CHECK(std::abs(loss::ssim_forward<Scalar, 1>(x1, y1, ctx1) - ssim_direct(x1, y1)) < tol);
  }
}

TEST_CASE("ssim: other window options (radius, sigma) on a reused context") {
  const auto x = random_image<double, 3>(23, 17, 61), y = random_image<double, 3>(23, 17, 62);
  loss::SsimContext<double, 3> ctx;
  CHECK(std::abs(loss::ssim_forward<double, 3>(x, y, ctx) - ssim_direct(x, y)) < 1e-12);
  ctx.options.sigma = 0.8;  // same radius: the taps must still be rebuilt
  CHECK(std::abs(loss::ssim_forward<double, 3>(x, y, ctx) - ssim_direct(x, y, 5, 0.8)) < 1e-12);
  ctx.options.radius = 3;
  CHECK(std::abs(loss::ssim_forward<double, 3>(x, y, ctx) - ssim_direct(x, y, 3, 0.8)) < 1e-12);
  ctx.options.radius = 0;  // 1x1 window: per-pixel SSIM
  CHECK(std::abs(loss::ssim_forward<double, 3>(x, y, ctx) - ssim_direct(x, y, 0, 0.8)) < 1e-12);
}

TEST_CASE_TEMPLATE("ssim: SSIM(x, x) == 1 and D-SSIM(x, x) == 0 up to rounding", Scalar, float, double) {
  // Exactly 1 with the default (non-FMA) code generation; a few ulps if the compiler contracts to FMA.
  const Scalar tol = 8 * std::numeric_limits<Scalar>::epsilon();
  loss::SsimContext<Scalar, 3> ctx;
  for (std::uint64_t seed : {1u, 2u, 3u}) {
    const auto x = random_image<Scalar, 3>(37, 23, seed);
    CHECK(std::abs(loss::ssim_forward<Scalar, 3>(x, x, ctx) - Scalar(1)) <= tol);
    CHECK(std::abs(loss::dssim_forward<Scalar, 3>(x, x, ctx)) <= tol);
  }
  // Constant and black images: no 0/0.
  const Image<Scalar, 3> black(9, 7, Scalar(0)), white(9, 7, Scalar(1));
  CHECK(std::abs(loss::ssim_forward<Scalar, 3>(black, black, ctx) - Scalar(1)) <= tol);
  const Scalar bw = loss::ssim_forward<Scalar, 3>(black, white, ctx);
  CHECK(std::isfinite(bw));
  CHECK(bw < Scalar(0.01));
  Image<Scalar, 3> g(9, 7, Scalar(0));
  loss::ssim_backward<Scalar, 3>(ctx, Scalar(1), g);
  for (Scalar v : g.storage()) REQUIRE(std::isfinite(v));
}

TEST_CASE("ssim: backward matches central differences in double (all pixels incl. borders)") {
  for (const auto& c : {std::tuple{37, 23, 7}, std::tuple{5, 4, 8}, std::tuple{13, 1, 9}}) {
    const int w = std::get<0>(c), h = std::get<1>(c), seed = std::get<2>(c);  // not a binding: INFO captures them
    INFO("size " << w << "x" << h << " seed " << seed);
    auto x = random_image<double, 3>(w, h, static_cast<std::uint64_t>(seed));
    const auto y = random_image<double, 3>(w, h, static_cast<std::uint64_t>(seed) + 100);
    // Make x correlated with y so the gradient is not dominated by one term.
    for (std::size_t i = 0; i < x.size(); ++i) x.data()[i] = 0.5 * x.data()[i] + 0.5 * y.data()[i];
    const double M = static_cast<double>(x.size());  // check M * SSIM so every entry is O(1)
    loss::SsimContext<double, 3> ctx;
    (void)loss::ssim_forward<double, 3>(x, y, ctx);
    Image<double, 3> grad(w, h, 0.0);
    loss::ssim_backward<double, 3>(ctx, M, grad);
    loss::SsimContext<double, 3> probe;
    // atol: L = M SSIM is ~M (2553 at 37x23), so with h = 1e-5 the central difference carries rounding
    // noise eps |L| / h ~ 6e-8 on every entry (measured up to 7e-8).
    const testing::GradTolerance tol{.rtol = 1e-6, .atol = 2e-7};
    const auto r = testing::check_gradient(
        "ssim", std::span<double>(x.storage()), std::span<const double>(grad.storage()),
        [&] { return M * loss::ssim_value<double, 3>(x, y, probe); }, tol, 1e-5);
    INFO(r);
    CHECK(r.ok());

    // D-SSIM: same gradient with the opposite sign; backward adds into its output.
    Image<double, 3> g2(w, h, 0.0);
    (void)loss::dssim_forward<double, 3>(x, y, ctx);
    loss::dssim_backward<double, 3>(ctx, M, g2);
    const auto rd = testing::check_gradient(
        "dssim", std::span<double>(x.storage()), std::span<const double>(g2.storage()),
        [&] { return M * (1.0 - loss::ssim_value<double, 3>(x, y, probe)); }, tol, 1e-5);
    INFO(rd);
    CHECK(rd.ok());
    loss::dssim_backward<double, 3>(ctx, M, g2);
    bool doubled = true;
    for (std::size_t i = 0; i < g2.size(); ++i) doubled = doubled && g2.data()[i] == -2.0 * grad.data()[i];
    CHECK(doubled);
  }
}

TEST_CASE("ssim: one-channel backward and out-of-range renders") {
  auto x = random_image<double, 1>(11, 9, 21, -0.3, 1.4);
  const auto y = random_image<double, 1>(11, 9, 22);
  const double M = static_cast<double>(x.size());
  loss::SsimContext<double, 1> ctx, probe;
  (void)loss::ssim_forward<double, 1>(x, y, ctx);
  Image<double, 1> grad(11, 9, 0.0);
  loss::ssim_backward<double, 1>(ctx, M, grad);
  const auto r = testing::check_gradient(
      "ssim1", std::span<double>(x.storage()), std::span<const double>(grad.storage()),
      [&] { return M * loss::ssim_value<double, 1>(x, y, probe); }, {.rtol = 1e-6}, 1e-5);
  INFO(r);
  CHECK(r.ok());
}

TEST_CASE("ssim: backward with a non-default window (run-time tap count) matches central differences") {
  auto x = random_image<double, 3>(9, 14, 71);
  const auto y = random_image<double, 3>(9, 14, 72);
  const double M = static_cast<double>(x.size());
  loss::SsimOptions opts;
  opts.radius = 3;
  opts.sigma = 1.1;
  loss::SsimContext<double, 3> ctx(opts), probe(opts);
  (void)loss::ssim_forward<double, 3>(x, y, ctx);
  CHECK(std::abs(ctx.value - ssim_direct(x, y, 3, 1.1)) < 1e-12);
  Image<double, 3> grad(9, 14, 0.0);
  loss::ssim_backward<double, 3>(ctx, M, grad);
  const auto r = testing::check_gradient(
      "ssim_r3", std::span<double>(x.storage()), std::span<const double>(grad.storage()),
      [&] { return M * loss::ssim_value<double, 3>(x, y, probe); }, {.rtol = 1e-6}, 1e-5);
  INFO(r);
  CHECK(r.ok());
}

TEST_CASE_TEMPLATE("ssim: forward and backward are bit-identical for any thread count; views with stride", Scalar, float,
                   double) {
  const auto x = random_image<Scalar, 3>(101, 67, 31);
  const auto y = random_image<Scalar, 3>(101, 67, 32);
  loss::SsimContext<Scalar, 3> c0, c1, c2;
  Image<Scalar, 3> g0(101, 67), g1(101, 67), g2(101, 67);
  ThreadPool one(1), two(2);
  const Scalar s0 = loss::ssim_forward<Scalar, 3>(x, y, c0, nullptr);
  const Scalar s1 = loss::ssim_forward<Scalar, 3>(x, y, c1, &one);
  const Scalar s2 = loss::ssim_forward<Scalar, 3>(x, y, c2, &two);
  CHECK(s0 == s1);
  CHECK(s0 == s2);
  loss::ssim_backward<Scalar, 3>(c0, Scalar(1), g0, nullptr);
  loss::ssim_backward<Scalar, 3>(c1, Scalar(1), g1, &one);
  loss::ssim_backward<Scalar, 3>(c2, Scalar(1), g2, &two);
  CHECK(g0.storage() == g1.storage());
  CHECK(g0.storage() == g2.storage());

  // A cropped view (stride > width * C) gives the same result as a contiguous copy.
  const auto xc = x.view().crop(3, 2, 50, 40), yc = y.view().crop(3, 2, 50, 40);
  const auto xcopy = Image<Scalar, 3>::from_view(xc), ycopy = Image<Scalar, 3>::from_view(yc);
  CHECK(loss::ssim_forward<Scalar, 3>(xc, yc, c0, &two) == loss::ssim_forward<Scalar, 3>(xcopy, ycopy, c1, &two));
}

namespace {

/// Plain and shared-target SSIM of two renders against one target: values, ssim_value and gradients
/// (added into a non-zero buffer) bit for bit; one context per path, reused across calls.
template <class Scalar, int C>
void check_shared_target(int w, int h, const loss::SsimOptions& opts, ThreadPool* pool, std::uint64_t seed) {
  INFO("C " << C << " size " << w << "x" << h << " radius " << opts.radius << " sigma " << opts.sigma << " pool " << (pool != nullptr)
            << " seed " << seed);
  const auto y = random_image<Scalar, C>(w, h, seed);
  auto x0 = random_image<Scalar, C>(w, h, seed + 1), x1 = random_image<Scalar, C>(w, h, seed + 2);
  for (std::size_t i = 0; i < x0.size(); ++i) x0.data()[i] = static_cast<Scalar>(0.6 * x0.data()[i] + 0.4 * y.data()[i]);
  loss::SsimTarget<Scalar, C> target;
  loss::fill_ssim_target<Scalar, C>(y, target, opts, pool);
  CHECK(target.fits(w, h, opts));
  loss::SsimContext<Scalar, C> plain(opts), shared(opts);
  const Image<Scalar, C> start = random_image<Scalar, C>(w, h, seed + 3);
  for (const Image<Scalar, C>* x : {&x0, &x1}) {
    const Scalar sp = loss::ssim_forward<Scalar, C>(*x, y, plain, pool);
    const Scalar ss = loss::ssim_forward<Scalar, C>(*x, target, shared, pool);
    CHECK(sp == ss);
    Image<Scalar, C> gp = start, gs = start;
    loss::ssim_backward<Scalar, C>(plain, Scalar(0.7), gp, pool);
    loss::ssim_backward<Scalar, C>(shared, Scalar(0.7), gs, pool);
    CHECK(gp.storage() == gs.storage());
    CHECK(loss::ssim_value<Scalar, C>(*x, y, plain, pool) == loss::ssim_value<Scalar, C>(*x, target, shared, pool));
    CHECK(loss::dssim_forward<Scalar, C>(*x, y, plain, pool) == loss::dssim_forward<Scalar, C>(*x, target, shared, pool));
  }
}

}  // namespace

TEST_CASE_TEMPLATE("ssim: a shared SsimTarget gives the plain value and gradient bit for bit (sizes, channels, windows, threads)", Scalar,
                   float, double) {
  ThreadPool two(2);
  loss::SsimOptions r3;
  r3.radius = 3, r3.sigma = 1.1;  // run-time tap count
  loss::SsimOptions r0;
  r0.radius = 0;  // 1x1 window
  std::uint64_t seed = 300;
  for (const auto& size : {std::pair{37, 23}, std::pair{101, 67}, std::pair{4, 3}, std::pair{1, 1}, std::pair{13, 1}, std::pair{12, 29}})
    for (const loss::SsimOptions& o : {loss::SsimOptions{}, r3, r0})
      for (ThreadPool* pool : {static_cast<ThreadPool*>(nullptr), &two}) {
        check_shared_target<Scalar, 3>(size.first, size.second, o, pool, seed++);
        check_shared_target<Scalar, 1>(size.first, size.second, o, pool, seed++);
      }
}

TEST_CASE_TEMPLATE("ssim: one context alternating plain and shared-target calls, sizes and windows; refills of one target", Scalar, float,
                   double) {
  // The shared path lays out three of the five horizontal maps: a context must stay exact when it
  // switches between the paths, and a target when it is refilled for another size or window.
  loss::SsimContext<Scalar, 3> ctx;
  loss::SsimTarget<Scalar, 3> target;
  std::uint64_t seed = 500;
  for (const auto& c : {std::tuple{23, 17, 5}, std::tuple{23, 17, 5}, std::tuple{9, 4, 3}, std::tuple{30, 11, 5}, std::tuple{9, 4, 5}}) {
    const int w = std::get<0>(c), h = std::get<1>(c), r = std::get<2>(c);  // not a binding: INFO captures them
    INFO("size " << w << "x" << h << " radius " << r << " seed " << seed);
    const auto x = random_image<Scalar, 3>(w, h, seed), y = random_image<Scalar, 3>(w, h, seed + 1);
    seed += 2;
    ctx.options.radius = r;
    loss::SsimContext<Scalar, 3> fresh(ctx.options);
    loss::fill_ssim_target<Scalar, 3>(y, target, ctx.options);
    Image<Scalar, 3> g_ref(w, h), g_shared(w, h), g_plain(w, h);
    const Scalar ref = loss::ssim_forward<Scalar, 3>(x, y, fresh);
    loss::ssim_backward<Scalar, 3>(fresh, Scalar(1), g_ref);
    CHECK(loss::ssim_forward<Scalar, 3>(x, target, ctx) == ref);
    loss::ssim_backward<Scalar, 3>(ctx, Scalar(1), g_shared);
    CHECK(loss::ssim_forward<Scalar, 3>(x, y, ctx) == ref);
    loss::ssim_backward<Scalar, 3>(ctx, Scalar(1), g_plain);
    CHECK(g_shared.storage() == g_ref.storage());
    CHECK(g_plain.storage() == g_ref.storage());
  }
}

TEST_CASE("ssim: shared-target backward matches central differences in double") {
  for (const auto& c : {std::tuple{37, 23, 7, 5}, std::tuple{5, 4, 8, 5}, std::tuple{9, 14, 9, 3}}) {
    const int w = std::get<0>(c), h = std::get<1>(c), seed = std::get<2>(c);  // not a binding: INFO captures them
    loss::SsimOptions opts;
    opts.radius = std::get<3>(c);
    INFO("size " << w << "x" << h << " seed " << seed << " radius " << opts.radius);
    auto x = random_image<double, 3>(w, h, static_cast<std::uint64_t>(seed));
    const auto y = random_image<double, 3>(w, h, static_cast<std::uint64_t>(seed) + 100);
    for (std::size_t i = 0; i < x.size(); ++i) x.data()[i] = 0.5 * x.data()[i] + 0.5 * y.data()[i];
    const double M = static_cast<double>(x.size());  // check M * SSIM so every entry is O(1)
    loss::SsimTarget<double, 3> target;
    loss::fill_ssim_target<double, 3>(y, target, opts);
    loss::SsimContext<double, 3> ctx(opts), probe(opts);
    (void)loss::ssim_forward<double, 3>(x, target, ctx);
    Image<double, 3> grad(w, h, 0.0);
    loss::ssim_backward<double, 3>(ctx, M, grad);
    // atol: as in the plain check above (L ~ M, h = 1e-5: rounding noise ~ eps |L| / h ~ 6e-8).
    const auto r = testing::check_gradient(
        "ssim_shared_target", std::span<double>(x.storage()), std::span<const double>(grad.storage()),
        [&] { return M * loss::ssim_value<double, 3>(x, target, probe); }, {.rtol = 1e-6, .atol = 2e-7}, 1e-5);
    INFO(r);
    CHECK(r.ok());
  }
}

TEST_CASE("ssim: an SsimTarget is refused when unfilled, of another size or another window; refilled after new pixels it is exact") {
  auto y = random_image<double, 3>(20, 15, 81);
  const auto x = random_image<double, 3>(20, 15, 82), wide = random_image<double, 3>(21, 15, 83);
  loss::SsimTarget<double, 3> target;
  loss::SsimContext<double, 3> ctx, plain;
  // The id of the option_error that f throws ("" if it throws none).
  const auto id_of = [](auto&& f) -> std::string {
    try {
      f();
    } catch (const option_error& e) {
      return std::string(e.id());
    }
    return "";
  };
  CHECK(!target.fits(20, 15, ctx.options));
  CHECK(id_of([&] { (void)loss::ssim_forward<double, 3>(x, target, ctx); }) == "option.ssim");
  loss::fill_ssim_target<double, 3>(y, target);
  CHECK(id_of([&] { (void)loss::ssim_forward<double, 3>(wide, target, ctx); }) == "option.size");
  ctx.options.sigma = 1.2;  // the same radius, another window
  CHECK(!target.fits(20, 15, ctx.options));
  CHECK(id_of([&] { (void)loss::ssim_forward<double, 3>(x, target, ctx); }) == "option.ssim");
  ctx.options.sigma = 1.5, ctx.options.radius = 4;
  CHECK(id_of([&] { (void)loss::ssim_value<double, 3>(x, target, ctx); }) == "option.ssim");
  {  // a backward needs its forward's saved statistics: a fresh context, or one after ssim_value, has none
    loss::SsimContext<double, 3> fresh;
    Image<double, 3> g(20, 15, 0.0);
    CHECK(id_of([&] { loss::ssim_backward<double, 3>(fresh, 1.0, g.view()); }) == "option.ssim");
    (void)loss::ssim_value<double, 3>(x, y, fresh);
    CHECK(id_of([&] { loss::ssim_backward<double, 3>(fresh, 1.0, g.view()); }) == "option.ssim");
    (void)loss::ssim_forward<double, 3>(x, y, fresh);
    CHECK(id_of([&] { loss::ssim_backward<double, 3>(fresh, 1.0, g.view()); }) == "");
  }
  ctx.options.radius = 5;
  ctx.options.c1 = 2e-4;  // C1, C2 do not enter the target's maps
  CHECK(loss::ssim_forward<double, 3>(x, target, ctx) == loss::ssim_forward<double, 3>(x, y, ctx));
  ctx.options.c1 = 1e-4;
  loss::SsimOptions bad;
  bad.sigma = 0;
  CHECK_THROWS_AS((loss::fill_ssim_target<double, 3>(y, target, bad)), option_error);
  CHECK_THROWS_AS((loss::fill_ssim_target<double, 3>(ConstImageView<double, 3>(), target)), option_error);

  // New pixels in the same buffer: a refill gives the new target's result.
  const double before = loss::ssim_forward<double, 3>(x, target, ctx);
  for (auto& v : y.storage()) v = 1.0 - v;
  loss::fill_ssim_target<double, 3>(y, target);
  const double after = loss::ssim_forward<double, 3>(x, target, ctx);
  CHECK(after == loss::ssim_forward<double, 3>(x, y, plain));
  CHECK(after != before);

  // A cropped target view (stride > width * C): the same bits as the plain call on it.
  const ConstImageView<double, 3> yc = y.view().crop(2, 3, 11, 9), xc = x.view().crop(4, 1, 11, 9);
  loss::fill_ssim_target<double, 3>(yc, target);
  CHECK(loss::ssim_forward<double, 3>(xc, target, ctx) == loss::ssim_forward<double, 3>(xc, yc, plain));
}

TEST_CASE_TEMPLATE("ssim: the AVX2 filters give the portable bits (plain, shared target, backward, odd sizes and windows)", Scalar, float,
                   double) {
  loss::SsimOptions portable;
  portable.simd = Isa::portable;
  loss::SsimOptions bad = portable;
  bad.simd = Isa::avx512;  // no such copy
  loss::SsimContext<Scalar, 3> refused(bad);
  const auto a = random_image<Scalar, 3>(9, 7, 1), b = random_image<Scalar, 3>(9, 7, 2);
  CHECK_THROWS_WITH_AS((loss::ssim_forward<Scalar, 3>(a, b, refused)), doctest::Contains("simd"), option_error);
  if (!isa_supported(Isa::avx2)) {
    loss::SsimOptions avx2 = portable;
    avx2.simd = Isa::avx2;
    loss::SsimContext<Scalar, 3> no(avx2);
    CHECK_THROWS_AS((loss::ssim_forward<Scalar, 3>(a, b, no)), option_error);
    test::skip("this CPU has no AVX2: only the portable filters run");
    return;
  }
  ThreadPool two(2);
  std::uint64_t seed = 700;
  for (const auto& size : {std::pair{101, 67}, std::pair{37, 23}, std::pair{5, 3}, std::pair{13, 1}})
    for (int radius : {5, 3, 0}) {
      loss::SsimOptions p = portable, v = portable;
      p.radius = v.radius = radius;
      v.simd = Isa::avx2;
      INFO("size " << size.first << "x" << size.second << " radius " << radius);
      const int w = size.first, h = size.second;
      const auto y = random_image<Scalar, 3>(w, h, seed++);
      auto x = random_image<Scalar, 3>(w, h, seed++);
      for (std::size_t i = 0; i < x.size(); ++i) x.data()[i] = static_cast<Scalar>(0.7 * x.data()[i] + 0.3 * y.data()[i]);
      loss::SsimContext<Scalar, 3> cp(p), cv(v);
      CHECK(loss::ssim_forward<Scalar, 3>(x, y, cp, &two) == loss::ssim_forward<Scalar, 3>(x, y, cv, &two));
      Image<Scalar, 3> gp(w, h), gv(w, h);
      loss::ssim_backward<Scalar, 3>(cp, Scalar(0.9), gp, &two);
      loss::ssim_backward<Scalar, 3>(cv, Scalar(0.9), gv, &two);
      CHECK(gp.storage() == gv.storage());
      loss::SsimTarget<Scalar, 3> tp, tv;
      loss::fill_ssim_target<Scalar, 3>(y, tp, p, &two);
      loss::fill_ssim_target<Scalar, 3>(y, tv, v, &two);
      CHECK(tp.my == tv.my);
      CHECK(tp.eyy == tv.eyy);
      CHECK(loss::ssim_forward<Scalar, 3>(x, tp, cp, nullptr) == loss::ssim_forward<Scalar, 3>(x, tv, cv, nullptr));
      loss::ssim_backward<Scalar, 3>(cp, Scalar(0.9), gp, nullptr);
      loss::ssim_backward<Scalar, 3>(cv, Scalar(0.9), gv, nullptr);
      CHECK(gp.storage() == gv.storage());
      CHECK(loss::ssim_value<Scalar, 3>(x, y, cp, &two) == loss::ssim_value<Scalar, 3>(x, y, cv, &two));
    }
}
