#pragma once
/// @file
/// COLMAP records -> video3dgs types: `Camera<Scalar>` per image and `SfmResult<Scalar>` per model.
///
/// Intrinsics: SIMPLE_PINHOLE (f, cx, cy) gives fx = fy = f; PINHOLE (fx, fy, cx, cy) maps directly.
/// Every other model has lens distortion, which `Camera` does not represent: such a camera is
/// rejected with `[colmap.distorted_camera]` (undistort the model first with `undistort_model`,
/// colmap/undistort.hpp, i.e. `colmap image_undistorter`). The one exception is a distorted model
/// whose distortion parameters are all exactly 0, which *is* a pinhole camera and converts exactly.
/// Both COLMAP and video3dgs put the centre of the top-left pixel at (0.5, 0.5), so cx, cy carry over.

#include <algorithm>
#include <cmath>
#include <functional>
#include <optional>
#include <string>

#include <Eigen/Geometry>

#include "video3dgs/colmap/model.hpp"
#include "video3dgs/core/camera.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/scheduling/sfm_result.hpp"

namespace video3dgs::colmap {

/// Pinhole intrinsics of a COLMAP camera.
/// @throws error `colmap.distorted_camera` for a model with non-zero distortion,
///         io_error `colmap.malformed` for a wrong parameter count or unknown model.
template <class Scalar = double>
[[nodiscard]] Camera<Scalar> to_intrinsics(const CameraRecord& c) {
  const CameraModelInfo* m = find_camera_model(c.model_id);
  const std::string where = "camera " + std::to_string(c.id);
  if (!m) throw io_error("colmap.malformed", where, "unknown camera model id " + std::to_string(c.model_id));
  if (c.params.size() != static_cast<std::size_t>(m->num_params))
    throw io_error("colmap.malformed", where, std::string(m->name) + " needs " + std::to_string(m->num_params) + " params");
  const int nf = m->num_focal_params;
  const bool distortion_free =
      std::all_of(c.params.begin() + nf + 2, c.params.end(), [](double p) { return p == 0.0; });
  if (!m->pinhole && !distortion_free) {
    std::string values;
    for (std::size_t i = static_cast<std::size_t>(nf + 2); i < c.params.size(); ++i) values += (values.empty() ? "" : ", ") + std::to_string(c.params[i]);
    throw error("colmap.distorted_camera", where,
                std::string("model ") + m->name + " has lens distortion (" + values + ") that a pinhole Camera cannot represent; "
                "undistort the model first (video3dgs::colmap::undistort_model, or `colmap image_undistorter "
                "--output_type COLMAP`), or reconstruct with SIMPLE_PINHOLE/PINHOLE");
  }
  Camera<Scalar> cam;
  cam.width = static_cast<int>(c.width);
  cam.height = static_cast<int>(c.height);
  cam.fx = Scalar(c.params[0]);
  cam.fy = Scalar(nf == 2 ? c.params[1] : c.params[0]);
  cam.cx = Scalar(c.params[static_cast<std::size_t>(nf)]);
  cam.cy = Scalar(c.params[static_cast<std::size_t>(nf + 1)]);
  return cam;
}

/// The full camera (intrinsics + world -> camera pose) of an image.
/// @throws as `to_intrinsics`; io_error `colmap.malformed` if the image's camera is missing.
template <class Scalar = double>
[[nodiscard]] Camera<Scalar> to_camera(const Model& model, const ImageRecord& image) {
  auto it = model.cameras.find(image.camera_id);
  if (it == model.cameras.end())
    throw io_error("colmap.malformed", "image " + std::to_string(image.id) + " '" + image.name + "'",
                   "camera " + std::to_string(image.camera_id) + " does not exist");
  Camera<Scalar> cam = to_intrinsics<Scalar>(it->second);
  const Eigen::Quaternion<Scalar> q(Scalar(image.qvec[0]), Scalar(image.qvec[1]), Scalar(image.qvec[2]), Scalar(image.qvec[3]));
  cam.set_pose(q, typename Camera<Scalar>::Vec3(Scalar(image.tvec[0]), Scalar(image.tvec[1]), Scalar(image.tvec[2])));
  return cam;
}

/// A model as an `SfmResult`: registered frames (via `frame_of(image name)`, which returns the video
/// frame index or nullopt to skip the image), one camera per frame in ascending frame order, and every
/// 3D point with its colour, error and track length. Status: success if every frame of `range` is
/// registered and there is at least one point, otherwise soft_failure with a message saying what is
/// missing.
template <class Scalar = double>
[[nodiscard]] SfmResult<Scalar> to_sfm_result(const Model& model, FrameRange range,
                                              const std::function<std::optional<int>(const std::string&)>& frame_of) {
  SfmResult<Scalar> r;
  r.range = range;
  std::vector<std::pair<int, const ImageRecord*>> reg;
  for (const auto& [id, im] : model.images)
    if (auto f = frame_of(im.name)) reg.emplace_back(*f, &im);
  std::sort(reg.begin(), reg.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& [f, im] : reg) {
    if (!r.frames.empty() && r.frames.back() == f)
      throw io_error("colmap.malformed", im->name, "two images map to frame " + std::to_string(f));
    r.frames.push_back(f);
    r.cameras.push_back(to_camera<Scalar>(model, *im));
  }
  r.points.reserve(model.points.size());
  for (const auto& [id, p] : model.points) {
    SfmPoint<Scalar> q;
    q.xyz = Eigen::Matrix<Scalar, 3, 1>(Scalar(p.xyz[0]), Scalar(p.xyz[1]), Scalar(p.xyz[2]));
    q.rgb = p.rgb;
    q.error = Scalar(p.error);
    q.track_length = static_cast<int>(p.track.size());
    r.points.push_back(q);
  }
  if (r.complete()) {
    r.status = SfmStatus::success;
  } else {
    r.status = SfmStatus::soft_failure;
    int missing = 0;
    for (int f = range.first; f <= range.last; ++f) missing += r.index_of(f) < 0 ? 1 : 0;
    r.message = std::to_string(range.size() - missing) + " of " + std::to_string(range.size()) + " frames registered, " +
                std::to_string(r.points.size()) + " points";
  }
  return r;
}

}  // namespace video3dgs::colmap
