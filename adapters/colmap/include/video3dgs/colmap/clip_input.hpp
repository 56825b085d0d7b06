#pragma once
/// @file
/// A real clip for training outside `video3dgs reconstruct` (benchmarks, `video3dgs trade`): frames
/// first..last of a frame folder, their masks, and the cameras and points of a COLMAP model that
/// registers every one of them, so SfM is not run again.
///
///     auto clip = colmap::load_clip_input("frames/", "masks/", "out/sfm/frames_00000_00009/model", {0, 9});
///     auto model = make_clip_model<float>(clip.sfm, {}, clip.masks);
///
/// Frame f of the video is the f-th file of the folder in natural order (io::list_frames). An image of
/// the model maps to frame f when its name is the number f (000007.jpg: ColmapSfm's names) or, failing
/// that, when it is the name of frame f's file. With `scale` < 1 the frames (and masks) are resampled
/// area-weighted to round(scale x size) and the cameras follow (Camera::resized: pixel centres stay at
/// +0.5).
///
/// Errors: `option.range` (a range outside the folder, a scale outside (0, 1]), `io.incomplete` (the
/// model does not register a frame of the range, naming the model folder), the errors of
/// io::list_frames, io::read_frames and colmap::read_model.

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "video3dgs/colmap/convert.hpp"
#include "video3dgs/colmap/model_io.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/core/resample.hpp"
#include "video3dgs/io/frame_folder.hpp"
#include "video3dgs/scheduling/sfm_result.hpp"

namespace video3dgs::colmap {

struct ClipInput {
  SfmResult<double> sfm;                    ///< cameras at the training size, points in world units
  std::vector<Image<float, 3>> frames;      ///< one per frame of the range, at the training size
  std::vector<Image<float, 1>> masks;       ///< empty without a mask folder
  int source_width = 0, source_height = 0;  ///< the files' size
};

/// @param range frames of the folder (last = -1: to the last file)
/// @param scale training size = round(scale x file size), in (0, 1]
[[nodiscard]] inline ClipInput load_clip_input(const std::filesystem::path& frames_dir, const std::filesystem::path& masks_dir,
                                               const std::filesystem::path& sparse_dir, FrameRange range, double scale = 1.0,
                                               ThreadPool* pool = nullptr) {
  if (!(scale > 0 && scale <= 1)) throw option_error("option.range", "scale", "must be in (0, 1]");
  const io::FrameList list = io::list_frames(frames_dir, masks_dir);
  const int n = static_cast<int>(list.frames.size());
  if (range.last < 0) range.last = n - 1;
  if (range.first < 0 || range.last >= n || range.first > range.last)
    throw option_error("option.range", "frames " + std::to_string(range.first) + "-" + std::to_string(range.last),
                       "outside the folder's " + std::to_string(n) + " frames");
  const Model model = read_model(sparse_dir);
  ClipInput out;
  out.sfm = to_sfm_result<double>(model, range, [&](const std::string& name) -> std::optional<int> {
    const std::string stem = name.substr(0, name.find('.'));
    if (!stem.empty() && stem.size() < 10 && stem.find_first_not_of("0123456789") == std::string::npos) return std::stoi(stem);
    for (int i = 0; i < n; ++i)
      if (list.frames[std::size_t(i)].filename().string() == name) return i;
    return std::nullopt;
  });
  for (int f = range.first; f <= range.last; ++f)
    if (out.sfm.index_of(f) < 0) throw io_error("io.incomplete", sparse_dir.string(), "does not register frame " + std::to_string(f));
  io::FrameList clip = list;
  clip.frames.assign(list.frames.begin() + range.first, list.frames.begin() + range.last + 1);
  if (!clip.masks.empty()) clip.masks.assign(list.masks.begin() + range.first, list.masks.begin() + range.last + 1);
  out.frames = io::read_frames(clip, pool);
  out.masks = io::read_masks(clip, pool);
  out.source_width = out.frames.front().width();
  out.source_height = out.frames.front().height();
  const int W = std::max(1, static_cast<int>(std::lround(out.source_width * scale)));
  const int H = std::max(1, static_cast<int>(std::lround(out.source_height * scale)));
  if (W != out.source_width || H != out.source_height) {
    for (auto& f : out.frames) f = resize_area(f, W, H);
    for (auto& m : out.masks) m = resize_area(m, W, H);
  }
  for (auto& c : out.sfm.cameras) c = c.resized(W, H);
  return out;
}

}  // namespace video3dgs::colmap
