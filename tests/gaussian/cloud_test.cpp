#include "video3dgs/gaussian.hpp"

#include <doctest/doctest.h>

using namespace video3dgs;

TEST_CASE_TEMPLATE("cloud: push_back / get round trip and views", Scalar, float, double) {
  GaussianCloud<Scalar, 2> cloud;
  Gaussian<Scalar, 2> g;
  g.mean = {1, 2, 3};
  g.log_scale = {-1, -2, -3};
  g.rotation = {Scalar(0.5), Scalar(0.5), Scalar(0.5), Scalar(0.5)};
  g.opacity_logit = Scalar(0.25);
  for (int k = 0; k < 27; ++k) g.sh[k] = Scalar(k);
  cloud.push_back(g);
  cloud.push_back(Gaussian<Scalar, 2>{});
  REQUIRE(cloud.size() == 2);
  const auto back = cloud.get(0);
  CHECK(back.mean == g.mean);
  CHECK(back.sh == g.sh);
  CHECK(cloud.get(1).rotation[0] == Scalar(1));
  const auto p = cloud.params();
  CHECK(p.count == 2);
  CHECK(p.sh_degree == 2);
  CHECK(p.sh.size() == 2 * 27u);
  p.validate();
  auto bad = p;
  bad.rotation = bad.rotation.first(3);
  CHECK_THROWS_AS(bad.validate(), option_error);
  cloud.resize(5);
  CHECK(cloud.get(4).rotation[0] == Scalar(1));
  GaussianCloudGrad<Scalar, 2> grad(5);
  CHECK(grad.grads().dL_dsh.size() == 5 * 27u);
}

TEST_CASE_TEMPLATE("cloud: keep_rows drops the masked rows and keeps the others in order", Scalar, float, double) {
  GaussianCloud<Scalar, 1> cloud;
  for (int i = 0; i < 5; ++i) {
    Gaussian<Scalar, 1> g;
    g.mean = {Scalar(i), Scalar(10 + i), Scalar(20 + i)};
    g.log_scale = {Scalar(-i), Scalar(-i), Scalar(-i)};
    g.rotation = {Scalar(1), Scalar(i), Scalar(0), Scalar(0)};
    g.opacity_logit = Scalar(i) / 8;
    for (int k = 0; k < 12; ++k) g.sh[k] = Scalar(100 * i + k);
    cloud.push_back(g);
  }
  const auto before = cloud;
  const std::uint8_t keep[5] = {0, 1, 0, 1, 1};
  cloud.keep_rows(keep);
  REQUIRE(cloud.size() == 3);
  const std::size_t kept[3] = {1, 3, 4};
  for (std::size_t j = 0; j < 3; ++j) {
    const auto a = cloud.get(j), b = before.get(kept[j]);
    CHECK(a.mean == b.mean);
    CHECK(a.log_scale == b.log_scale);
    CHECK(a.rotation == b.rotation);
    CHECK(a.opacity_logit == b.opacity_logit);
    CHECK(a.sh == b.sh);
  }
  const std::uint8_t two[2] = {1, 1};
  CHECK_THROWS_AS(cloud.keep_rows(two), option_error);
  CHECK(cloud.size() == 3);
  const std::uint8_t none[3] = {0, 0, 0};
  cloud.keep_rows(none);
  CHECK(cloud.empty());
  CHECK(cloud.sh.empty());
}
