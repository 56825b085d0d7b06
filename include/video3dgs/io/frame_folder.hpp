#pragma once
/// @file
/// Frame folders: a video as a folder of images (`.jpg`, `.jpeg`, `.png`, any case) in natural sort
/// order ("frame2" < "frame10"), optionally with a folder of masks matched to the frames by file stem
/// (`frames/00012.jpg` <-> `masks/00012.png`). Hidden files (names starting with '.') and other
/// extensions are ignored.
///
/// Errors (`io_error`): `io.missing` (folder missing or not a folder), `io.empty` (no images),
/// `io.mask_missing` (a frame has no mask, names the frame), `io.count_mismatch` (more masks than
/// frames), `io.duplicate_stem` (two images with one stem, e.g. 0001.jpg and 0001.png, when masks are
/// matched), `io.size_mismatch` (a frame or mask whose size differs from the first frame, names it),
/// plus the errors of `read_image` / `read_mask`.
///
/// A long video need not be held: `check_frames` validates every file keeping none, and the ranged
/// `read_frames` / `read_masks` decode one clip's files.

#include <algorithm>
#include <cctype>
#include <cstddef>
#include <exception>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/io/image_io.hpp"

namespace video3dgs::io {

/// The images of a video, in order. `masks[i]` belongs to `frames[i]`; `masks` is empty when no mask
/// folder was given.
struct FrameList {
  std::vector<std::filesystem::path> frames;
  std::vector<std::filesystem::path> masks;

  [[nodiscard]] std::size_t size() const noexcept { return frames.size(); }
  [[nodiscard]] bool has_masks() const noexcept { return !masks.empty(); }
};

/// Natural order: digit runs compare as numbers ("2" < "10", "007" == "7" then fewer leading zeros
/// first), other characters compare case-insensitively (ASCII); strings equal under those rules fall
/// back to plain byte order, so this is a strict weak ordering.
[[nodiscard]] inline bool natural_less(std::string_view a, std::string_view b) {
  auto is_digit = [](char c) { return c >= '0' && c <= '9'; };
  std::size_t i = 0, j = 0;
  int zeros_tiebreak = 0;  // < 0: a had fewer leading zeros in the first differing run
  while (i < a.size() && j < b.size()) {
    if (is_digit(a[i]) && is_digit(b[j])) {
      std::size_t ia = i, jb = j;
      while (ia < a.size() && a[ia] == '0') ++ia;
      while (jb < b.size() && b[jb] == '0') ++jb;
      std::size_t ea = ia, eb = jb;
      while (ea < a.size() && is_digit(a[ea])) ++ea;
      while (eb < b.size() && is_digit(b[eb])) ++eb;
      const std::size_t la = ea - ia, lb = eb - jb;
      if (la != lb) return la < lb;
      const int cmp = a.substr(ia, la).compare(b.substr(jb, lb));
      if (cmp != 0) return cmp < 0;
      if (zeros_tiebreak == 0 && (ia - i) != (jb - j)) zeros_tiebreak = (ia - i) < (jb - j) ? -1 : 1;
      i = ea;
      j = eb;
      continue;
    }
    const int ca = std::tolower(static_cast<unsigned char>(a[i]));
    const int cb = std::tolower(static_cast<unsigned char>(b[j]));
    if (ca != cb) return ca < cb;
    ++i;
    ++j;
  }
  const bool a_done = i >= a.size(), b_done = j >= b.size();
  if (a_done != b_done) return a_done;
  if (zeros_tiebreak != 0) return zeros_tiebreak < 0;
  return a < b;
}

namespace detail {

[[nodiscard]] inline bool is_image_extension(const std::filesystem::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".jpg" || ext == ".jpeg" || ext == ".png";
}

/// The image files of a folder, in natural order of their file names.
[[nodiscard]] inline std::vector<std::filesystem::path> list_images(const std::filesystem::path& dir) {
  std::error_code ec;
  const std::string where = dir.string();
  if (!std::filesystem::exists(dir, ec)) throw io_error("io.missing", where, "no such folder");
  if (!std::filesystem::is_directory(dir, ec)) throw io_error("io.missing", where, "not a folder");
  std::vector<std::filesystem::path> files;
  std::filesystem::directory_iterator it(dir, ec);
  if (ec) throw io_error("io.unreadable", where, "cannot list the folder: " + ec.message());
  for (const auto& entry : it) {
    const auto name = entry.path().filename().string();
    if (name.empty() || name[0] == '.') continue;
    std::error_code fec;
    if (!is_image_extension(entry.path())) continue;
    if (!entry.is_regular_file(fec)) {
      // A frame name whose link leads nowhere would otherwise vanish from the video without a word.
      if (entry.is_symlink(fec) && !std::filesystem::exists(entry.path(), fec))
        throw io_error("io.missing", entry.path().string(), "a broken symbolic link (its target does not exist): fix or remove it");
      continue;
    }
    files.push_back(entry.path());
  }
  if (files.empty()) throw io_error("io.empty", where, "no .jpg/.jpeg/.png images in the folder (other formats: convert them first, e.g. `mogrify -format png *.bmp`)");
  std::sort(files.begin(), files.end(), [](const auto& x, const auto& y) {
    return natural_less(x.filename().string(), y.filename().string());
  });
  return files;
}

/// stem -> path; @throws io_error `io.duplicate_stem`
[[nodiscard]] inline std::map<std::string, std::filesystem::path> by_stem(const std::vector<std::filesystem::path>& files) {
  std::map<std::string, std::filesystem::path> m;
  for (const auto& f : files) {
    auto [it, inserted] = m.emplace(f.stem().string(), f);
    if (!inserted)
      throw io_error("io.duplicate_stem", f.string(), "has the same stem as " + it->second.filename().string());
  }
  return m;
}

/// Runs fn(i) for every i (in parallel when a pool is given); rethrows the error of the lowest
/// failing index, so the reported error does not depend on thread timing.
template <class Fn>
void for_each_checked(std::size_t n, ThreadPool* pool, Fn&& fn) {
  std::vector<std::exception_ptr> errors(n);
  parallel_for(
      pool, n,
      [&](std::size_t i) {
        try {
          fn(i);
        } catch (...) {
          errors[i] = std::current_exception();
        }
      },
      1);
  for (auto& e : errors)
    if (e) std::rethrow_exception(e);
}

/// Runs load(i) for every i and keeps the results (errors as `for_each_checked`).
template <class T, class Load>
[[nodiscard]] std::vector<T> load_all(std::size_t n, ThreadPool* pool, Load&& load) {
  std::vector<T> out(n);
  for_each_checked(n, pool, [&](std::size_t i) { out[i] = load(i); });
  return out;
}

/// `first..last` as indices of a list of n files. @throws option_error `option.range`
inline void check_range(std::size_t n, int first, int last) {
  if (first < 0 || last < first || std::size_t(last) >= n)
    throw option_error("option.range", "frames " + std::to_string(first) + "-" + std::to_string(last),
                       "outside the video's " + std::to_string(n) + " frames");
}

inline void check_size(int w, int h, int w0, int h0, const std::filesystem::path& file, const std::filesystem::path& first) {
  if (w != w0 || h != h0)
    throw io_error("io.size_mismatch", file.string(),
                   "is " + std::to_string(w) + "x" + std::to_string(h) + " but the first frame (" +
                       first.filename().string() + ") is " + std::to_string(w0) + "x" + std::to_string(h0));
}

}  // namespace detail

/// Lists the frames of `frames_dir` in natural order and, if `masks_dir` is not empty, the mask of
/// each frame (same file stem, any image extension).
/// @throws io_error `io.missing`, `io.empty`, `io.mask_missing`, `io.count_mismatch`, `io.duplicate_stem`
[[nodiscard]] inline FrameList list_frames(const std::filesystem::path& frames_dir,
                                           const std::filesystem::path& masks_dir = {}) {
  FrameList list;
  list.frames = detail::list_images(frames_dir);
  if (masks_dir.empty()) return list;
  (void)detail::by_stem(list.frames);
  const auto masks = detail::by_stem(detail::list_images(masks_dir));
  list.masks.reserve(list.frames.size());
  for (const auto& f : list.frames) {
    auto it = masks.find(f.stem().string());
    if (it == masks.end())
      throw io_error("io.mask_missing", f.string(), "no mask with stem '" + f.stem().string() + "' in " + masks_dir.string());
    list.masks.push_back(it->second);
  }
  if (masks.size() != list.frames.size()) {
    std::string extra;
    for (const auto& [stem, path] : masks) {
      const bool used = std::find(list.masks.begin(), list.masks.end(), path) != list.masks.end();
      if (!used) {
        extra = path.filename().string();
        break;
      }
    }
    throw io_error("io.count_mismatch", masks_dir.string(),
                   std::to_string(masks.size()) + " masks for " + std::to_string(list.frames.size()) +
                       " frames (no frame for mask " + extra + ")");
  }
  return list;
}

/// Reads every frame as RGB (in parallel when `pool` is given; results do not depend on it) and
/// checks that all have the size of the first.
/// @throws io_error `io.size_mismatch` naming the file, or the errors of `read_image`.
[[nodiscard]] inline std::vector<Image<float, 3>> read_frames(const FrameList& list, ThreadPool* pool = nullptr) {
  auto frames = detail::load_all<Image<float, 3>>(list.frames.size(), pool,
                                                  [&](std::size_t i) { return read_image<3>(list.frames[i]); });
  for (std::size_t i = 1; i < frames.size(); ++i)
    detail::check_size(frames[i].width(), frames[i].height(), frames[0].width(), frames[0].height(), list.frames[i],
                       list.frames[0]);
  return frames;
}

/// Reads every mask (values 0/1, see `read_mask`) and checks that each has the size of the first
/// frame. Returns an empty vector when the list has no masks.
/// @throws io_error `io.size_mismatch` naming the mask, or the errors of `read_mask` / `read_image_info`.
[[nodiscard]] inline std::vector<Image<float, 1>> read_masks(const FrameList& list, ThreadPool* pool = nullptr) {
  if (list.masks.empty()) return {};
  const ImageInfo first = read_image_info(list.frames.at(0));
  auto masks = detail::load_all<Image<float, 1>>(list.masks.size(), pool,
                                                 [&](std::size_t i) { return read_mask(list.masks[i]); });
  for (std::size_t i = 0; i < masks.size(); ++i)
    detail::check_size(masks[i].width(), masks[i].height(), first.width, first.height, list.masks[i], list.frames[0]);
  return masks;
}

/// Decodes every frame and every mask once, keeping none of them (memory: one image per thread), and
/// checks their sizes: what `read_frames` and `read_masks` check, for videos too long to hold.
/// Returns the first frame's header.
/// @throws io_error as `read_frames`, then as `read_masks` (the lowest failing index of each).
[[nodiscard]] inline ImageInfo check_frames(const FrameList& list, ThreadPool* pool = nullptr) {
  const ImageInfo first = read_image_info(list.frames.at(0));
  detail::for_each_checked(list.frames.size(), pool, [&](std::size_t i) {
    const Image<float, 3> f = read_image<3>(list.frames[i]);
    detail::check_size(f.width(), f.height(), first.width, first.height, list.frames[i], list.frames[0]);
  });
  detail::for_each_checked(list.masks.size(), pool, [&](std::size_t i) {
    const Image<float, 1> m = read_mask(list.masks[i]);
    detail::check_size(m.width(), m.height(), first.width, first.height, list.masks[i], list.frames[0]);
  });
  return first;
}

/// Frames `first..last` of the list as RGB (no size check beyond `check_frames`'s).
/// @throws option_error `option.range`; the errors of `read_image`.
[[nodiscard]] inline std::vector<Image<float, 3>> read_frames(const FrameList& list, int first, int last, ThreadPool* pool = nullptr) {
  detail::check_range(list.frames.size(), first, last);
  return detail::load_all<Image<float, 3>>(std::size_t(last - first + 1), pool,
                                           [&](std::size_t i) { return read_image<3>(list.frames[std::size_t(first) + i]); });
}

/// Masks `first..last` of the list (empty when the list has no masks).
/// @throws option_error `option.range`; the errors of `read_mask`.
[[nodiscard]] inline std::vector<Image<float, 1>> read_masks(const FrameList& list, int first, int last, ThreadPool* pool = nullptr) {
  detail::check_range(list.frames.size(), first, last);
  if (list.masks.empty()) return {};
  return detail::load_all<Image<float, 1>>(std::size_t(last - first + 1), pool,
                                           [&](std::size_t i) { return read_mask(list.masks[std::size_t(first) + i]); });
}

}  // namespace video3dgs::io
