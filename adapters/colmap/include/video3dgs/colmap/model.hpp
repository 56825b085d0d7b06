#pragma once
/// @file
/// A COLMAP sparse model in memory: cameras, images (poses + 2D points) and 3D points, exactly as
/// COLMAP stores them (cameras.{txt,bin}, images.{txt,bin}, points3D.{txt,bin}), plus the table of
/// COLMAP's camera models with their parameter counts.
///
/// Conventions (COLMAP's): an image's pose is world -> camera, quaternion (qw, qx, qy, qz) and
/// translation t, x_c = R(q) x_w + t. Pixel coordinates have their origin at the image's top-left
/// corner, the centre of the top-left pixel at (0.5, 0.5) — the same as video3dgs::Camera.

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

namespace video3dgs::colmap {

/// One of COLMAP's camera models.
struct CameraModelInfo {
  int id;                 ///< COLMAP's model id (cameras.bin)
  const char* name;       ///< COLMAP's model name (cameras.txt)
  int num_params;         ///< parameter count
  const char* params;     ///< parameter names, comma separated
  int num_focal_params;   ///< 1 (f) or 2 (fx, fy); the parameters start with focal(s), cx, cy
  bool pinhole;           ///< no distortion parameters at all
};

/// COLMAP's camera models (ids 0-10 as in COLMAP 3.8; id 11 added in later COLMAP versions).
inline constexpr std::array<CameraModelInfo, 12> kCameraModels{{
    {0, "SIMPLE_PINHOLE", 3, "f,cx,cy", 1, true},
    {1, "PINHOLE", 4, "fx,fy,cx,cy", 2, true},
    {2, "SIMPLE_RADIAL", 4, "f,cx,cy,k", 1, false},
    {3, "RADIAL", 5, "f,cx,cy,k1,k2", 1, false},
    {4, "OPENCV", 8, "fx,fy,cx,cy,k1,k2,p1,p2", 2, false},
    {5, "OPENCV_FISHEYE", 8, "fx,fy,cx,cy,k1,k2,k3,k4", 2, false},
    {6, "FULL_OPENCV", 12, "fx,fy,cx,cy,k1,k2,p1,p2,k3,k4,k5,k6", 2, false},
    {7, "FOV", 5, "fx,fy,cx,cy,omega", 2, false},
    {8, "SIMPLE_RADIAL_FISHEYE", 4, "f,cx,cy,k", 1, false},
    {9, "RADIAL_FISHEYE", 5, "f,cx,cy,k1,k2", 1, false},
    {10, "THIN_PRISM_FISHEYE", 12, "fx,fy,cx,cy,k1,k2,p1,p2,k3,k4,sx1,sy1", 2, false},
    {11, "RAD_TAN_THIN_PRISM_FISHEYE", 16, "fx,fy,cx,cy,k0,k1,k2,k3,k4,k5,p0,p1,s0,s1,s2,s3", 2, false},
}};

/// The model with COLMAP id `id`, or nullptr.
[[nodiscard]] inline const CameraModelInfo* find_camera_model(int id) noexcept {
  for (const auto& m : kCameraModels)
    if (m.id == id) return &m;
  return nullptr;
}
/// The model called `name` (exact, upper case as COLMAP writes it), or nullptr.
[[nodiscard]] inline const CameraModelInfo* find_camera_model(std::string_view name) noexcept {
  for (const auto& m : kCameraModels)
    if (name == m.name) return &m;
  return nullptr;
}

/// A row of cameras.{txt,bin}.
struct CameraRecord {
  std::uint32_t id = 0;
  int model_id = 0;  ///< see kCameraModels
  std::uint64_t width = 0;
  std::uint64_t height = 0;
  std::vector<double> params;  ///< find_camera_model(model_id)->num_params values

  friend bool operator==(const CameraRecord&, const CameraRecord&) = default;
};

/// "No 3D point" in ImageRecord::point3D_ids (COLMAP writes -1 in text, 2^64-1 in binary).
inline constexpr std::int64_t kNoPoint3D = -1;

/// An image of images.{txt,bin}: its pose and its 2D feature points.
struct ImageRecord {
  std::uint32_t id = 0;
  std::array<double, 4> qvec{1, 0, 0, 0};  ///< world -> camera rotation (qw, qx, qy, qz)
  std::array<double, 3> tvec{0, 0, 0};     ///< world -> camera translation
  std::uint32_t camera_id = 0;
  std::string name;                             ///< path relative to the image folder
  std::vector<std::array<double, 2>> points2D;  ///< pixel coordinates (x, y)
  std::vector<std::int64_t> point3D_ids;        ///< per 2D point, kNoPoint3D if none

  friend bool operator==(const ImageRecord&, const ImageRecord&) = default;
};

/// One observation of a 3D point: image id and index into that image's points2D.
struct TrackElement {
  std::uint32_t image_id = 0;
  std::uint32_t point2D_idx = 0;
  friend bool operator==(const TrackElement&, const TrackElement&) = default;
};

/// A row of points3D.{txt,bin}.
struct Point3DRecord {
  std::uint64_t id = 0;
  std::array<double, 3> xyz{0, 0, 0};
  std::array<std::uint8_t, 3> rgb{0, 0, 0};
  double error = 0;  ///< mean reprojection error (pixels)
  std::vector<TrackElement> track;

  friend bool operator==(const Point3DRecord&, const Point3DRecord&) = default;
};

/// A whole sparse model, keyed by id (so iteration and writing are in id order).
struct Model {
  std::map<std::uint32_t, CameraRecord> cameras;
  std::map<std::uint32_t, ImageRecord> images;
  std::map<std::uint64_t, Point3DRecord> points;

  friend bool operator==(const Model&, const Model&) = default;

  /// The image called `name`, or nullptr.
  [[nodiscard]] const ImageRecord* find_image(std::string_view name) const noexcept {
    for (const auto& [id, im] : images)
      if (im.name == name) return &im;
    return nullptr;
  }
};

}  // namespace video3dgs::colmap
