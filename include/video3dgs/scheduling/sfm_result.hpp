#pragma once
/// @file
/// What a structure-from-motion back end returns for one clip, and the concept a back end satisfies
/// to be driven by `schedule_clips` (scheduling/schedule_clips.hpp).
///
/// A back end is any callable `sfm(FrameRange) -> R` where R models `SfmResultLike`:
///
///     r.status        SfmStatus   success / soft_failure (growing the clip may help) / hard_error
///                                 (growing cannot help: a missing program, an unreadable frame, ...)
///     r.message       string      why, for a person (may be empty on success)
///     r.frames        sized range of int: the registered frames, as indices into the whole video
///     r.cameras       sized range: one camera per registered frame (same order as r.frames)
///     r.points        sized range: the reconstructed 3D points
///
/// `SfmResult<Scalar>` below is the concrete type the COLMAP adapter returns and later stages
/// consume; a test or another SfM program may return its own type with the same members.

#include <algorithm>
#include <array>
#include <cmath>
#include <concepts>
#include <cstdio>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "video3dgs/core/camera.hpp"

namespace video3dgs {

/// Outcome of one SfM attempt on one clip.
enum class SfmStatus {
  success,       ///< every frame registered and at least one 3D point (the back end decides)
  soft_failure,  ///< no usable reconstruction; a longer clip may succeed
  hard_error,    ///< retrying or growing the clip cannot help; the scheduler stops
};

[[nodiscard]] inline const char* to_string(SfmStatus s) noexcept {
  switch (s) {
    case SfmStatus::success: return "success";
    case SfmStatus::soft_failure: return "soft_failure";
    case SfmStatus::hard_error: return "hard_error";
  }
  return "unknown";
}

/// A contiguous, inclusive range of frames [first, last] of a video (0-based indices).
struct FrameRange {
  int first = 0;
  int last = -1;
  /// Number of frames, last - first + 1 (0 for an empty range).
  [[nodiscard]] int size() const noexcept { return last >= first ? last - first + 1 : 0; }
  [[nodiscard]] bool contains(int frame) const noexcept { return frame >= first && frame <= last; }
  friend bool operator==(const FrameRange&, const FrameRange&) = default;
};

/// A reconstructed 3D point (world frame of its clip).
template <class Scalar = double>
struct SfmPoint {
  Eigen::Matrix<Scalar, 3, 1> xyz = Eigen::Matrix<Scalar, 3, 1>::Zero();
  std::array<std::uint8_t, 3> rgb{0, 0, 0};  ///< colour, 0..255
  Scalar error = 0;                          ///< mean reprojection error in pixels
  int track_length = 0;                      ///< number of observations
};

/// One clip's reconstruction: registered frames with their cameras (COLMAP convention, world ->
/// camera R, t; pinhole intrinsics in pixels of the original frames) and the sparse points.
template <class Scalar = double>
struct SfmResult {
  SfmStatus status = SfmStatus::soft_failure;
  std::string message;
  FrameRange range;                      ///< the frames that were given to the back end
  std::vector<int> frames;               ///< registered frames (video indices), ascending
  std::vector<Camera<Scalar>> cameras;   ///< cameras[i] belongs to frames[i]
  std::vector<SfmPoint<Scalar>> points;  ///< sparse points
  std::filesystem::path model_dir;       ///< where the back end left its model (may be empty)

  /// Index into frames/cameras of a video frame, or -1 if that frame is not registered.
  [[nodiscard]] int index_of(int frame) const noexcept {
    for (std::size_t i = 0; i < frames.size(); ++i)
      if (frames[i] == frame) return static_cast<int>(i);
    return -1;
  }
  /// True if every frame of `range` is registered and there is at least one point.
  [[nodiscard]] bool complete() const noexcept {
    if (points.empty() || range.size() == 0) return false;
    for (int f = range.first; f <= range.last; ++f)
      if (index_of(f) < 0) return false;
    return true;
  }
};

using SfmResultD = SfmResult<double>;
using SfmResultF = SfmResult<float>;

/// What a clip's cameras must rest on before the scheduler trusts them (`ScheduleOptions::quality`;
/// every limit 0 = off, which is the method's rule: all frames registered and one point). Judged on
/// the result of a back end that said `success`:
///
///     points >= max(1, ceil(min_points_per_frame x frames of the range))
///     mean_i e_i <= max_reprojection_error      e_i: point i's mean reprojection error (pixels)
///     mean_i n_i >= min_track_length            n_i: point i's observations
///
/// The last two need points with members `error` and `track_length` (as SfmPoint has); for other
/// point types only the count is judged.
struct CameraQuality {
  double min_points_per_frame = 0;
  double max_reprojection_error = 0;  ///< pixels
  double min_track_length = 0;        ///< observations per point
};

/// The points a clip of `frames` frames needs under a floor of `per_frame` points per frame:
/// max(1, ceil(per_frame x frames)).
[[nodiscard]] inline std::size_t points_floor(double per_frame, int frames) noexcept {
  return std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(per_frame * double(frames))));
}

/// Mean over `points` of their mean reprojection errors (pixels; 0 for no points).
template <class Points>
[[nodiscard]] double mean_reprojection_error(const Points& points) {
  double e = 0;
  std::size_t n = 0;
  for (const auto& p : points) e += double(p.error), ++n;
  return n ? e / double(n) : 0.0;
}

/// Empty if `r` (the result for `range`) meets `q`, else what it misses, for a person.
template <class R>
[[nodiscard]] std::string camera_quality_shortfall(const R& r, FrameRange range, const CameraQuality& q) {
  auto fmt = [](double v) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%.3g", v);
    return std::string(buf);
  };
  const std::size_t n = std::size(r.points);
  if (q.min_points_per_frame > 0) {
    const std::size_t need = points_floor(q.min_points_per_frame, range.size());
    if (n < need)
      return std::to_string(n) + " 3D points, fewer than " + std::to_string(need) + " (min_points_per_frame " +
             fmt(q.min_points_per_frame) + " x " + std::to_string(range.size()) + " frames)";
  }
  if constexpr (requires {
                  double((*std::begin(r.points)).error);
                  double((*std::begin(r.points)).track_length);
                }) {
    if (n > 0 && (q.max_reprojection_error > 0 || q.min_track_length > 0)) {
      const double err = mean_reprojection_error(r.points);
      double track = 0;
      for (const auto& p : r.points) track += double(p.track_length);
      track /= double(n);
      if (q.max_reprojection_error > 0 && !(err <= q.max_reprojection_error))
        return "mean reprojection error " + fmt(err) + " px, above max_reprojection_error " + fmt(q.max_reprojection_error) + " px";
      if (q.min_track_length > 0 && !(track >= q.min_track_length))
        return "mean track length " + fmt(track) + ", below min_track_length " + fmt(q.min_track_length);
    }
  }
  return {};
}

/// What `schedule_clips` needs from a back end's result (see the file comment).
template <class R>
concept SfmResultLike = requires(const R& r) {
  { r.status } -> std::convertible_to<SfmStatus>;
  { r.message } -> std::convertible_to<std::string>;
  { std::size(r.frames) } -> std::convertible_to<std::size_t>;
  { *std::begin(r.frames) } -> std::convertible_to<int>;
  { std::size(r.cameras) } -> std::convertible_to<std::size_t>;
  { std::size(r.points) } -> std::convertible_to<std::size_t>;
};

/// A structure-from-motion back end: called with a frame range, returns an `SfmResultLike` value.
/// It may also throw (a `video3dgs::error`); the exception leaves `schedule_clips` unchanged.
template <class F>
concept SfmBackend = std::invocable<F&, FrameRange> &&
                     SfmResultLike<std::remove_cvref_t<std::invoke_result_t<F&, FrameRange>>>;

/// The result type of back end F.
template <class F>
using sfm_result_t = std::remove_cvref_t<std::invoke_result_t<F&, FrameRange>>;

}  // namespace video3dgs
