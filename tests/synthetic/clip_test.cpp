// make_synthetic_clip: determinism, shapes, masks that match the object, noisy points near it, an
// SfM result the clip model accepts, option errors.
#include <cmath>

#include <doctest/doctest.h>

#include "video3dgs/synthetic/clip.hpp"

using namespace video3dgs;

TEST_CASE("make_synthetic_clip: seeded, exact cameras, masks and noisy foreground points") {
  synthetic::SyntheticClipOptions o;
  o.frames = 4;
  o.width = 64;
  o.height = 48;
  o.object_gaussians = 600;
  o.background_gaussians = 1500;
  o.foreground_points = 100;
  o.point_noise = 0.02;
  ThreadPool pool(2);
  const auto a = synthetic::make_synthetic_clip<float>(o, &pool);
  const auto b = synthetic::make_synthetic_clip<float>(o);
  REQUIRE(a.frames.size() == 4);
  REQUIRE(a.masks.size() == 4);
  REQUIRE(a.cameras.size() == 4);
  CHECK(a.points.size() == 100);
  for (int i = 0; i < 4; ++i) {
    CHECK(a.frames[i].storage() == b.frames[i].storage());  // same seed, any thread count
    CHECK(a.frames[i].width() == 64);
    double area = 0, inside_diff = 0;
    for (std::size_t p = 0; p < a.masks[i].size(); ++p) area += a.masks[i].data()[p];
    area /= double(a.masks[i].size());
    CHECK(area > 0.05);  // the object is visible...
    CHECK(area < 0.6);   // ... and so is the background
    (void)inside_diff;
  }
  // The object moves: masks differ between the first and last frame.
  CHECK(a.masks.front().storage() != a.masks.back().storage());
  // The camera moves on the arc, at the requested distance, looking at the origin.
  CHECK((a.cameras.front().center() - a.cameras.back().center()).norm() > 0.5f);
  CHECK(a.cameras[1].center().norm() == doctest::Approx(std::hypot(4.0, 0.4 * (1.0 / 3 - 0.5))).epsilon(1e-4));
  const auto uv = a.cameras[2].world_to_pixel(Eigen::Vector3f::Zero());
  CHECK(uv.x() == doctest::Approx(32.0).epsilon(1e-4));
  // Points: within noise of the unit sphere (t = 0 pose centre (-0.3, 0, 0)).
  double max_err = 0;
  for (const auto& p : a.points) max_err = std::max(max_err, std::abs((p.xyz - Eigen::Vector3d(-0.3, 0, 0)).norm() - 1.0));
  CHECK(max_err < 0.1);
  CHECK(max_err > 0.0);
  // A different seed changes the noise.
  o.seed = 2;
  const auto c = synthetic::make_synthetic_clip<float>(o);
  CHECK(c.points[5].xyz != a.points[5].xyz);
  // As an SfM result.
  const auto sfm = a.sfm_result();
  CHECK(sfm.status == SfmStatus::success);
  CHECK(sfm.complete());
  CHECK(sfm.frames.size() == 4);
}

TEST_CASE("make_synthetic_clip: option errors") {
  synthetic::SyntheticClipOptions o;
  o.frames = 0;
  CHECK_THROWS_AS((void)synthetic::make_synthetic_clip<float>(o), option_error);
  o = {};
  o.dome_radius = 3;
  CHECK_THROWS_AS((void)synthetic::make_synthetic_clip<float>(o), option_error);
}
