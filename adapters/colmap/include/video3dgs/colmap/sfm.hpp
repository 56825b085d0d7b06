#pragma once
/// @file
/// `ColmapSfm`: an `SfmBackend` (video3dgs/scheduling/sfm_result.hpp) that reconstructs a clip of a
/// video with the `colmap` program — MC-COLMAP's per-clip step (docs/method.md).
///
/// For frames [first, last] it makes `work_dir/frames_<first>_<last>/` with
///   images/<frame:06d>.<ext>        the frames (symlinks, or copies where links are impossible)
///   masks/<frame:06d>.<ext>.png     COLMAP masks (255 = use, 0 = ignore), when masks are given and
///                                   their mean area is >= min_mask_area (else the full frames are used)
///   database.db, matches.txt (the exact raw matches, when `deterministic`), sparse/,
///   sparse_relaxed[_2,_3]/, extract.log, match.log, mapper.log,
///   mapper_relaxed[_2,_3].log, model/ (the chosen model)
///   full_frames/ | masked/          the other pass, when the first did not register every frame:
///                                   whole frames after masks (full_frame_fallback), masks after whole
///                                   frames chosen for a small mask area (masked_fallback_min_area)
///   database.key                    what the database was made with (masks, SIFT, intrinsics)
///   outcome.json                    written last: status, timings, the key of the settings it was
///                                   made with (outcome.txt in version 0.1, still read)
/// and runs
///   colmap feature_extractor   SIMPLE_PINHOLE, one shared camera, masks, CPU SIFT
///                              (+ ImageReader.camera_params f,cx,cy once intrinsics are shared)
///   exact matching (colmap/matcher.hpp) + colmap matches_importer, guided matching, CPU
///                              (or colmap exhaustive_matcher when `deterministic` is off)
///   colmap mapper              (+ no refinement of f, cx, cy once intrinsics are shared)
/// With `deterministic` (the default) the same frames and options give the same clips, byte for byte
/// the same database matches and the same model files: COLMAP's steps run on one thread each, the
/// features whose descriptors COLMAP may leave unwritten are dropped (drop_border_features), and the
/// raw matches come from our exact matcher instead of COLMAP's randomised one (docs/colmap-notes.md
/// has the runs). Feature extraction on more threads numbers the images in the order they finish, and
/// the matcher's and mapper's results depend on which thread ran what.
/// Success = every frame registered and at least `min_points_per_frame` x frames 3D points (and one)
/// and, with `max_reprojection_error`, a mean reprojection error at most that, judged on the mapper's
/// largest model; a model below the points floor or above the error limit counts as a failed run, so
/// the relaxed retries, the other pass and growth still get their turn. If the
/// mapper fails, it is re-run (up to `relaxed_tries` times, with random seeds 1, 2, ...) with relaxed
/// triangulation angles (Mapper.init_min_tri_angle 1 degree instead of 16, Mapper.tri_min_angle and
/// Mapper.filter_min_tri_angle 0.5 instead of 1.5): nearly static clips have too little parallax for
/// COLMAP's defaults. After the first successful clip its f, cx, cy are reused, unrefined, for every
/// later clip. If a masked pass still misses frames, the pass is repeated on the whole frames
/// (`full_frame_fallback`) and the better model is kept (a static background adds the parallax a
/// foreground may lack); conversely a failed full-frame pass chosen for a mask area below
/// `min_mask_area` (but at least `masked_fallback_min_area`) is repeated with the masks, once the clip
/// has grown from `masked_fallback_after` failed attempts. By default (`min_mask_area` 1) every clip
/// starts on whole frames and masks are the last resort; the method's rule (masks first from 10 % of
/// the frame, the masked pass at once) is `min_mask_area` 0.10 with `masked_fallback_after` 0. A grown clip starts from the database of the
/// failed attempt it grew from (`reuse_databases`), so each growth step extracts and matches only the
/// new frame. The runs on DAVIS that motivated each of these choices are in docs/colmap-notes.md.
///
/// Outcomes: `success`; `soft_failure` (the mapper found no complete model; a longer clip may help);
/// thrown errors for what growing cannot fix: `[colmap.missing]` (with how to install it),
/// `[colmap.failed]` (feature extraction or matching exited non-zero; log tail included),
/// `[colmap.timeout]` (a step exceeded `step_timeout_seconds`), `io.*` (unreadable frames/masks).
/// With `reuse_finished`, an attempt folder whose outcome.json matches the current settings is reused
/// without running COLMAP again (so an interrupted `video3dgs sfm` resumes).

#include <algorithm>
#include <array>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "video3dgs/colmap/convert.hpp"
#include "video3dgs/colmap/matcher.hpp"
#include "video3dgs/colmap/model.hpp"
#include "video3dgs/colmap/model_io.hpp"
#include "video3dgs/colmap/process.hpp"
#include <nlohmann/json.hpp>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/hash.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/scheduling/sfm_result.hpp"

namespace video3dgs::colmap {

struct ColmapSfmOptions {
  std::filesystem::path executable = "colmap";  ///< program name (searched on PATH) or path
  std::filesystem::path work_dir;               ///< required: one sub-folder per attempt
  int threads = 0;                              ///< threads of the matcher (every COLMAP step unless deterministic); 0 = all cores
  /// Reproducible SfM (see the file comment): COLMAP's extraction, match import/verification and
  /// mapper on one thread, raw matches from write_match_list (on `threads`). false: COLMAP's own
  /// matcher and every step on `threads`: faster on many cores, but two runs give different cameras.
  bool deterministic = true;
  double step_timeout_seconds = 3600;           ///< per COLMAP step; 0 = none
  /// false: after each attempt delete its images, masks, database and raw mapper output; with
  /// reuse_finished the logs, outcome.json and the chosen model (model/) stay so a re-run can reuse
  /// them, without it the whole attempt folder goes (and SfmResult::model_dir is empty).
  bool keep_work = true;
  bool reuse_finished = true;  ///< reuse attempt folders made with the same settings
  bool use_masks = true;       ///< restrict features to the masks' foreground (when masks are given)
  /// Below this mean foreground fraction the first pass uses the full frames. 1 (the default): whole
  /// frames first, masks only as the fallback; the method's rule is 0.10 (with masked_fallback_after
  /// 0). docs/performance.md "SfM on masked or whole frames" has the training PSNR of both.
  double min_mask_area = 1.0;
  int max_image_size = 0;      ///< SiftExtraction.max_image_size (longest side); 0 = COLMAP's 3200
  int max_num_features = 0;    ///< SiftExtraction.max_num_features; 0 = COLMAP's 8192
  bool guided_matching = true;
  bool reuse_intrinsics = true;              ///< share the first successful clip's f, cx, cy
  /// Known focal length in pixels at the frames' size: every clip uses it with the principal point at
  /// the frame's centre, neither refined (as shared intrinsics are). 0 = estimated by COLMAP.
  double focal = 0;
  /// An estimated focal length below min_focal_ratio or above max_focal_ratio times the frame's longer
  /// side (a field of view above 157 or below 0.6 degrees) is COLMAP's estimate degenerating on too
  /// little parallax, not a lens: the attempt is a soft failure (the clip grows) and the focal length is
  /// not shared, which would doom every later clip.
  double min_focal_ratio = 0.1, max_focal_ratio = 100;
  /// A mapper model that registers every frame with fewer than ceil(min_points_per_frame x frames) 3D
  /// points is not a success: such cameras rest on a handful of tracks (a relaxed run once registered
  /// horsejump-high 0-9 with 2 points, where the masked pass found 444) and the clip's Gaussians start
  /// from nothing. 0 = the method's rule (one point).
  double min_points_per_frame = 2.0;
  /// A mapper model whose points' mean reprojection error exceeds this (pixels) is not a success either
  /// (CameraQuality, scheduling/sfm_result.hpp): the relaxed retries, the other pass (whole frames after
  /// masks, or masks after whole frames) and growth get their turn. 0 = no limit (the method's rule).
  double max_reprojection_error = 0;
  bool relaxed_retry = true;                 ///< re-run a failed mapper with a relaxed initialisation
  double relaxed_init_min_tri_angle = 1.0;    ///< degrees (COLMAP default 16)
  double relaxed_tri_min_angle = 0.5;         ///< degrees (COLMAP default 1.5)
  double relaxed_filter_min_tri_angle = 0.5;  ///< degrees (COLMAP default 1.5)
  int relaxed_init_min_num_inliers = 100;     ///< (COLMAP default 100)
  /// Relaxed mapper runs (random seeds 1, 2, ...) until one registers every frame: on these
  /// low-parallax clips the outcome of one run depends on RANSAC's samples.
  int relaxed_tries = 3;
  /// When masked SfM (with its relaxed retries) does not register every frame, run the whole pass
  /// again on the full frames (sub-folder full_frames/) and keep the better model.
  bool full_frame_fallback = true;
  /// The reverse: when the mask area is below min_mask_area but at least this, a failed full-frame
  /// pass is repeated with the masks (sub-folder masked/). 0 disables it.
  double masked_fallback_min_area = 0.05;
  /// ... but only once the clip has failed on whole frames this many times already: the failed
  /// attempts it grew from, one frame at a time, among this object's attempts. Before that a failed
  /// full-frame attempt stays a soft failure and the scheduler grows the clip (a longer clip gives
  /// whole frames more parallax; masked cameras follow the foreground and fit the background worse).
  /// 0 = the masked pass at once (the method's rule).
  int masked_fallback_after = 2;
  /// A grown clip (one frame more than a failed attempt) starts from that attempt's database:
  /// COLMAP skips the features and image pairs it already has, so a growth step extracts one frame
  /// and matches its pairs only. Failed attempts keep their database.db for this (moved on, or
  /// deleted with the attempt's bulk when keep_work is false and the clip succeeds).
  bool reuse_databases = true;
};

/// What one call did (for reports and tests).
struct ColmapAttempt {
  FrameRange range;
  SfmStatus status = SfmStatus::soft_failure;
  std::string message;
  bool reused = false;            ///< loaded from a finished attempt folder
  bool masked = false;            ///< masks were given to COLMAP
  double mask_area = -1;          ///< mean foreground fraction (-1 = no masks)
  bool relaxed_tried = false;
  bool relaxed_succeeded = false;
  int relaxed_runs = 0;           ///< relaxed mapper runs made (both passes)
  bool fallback_tried = false;    ///< the other pass (full frames after masked, or masked after full) ran
  bool fallback_succeeded = false;
  int databases_reused = 0;       ///< passes that started from a grown-from attempt's database
  double seconds_extract = 0, seconds_match = 0, seconds_map = 0, seconds_map_relaxed = 0;
  int registered = 0;
  std::size_t points = 0;
  double mean_reprojection_error = 0;  ///< mean over the chosen model's points (pixels; 0 without points)
  std::filesystem::path dir;
  [[nodiscard]] double seconds() const noexcept { return seconds_extract + seconds_match + seconds_map + seconds_map_relaxed; }
};

/// `SfmResult<double>` plus the raw COLMAP model it came from and what the call did.
struct ColmapClipResult : SfmResult<double> {
  Model model;
  ColmapAttempt attempt;
};

/// Pinhole intrinsics shared between clips (SIMPLE_PINHOLE: f, cx, cy in pixels).
struct SharedIntrinsics {
  double f = 0, cx = 0, cy = 0;
};

class ColmapSfm {
 public:
  /// The video frame of an image name written by this back end ("00012.png" -> 12), or nullopt for a
  /// name that is not digits before its first dot, or a number beyond int (such images are ignored).
  static std::optional<int> frame_of_name(const std::string& name) {
    const std::string_view stem = std::string_view(name).substr(0, name.find('.'));
    if (stem.empty() || stem.find_first_not_of("0123456789") != std::string_view::npos) return std::nullopt;
    int f = 0;
    if (const auto [end, ec] = std::from_chars(stem.data(), stem.data() + stem.size(), f); ec != std::errc{}) return std::nullopt;
    return f;
  }

  /// Writes dir/outcome.json (atomic): the attempt's status and figures under settings `key`.
  static void write_outcome(const std::filesystem::path& dir, const std::string& key, const ColmapAttempt& a) {
    const nlohmann::ordered_json o = {
        {"key", key}, {"status", to_string(a.status)}, {"masked", a.masked}, {"mask_area", a.mask_area}, {"relaxed_tried", a.relaxed_tried},
        {"relaxed_succeeded", a.relaxed_succeeded}, {"relaxed_runs", a.relaxed_runs}, {"fallback_tried", a.fallback_tried},
        {"fallback_succeeded", a.fallback_succeeded}, {"databases_reused", a.databases_reused}, {"seconds_extract", a.seconds_extract},
        {"seconds_match", a.seconds_match}, {"seconds_map", a.seconds_map}, {"seconds_map_relaxed", a.seconds_map_relaxed},
        {"message", a.message}};
    io::write_file_atomic(dir / "outcome.json", o.dump(1) + "\n");
  }

  /// outcome.json as written by write_outcome, or the "name value" lines of version 0.1's outcome.txt
  /// as an object of strings; empty when neither exists.
  static nlohmann::json read_outcome(const std::filesystem::path& dir, bool& legacy) {
    std::error_code ec;
    legacy = false;
    if (std::filesystem::is_regular_file(dir / "outcome.json", ec)) {
      std::ifstream in(dir / "outcome.json");
      auto j = nlohmann::json::parse(in, nullptr, false);
      return j.is_object() ? j : nlohmann::json::object();
    }
    nlohmann::json kv = nlohmann::json::object();
    std::ifstream in(dir / "outcome.txt");
    std::string line;
    while (std::getline(in, line)) {
      const auto sp = line.find(' ');
      kv[line.substr(0, sp)] = sp == std::string::npos ? "" : line.substr(sp + 1);
    }
    legacy = !kv.empty();
    return kv;
  }

  /// The attempt of frames `r` finished earlier in `dir` under settings `key` (or, for version 0.1's
  /// outcome.txt, `legacy_key`): its outcome and, when it succeeded, its model (dir/model); nothing
  /// when there is none or it was made under other settings.
  static std::optional<ColmapClipResult> load_finished(const std::filesystem::path& dir, FrameRange r, const std::string& key,
                                                       const std::string& legacy_key) {
    std::error_code ec;
    bool legacy = false;
    const nlohmann::json kv = read_outcome(dir, legacy);
    const std::string file = (dir / (legacy ? "outcome.txt" : "outcome.json")).string();
    auto text = [&](const char* k) {
      const auto it = kv.find(k);
      return it != kv.end() && it->is_string() ? it->get<std::string>() : std::string();
    };
    if (text("key") != (legacy ? legacy_key : key)) return std::nullopt;
    // A figure: absent = 0; otherwise a finite number, as a JSON number or (version 0.1) as text.
    auto d = [&](const char* k) {
      const auto it = kv.find(k);
      if (it == kv.end()) return 0.0;
      double v = std::numeric_limits<double>::quiet_NaN();
      if (it->is_number()) {
        v = it->get<double>();
      } else if (it->is_string()) {
        const std::string& t = it->get_ref<const std::string&>();
        if (const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v); ec != std::errc{} || end != t.data() + t.size())
          v = std::numeric_limits<double>::quiet_NaN();
      }
      if (!std::isfinite(v)) throw io_error("io.format", file, std::string("field '") + k + "' is not a finite number");
      return v;
    };
    auto count = [&](const char* k) {
      const double v = d(k);
      if (!(v >= 0 && v <= std::numeric_limits<int>::max() && v == std::floor(v)))
        throw io_error("io.format", file, std::string("field '") + k + "' must be a count");
      return static_cast<int>(v);
    };
    auto flag = [&](const char* k) { return kv.contains(k) && (kv[k].is_boolean() ? kv[k].get<bool>() : kv[k] == "1"); };
    const std::string status = text("status");
    ColmapAttempt info;
    info.range = r;
    info.dir = dir;
    info.reused = true;
    info.masked = flag("masked");
    info.mask_area = d("mask_area");
    info.relaxed_tried = flag("relaxed_tried");
    info.relaxed_succeeded = flag("relaxed_succeeded");
    info.relaxed_runs = count("relaxed_runs");
    info.fallback_tried = flag("fallback_tried");
    info.fallback_succeeded = flag("fallback_succeeded");
    info.databases_reused = count("databases_reused");
    info.seconds_extract = d("seconds_extract");
    info.seconds_match = d("seconds_match");
    info.seconds_map = d("seconds_map");
    info.seconds_map_relaxed = d("seconds_map_relaxed");
    ColmapClipResult out;
    out.range = r;
    if (status == "success" || std::filesystem::is_directory(dir / "model", ec)) {
      if (!std::filesystem::is_directory(dir / "model", ec)) return std::nullopt;
      out.model = read_model(dir / "model", Format::binary);
      static_cast<SfmResult<double>&>(out) = to_sfm_result<double>(out.model, r, &ColmapSfm::frame_of_name);
      out.model_dir = dir / "model";
      if (status != "success") out.status = SfmStatus::soft_failure;
    } else {
      out.status = SfmStatus::soft_failure;
    }
    if (out.status != SfmStatus::success) out.message = text("message");
    info.status = out.status;
    info.message = out.message;
    info.registered = static_cast<int>(out.frames.size());
    info.points = out.points.size();
    info.mean_reprojection_error = video3dgs::mean_reprojection_error(out.points);
    out.attempt = info;
    return out;
  }

  /// @param frames the video's frames in order; @param masks one per frame (1 = foreground), or empty
  ColmapSfm(std::vector<std::filesystem::path> frames, std::vector<std::filesystem::path> masks, ColmapSfmOptions options)
      : frames_(std::move(frames)), masks_(std::move(masks)), opt_(std::move(options)) {
    if (opt_.work_dir.empty()) throw option_error("option.work_dir", "work_dir", "ColmapSfm needs a work folder");
    if (!masks_.empty() && masks_.size() != frames_.size())
      throw option_error("option.masks", "masks", std::to_string(masks_.size()) + " masks for " + std::to_string(frames_.size()) + " frames");
    if (opt_.threads < 0) throw option_error("option.range", "threads", "must be >= 0 (0 = all cores)");
    if (!(opt_.min_mask_area >= 0 && opt_.min_mask_area <= 1)) throw option_error("option.range", "min_mask_area", "must be in [0, 1]");
    if (opt_.masked_fallback_after < 0) throw option_error("option.range", "masked_fallback_after", "must be >= 0 (0 = at once)");
    if (!(opt_.focal >= 0 && opt_.focal < 1e7)) throw option_error("option.range", "focal", "must be in [0, 1e7) pixels (0 = estimated)");
    if (!(opt_.min_points_per_frame >= 0 && opt_.min_points_per_frame <= 1e6))
      throw option_error("option.range", "min_points_per_frame", "must be in [0, 1e6]");
    if (!(opt_.max_reprojection_error >= 0 && opt_.max_reprojection_error <= 1e6))
      throw option_error("option.range", "max_reprojection_error", "must be in [0, 1e6] pixels (0 = no limit)");
    if (!(opt_.min_focal_ratio >= 0 && opt_.max_focal_ratio > opt_.min_focal_ratio))
      throw option_error("option.range", "min_focal_ratio/max_focal_ratio", "need 0 <= min < max");
    if (opt_.focal > 0 && !frames_.empty()) {
      const io::ImageInfo first = io::read_image_info(frames_.front());
      intrinsics_ = SharedIntrinsics{opt_.focal, 0.5 * first.width, 0.5 * first.height};
    }
  }

  [[nodiscard]] int frame_count() const noexcept { return static_cast<int>(frames_.size()); }
  [[nodiscard]] const ColmapSfmOptions& options() const noexcept { return opt_; }
  [[nodiscard]] const std::optional<SharedIntrinsics>& shared_intrinsics() const noexcept { return intrinsics_; }
  void set_shared_intrinsics(std::optional<SharedIntrinsics> k) { intrinsics_ = k; }
  /// Every call so far, in order.
  [[nodiscard]] const std::vector<ColmapAttempt>& attempts() const noexcept { return attempts_; }

  /// The attempt folder of a range.
  [[nodiscard]] std::filesystem::path attempt_dir(FrameRange r) const {
    char buf[64];
    std::snprintf(buf, sizeof(buf), "frames_%05d_%05d", r.first, r.last);
    return opt_.work_dir / buf;
  }

  /// Checks that the colmap program can be started.
  /// @throws external_error `colmap.missing` saying how to install it
  void require_colmap() const {
    if (find_executable(opt_.executable).empty())
      throw external_error("colmap.missing", opt_.executable.string(),
                           "the COLMAP program was not found; install it (Debian/Ubuntu: `sudo apt-get install colmap`, "
                           "the CPU build is enough) or pass its path (ColmapSfmOptions::executable, `--colmap`)");
  }

  /// Reconstructs frames [range.first, range.last] (see the file comment).
  ColmapClipResult operator()(FrameRange range) {
    if (range.first < 0 || range.last >= frame_count() || range.size() == 0)
      throw option_error("option.range", "frames " + std::to_string(range.first) + "-" + std::to_string(range.last),
                         "outside the video's " + std::to_string(frame_count()) + " frames");
    require_colmap();
    const std::filesystem::path dir = attempt_dir(range);
    const std::string text = settings_text(range);
    const std::string key = stable_key(text);
    ColmapClipResult out;
    if (opt_.reuse_finished) {
      // Version 0.1 wrote outcome.txt under std::hash of the same text: still recognised, never written.
      if (auto cached = load_finished(dir, range, key, std::to_string(std::hash<std::string>{}(text)))) out = std::move(*cached);
    }
    if (!out.attempt.reused) out = run(range, dir, key);
    if (out.status == SfmStatus::success && !fixed_intrinsics() && !out.cameras.empty()) {
      const io::ImageInfo size = io::read_image_info(frames_[static_cast<std::size_t>(range.first)]);
      const double side = std::max(size.width, size.height), f = out.cameras.front().fx;
      if (!(f >= opt_.min_focal_ratio * side && f <= opt_.max_focal_ratio * side)) {
        out.status = out.attempt.status = SfmStatus::soft_failure;
        out.message = out.attempt.message = "focal length " + num(f) + " px for " + std::to_string(size.width) + "x" +
                                            std::to_string(size.height) + " frames is no lens (too little parallax to estimate it); "
                                            "give the camera's with --focal if it is known";
      }
    }
    if (out.status == SfmStatus::success && opt_.reuse_intrinsics && !intrinsics_ && !out.cameras.empty()) {
      const auto& c = out.cameras.front();
      intrinsics_ = SharedIntrinsics{c.fx, c.cx, c.cy};
    }
    attempts_.push_back(out.attempt);
    return out;
  }

 private:
  static std::string num(double v) { return detail::fmt(v); }
  /// Whether every clip gets intrinsics_ (fixed, not refined): known (focal) or shared from a clip.
  [[nodiscard]] bool fixed_intrinsics() const noexcept { return intrinsics_ && (opt_.reuse_intrinsics || opt_.focal > 0); }

  /// COLMAP's name for frame f: its index and the file's extension (".png" for an upright copy).
  std::string frame_name(int f, bool upright_copy) const {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%06d", f);
    if (upright_copy) return std::string(buf) + ".png";
    std::string ext = frames_[static_cast<std::size_t>(f)].extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return buf + ext;
  }

  /// What an attempt's outcome depends on, as canonical text; its stable_key is the attempt's key.
  std::string settings_text(FrameRange r) const {
    std::ostringstream k;
    k << "v1|mis=" << opt_.max_image_size << "|mnf=" << opt_.max_num_features << "|guided=" << opt_.guided_matching
      << "|masks=" << (opt_.use_masks && !masks_.empty()) << "|minarea=" << num(opt_.min_mask_area)
      << "|relaxed=" << opt_.relaxed_retry << "," << num(opt_.relaxed_init_min_tri_angle) << ","
      << num(opt_.relaxed_tri_min_angle) << "," << num(opt_.relaxed_filter_min_tri_angle) << "," << opt_.relaxed_tries << ","
      << opt_.relaxed_init_min_num_inliers << "|fallback=" << opt_.full_frame_fallback << "," << num(opt_.masked_fallback_min_area)
      << (opt_.masked_fallback_after > 0 ? "," + std::to_string(opt_.masked_fallback_after) : std::string())
      << "|minpts=" << num(opt_.min_points_per_frame);
    if (opt_.max_reprojection_error > 0) k << "|maxerr=" << num(opt_.max_reprojection_error);  // absent: keys as before
    if (opt_.deterministic) k << "|det=1";  // absent for COLMAP's own matcher, as before the option
    if (fixed_intrinsics()) k << "|K=" << num(intrinsics_->f) << "," << num(intrinsics_->cx) << "," << num(intrinsics_->cy);
    for (int f = r.first; f <= r.last; ++f) {
      k << "|" << std::filesystem::absolute(frames_[static_cast<std::size_t>(f)]).string();
      if (!masks_.empty()) k << ":" << std::filesystem::absolute(masks_[static_cast<std::size_t>(f)]).string();
    }
    return k.str();
  }

  std::vector<std::string> base(const char* command) const {
    return {opt_.executable.string(), command};
  }
  std::string threads_arg() const { return opt_.threads == 0 ? "-1" : std::to_string(opt_.threads); }
  /// Threads of a COLMAP step whose result depends on scheduling: one when `deterministic`.
  std::string colmap_threads_arg() const { return opt_.deterministic ? "1" : threads_arg(); }

  /// Runs one COLMAP step; throws for missing program / timeouts; returns the process result.
  ProcessResult step(const std::vector<std::string>& argv, const std::filesystem::path& log, FrameRange r) const {
    ProcessResult pr;
    try {
      pr = run_process(argv, log, opt_.step_timeout_seconds, {"QT_QPA_PLATFORM=offscreen"});
    } catch (const external_error& e) {
      if (e.id() == "external.missing") require_colmap();
      throw;
    }
    if (pr.timed_out)
      throw external_error("colmap.timeout", log.string(),
                           "colmap " + argv[1] + " on frames " + std::to_string(r.first) + "-" + std::to_string(r.last) +
                               " exceeded " + num(opt_.step_timeout_seconds) + " s and was killed");
    return pr;
  }

  /// Largest model (most registered frames of the range, then most points) under `sparse`.
  std::optional<std::pair<Model, ColmapClipResult>> best_model(const std::filesystem::path& sparse, FrameRange r) const {
    std::optional<std::pair<Model, ColmapClipResult>> best;
    std::error_code ec;
    if (!std::filesystem::is_directory(sparse, ec)) return best;
    std::vector<std::filesystem::path> dirs;
    for (const auto& e : std::filesystem::directory_iterator(sparse, ec))
      if (e.is_directory()) dirs.push_back(e.path());
    std::sort(dirs.begin(), dirs.end());
    for (const auto& d : dirs) {
      Model m = read_model(d, Format::binary);
      ColmapClipResult res;
      static_cast<SfmResult<double>&>(res) = to_sfm_result<double>(m, r, &ColmapSfm::frame_of_name);
      res.model_dir = d;
      const bool better = !best || res.frames.size() > best->second.frames.size() ||
                          (res.frames.size() == best->second.frames.size() && res.points.size() > best->second.points.size());
      if (better) best.emplace(std::move(m), std::move(res));
    }
    return best;
  }

  /// What a pass's database depends on besides its frames: masks or not, SIFT settings, fixed
  /// intrinsics. A database is reused only under the same key (file database.key beside it).
  std::string database_key(bool masked) const {
    std::ostringstream k;
    k << "db1|masked=" << masked << "|mis=" << opt_.max_image_size << "|mnf=" << opt_.max_num_features << "|guided=" << opt_.guided_matching;
    if (opt_.deterministic) k << "|exact_matches";
    if (fixed_intrinsics()) k << "|K=" << num(intrinsics_->f) << "," << num(intrinsics_->cx) << "," << num(intrinsics_->cy);
    return k.str();
  }

  /// The ranges r may have grown from, one frame shorter at either end (may be empty).
  static std::array<FrameRange, 2> grown_from(FrameRange r) noexcept { return {{{r.first, r.last - 1}, {r.first + 1, r.last}}}; }

  /// The database of the attempt this range grew from (`grown_from`), in its main, full_frames/ or
  /// masked/ pass, made under `key`; empty if there is none.
  std::filesystem::path prior_database(FrameRange r, const std::string& key) const {
    std::error_code ec;
    for (const FrameRange& p : grown_from(r)) {
      if (p.first > p.last) continue;
      const auto pd = attempt_dir(p);
      for (const auto& d : {pd, pd / "full_frames", pd / "masked"}) {
        if (!std::filesystem::is_regular_file(d / "database.db", ec)) continue;
        std::ifstream in(d / "database.key");
        std::string line;
        if (std::getline(in, line) && line == key) return d / "database.db";
      }
    }
    return {};
  }

  /// How many failed attempts range r grew from, one frame at a time (`grown_from`), among attempts_;
  /// counting stops at `cap`.
  [[nodiscard]] int failed_growth_steps(FrameRange r, int cap) const noexcept {
    int n = 0;
    while (n < cap) {
      const auto from = grown_from(r);
      const auto failed = std::find_if(attempts_.begin(), attempts_.end(), [&](const ColmapAttempt& a) {
        return a.status != SfmStatus::success && (a.range == from[0] || a.range == from[1]);
      });
      if (failed == attempts_.end()) break;
      r = failed->range;
      ++n;
    }
    return n;
  }

  /// The points floor of a success on range r (at least 1).
  [[nodiscard]] std::size_t min_points(FrameRange r) const noexcept {
    return points_floor(opt_.min_points_per_frame, r.size());
  }

  /// True if `a` is a better outcome than `b`: success, else more registered frames, then more points.
  static bool better_result(const ColmapClipResult& a, const ColmapClipResult& b) noexcept {
    if ((a.status == SfmStatus::success) != (b.status == SfmStatus::success)) return a.status == SfmStatus::success;
    return a.frames.size() > b.frames.size() || (a.frames.size() == b.frames.size() && a.points.size() > b.points.size());
  }

  /// One COLMAP pass in `dir` (database.db, sparse*/, logs) over the frames in `images`, with COLMAP
  /// masks from `masks` (empty = whole frames): features, exhaustive matches, the mapper and the
  /// relaxed retries. Adds its seconds and relaxed runs to `info`; returns the best model found.
  std::pair<Model, ColmapClipResult> reconstruct_pass(FrameRange r, const std::filesystem::path& dir, const std::filesystem::path& images,
                                                      const std::filesystem::path& masks, ColmapAttempt& info) const {
    std::error_code ec;
    const auto db = dir / "database.db";
    const std::string dbk = database_key(!masks.empty());
    const std::filesystem::path seed = opt_.reuse_databases ? prior_database(r, dbk) : std::filesystem::path{};
    bool seeded = false;
    if (!seed.empty()) {
      if (opt_.keep_work) std::filesystem::copy_file(seed, db, std::filesystem::copy_options::overwrite_existing, ec);
      else std::filesystem::rename(seed, db, ec);
      seeded = !ec;
      if (!seeded) std::filesystem::remove(db, ec);
    }
    if (seeded) ++info.databases_reused;
    io::write_file_atomic(dir / "database.key", dbk + "\n");
    // 1. Features.
    std::vector<std::string> ex = base("feature_extractor");
    ex.insert(ex.end(), {"--database_path", db.string(), "--image_path", images.string(), "--ImageReader.camera_model",
                         "SIMPLE_PINHOLE", "--ImageReader.single_camera", "1", "--SiftExtraction.use_gpu", "0",
                         "--SiftExtraction.num_threads", colmap_threads_arg()});
    if (!masks.empty()) ex.insert(ex.end(), {"--ImageReader.mask_path", masks.string()});
    if (seeded) ex.insert(ex.end(), {"--ImageReader.existing_camera_id", "1"});  // the one camera of the seed
    if (fixed_intrinsics())
      ex.insert(ex.end(), {"--ImageReader.camera_params", num(intrinsics_->f) + "," + num(intrinsics_->cx) + "," + num(intrinsics_->cy)});
    if (opt_.max_image_size > 0) ex.insert(ex.end(), {"--SiftExtraction.max_image_size", std::to_string(opt_.max_image_size)});
    if (opt_.max_num_features > 0) ex.insert(ex.end(), {"--SiftExtraction.max_num_features", std::to_string(opt_.max_num_features)});
    auto pr = step(ex, dir / "extract.log", r);
    info.seconds_extract += pr.seconds;
    if (!pr.ok())
      throw external_error("colmap.failed", (dir / "extract.log").string(),
                           "colmap feature_extractor exited with " + exit_text(pr) + ": " + log_tail(dir / "extract.log"));
    if (opt_.deterministic) (void)drop_border_features(db);  // descriptors COLMAP may leave unwritten (matcher.hpp)
    // 2. Matches: exact raw matches imported and verified by COLMAP, or COLMAP's own matcher.
    // (matches_importer verifies raw matches but does not run guided matching: guide_matches does.)
    std::optional<ThreadPool> pool;
    MatchListStats ms;
    std::vector<std::string> mt;
    auto timed = [&](auto&& f) {
      const auto t0 = std::chrono::steady_clock::now();
      f();
      info.seconds_match += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    };
    if (opt_.deterministic) {
      pool.emplace(static_cast<unsigned>(std::max(0, opt_.threads)));
      const auto list = dir / "matches.txt";
      timed([&] { ms = write_match_list(db, list, {}, &*pool); });
      mt = base("matches_importer");
      mt.insert(mt.end(), {"--database_path", db.string(), "--match_list_path", list.string(), "--match_type", "raw",
                           "--SiftMatching.guided_matching", "0"});
      if (ms.pair_ids.empty()) mt.clear();  // a grown clip whose pairs were all matched before
    } else {
      mt = base("exhaustive_matcher");
      mt.insert(mt.end(), {"--database_path", db.string(), "--SiftMatching.guided_matching", opt_.guided_matching ? "1" : "0"});
    }
    if (!mt.empty()) {
      mt.insert(mt.end(), {"--SiftMatching.use_gpu", "0", "--SiftMatching.num_threads", colmap_threads_arg()});
      pr = step(mt, dir / "match.log", r);
      info.seconds_match += pr.seconds;
      if (!pr.ok())
        throw external_error("colmap.failed", (dir / "match.log").string(),
                             "colmap " + mt[1] + " exited with " + exit_text(pr) + ": " + log_tail(dir / "match.log"));
      if (opt_.deterministic && opt_.guided_matching) timed([&] { guide_matches(db, ms.pair_ids, {}, &*pool); });
    }
    // 3. Mapper, then the relaxed retry.
    auto map_once = [&](const std::filesystem::path& sparse, const std::filesystem::path& log, int relaxed_seed, double& secs) {
      const bool relaxed = relaxed_seed > 0;
      std::filesystem::create_directories(sparse, ec);
      std::vector<std::string> mp = base("mapper");
      mp.insert(mp.end(), {"--database_path", db.string(), "--image_path", images.string(), "--output_path", sparse.string(),
                           "--Mapper.num_threads", colmap_threads_arg(), "--Mapper.min_model_size", "2"});
      if (fixed_intrinsics())
        mp.insert(mp.end(), {"--Mapper.ba_refine_focal_length", "0", "--Mapper.ba_refine_principal_point", "0",
                             "--Mapper.ba_refine_extra_params", "0"});
      if (relaxed)
        mp.insert(mp.end(), {"--Mapper.init_min_tri_angle", num(opt_.relaxed_init_min_tri_angle), "--Mapper.tri_min_angle",
                             num(opt_.relaxed_tri_min_angle), "--Mapper.filter_min_tri_angle",
                             num(opt_.relaxed_filter_min_tri_angle), "--Mapper.init_min_num_inliers",
                             std::to_string(opt_.relaxed_init_min_num_inliers), "--random_seed", std::to_string(relaxed_seed)});
      const auto res = step(mp, log, r);
      secs += res.seconds;
      auto best = best_model(sparse, r);
      if (!best) {
        ColmapClipResult none;
        none.range = r;
        none.status = SfmStatus::soft_failure;
        none.message = "colmap mapper made no model (" + exit_text(res) + ")";
        return std::make_pair(Model{}, std::move(none));
      }
      ColmapClipResult& found = best->second;
      const std::size_t need = min_points(r);
      if (found.status == SfmStatus::success && found.points.size() < need) {
        found.status = SfmStatus::soft_failure;
        found.message = "every frame registered but only " + std::to_string(found.points.size()) + " 3D points (fewer than " +
                        std::to_string(need) + " = min_points_per_frame x frames): too few to trust the cameras";
      }
      if (found.status == SfmStatus::success && opt_.max_reprojection_error > 0) {
        CameraQuality q;
        q.max_reprojection_error = opt_.max_reprojection_error;
        if (std::string why = camera_quality_shortfall(found, r, q); !why.empty()) {
          found.status = SfmStatus::soft_failure;
          found.message = "every frame registered but the " + why + ": cameras not trusted";
        }
      }
      return std::move(*best);
    };
    auto [model, result] = map_once(dir / "sparse", dir / "mapper.log", 0, info.seconds_map);
    if (result.status != SfmStatus::success && opt_.relaxed_retry) {
      info.relaxed_tried = true;
      bool improved = false;
      for (int seed = 1; seed <= std::max(1, opt_.relaxed_tries) && result.status != SfmStatus::success; ++seed) {
        const std::string suffix = seed == 1 ? "" : "_" + std::to_string(seed);
        auto [model2, result2] = map_once(dir / ("sparse_relaxed" + suffix), dir / ("mapper_relaxed" + suffix + ".log"), seed,
                                          info.seconds_map_relaxed);
        ++info.relaxed_runs;
        if (better_result(result2, result)) {
          info.relaxed_succeeded = result2.status == SfmStatus::success;
          improved = true;
          model = std::move(model2);
          result = std::move(result2);
        }
      }
      if (result.status != SfmStatus::success)
        result.message += improved ? " (after relaxed retries)" : " (relaxed retries did not help)";
    }
    return std::make_pair(std::move(model), std::move(result));
  }

  ColmapClipResult run(FrameRange r, const std::filesystem::path& dir, const std::string& key) const {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
    const auto images = dir / "images", masks = dir / "masks";
    std::filesystem::create_directories(images, ec);
    if (ec) throw io_error("io.unwritable", images.string(), "cannot create folder: " + ec.message());
    ColmapAttempt info;
    info.range = r;
    info.dir = dir;

    // Frames: symlinks (copies if the file system refuses links). A JPEG with an EXIF orientation other
    // than 1 is written upright as PNG instead, because COLMAP reads the stored pixels (it ignores the tag)
    // while training reads them upright: both must see the same image.
    std::vector<std::string> names;
    std::vector<io::ImageInfo> infos;  // upright sizes, for the masks' check below
    for (int f = r.first; f <= r.last; ++f) {
      const auto src = std::filesystem::absolute(frames_[static_cast<std::size_t>(f)]);
      if (!std::filesystem::is_regular_file(src, ec)) throw io_error("io.missing", src.string(), "frame file not found");
      infos.push_back(io::read_image_info(src));
      const bool upright_copy = infos.back().orientation != 1;
      names.push_back(frame_name(f, upright_copy));
      const auto dst = images / names.back();
      if (upright_copy) {
        io::write_png(dst, io::read_image<3>(src));
        continue;
      }
      std::filesystem::create_symlink(src, dst, ec);
      if (ec) {
        std::filesystem::copy_file(src, dst, std::filesystem::copy_options::overwrite_existing, ec);
        if (ec) throw io_error("io.unwritable", dst.string(), "cannot link or copy the frame: " + ec.message());
      }
    }
    // Masks: mean area decides whether they are used.
    std::vector<Image<float, 1>> ms;
    auto write_masks = [&] {
      std::filesystem::create_directories(masks, ec);
      for (int f = r.first; f <= r.last; ++f)
        io::write_png(masks / (names[static_cast<std::size_t>(f - r.first)] + ".png"), ms[static_cast<std::size_t>(f - r.first)]);
    };
    if (opt_.use_masks && !masks_.empty()) {
      double area = 0;
      for (int f = r.first; f <= r.last; ++f) {
        const auto& mp = masks_[static_cast<std::size_t>(f)];
        Image<float, 1> m = io::read_mask(mp);
        const io::ImageInfo& info_f = infos[static_cast<std::size_t>(f - r.first)];
        if (m.width() != info_f.width || m.height() != info_f.height)
          throw io_error("io.size_mismatch", mp.string(),
                         "mask is " + std::to_string(m.width()) + "x" + std::to_string(m.height()) + ", its frame " +
                             std::to_string(info_f.width) + "x" + std::to_string(info_f.height));
        double s = 0;
        for (std::size_t i = 0; i < m.pixel_count(); ++i) s += m.data()[i];
        area += m.pixel_count() ? s / double(m.pixel_count()) : 0.0;
        ms.push_back(std::move(m));
      }
      info.mask_area = area / double(r.size());
      if (info.mask_area >= opt_.min_mask_area) {
        info.masked = true;
        write_masks();
      }
    }

    const bool first_masked = info.masked;
    auto [model, result] = reconstruct_pass(r, dir, images, first_masked ? masks : std::filesystem::path{}, info);
    // The other pass, before the scheduler grows the clip: after failed masked SfM the whole frames
    // (a static background gives the parallax a nearly static foreground lacks); after failed
    // full-frame SfM (masks below min_mask_area) the masks (the moving foreground misleads it).
    const bool other = first_masked ? opt_.full_frame_fallback
                                     : !ms.empty() && opt_.masked_fallback_min_area > 0 && info.mask_area >= opt_.masked_fallback_min_area &&
                                           failed_growth_steps(r, opt_.masked_fallback_after) >= opt_.masked_fallback_after;
    if (result.status != SfmStatus::success && other) {
      info.fallback_tried = true;
      const auto sub = dir / (first_masked ? "full_frames" : "masked");
      std::filesystem::create_directories(sub, ec);
      if (!first_masked) write_masks();
      auto [model2, result2] = reconstruct_pass(r, sub, images, first_masked ? std::filesystem::path{} : masks, info);
      if (better_result(result2, result)) {
        info.fallback_succeeded = result2.status == SfmStatus::success;
        info.masked = !first_masked;
        model = std::move(model2);
        result = std::move(result2);
      }
      if (result.status != SfmStatus::success)
        result.message += first_masked ? " (the full-frame pass did not complete it either)" : " (the masked pass did not complete it either)";
    }
    ColmapClipResult out;
    static_cast<SfmResult<double>&>(out) = std::move(result);
    out.model = std::move(model);
    info.status = out.status;
    info.message = out.message;
    info.registered = static_cast<int>(out.frames.size());
    info.points = out.points.size();
    info.mean_reprojection_error = video3dgs::mean_reprojection_error(out.points);

    // The chosen model gets a stable place so that the bulky rest can go.
    if (!out.model.images.empty()) {
      write_model(dir / "model", out.model, Format::binary);
      out.model_dir = dir / "model";
    } else {
      out.model_dir.clear();
    }
    write_outcome(dir, key, info);
    if (!opt_.keep_work) {
      if (opt_.reuse_finished) {
        // A failed attempt keeps its databases for the attempt that grows it (reuse_databases).
        const bool keep_db = opt_.reuse_databases && out.status != SfmStatus::success;
        for (const auto& d : {dir, dir / "full_frames", dir / "masked"}) {
          for (const char* p : {"images", "masks", "sparse", "sparse_relaxed", "sparse_relaxed_2", "sparse_relaxed_3", "matches.txt", "database.db-shm",
                                "database.db-wal"})
            std::filesystem::remove_all(d / p, ec);
          for (int seed = 4; seed <= opt_.relaxed_tries; ++seed) std::filesystem::remove_all(d / ("sparse_relaxed_" + std::to_string(seed)), ec);
          if (!keep_db) std::filesystem::remove(d / "database.db", ec);
        }
        if (!keep_db) {
          std::filesystem::remove_all(dir / "full_frames", ec);
          std::filesystem::remove_all(dir / "masked", ec);
        }
      } else {
        std::filesystem::remove_all(dir, ec);
        out.model_dir.clear();
      }
    }
    out.attempt = info;
    return out;
  }

  static std::string exit_text(const ProcessResult& pr) {
    if (pr.signal) return "signal " + std::to_string(pr.signal);
    return "status " + std::to_string(pr.exit_code);
  }


  std::vector<std::filesystem::path> frames_;
  std::vector<std::filesystem::path> masks_;
  ColmapSfmOptions opt_;
  std::optional<SharedIntrinsics> intrinsics_;
  std::vector<ColmapAttempt> attempts_;
};

static_assert(SfmBackend<ColmapSfm>, "ColmapSfm must model SfmBackend");

}  // namespace video3dgs::colmap
