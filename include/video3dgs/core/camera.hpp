#pragma once
/// @file
/// `Camera<Scalar>`: a pinhole camera in the COLMAP / OpenCV convention.
///
///   x_c = R x_w + t            (world -> camera; +z forward, +x right, +y down)
///   u   = fx x_c/z_c + cx,  v = fy y_c/z_c + cy      (pixel coordinates)
///
/// Pixel (i, j) covers [i, i+1) x [j, j+1); its centre is at (i + 0.5, j + 0.5). So a camera with
/// cx = width/2 looks through the centre of the image. Lens distortion is not modelled here: the
/// COLMAP adapter undistorts or rejects distorted models, never ignores them.

#include <algorithm>
#include <cmath>
#include <string>
#include <type_traits>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/scalar_traits.hpp"

namespace video3dgs {

template <class Scalar>
struct Camera {
  static_assert(std::is_floating_point_v<Scalar>, "video3dgs: Camera<Scalar> needs a floating-point Scalar");
  using Vec2 = Eigen::Matrix<Scalar, 2, 1>;
  using Vec3 = Eigen::Matrix<Scalar, 3, 1>;
  using Mat3 = Eigen::Matrix<Scalar, 3, 3>;

  int width = 0;
  int height = 0;
  Scalar fx = 1, fy = 1, cx = 0, cy = 0;
  Mat3 R = Mat3::Identity();  ///< world -> camera rotation
  Vec3 t = Vec3::Zero();      ///< world -> camera translation

  /// A camera at the world origin looking down +z with the given field of view in x (radians).
  [[nodiscard]] static Camera from_fov(int width, int height, Scalar fov_x) {
    Camera c;
    c.width = width;
    c.height = height;
    c.fx = c.fy = Scalar(0.5) * Scalar(width) / std::tan(Scalar(0.5) * fov_x);
    c.cx = Scalar(0.5) * Scalar(width);
    c.cy = Scalar(0.5) * Scalar(height);
    return c;
  }

  /// Pose from a COLMAP quaternion (qw, qx, qy, qz) and translation (world -> camera).
  void set_pose(const Eigen::Quaternion<Scalar>& q_world_to_camera, const Vec3& translation) {
    R = q_world_to_camera.normalized().toRotationMatrix();
    t = translation;
  }
  /// Places the camera at `eye` looking at `target`, with `up` (world) roughly towards -y of the image.
  void look_at(const Vec3& eye, const Vec3& target, const Vec3& up = Vec3(0, -1, 0)) {
    const Vec3 z = (target - eye).normalized();
    Vec3 x = (-up).cross(z);  // image +x (right), with image +y (down) along -up
    if (x.norm() < Scalar(1e-12)) x = z.unitOrthogonal();
    x.normalize();
    const Vec3 y = z.cross(x);
    R.row(0) = x.transpose();
    R.row(1) = y.transpose();
    R.row(2) = z.transpose();
    t = -R * eye;
  }

  [[nodiscard]] Vec3 world_to_camera(const Vec3& xw) const { return R * xw + t; }
  [[nodiscard]] Vec3 camera_to_world(const Vec3& xc) const { return R.transpose() * (xc - t); }
  /// Camera centre in world coordinates, -R^T t.
  [[nodiscard]] Vec3 center() const { return -(R.transpose() * t); }

  /// Camera coordinates -> pixel coordinates (z must be > 0).
  [[nodiscard]] Vec2 camera_to_pixel(const Vec3& xc) const {
    return Vec2(fx * xc.x() / xc.z() + cx, fy * xc.y() / xc.z() + cy);
  }
  /// Pixel coordinates and depth (z_c) -> camera coordinates.
  [[nodiscard]] Vec3 pixel_to_camera(const Vec2& uv, Scalar depth) const {
    return Vec3((uv.x() - cx) / fx * depth, (uv.y() - cy) / fy * depth, depth);
  }
  [[nodiscard]] Vec2 world_to_pixel(const Vec3& xw) const { return camera_to_pixel(world_to_camera(xw)); }
  [[nodiscard]] Vec3 pixel_to_world(const Vec2& uv, Scalar depth) const { return camera_to_world(pixel_to_camera(uv, depth)); }
  /// Unit ray direction (world) through pixel coordinates uv.
  [[nodiscard]] Vec3 ray_direction(const Vec2& uv) const {
    return (R.transpose() * pixel_to_camera(uv, Scalar(1))).normalized();
  }

  /// tan of half the field of view in x and y (used by the rasterizer's Jacobian clamp).
  [[nodiscard]] Scalar tan_half_fov_x() const { return Scalar(0.5) * Scalar(width) / fx; }
  [[nodiscard]] Scalar tan_half_fov_y() const { return Scalar(0.5) * Scalar(height) / fy; }

  /// The same camera for an image resized by `s` (intrinsics scale; pixel-centre convention kept).
  [[nodiscard]] Camera scaled(Scalar s) const {
    return resized(std::max(1, static_cast<int>(std::lround(Scalar(width) * s))), std::max(1, static_cast<int>(std::lround(Scalar(height) * s))));
  }
  /// The same camera for the image resampled to w x h (`resize_area`, core/resample.hpp): pixel i
  /// covers [i, i + 1) in both, so continuous pixel coordinates scale by sx = w / width and
  /// sy = h / height (fx, cx by sx; fy, cy by sy) and every point projects to the same place
  /// relative to the image.
  /// @throws option_error `option.size` unless w, h >= 1.
  [[nodiscard]] Camera resized(int w, int h) const {
    if (w < 1 || h < 1) throw option_error("option.size", "camera.resized", "sizes must be >= 1");
    Camera c = *this;
    c.width = w;
    c.height = h;
    const Scalar sx = Scalar(w) / Scalar(width), sy = Scalar(h) / Scalar(height);
    c.fx *= sx; c.cx *= sx;
    c.fy *= sy; c.cy *= sy;
    return c;
  }

  /// The same camera for the window [x, x + w) x [y, y + h) of its image: the principal point moves
  /// by (-x, -y), so a point at pixel coordinates (u, v) lands at (u - x, v - y) of the window.
  /// @throws option_error `option.size` unless w, h >= 1.
  [[nodiscard]] Camera cropped(int x, int y, int w, int h) const {
    if (w < 1 || h < 1) throw option_error("option.size", "camera.cropped", "sizes must be >= 1");
    Camera c = *this;
    c.width = w;
    c.height = h;
    c.cx -= Scalar(x);
    c.cy -= Scalar(y);
    return c;
  }

  /// The camera that sees the world as this one sees it after the rigid move
  ///   T(x) = o + E (x - o) + tau,   E = exp([omega]x) (rotation vector omega), o = center():
  /// R' = R E, t' = t + R (tau + o - E o), so R' x + t' = R T(x) + t for every x. R' is
  /// re-orthonormalised (through a unit quaternion): repeated moves do not drift off SO(3).
  [[nodiscard]] Camera world_moved(const Vec3& omega, const Vec3& tau) const {
    const Scalar angle = omega.norm();
    const Mat3 E = angle > Scalar(0) ? Mat3(Eigen::AngleAxis<Scalar>(angle, omega / angle)) : Mat3::Identity();
    const Vec3 o = center();
    Camera c = *this;
    c.R = Eigen::Quaternion<Scalar>(R * E).normalized().toRotationMatrix();
    c.t = t + R * (tau + o - E * o);
    return c;
  }

  template <class Other>
  [[nodiscard]] Camera<Other> cast() const {
    Camera<Other> c;
    c.width = width; c.height = height;
    c.fx = Other(fx); c.fy = Other(fy); c.cx = Other(cx); c.cy = Other(cy);
    c.R = R.template cast<Other>();
    c.t = t.template cast<Other>();
    return c;
  }

  /// Throws `option.camera` naming the field if the camera cannot be used.
  void validate(const char* where = "camera") const {
    auto bad = [&](const char* field, const char* why) { throw option_error("option.camera", std::string(where) + "." + field, why); };
    if (width <= 0 || height <= 0) bad("width/height", "image size must be positive");
    if (!(std::isfinite(fx) && fx > 0)) bad("fx", "focal length must be finite and positive");
    if (!(std::isfinite(fy) && fy > 0)) bad("fy", "focal length must be finite and positive");
    if (!std::isfinite(cx)) bad("cx", "principal point must be finite");
    if (!std::isfinite(cy)) bad("cy", "principal point must be finite");
    if (!R.allFinite()) bad("R", "rotation must be finite");
    if (!t.allFinite()) bad("t", "translation must be finite");
    const Scalar orth = (R * R.transpose() - Mat3::Identity()).cwiseAbs().maxCoeff();
    if (orth > Scalar(1e-3)) bad("R", "rotation is not orthonormal (|R R^T - I| > 1e-3)");
    if (R.determinant() < 0) bad("R", "rotation has determinant -1 (a reflection)");
  }
};

using CameraF = Camera<float>;
using CameraD = Camera<double>;

}  // namespace video3dgs
