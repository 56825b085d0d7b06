#pragma once
/// @file
/// `make_synthetic_clip(options)`: a seeded synthetic video clip with exact ground truth, for tests,
/// benchmarks and the demo, without third-party data (world units, COLMAP camera convention):
///
///   object      a textured sphere of `object_gaussians` flat surface Gaussians (radius
///               `object_radius`, smooth two-colour bands), moving: at time t in [0, 1] it is
///               translated by motion (t - 1/2, -0.3 sin(pi t) motion / 2, 0) and spun by spin t about y;
///   background  a textured dome: `background_gaussians` flat Gaussians on the sphere of radius
///               `dome_radius` around the origin, facing inwards (smooth colour waves);
///   camera      on an arc of `arc_degrees` at distance `camera_distance` from the origin, looking at it;
///   time        t = i / (n - 1) for frame i of n; with `sweep_frames` = S > 1 the clip instead sweeps
///               back and forth, t rising from 0 to 1 over S frames and falling back over the next S - 1
///               (triangle wave of period 2 (S - 1)), so the motion per frame does not shrink as n grows;
///   frames      rendered by our rasterizer (black background), W x H x 3 in [0, 1];
///   masks       1 where the object alone has accumulated alpha > 0.5;
///   points      `foreground_points` object Gaussian centres at t = 0 plus N(0, point_noise^2) noise,
///               with their colours (an "SfM" point cloud of the foreground, canonical = t = 0 pose).
///
/// Uses `synthetic::Random` (scene.hpp) so the clip is the same on every platform for a seed.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numbers>
#include <type_traits>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "video3dgs/core/camera.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/gaussian/activations.hpp"
#include "video3dgs/gaussian/cloud.hpp"
#include "video3dgs/rasterizer/rasterizer.hpp"
#include "video3dgs/scheduling/sfm_result.hpp"
#include "video3dgs/synthetic/scene.hpp"

namespace video3dgs::synthetic {

struct SyntheticClipOptions {
  int frames = 10;
  int width = 128, height = 96;
  std::uint64_t seed = 1;
  int object_gaussians = 1200;
  int background_gaussians = 4000;
  double object_radius = 1.0;
  double dome_radius = 6.0;
  double motion = 0.6;             ///< object translation over the clip (world units)
  double spin_degrees = 20;        ///< object rotation over the clip
  double arc_degrees = 20;         ///< camera arc over the clip
  double camera_distance = 4.0;
  double fov_degrees = 60;
  double texture_frequency = 1.0;  ///< scales the texture patterns (higher = finer detail)
  int foreground_points = 400;
  double point_noise = 0.01;       ///< std of the point noise (world units)
  int sweep_frames = 0;            ///< frames of one sweep of t from 0 to 1 (0 = the whole clip)
};

/// Time t in [0, 1] of clip frame i (see the file comment).
[[nodiscard]] inline double synthetic_clip_time(const SyntheticClipOptions& o, int i) {
  const int s = o.sweep_frames > 1 ? o.sweep_frames : o.frames;
  if (s <= 1) return 0.0;
  const long long period = 2LL * (s - 1), u = i % period;
  return u <= s - 1 ? double(u) / double(s - 1) : double(period - u) / double(s - 1);
}

template <class Scalar>
struct SyntheticClip {
  std::vector<Image<Scalar, 3>> frames;
  std::vector<Image<Scalar, 1>> masks;   ///< 1 foreground, 0 background
  std::vector<Camera<Scalar>> cameras;
  std::vector<SfmPoint<double>> points;  ///< noisy foreground points (t = 0 pose)
  GaussianCloud<Scalar, 0> object, background;  ///< ground truth (object at t = 0)

  /// The clip as an SfM result (success, frames 0..n-1, exact cameras, the noisy points).
  [[nodiscard]] SfmResult<double> sfm_result() const {
    SfmResult<double> r;
    r.status = SfmStatus::success;
    r.range = {0, static_cast<int>(cameras.size()) - 1};
    for (std::size_t i = 0; i < cameras.size(); ++i) {
      r.frames.push_back(static_cast<int>(i));
      r.cameras.push_back(cameras[i].template cast<double>());
    }
    r.points = points;
    return r;
  }
};

namespace detail {
/// Flat disc Gaussian tangent to a sphere at unit normal n (thin along n).
template <class Scalar>
void surface_gaussian(Gaussian<Scalar, 0>& g, const Eigen::Vector3d& p, const Eigen::Vector3d& n, double tangent_sigma,
                      double normal_sigma, double opacity, const Eigen::Vector3d& rgb) {
  g.mean = {Scalar(p.x()), Scalar(p.y()), Scalar(p.z())};
  const auto q = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d(0, 0, 1), n);
  g.rotation = {Scalar(q.w()), Scalar(q.x()), Scalar(q.y()), Scalar(q.z())};
  g.log_scale = {Scalar(std::log(tangent_sigma)), Scalar(std::log(tangent_sigma)), Scalar(std::log(normal_sigma))};
  g.opacity_logit = logit(Scalar(opacity));
  g.set_rgb(Scalar(rgb.x()), Scalar(rgb.y()), Scalar(rgb.z()));
}
}  // namespace detail

/// Object pose at time t: x -> R_y(spin t) x + offset(t).
template <class Scalar>
void pose_object(const GaussianCloud<Scalar, 0>& canonical, GaussianCloud<Scalar, 0>& out, double t, const SyntheticClipOptions& o) {
  out = canonical;
  const double a = o.spin_degrees * std::numbers::pi / 180.0 * t;
  const Eigen::Quaterniond r(Eigen::AngleAxisd(a, Eigen::Vector3d::UnitY()));
  const Eigen::Vector3d off(o.motion * (t - 0.5), -0.15 * o.motion * std::sin(std::numbers::pi * t), 0.0);
  for (std::size_t i = 0; i < canonical.size(); ++i) {
    const Eigen::Vector3d p(canonical.mean[3 * i], canonical.mean[3 * i + 1], canonical.mean[3 * i + 2]);
    const Eigen::Vector3d q = r * p + off;
    for (int k = 0; k < 3; ++k) out.mean[3 * i + k] = Scalar(q[k]);
    const Eigen::Quaterniond g(canonical.rotation[4 * i], canonical.rotation[4 * i + 1], canonical.rotation[4 * i + 2],
                               canonical.rotation[4 * i + 3]);
    const Eigen::Quaterniond h = r * g;
    out.rotation[4 * i] = Scalar(h.w());
    out.rotation[4 * i + 1] = Scalar(h.x());
    out.rotation[4 * i + 2] = Scalar(h.y());
    out.rotation[4 * i + 3] = Scalar(h.z());
  }
}

/// Camera of clip frame i of n (see the file comment).
template <class Scalar>
[[nodiscard]] Camera<Scalar> synthetic_clip_camera(const SyntheticClipOptions& o, int i) {
  auto cam = Camera<Scalar>::from_fov(o.width, o.height, Scalar(o.fov_degrees * std::numbers::pi / 180.0));
  const double t = synthetic_clip_time(o, i);
  const double a = (t - 0.5) * o.arc_degrees * std::numbers::pi / 180.0;
  const double d = o.camera_distance;
  const typename Camera<Scalar>::Vec3 eye(Scalar(d * std::sin(a)), Scalar(-0.1 * d * (t - 0.5)), Scalar(-d * std::cos(a)));
  cam.look_at(eye, Camera<Scalar>::Vec3::Zero());
  return cam;
}

/// Generates the clip (see the file comment). With `on_frame`, each frame i is handed over as
/// on_frame(i, frame, mask) in order and not kept (clip.frames and clip.masks stay empty), so a long video
/// needs the memory of one frame. @throws option_error `option.synthetic` on bad options.
template <class Scalar = float, class OnFrame = std::nullptr_t>
[[nodiscard]] SyntheticClip<Scalar> make_synthetic_clip(const SyntheticClipOptions& o = {}, ThreadPool* pool = nullptr,
                                                        OnFrame&& on_frame = nullptr) {
  auto bad = [](const char* f, const char* why) { throw option_error("option.synthetic", f, why); };
  if (o.frames < 1) bad("frames", "must be >= 1");
  if (o.width < 1 || o.height < 1) bad("width/height", "must be >= 1");
  if (o.object_gaussians < 1 || o.background_gaussians < 1) bad("*_gaussians", "must be >= 1");
  if (!(o.object_radius > 0) || !(o.dome_radius > o.camera_distance + 0.5) || !(o.camera_distance > 2 * o.object_radius))
    bad("radii", "need object_radius > 0, camera_distance > 2 object_radius, dome_radius > camera_distance + 0.5");
  if (o.foreground_points < 0 || !(o.point_noise >= 0)) bad("foreground_points/point_noise", "must be >= 0");
  if (o.sweep_frames < 0) bad("sweep_frames", "must be >= 0");

  Random rnd(o.seed);
  SyntheticClip<Scalar> clip;
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  const double f = o.texture_frequency;
  Gaussian<Scalar, 0> g;
  // Object: smooth bands in latitude, modulated in longitude.
  {
    const int n = o.object_gaussians;
    const double spacing = o.object_radius * std::sqrt(4 * std::numbers::pi / n);
    for (int i = 0; i < n; ++i) {
      const double y = 1 - 2 * (i + 0.5) / n, r = std::sqrt(std::max(0.0, 1 - y * y)), phi = golden * i;
      const Eigen::Vector3d nrm(r * std::cos(phi), y, r * std::sin(phi));
      const double lat = std::asin(y), lon = std::atan2(nrm.z(), nrm.x());
      const double band = 0.5 + 0.5 * std::sin(f * (3.0 * lat + std::sin(2.0 * lon)) * 2.0);
      const double j = 0.02 * rnd.normal();
      const Eigen::Vector3d c = band * Eigen::Vector3d(0.9, 0.4, 0.15) + (1 - band) * Eigen::Vector3d(0.15, 0.35, 0.85) +
                                Eigen::Vector3d::Constant(j);
      detail::surface_gaussian(g, o.object_radius * nrm, nrm, 0.6 * spacing, 0.05 * spacing, 0.95, c);
      clip.object.push_back(g);
    }
  }
  // Dome: colour waves, facing inwards.
  {
    const int n = o.background_gaussians;
    const double spacing = o.dome_radius * std::sqrt(4 * std::numbers::pi / n);
    for (int i = 0; i < n; ++i) {
      const double y = 1 - 2 * (i + 0.5) / n, r = std::sqrt(std::max(0.0, 1 - y * y)), phi = golden * i;
      const Eigen::Vector3d nrm(r * std::cos(phi), y, r * std::sin(phi));
      const double lat = std::asin(y), lon = std::atan2(nrm.z(), nrm.x());
      const Eigen::Vector3d c(0.45 + 0.3 * std::sin(f * 4 * lon) * std::cos(f * 3 * lat), 0.5 + 0.25 * std::cos(f * 5 * lat + 1.0),
                              0.4 + 0.3 * std::sin(f * 3 * lon + f * 4 * lat) + 0.02 * rnd.normal());
      detail::surface_gaussian(g, o.dome_radius * nrm, -nrm, 0.7 * spacing, 0.05 * spacing, 0.98, c);
      clip.background.push_back(g);
    }
  }
  // Frames and masks.
  Rasterizer<Scalar> raster;  // images do not depend on the tile size: the default one
  RasterContext<Scalar, 3> ctx;
  GaussianCloud<Scalar, 0> posed, all;
  Image<Scalar, 3> frame;
  for (int i = 0; i < o.frames; ++i) {
    const Camera<Scalar> cam = synthetic_clip_camera<Scalar>(o, i);
    pose_object(clip.object, posed, synthetic_clip_time(o, i), o);
    all = posed;
    for (std::size_t k = 0; k < clip.background.size(); ++k) all.push_back(clip.background.get(k));
    raster.forward(cam, all.params(), ctx, pool);
    frame = ctx.image;
    raster.forward(cam, posed.params(), ctx, pool);
    Image<Scalar, 1> mask(o.width, o.height);
    for (std::size_t p = 0; p < mask.size(); ++p) mask.data()[p] = ctx.alpha.data()[p] > Scalar(0.5) ? Scalar(1) : Scalar(0);
    if constexpr (std::is_same_v<std::remove_cvref_t<OnFrame>, std::nullptr_t>) {
      clip.frames.push_back(std::move(frame));
      clip.masks.push_back(std::move(mask));
    } else {
      on_frame(i, std::as_const(frame), std::as_const(mask));
    }
    clip.cameras.push_back(cam);
  }
  // Noisy foreground points (t = 0 pose of the object).
  pose_object(clip.object, posed, 0.0, o);
  const int np = std::min(o.foreground_points, o.object_gaussians);
  for (int k = 0; k < np; ++k) {
    const std::size_t i = static_cast<std::size_t>((static_cast<long long>(k) * o.object_gaussians) / std::max(np, 1));
    SfmPoint<double> p;
    for (int d = 0; d < 3; ++d) p.xyz[d] = double(posed.mean[3 * i + d]) + o.point_noise * rnd.normal();
    for (int c = 0; c < 3; ++c) {
      const double v = std::clamp(double(sh::dc_to_rgb(posed.sh[c])), 0.0, 1.0);
      p.rgb[std::size_t(c)] = static_cast<std::uint8_t>(std::lround(255 * v));
    }
    p.track_length = 2;
    clip.points.push_back(p);
  }
  return clip;
}

}  // namespace video3dgs::synthetic
