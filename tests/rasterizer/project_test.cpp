#include "video3dgs/rasterizer/project.hpp"

#include <cmath>

#include <doctest/doctest.h>

#include "video3dgs/gaussian/activations.hpp"

using namespace video3dgs;

TEST_CASE_TEMPLATE("project: an isotropic Gaussian on the optical axis", Scalar, float, double) {
  Camera<Scalar> cam;
  cam.width = 100, cam.height = 80;
  cam.fx = cam.fy = 50, cam.cx = 50, cam.cy = 40;
  RasterSettings<Scalar, 3> s;
  const Scalar mean[3] = {0, 0, 4};
  const Scalar ls[3] = {Scalar(std::log(0.4)), Scalar(std::log(0.4)), Scalar(std::log(0.4))};
  const Scalar q[4] = {1, 0, 0, 0};
  ProjectedGaussian<Scalar> pg;
  REQUIRE(project_gaussian(cam, s, mean, ls, q, Scalar(0), pg));
  CHECK(pg.u == doctest::Approx(50));
  CHECK(pg.v == doctest::Approx(40));
  CHECK(pg.depth == doctest::Approx(4));
  const double var = std::pow(50 * 0.4 / 4, 2) + 0.3;  // (f s / z)² + low-pass
  CHECK(pg.cov[0] == doctest::Approx(var).epsilon(1e-5));
  CHECK(pg.cov[2] == doctest::Approx(var).epsilon(1e-5));
  CHECK(pg.conic[0] == doctest::Approx(1 / var).epsilon(1e-5));
  CHECK(pg.radius == int(std::ceil(3 * std::sqrt(var))));
  CHECK(pg.opacity == doctest::Approx(0.5));
  // Footprint: alpha = 0.5 exp(-r²/(2 var)) >= 1/255 for r <= sqrt(2 var ln(127.5)).
  const double ext = std::sqrt(2 * var * std::log(127.5));
  CHECK(pg.x0 == doctest::Approx(std::ceil(50 - ext - 0.5)).epsilon(0.02));
  CHECK(pg.x1 - pg.x0 >= int(2 * ext));

  // Antialiased mode scales opacity by sqrt(det(cov - 0.3 I) / det(cov)).
  s.antialiased = true;
  REQUIRE(project_gaussian(cam, s, mean, ls, q, Scalar(0), pg));
  CHECK(pg.opacity == doctest::Approx(0.5 * (var - 0.3) / var).epsilon(1e-5));
}

TEST_CASE("project: culling") {
  Camera<double> cam = Camera<double>::from_fov(64, 48, 1.0);
  RasterSettings<double, 3> s;
  const double ls[3] = {-2, -2, -2};
  const double q[4] = {1, 0, 0, 0};
  ProjectedGaussian<double> pg;
  const double behind[3] = {0, 0, -1}, on_near[3] = {0, 0, 0.2}, just_in[3] = {0, 0, 0.21}, far_side[3] = {100, 0, 1};
  CHECK_FALSE(project_gaussian(cam, s, behind, ls, q, 0.0, pg));
  CHECK_FALSE(project_gaussian(cam, s, on_near, ls, q, 0.0, pg));
  CHECK(project_gaussian(cam, s, just_in, ls, q, 0.0, pg));
  CHECK_FALSE(project_gaussian(cam, s, far_side, ls, q, 0.0, pg));  // footprint outside the image
  const double nan_mean[3] = {0, NAN, 3};
  CHECK_FALSE(project_gaussian(cam, s, nan_mean, ls, q, 0.0, pg));
  const double ok_mean[3] = {0, 0, 3};
  CHECK_FALSE(project_gaussian(cam, s, ok_mean, ls, q, -30.0, pg));  // opacity below 1/255
  CHECK_FALSE(project_gaussian(cam, s, ok_mean, ls, q, double(INFINITY), pg));
  s.far_plane = 2;
  CHECK_FALSE(project_gaussian(cam, s, ok_mean, ls, q, 0.0, pg));
}
