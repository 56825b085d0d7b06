#include "video3dgs/core/resample.hpp"

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include <doctest/doctest.h>

#include "video3dgs/core/camera.hpp"

using namespace video3dgs;

namespace {
template <class Scalar, int C>
Image<Scalar, C> noise_image(int w, int h, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(-1, 1);
  Image<Scalar, C> img(w, h);
  for (std::size_t i = 0; i < img.size(); ++i) img.data()[i] = Scalar(U(rng));
  return img;
}
template <class Scalar, int C>
double dot(const Image<Scalar, C>& a, const Image<Scalar, C>& b) {
  double s = 0;
  for (std::size_t i = 0; i < a.size(); ++i) s += double(a.data()[i]) * double(b.data()[i]);
  return s;
}
}  // namespace

TEST_CASE("AreaResampler: constants stay constant, means are kept on exact ratios, any ratio up or down") {
  for (const auto& dims : {std::array{854, 480, 214, 120}, std::array{854, 480, 427, 240}, std::array{7, 5, 3, 2}, std::array{3, 2, 7, 5},
                           std::array{1, 1, 4, 3}, std::array{9, 4, 9, 4}}) {
    const int wi = dims[0], hi = dims[1], wo = dims[2], ho = dims[3];  // not a binding: INFO captures them
    INFO(wi << "x" << hi << " -> " << wo << "x" << ho);
    AreaResampler r(wi, hi, wo, ho);
    Image<double, 3> in(wi, hi, 0.375), out(wo, ho);
    r.forward<double, 3>(in, out);
    for (std::size_t i = 0; i < out.size(); ++i) CHECK(out.data()[i] == doctest::Approx(0.375).epsilon(1e-14));
  }
  // 4x2 -> 2x1: each output pixel is the mean of its 2x2 block.
  Image<double, 1> in(4, 2);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 4; ++x) in(x, y) = 10 * y + x;
  Image<double, 1> out(2, 1);
  AreaResampler(4, 2, 2, 1).forward<double, 1>(in, out);
  CHECK(out(0, 0) == doctest::Approx((0 + 1 + 10 + 11) / 4.0));
  CHECK(out(1, 0) == doctest::Approx((2 + 3 + 12 + 13) / 4.0));
  // Non-integer ratio 3 -> 2: output 0 covers [0, 1.5): pixel 0 fully, pixel 1 half.
  Image<double, 1> row(3, 1), row2(2, 1);
  row(0, 0) = 1, row(1, 0) = 4, row(2, 0) = 7;
  AreaResampler(3, 1, 2, 1).forward<double, 1>(row, row2);
  CHECK(row2(0, 0) == doctest::Approx((1 * 1.0 + 4 * 0.5) / 1.5));
  CHECK(row2(1, 0) == doctest::Approx((4 * 0.5 + 7 * 1.0) / 1.5));
}

TEST_CASE_TEMPLATE("AreaResampler: adjoint_add is the transpose (<R a, b> = <a, R^T b>) and accumulates", Scalar, float, double) {
  for (const auto& dims : {std::array{37, 23, 9, 6}, std::array{10, 7, 25, 13}, std::array{16, 12, 8, 6}}) {
    const int wi = dims[0], hi = dims[1], wo = dims[2], ho = dims[3];  // not a binding: INFO captures them
    INFO(wi << "x" << hi << " -> " << wo << "x" << ho);
    AreaResampler r(wi, hi, wo, ho);
    const auto a = noise_image<Scalar, 2>(wi, hi, 1), b = noise_image<Scalar, 2>(wo, ho, 2);
    Image<Scalar, 2> ra(wo, ho), rtb(wi, hi, Scalar(0));
    r.forward<Scalar, 2>(a, ra);
    r.adjoint_add<Scalar, 2>(b, rtb);
    const double tol = std::is_same_v<Scalar, float> ? 1e-4 : 1e-12;
    CHECK(dot(ra, b) == doctest::Approx(dot(a, rtb)).epsilon(tol));
    Image<Scalar, 2> twice = rtb;
    r.adjoint_add<Scalar, 2>(b, twice);  // adds: 2 R^T b
    for (std::size_t i = 0; i < rtb.size(); ++i) CHECK(twice.data()[i] == doctest::Approx(2 * double(rtb.data()[i])).epsilon(tol));
  }
}

TEST_CASE("AreaResampler: resize_area is its forward; sizes are checked with their id") {
  const auto a = noise_image<float, 3>(31, 17, 3);
  const Image<float, 3> small = resize_area(a, 12, 7);
  Image<float, 3> direct(12, 7);
  AreaResampler(31, 17, 12, 7).forward<float, 3>(a, direct);
  CHECK(small.storage() == direct.storage());
  CHECK(resize_area(a, 31, 17).storage() == a.storage());
  CHECK_THROWS_WITH_AS(AreaResampler(0, 3, 2, 2), doctest::Contains("[option.size]"), option_error);
  AreaResampler r(31, 17, 12, 7);
  Image<float, 3> wrong(11, 7);
  CHECK_THROWS_WITH_AS((r.forward<float, 3>(a, wrong)), doctest::Contains("resample.forward"), option_error);
  CHECK(r.maps(31, 17, 12, 7));
  CHECK(!r.maps(31, 17, 12, 8));
}

TEST_CASE("camera: resized scales pixel coordinates by w / width and h / height") {
  CameraD cam = CameraD::from_fov(854, 480, 1.1);
  cam.cx += 3.25, cam.cy -= 1.5;
  const CameraD low = cam.resized(214, 120);
  CHECK(low.width == 214);
  CHECK(low.height == 120);
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(0.2, 0.1, 3.0), Eigen::Vector3d(-1, 0.4, 2.0)}) {
    CHECK(low.world_to_pixel(p).x() == doctest::Approx(cam.world_to_pixel(p).x() * 214.0 / 854.0));
    CHECK(low.world_to_pixel(p).y() == doctest::Approx(cam.world_to_pixel(p).y() * 120.0 / 480.0));
  }
  // The image's corners are the same rays.
  CHECK((low.ray_direction({0, 0}) - cam.ray_direction({0, 0})).norm() < 1e-12);
  CHECK((low.ray_direction({214, 120}) - cam.ray_direction({854, 480})).norm() < 1e-12);
  CHECK(cam.scaled(0.25).fx == low.fx);
  CHECK_THROWS_AS((void)cam.resized(0, 5), option_error);
}

TEST_CASE("camera: cropped moves pixel coordinates by the window's origin") {
  CameraD cam = CameraD::from_fov(854, 480, 1.1);
  cam.cx += 3.25, cam.cy -= 1.5;
  const CameraD win = cam.cropped(300, 121, 427, 240);
  CHECK(win.width == 427);
  CHECK(win.height == 240);
  CHECK(win.fx == cam.fx);
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(0.2, 0.1, 3.0), Eigen::Vector3d(-1, 0.4, 2.0)}) {
    CHECK(win.world_to_pixel(p).x() == doctest::Approx(cam.world_to_pixel(p).x() - 300.0));
    CHECK(win.world_to_pixel(p).y() == doctest::Approx(cam.world_to_pixel(p).y() - 121.0));
  }
  // The window's corners are the frame's rays through (300, 121) and (727, 361).
  CHECK((win.ray_direction({0, 0}) - cam.ray_direction({300, 121})).norm() < 1e-12);
  CHECK((win.ray_direction({427, 240}) - cam.ray_direction({727, 361})).norm() < 1e-12);
  CHECK_THROWS_AS((void)cam.cropped(0, 0, 0, 5), option_error);
}
