#pragma once
/// @file
/// `VideoModel<Scalar, SHDegree, Field>`: a whole video as the clips' `ClipModel`s plus the schedule
/// (each clip's frame range). Renders any frame; saved and loaded as a folder.
///
/// Overlaps. MC-COLMAP's clips share frames (>= 1 per boundary; more when the last clip is extended
/// backwards). A frame f covered by several clips is the normalised weighted sum of their renders
/// (image space, each clip in its own world frame):
///
///     I_f = sum_c w_c(f) I_c(f) / sum_c w_c(f)
///     w_c(f) = 1 + min(d_first, d_last),  d_first = f - first_c (infinite if first_c = 0),
///                                          d_last  = last_c - f  (infinite if last_c = N - 1)
///
/// (infinities capped at N). For two clips overlapping on [a, b] (the later starts at a, the earlier
/// ends at b) and clips longer than the overlap this is the linear cross-fade
/// w_later = (f - a + 1) / (b - a + 2): each clip fades out towards its own boundary, so a clip
/// boundary never switches models from one frame to the next (the reference overwrites the overlap
/// with the later clip, which flickers). A frame covered by one clip is that clip's render.
///
/// Folder layout (`save_video_model` / `load_video_model`):
///
///     DIR/manifest.txt     "video3dgs-video-model 1", then "frames N", "width W", "height H",
///                          "clips K", and K lines "clip <first> <last> <file>"
///     DIR/clip_000.model   one `save_clip_model` file per clip (model/clip_model_io.hpp)
///
/// Every file is written atomically; the manifest last, so a folder with a manifest is complete.
/// `VideoModelFolder` renders from such a folder holding only the clips of the frame at hand.
/// Errors: `io.missing` (no manifest), `io.format` (malformed manifest, clips that do not cover the
/// frames in order, a clip file whose range or size disagrees), and the clip files' `io.*`.

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/gaussian/cloud.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/model/clip_model_io.hpp"
#include "video3dgs/model/render_clip.hpp"

namespace video3dgs {

inline constexpr const char* kVideoModelManifest = "manifest.txt";
inline constexpr const char* kVideoModelHeader = "video3dgs-video-model 1";

/// One clip's share of a frame: its index and normalised blend weight.
struct ClipWeight {
  int clip = 0;
  double weight = 0;
};

/// Blend weights of frame f for clips with ranges `ranges` in a video of `frame_count` frames (see
/// the file comment). Weights of the covering clips sum to 1; the result is empty if no clip covers f.
[[nodiscard]] inline std::vector<ClipWeight> blend_weights(const std::vector<FrameRange>& ranges, int frame_count, int f) {
  std::vector<ClipWeight> w;
  const double cap = std::max(frame_count, 1);
  double sum = 0;
  for (std::size_t c = 0; c < ranges.size(); ++c) {
    const FrameRange r = ranges[c];
    if (!r.contains(f)) continue;
    const double d_first = r.first == 0 ? cap : double(f - r.first);
    const double d_last = r.last >= frame_count - 1 ? cap : double(r.last - f);
    const double v = 1.0 + std::min(d_first, d_last);
    w.push_back({static_cast<int>(c), v});
    sum += v;
  }
  for (auto& x : w) x.weight /= sum;
  return w;
}

/// Checks that clip ranges cover frames [0, frame_count) in order (a clip starts after the previous
/// one's start and at most one frame after the frames covered so far).
/// @throws io_error `io.format` naming what is wrong (`where` names the source).
inline void validate_clip_ranges(const std::vector<FrameRange>& ranges, int frame_count, const std::string& where) {
  auto bad = [&](const std::string& why) { throw io_error("io.format", where, why); };
  if (frame_count < 1) bad("no frames");
  if (ranges.empty()) bad("no clips");
  int covered = -1;
  for (std::size_t c = 0; c < ranges.size(); ++c) {
    const FrameRange r = ranges[c];
    if (r.size() < 1) bad("clip " + std::to_string(c) + ": empty range");
    if (r.first > covered + 1) bad("frames " + std::to_string(covered + 1) + "-" + std::to_string(r.first - 1) + " are in no clip");
    if (c > 0 && r.first <= ranges[c - 1].first) bad("clips are not in order");
    covered = std::max(covered, r.last);
  }
  if (covered != frame_count - 1) bad("clips cover frames 0-" + std::to_string(covered) + " of " + std::to_string(frame_count));
}

/// Reusable buffers of `VideoModel::render_frame`.
template <class Scalar, class Field = DefaultDeformationField<Scalar>>
struct VideoRenderBuffers {
  ClipRenderBuffers<Scalar, Field> clip;
  Image<Scalar, 3> image;  ///< the blended frame
};

namespace detail {
/// Frame f blended over its clips (see the file comment): `clip_at(c)` gives clip c.
/// @throws option_error `option.frame` if no clip holds f.
template <class Scalar, class Field, class ClipAt>
const Image<Scalar, 3>& blend_frame(const std::vector<FrameRange>& ranges, int frame_count, int width, int height, int f, ClipAt&& clip_at,
                                    VideoRenderBuffers<Scalar, Field>& buf, ThreadPool* pool, const RasterSettings<Scalar, 3>& settings) {
  const auto w = blend_weights(ranges, frame_count, f);
  if (w.empty()) throw option_error("option.frame", "frame " + std::to_string(f), "outside the video's " + std::to_string(frame_count) + " frames");
  buf.image.resize(width, height, Scalar(0));
  for (const auto& x : w) {
    const auto& m = clip_at(std::size_t(x.clip));
    render_clip_frame(m, m.index_of_frame(f), buf.clip, pool, settings);
    const Scalar a = Scalar(x.weight);
    Scalar* out = buf.image.data();
    const Scalar* in = buf.clip.merged.data();
    for (std::size_t i = 0; i < buf.image.size(); ++i) out[i] += a * in[i];
  }
  return buf.image;
}
}  // namespace detail

template <class Scalar, int SHDegree = 3, class Field = DefaultDeformationField<Scalar>>
class VideoModel {
 public:
  using Clip = ClipModel<Scalar, SHDegree, Field>;
  using scalar_type = Scalar;

  int frame_count = 0;       ///< N frames of the video
  int width = 0, height = 0; ///< render size (every clip's cameras)
  std::vector<Clip> clips;   ///< in schedule order; clips[c].range is its frame range

  [[nodiscard]] std::vector<FrameRange> ranges() const {
    std::vector<FrameRange> r;
    for (const auto& c : clips) r.push_back(c.range);
    return r;
  }
  [[nodiscard]] std::vector<ClipWeight> weights(int f) const { return blend_weights(ranges(), frame_count, f); }

  /// The clip with the largest weight at frame f (the later one on a tie).
  [[nodiscard]] int main_clip(int f) const {
    const auto w = weights(f);
    if (w.empty()) throw option_error("option.frame", "frame " + std::to_string(f), "outside the video's " + std::to_string(frame_count) + " frames");
    int best = w.front().clip;
    double bw = -1;
    for (const auto& x : w)
      if (x.weight >= bw) bw = x.weight, best = x.clip;
    return best;
  }

  /// Checks that the clips cover [0, frame_count) in order with one render size.
  /// @throws io_error `io.format` naming what is wrong (`where` names the source).
  void validate(const std::string& where = "video model") const {
    auto bad = [&](const std::string& why) { throw io_error("io.format", where, why); };
    for (std::size_t c = 0; c < clips.size(); ++c) {
      const auto& m = clips[c];
      if (m.range.size() < 1 || m.range.size() != m.frame_count()) bad("clip " + std::to_string(c) + ": range and cameras disagree");
      if (m.width() != width || m.height() != height) bad("clip " + std::to_string(c) + ": render size differs from the video's");
    }
    validate_clip_ranges(ranges(), frame_count, where);
  }

  /// Renders video frame f (blended over the clips that hold it) into `buf.image`.
  /// @throws option_error `option.frame` if f is outside the video.
  const Image<Scalar, 3>& render_frame(int f, VideoRenderBuffers<Scalar, Field>& buf, ThreadPool* pool = nullptr,
                                       RasterSettings<Scalar, 3> settings = {}) const {
    return detail::blend_frame(ranges(), frame_count, width, height, f, [&](std::size_t c) -> const Clip& { return clips[c]; }, buf, pool, settings);
  }

  /// Foreground and background Gaussians of frame f (deformed to it) from its main clip.
  [[nodiscard]] GaussianCloud<Scalar, SHDegree> frame_gaussians(int f, GaussianSet s, ThreadPool* pool = nullptr) const {
    const Clip& m = clips[std::size_t(main_clip(f))];
    return m.deformed_cloud(s, m.index_of_frame(f), pool);
  }
};

/// File name of clip c inside a model folder: clip_000.model, ...
[[nodiscard]] inline std::string video_model_clip_file(std::size_t c) {
  char name[32];
  std::snprintf(name, sizeof(name), "clip_%03zu.model", c);
  return name;
}

/// Writes the manifest of a model folder whose clip files exist already (atomic).
inline void write_video_manifest(const std::filesystem::path& dir, int frame_count, int width, int height,
                                 const std::vector<FrameRange>& ranges) {
  std::ostringstream o;
  o << kVideoModelHeader << "\nframes " << frame_count << "\nwidth " << width << "\nheight " << height << "\nclips " << ranges.size() << "\n";
  for (std::size_t c = 0; c < ranges.size(); ++c)
    o << "clip " << ranges[c].first << " " << ranges[c].last << " " << video_model_clip_file(c) << "\n";
  io::write_file_atomic(dir / kVideoModelManifest, o.str());
}

/// Saves every clip (clip_NNN.model) and then the manifest into `dir` (created if needed).
/// @throws io_error `io.unwritable`
template <class Scalar, int D, class Field>
void save_video_model(const std::filesystem::path& dir, VideoModel<Scalar, D, Field>& v) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw io_error("io.unwritable", dir.string(), "cannot create folder: " + ec.message());
  for (std::size_t c = 0; c < v.clips.size(); ++c) save_clip_model(dir / video_model_clip_file(c), v.clips[c]);
  write_video_manifest(dir, v.frame_count, v.width, v.height, v.ranges());
}

/// A parsed manifest.
struct VideoManifest {
  int frame_count = 0, width = 0, height = 0;
  std::vector<FrameRange> ranges;
  std::vector<std::string> files;
};

/// Reads DIR/manifest.txt. @throws io_error `io.missing`, `io.format`
[[nodiscard]] inline VideoManifest read_video_manifest(const std::filesystem::path& dir) {
  const auto path = dir / kVideoModelManifest;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw io_error("io.missing", path.string(), "no video model here (expected a folder written by `video3dgs reconstruct`, DIR/model)");
  std::ifstream in(path);
  std::string line;
  auto bad = [&](const std::string& why) { throw io_error("io.format", path.string(), why); };
  if (!std::getline(in, line) || line != kVideoModelHeader) bad("first line must be '" + std::string(kVideoModelHeader) + "'");
  VideoManifest m;
  int clips = -1;
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    std::istringstream s(line);
    std::string key;
    s >> key;
    if (key == "frames") s >> m.frame_count;
    else if (key == "width") s >> m.width;
    else if (key == "height") s >> m.height;
    else if (key == "clips") s >> clips;
    else if (key == "clip") {
      FrameRange r;
      std::string file;
      s >> r.first >> r.last >> file;
      if (!s || file.empty() || file.find('/') != std::string::npos) bad("malformed line '" + line + "'");
      m.ranges.push_back(r);
      m.files.push_back(file);
      continue;
    } else bad("unknown key '" + key + "'");
    if (!s) bad("malformed line '" + line + "'");
  }
  if (clips < 0 || clips != static_cast<int>(m.ranges.size())) bad("clip count disagrees with the clip lines");
  if (m.frame_count < 1 || m.width < 1 || m.height < 1) bad("frames, width and height must be >= 1");
  return m;
}

/// Loads a folder written by `save_video_model` (same template arguments).
/// @throws io_error (see the file comment)
template <class Scalar, int D = 3, class Field = DefaultDeformationField<Scalar>>
[[nodiscard]] VideoModel<Scalar, D, Field> load_video_model(const std::filesystem::path& dir) {
  const VideoManifest man = read_video_manifest(dir);
  VideoModel<Scalar, D, Field> v;
  v.frame_count = man.frame_count;
  v.width = man.width;
  v.height = man.height;
  for (std::size_t c = 0; c < man.ranges.size(); ++c) {
    const auto file = dir / man.files[c];
    auto m = load_clip_model<Scalar, D, Field>(file);
    if (!(m.range == man.ranges[c]))
      throw io_error("io.format", file.string(), "clip range differs from the manifest's");
    v.clips.push_back(std::move(m));
  }
  v.validate((dir / kVideoModelManifest).string());
  return v;
}

/// A video model read from its folder one clip at a time, for videos too long to hold: `render_frame`
/// loads the clips that hold frame f and releases every other, so memory is that of the clips of one
/// frame (two at an overlap) whatever the video's length. Frames rendered in increasing order load
/// each clip once. Renders equal `VideoModel::render_frame`'s of `load_video_model` bit for bit.
/// Not thread-safe (the loaded clips are state).
template <class Scalar, int SHDegree = 3, class Field = DefaultDeformationField<Scalar>>
class VideoModelFolder {
 public:
  using Clip = ClipModel<Scalar, SHDegree, Field>;
  using scalar_type = Scalar;

  /// Reads and checks the manifest (not the clip files: each is checked when loaded).
  /// @throws io_error `io.missing`, `io.format`
  explicit VideoModelFolder(std::filesystem::path dir) : dir_(std::move(dir)), man_(read_video_manifest(dir_)) {
    validate_clip_ranges(man_.ranges, man_.frame_count, (dir_ / kVideoModelManifest).string());
  }

  [[nodiscard]] int frame_count() const noexcept { return man_.frame_count; }
  [[nodiscard]] int width() const noexcept { return man_.width; }
  [[nodiscard]] int height() const noexcept { return man_.height; }
  [[nodiscard]] std::size_t clip_count() const noexcept { return man_.ranges.size(); }
  [[nodiscard]] const std::vector<FrameRange>& ranges() const noexcept { return man_.ranges; }
  [[nodiscard]] std::size_t loaded_clips() const noexcept { return loaded_.size(); }

  /// Clip c, loaded if it is not (it stays loaded until a `render_frame` no longer needs it or
  /// `release`). @throws the clip file's io errors; io_error `io.format` if its range or size disagrees
  /// with the manifest.
  const Clip& clip(std::size_t c) {
    if (auto it = loaded_.find(c); it != loaded_.end()) return it->second;
    const auto file = dir_ / man_.files.at(c);
    Clip m = load_clip_model<Scalar, SHDegree, Field>(file);
    if (!(m.range == man_.ranges[c])) throw io_error("io.format", file.string(), "clip range differs from the manifest's");
    if (m.range.size() != m.frame_count()) throw io_error("io.format", file.string(), "range and cameras disagree");
    if (m.width() != man_.width || m.height() != man_.height) throw io_error("io.format", file.string(), "render size differs from the video's");
    return loaded_.emplace(c, std::move(m)).first->second;
  }

  /// Releases every loaded clip.
  void release() noexcept { loaded_.clear(); }

  /// Renders video frame f into `buf.image` (see `VideoModel::render_frame`), after releasing the
  /// clips that do not hold f. @throws option_error `option.frame` if f is outside the video.
  const Image<Scalar, 3>& render_frame(int f, VideoRenderBuffers<Scalar, Field>& buf, ThreadPool* pool = nullptr,
                                       RasterSettings<Scalar, 3> settings = {}) {
    if (f >= 0 && f < man_.frame_count) std::erase_if(loaded_, [&](const auto& kv) { return !man_.ranges[kv.first].contains(f); });
    return detail::blend_frame(man_.ranges, man_.frame_count, man_.width, man_.height, f, [&](std::size_t c) -> const Clip& { return clip(c); }, buf,
                               pool, settings);
  }

 private:
  std::filesystem::path dir_;
  VideoManifest man_;
  std::map<std::size_t, Clip> loaded_;
};

}  // namespace video3dgs
