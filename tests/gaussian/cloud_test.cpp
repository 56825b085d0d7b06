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
