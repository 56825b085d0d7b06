#include "video3dgs/core/camera.hpp"

#include <doctest/doctest.h>

#include "video3dgs/core/error.hpp"

using namespace video3dgs;

TEST_CASE_TEMPLATE("camera: world <-> camera <-> pixel round trips, pixel centres at +0.5", Scalar, float, double) {
  Camera<Scalar> cam = Camera<Scalar>::from_fov(64, 48, Scalar(1.0));
  using V3 = typename Camera<Scalar>::Vec3;
  using V2 = typename Camera<Scalar>::Vec2;
  cam.look_at(V3(1, -2, -5), V3(0, 0, 0));
  const Scalar tol = Scalar(100) * scalar_traits<Scalar>::test_tolerance;
  // The look-at target projects to the principal point, which is the image centre (32, 24):
  // the border between pixels 31 and 32, since pixel 31's centre is at 31.5.
  const V2 uv = cam.world_to_pixel(V3(0, 0, 0));
  CHECK(uv.x() == doctest::Approx(32).epsilon(tol));
  CHECK(uv.y() == doctest::Approx(24).epsilon(tol));
  const V3 xw(0.3, -0.7, 1.1);
  const V3 back = cam.camera_to_world(cam.world_to_camera(xw));
  CHECK((back - xw).norm() < tol);
  const V3 xc = cam.world_to_camera(xw);
  const V3 again = cam.pixel_to_camera(cam.camera_to_pixel(xc), xc.z());
  CHECK((again - xc).norm() < tol);
  // Camera centre maps to camera origin; +z is forward (the target has positive depth).
  CHECK(cam.world_to_camera(cam.center()).norm() < tol);
  CHECK(cam.world_to_camera(V3(0, 0, 0)).z() > 0);
  // World "up" (-y) looks up in the image: a point above the target has a smaller v.
  CHECK(cam.world_to_pixel(V3(0, -0.5, 0)).y() < uv.y());
  CHECK_NOTHROW(cam.validate());
}

TEST_CASE("camera: scaled keeps the pixel-centre convention") {
  CameraD cam = CameraD::from_fov(100, 50, 1.2);
  const CameraD half = cam.scaled(0.5);
  CHECK(half.width == 50);
  CHECK(half.height == 25);
  const Eigen::Vector3d p(0.2, 0.1, 3.0);
  CHECK(half.camera_to_pixel(p).x() == doctest::Approx(cam.camera_to_pixel(p).x() * 0.5));
}

TEST_CASE("camera: validate names the bad field") {
  CameraD cam = CameraD::from_fov(10, 10, 1.0);
  cam.fx = -1;
  try {
    cam.validate("cam.json");
    FAIL("expected an error");
  } catch (const error& e) {
    CHECK(e.id() == "option.camera");
    CHECK(std::string(e.what()).find("cam.json.fx") != std::string::npos);
  }
  cam = CameraD::from_fov(10, 10, 1.0);
  cam.R(0, 0) = 2;
  CHECK_THROWS_AS(cam.validate(), option_error);
}

TEST_CASE("camera: world_moved sees the moved world as the camera saw it; zero is the identity") {
  using video3dgs::CameraD;
  CameraD cam = CameraD::from_fov(64, 48, 1.0);
  cam.look_at({0.3, -0.2, -4.0}, {0.1, 0.05, 0.0});
  const CameraD::Vec3 omega(0.03, -0.05, 0.02), tau(0.1, -0.04, 0.07), o = cam.center();
  const CameraD moved = cam.world_moved(omega, tau);
  const Eigen::Matrix3d E = Eigen::AngleAxisd(omega.norm(), omega.normalized()).toRotationMatrix();
  for (const CameraD::Vec3& x : {CameraD::Vec3(0, 0, 0), CameraD::Vec3(1, -2, 3), CameraD::Vec3(-0.5, 0.25, 7)}) {
    const CameraD::Vec3 Tx = o + E * (x - o) + tau;
    CHECK((moved.world_to_camera(x) - cam.world_to_camera(Tx)).norm() < 1e-12);
  }
  CHECK((moved.R * moved.R.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-14);
  CHECK(moved.R.determinant() > 0);
  CHECK(moved.fx == cam.fx);
  CHECK(moved.width == cam.width);
  const CameraD same = cam.world_moved(CameraD::Vec3::Zero(), CameraD::Vec3::Zero());
  CHECK((same.R - cam.R).cwiseAbs().maxCoeff() < 1e-15);
  CHECK((same.t - cam.t).cwiseAbs().maxCoeff() < 1e-14);
  // A pure translation of the world by tau moves the camera centre by -tau.
  const CameraD shifted = cam.world_moved(CameraD::Vec3::Zero(), tau);
  CHECK((shifted.center() - (o - tau)).norm() < 1e-12);
}
