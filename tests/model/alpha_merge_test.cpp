#include "video3dgs/model/alpha_merge.hpp"

#include <random>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "video3dgs/testing/grad_check.hpp"

using namespace video3dgs;

TEST_CASE("alpha_merge: forward stays between the renders; backward matches finite differences") {
  const std::uint64_t seed = 7;
  INFO("seed " << seed);
  auto rng = test::seeded_rng(seed);
  std::uniform_real_distribution<double> u(0, 1), ul(-4, 4);
  const int w = 7, h = 5;
  Image<double, 3> f(w, h), b(w, h), out(w, h), target(w, h);
  Image<double, 1> logit(w, h);
  for (auto& v : f.storage()) v = u(rng);
  for (auto& v : b.storage()) v = u(rng);
  for (auto& v : target.storage()) v = u(rng);
  for (auto& v : logit.storage()) v = ul(rng);
  logit(0, 0) = 800;  // extremes: saturated logits stay finite
  logit(1, 0) = -800;
  alpha_merge_forward<double, 3>(f, b, logit, out);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) {
        CHECK(out(x, y, c) >= std::min(f(x, y, c), b(x, y, c)) - 1e-15);
        CHECK(out(x, y, c) <= std::max(f(x, y, c), b(x, y, c)) + 1e-15);
      }
  CHECK(out(0, 0, 1) == doctest::Approx(f(0, 0, 1)));
  CHECK(out(1, 0, 1) == doctest::Approx(b(1, 0, 1)));

  // L = 0.5 sum (out - target)^2
  auto loss = [&] {
    alpha_merge_forward<double, 3>(f, b, logit, out);
    double l = 0;
    for (std::size_t i = 0; i < out.size(); ++i) l += 0.5 * (out.data()[i] - target.data()[i]) * (out.data()[i] - target.data()[i]);
    return l;
  };
  loss();
  Image<double, 3> g(w, h), df(w, h), db(w, h);
  Image<double, 1> dl(w, h);
  for (std::size_t i = 0; i < out.size(); ++i) g.data()[i] = out.data()[i] - target.data()[i];
  ThreadPool pool(2);
  alpha_merge_backward<double, 3>(f, b, logit, g, df, db, dl, &pool);
  CHECK(testing::check_gradient("frg", f.storage(), df.storage(), loss, {.rtol = 1e-8}).ok());
  CHECK(testing::check_gradient("bkg", b.storage(), db.storage(), loss, {.rtol = 1e-8}).ok());
  CHECK(testing::check_gradient("logit", logit.storage(), dl.storage(), loss, {.rtol = 1e-8}).ok());
  for (double v : dl.storage()) CHECK(std::isfinite(v));
}
