// make_synthetic_clip: determinism, shapes, masks that match the object, noisy points near it, an
// SfM result the clip model accepts, option errors.
#include <cmath>
#include <numbers>

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
    double area = 0;
    for (std::size_t p = 0; p < a.masks[i].size(); ++p) area += a.masks[i].data()[p];
    area /= double(a.masks[i].size());
    CHECK(area > 0.05);  // the object is visible...
    CHECK(area < 0.6);   // ... and so is the background
    // The mask is the object: the sphere of radius object_radius centred at the pose's offset
    // (motion (t - 1/2), -0.15 motion sin(pi t), 0), t = i / (n - 1), seen as a disc of radius
    // rho = f R / sqrt(z^2 - R^2) around the projected centre. Full inside 0.8 rho, empty outside
    // 1.2 rho + 1 px (the surface Gaussians blur the silhouette), area within 15 % of the disc's.
    const double t = double(i) / 3.0;
    const Eigen::Vector3f c(float(o.motion * (t - 0.5)), float(-0.15 * o.motion * std::sin(std::numbers::pi * t)), 0.f);
    const auto& cam = a.cameras[std::size_t(i)];
    const auto uv = cam.world_to_pixel(c);
    const double z = double((cam.R * c + cam.t).z());
    const double rho = double(cam.fx) * o.object_radius / std::sqrt(z * z - o.object_radius * o.object_radius);
    std::size_t inside_off = 0, outside_on = 0;
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 64; ++x) {
        const double r = std::hypot(x + 0.5 - double(uv.x()), y + 0.5 - double(uv.y()));
        const bool on = a.masks[std::size_t(i)](x, y, 0) > 0.5f;
        if (r < 0.8 * rho && !on) ++inside_off;
        if (r > 1.2 * rho + 1 && on) ++outside_on;
      }
    const double disc = std::numbers::pi * rho * rho / (64.0 * 48.0);
    INFO("frame " << i << ": mask area " << area << ", disc " << disc << ", rho " << rho);
    CHECK(inside_off == 0);
    CHECK(outside_on == 0);
    CHECK(area == doctest::Approx(disc).epsilon(0.15));
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

TEST_CASE("make_synthetic_clip: sweeps back and forth every sweep_frames frames; frames handed over one by one") {
  synthetic::SyntheticClipOptions o;
  o.frames = 9;
  o.sweep_frames = 4;  // t: 0 1/3 2/3 1 2/3 1/3 0 1/3 2/3
  o.width = 40;
  o.height = 30;
  o.object_gaussians = 300;
  o.background_gaussians = 800;
  const double expect[] = {0, 1. / 3, 2. / 3, 1, 2. / 3, 1. / 3, 0, 1. / 3, 2. / 3};
  for (int i = 0; i < 9; ++i) CHECK(synthetic::synthetic_clip_time(o, i) == doctest::Approx(expect[i]).epsilon(1e-15));
  const auto kept = synthetic::make_synthetic_clip<float>(o);
  REQUIRE(kept.frames.size() == 9);
  // Same t, same picture: frames 1, 5 and 7 are one frame; 0 and 6 too; so the sweep repeats exactly.
  CHECK(kept.frames[1].storage() == kept.frames[5].storage());
  CHECK(kept.frames[1].storage() == kept.frames[7].storage());
  CHECK(kept.frames[0].storage() == kept.frames[6].storage());
  CHECK(kept.masks[2].storage() == kept.masks[8].storage());
  CHECK(kept.frames[0].storage() != kept.frames[1].storage());
  // The first sweep is the 4-frame clip without sweeps.
  synthetic::SyntheticClipOptions short_clip = o;
  short_clip.frames = 4;
  short_clip.sweep_frames = 0;
  const auto once = synthetic::make_synthetic_clip<float>(short_clip);
  for (int i = 0; i < 4; ++i) CHECK(once.frames[std::size_t(i)].storage() == kept.frames[std::size_t(i)].storage());
  // With a sink the frames arrive in order, equal to the kept ones, and the clip holds none.
  int next = 0;
  const auto streamed = synthetic::make_synthetic_clip<float>(o, nullptr, [&](int i, const Image<float, 3>& f, const Image<float, 1>& m) {
    CHECK(i == next++);
    CHECK(f.storage() == kept.frames[std::size_t(i)].storage());
    CHECK(m.storage() == kept.masks[std::size_t(i)].storage());
  });
  CHECK(next == 9);
  CHECK(streamed.frames.empty());
  CHECK(streamed.cameras.size() == 9);
  CHECK(streamed.sfm_result().range.last == 8);
}

TEST_CASE("make_synthetic_clip: option errors") {
  synthetic::SyntheticClipOptions o;
  o.frames = 0;
  CHECK_THROWS_AS((void)synthetic::make_synthetic_clip<float>(o), option_error);
  o = {};
  o.dome_radius = 3;
  CHECK_THROWS_AS((void)synthetic::make_synthetic_clip<float>(o), option_error);
  o = {};
  o.sweep_frames = -1;
  CHECK_THROWS_AS((void)synthetic::make_synthetic_clip<float>(o), option_error);
}
