#pragma once
/// @file
/// The reconstruction job of a video, as library code (the `video3dgs reconstruct` command only
/// parses flags and draws progress):
///
///     pipeline::ReconstructOptions o;  o.frames_dir = "video/frames"; o.out = "out";
///     ThreadPool pool;
///     auto input = pipeline::prepare_input(o, &pool);        // every check, no long work, no writes
///     colmap::ColmapSfm sfm(input.list.frames, input.list.masks, {...});   // or any SfmBackend
///     auto report = pipeline::reconstruct_video(o, input, sfm, hooks, &pool);
///
/// Stages:
///   0. `prepare_input`: options; the output folder (not a file; an earlier reconstruction in it is
///      only touched with `resume` or `overwrite`); the frame list (`io.empty`, `io.mask_missing`, ...);
///      every frame and mask decoded up front (corrupt files, `io.size_mismatch`), frames resized
///      by `scale` (area-weighted). Nothing is written before all of it passed.
///   1. MC-COLMAP: `schedule_clips` over the back end (whose results must derive from SfmResult<double>,
///      cameras in pixels of the original frames; they are rescaled to the training size).
///   2. Each clip: `make_clip_model` + `ClipTrainer` with `TrainOptions::preset(preset)`
///      (iterations overridable, densification window kept at the preset's 2/3). A finished clip
///      is written to OUT/model/clip_NNN.model plus OUT/train/clip_NNN.done (its settings key, frame
///      range and figures); an unfinished one to OUT/train/clip_NNN.ckpt (every `checkpoint_every` iterations
///      and when stopped). With `resume`, a clip whose .done key matches is loaded, not retrained,
///      and a matching .ckpt continues where it stopped.
///   3. Every frame rendered from the `VideoModel` (overlaps blended, model/video_model.hpp):
///      OUT/renders/00000.png, OUT/compare/00000.png (source | render | error heat map),
///      OUT/metrics.csv (frame,psnr,ssim), OUT/metrics.png, OUT/ply/clip_NNN_{frg,bkg}.ply (first frame
///      of each clip), OUT/model/manifest.txt, and OUT/report.json last.
/// Every file is written atomically (temporary + rename).
///
/// Stopping: `hooks.stop` (e.g. set by a SIGINT handler) is polled between SfM attempts, every
/// training iteration and every rendered frame; the running clip's checkpoint is saved and
/// error `[run.interrupted]` is thrown (finished clips stay; rerun with `resume`).

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <concepts>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <sstream>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/io/frame_folder.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/loss/ssim.hpp"
#include "video3dgs/metrics/psnr.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/model/clip_model_io.hpp"
#include "video3dgs/model/video_model.hpp"
#include "video3dgs/pipeline/outputs.hpp"
#include "video3dgs/scheduling/schedule_clips.hpp"
#include "video3dgs/scheduling/sfm_result.hpp"
#include "video3dgs/training/clip_trainer.hpp"
#include "video3dgs/training/train_options.hpp"

namespace video3dgs::pipeline {

using VideoModelF = VideoModel<float>;

struct ReconstructOptions {
  std::filesystem::path frames_dir;  ///< required: folder of frames (natural order)
  std::filesystem::path masks_dir;   ///< optional: foreground masks matched by file stem
  std::filesystem::path out;         ///< required: output folder
  std::string preset = "3k";         ///< 3k | 5k | 10k
  int iterations = 0;                ///< > 0 overrides the preset's iterations
  double scale = 1.0;                ///< training / render size = round(scale x frame size), (0, 1]
  std::uint64_t seed = 0;
  int k = 10;                        ///< MC-COLMAP: frames of a new clip
  int max_clip_frames = 0;           ///< MC-COLMAP: longest clip (0 = whole video)
  bool resume = false;               ///< reuse finished clips / checkpoints in `out`
  bool overwrite = false;            ///< allow replacing an earlier reconstruction in `out`
  int checkpoint_every = 1000;       ///< iterations between trainer checkpoints (0 = only when stopped)
  ClipModelOptions model{};          ///< initialisation (background shells, ...)
  bool write_compare = true;
  bool write_ply = true;

  /// The training options these settings give. @throws option_error
  [[nodiscard]] TrainOptions train_options() const {
    TrainOptions t = TrainOptions::preset(preset);
    if (iterations > 0 && iterations != t.iterations) {
      // Keep the preset's proportions: densification window, warm-up and SH steps scaled; the
      // densification interval shrinks at most to 50 (each event can double a set: a scaled interval
      // of 10 over a short run multiplies the Gaussians ~50-fold for no gain).
      const double f = double(iterations) / double(t.iterations);
      t.iterations = iterations;
      t.densify_from = std::max(1, static_cast<int>(std::lround(t.densify_from * f)));
      t.densify_until = std::max(t.densify_from, static_cast<int>(std::lround(t.densify_until * f)));
      t.densify_interval = std::min(t.densify_interval, std::max(50, static_cast<int>(std::lround(t.densify_interval * f))));
      t.deformation_warmup = static_cast<int>(std::lround(t.deformation_warmup * f));
      t.sh_degree_interval = std::max(1, static_cast<int>(std::lround(t.sh_degree_interval * f)));
      t.opacity_reset_interval = std::max(1, static_cast<int>(std::lround(t.opacity_reset_interval * f)));
    }
    t.seed = seed;
    t.validate();
    return t;
  }

  /// @throws option_error `option.*` naming the field.
  void validate() const {
    if (frames_dir.empty()) throw option_error("option.required", "--frames", "a frame folder (or video file) is required");
    if (out.empty()) throw option_error("option.required", "--out", "an output folder is required");
    if (!(scale > 0 && scale <= 1)) throw option_error("option.range", "--scale", "must be in (0, 1]");
    if (iterations < 0 || iterations > 1000000) throw option_error("option.range", "--iterations", "must be in 0..1000000 (0 = preset)");
    if (k < 1) throw option_error("option.range", "-k", "must be >= 1");
    if (checkpoint_every < 0) throw option_error("option.range", "checkpoint_every", "must be >= 0");
    (void)train_options();
  }
};

/// The validated, decoded input.
struct PreparedInput {
  io::FrameList list;
  std::vector<Image<float, 3>> frames;  ///< at the training size
  std::vector<Image<float, 1>> masks;   ///< original size (empty without masks)
  int source_width = 0, source_height = 0;
  int width = 0, height = 0;            ///< training / render size
  [[nodiscard]] int frame_count() const noexcept { return static_cast<int>(frames.size()); }
};

/// A progress report of the job.
struct ProgressEvent {
  enum class Stage { sfm, train, render } stage = Stage::sfm;
  int clip = 0, clips = 0;            ///< clip being worked on (sfm: clips so far)
  int iteration = 0, iterations = 0;  ///< train: iterations done of this clip / per clip
  int frame = 0, frames = 0;          ///< render: frames done; sfm: frames covered
  double psnr = 0;                    ///< train: last iteration's PSNR; render: this frame's
  bool reused = false;                ///< train: the clip was loaded from an earlier run
  std::string message;                ///< sfm: what the attempt did
};

struct ReconstructHooks {
  std::function<void(const ProgressEvent&)> progress;  ///< optional
  const std::atomic<bool>* stop = nullptr;             ///< optional: set to stop early
};

/// Per clip figures of the report.
struct ClipReport {
  int first = 0, last = 0, iterations = 0;
  double psnr = 0, ssim = 0;
  std::size_t gaussians_frg = 0, gaussians_bkg = 0, model_bytes = 0;
  /// Training seconds of the clip as recorded when it was trained (checkpointed parts included): a clip
  /// reused by `resume` keeps the figure of the run that trained it (from its clip_NNN.done).
  double train_seconds = 0;
  bool reused = false;
  int sfm_attempts = 0;
  std::size_t sfm_points = 0;
  std::size_t sfm_registered = 0;  ///< frames of the clip its SfM result registers
  double sfm_seconds = 0;          ///< wall time of this run's SfM calls for the clip (~0 when reused)
  /// SfM seconds as recorded by the attempts that made the clip: a reused attempt keeps the figure of
  /// the run that computed it (back ends with `attempts()`, e.g. ColmapSfm; others: sfm_seconds).
  double sfm_seconds_recorded = 0;
  /// Whether the clip's cameras and points come from SfM on masked frames (true) or whole frames
  /// (false); unknown (null in JSON) for back ends whose attempts() do not say (ColmapSfm does).
  std::optional<bool> sfm_masked;
};

struct ReconstructReport {
  int frames = 0, width = 0, height = 0;
  double psnr = 0, ssim = 0;  ///< means over frames (PSNR of identical frames capped at 100 dB)
  /// Mean PSNR of a trivial model: each frame replaced by its own mean colour. A reconstruction
  /// worth keeping is well above it (tests use it as their floor's reference).
  double psnr_mean_colour = 0;
  double seconds_sfm = 0, seconds_train = 0, seconds_render = 0, seconds_total = 0;
  double seconds_sfm_recorded = 0;  ///< sum of the clips' sfm_seconds_recorded (what SfM cost, resumed runs included)
  /// Sum of the clips' train_seconds (what training cost, resumed runs included; seconds_train is this
  /// run's training wall time, about 0 when every clip is reused).
  double seconds_train_recorded = 0;
  std::vector<ClipReport> clips;
  std::vector<double> psnr_per_frame, ssim_per_frame;
  int trained_clips = 0;  ///< clips trained (not reused) in this run

  /// The report.json text (one object, see the file comment of the command).
  [[nodiscard]] std::string json() const;
};

namespace detail {

inline std::string json_number(double v) {
  if (!std::isfinite(v)) return "null";
  char b[40];
  std::snprintf(b, sizeof(b), "%.6g", v);
  return b;
}

inline std::string clip_stem(std::size_t c) {
  char b[32];
  std::snprintf(b, sizeof(b), "clip_%03zu", c);
  return b;
}

inline std::string frame_png(int f) {
  char b[32];
  std::snprintf(b, sizeof(b), "%05d.png", f);
  return b;
}

inline void make_dir(const std::filesystem::path& d) {
  std::error_code ec;
  std::filesystem::create_directories(d, ec);
  if (ec || !std::filesystem::is_directory(d)) throw io_error("io.unwritable", d.string(), "cannot create folder" + (ec ? ": " + ec.message() : std::string()));
}

/// key=value lines of a small text file (empty map if it does not exist).
inline std::map<std::string, std::string> read_kv(const std::filesystem::path& p) {
  std::map<std::string, std::string> kv;
  std::ifstream in(p);
  std::string line;
  while (std::getline(in, line)) {
    const auto eq = line.find('=');
    if (eq != std::string::npos) kv[line.substr(0, eq)] = line.substr(eq + 1);
  }
  return kv;
}

inline void check_stop(const ReconstructHooks& h, const std::string& where) {
  if (h.stop && h.stop->load())
    throw error("run.interrupted", where,
                "stopped on request; finished clips and the running clip's checkpoint are kept, rerun with --resume to continue");
}

}  // namespace detail

inline std::string ReconstructReport::json() const {
  using detail::json_number;
  std::ostringstream o;
  o << "{\"frames\":" << frames << ",\"width\":" << width << ",\"height\":" << height << ",\"psnr\":" << json_number(psnr)
    << ",\"ssim\":" << json_number(ssim) << ",\"psnr_mean_colour\":" << json_number(psnr_mean_colour) << ",\"seconds\":{\"sfm\":" << json_number(seconds_sfm) << ",\"train\":" << json_number(seconds_train)
    << ",\"render\":" << json_number(seconds_render) << ",\"total\":" << json_number(seconds_total)
    << ",\"sfm_recorded\":" << json_number(seconds_sfm_recorded) << ",\"train_recorded\":" << json_number(seconds_train_recorded) << "},\"trained_clips\":" << trained_clips
    << ",\"clips\":[";
  for (std::size_t c = 0; c < clips.size(); ++c) {
    const auto& r = clips[c];
    o << (c ? "," : "") << "{\"first\":" << r.first << ",\"last\":" << r.last << ",\"iterations\":" << r.iterations
      << ",\"psnr\":" << json_number(r.psnr) << ",\"ssim\":" << json_number(r.ssim) << ",\"gaussians_frg\":" << r.gaussians_frg
      << ",\"gaussians_bkg\":" << r.gaussians_bkg << ",\"model_bytes\":" << r.model_bytes << ",\"train_seconds\":" << json_number(r.train_seconds)
      << ",\"reused\":" << (r.reused ? "true" : "false") << ",\"sfm_attempts\":" << r.sfm_attempts << ",\"sfm_points\":" << r.sfm_points
      << ",\"sfm_registered\":" << r.sfm_registered << ",\"sfm_seconds\":" << json_number(r.sfm_seconds)
      << ",\"sfm_seconds_recorded\":" << json_number(r.sfm_seconds_recorded)
      << ",\"sfm_masked\":" << (r.sfm_masked ? (*r.sfm_masked ? "true" : "false") : "null") << "}";
  }
  o << "]}";
  return o.str();
}

/// Stage 0 (see the file comment): validates everything and decodes every frame. Writes nothing.
/// @throws option_error `option.*`; io_error `io.not_a_folder` (out is a file), `io.output_exists`
///         (an earlier reconstruction without resume/overwrite), the frame folder's `io.*` errors.
[[nodiscard]] inline PreparedInput prepare_input(const ReconstructOptions& o, ThreadPool* pool = nullptr) {
  o.validate();
  std::error_code ec;
  if (std::filesystem::exists(o.out, ec) && !std::filesystem::is_directory(o.out, ec))
    throw io_error("io.not_a_folder", o.out.string(), "the output path exists and is not a folder; choose another --out");
  if (!o.resume && !o.overwrite &&
      (std::filesystem::exists(o.out / "report.json", ec) || std::filesystem::exists(o.out / "model" / kVideoModelManifest, ec) ||
       std::filesystem::exists(o.out / "train", ec)))
    throw io_error("io.output_exists", o.out.string(),
                   "holds an earlier reconstruction; pass --resume to continue it or --overwrite to replace it");
  PreparedInput in;
  in.list = io::list_frames(o.frames_dir, o.masks_dir);
  auto frames = io::read_frames(in.list, pool);  // decodes every frame: corrupt files fail here
  in.masks = io::read_masks(in.list, pool);
  in.source_width = frames.front().width();
  in.source_height = frames.front().height();
  in.width = std::max(1, static_cast<int>(std::lround(in.source_width * o.scale)));
  in.height = std::max(1, static_cast<int>(std::lround(in.source_height * o.scale)));
  if (in.width < 8 || in.height < 8)
    throw option_error("option.range", "--scale", "frames of " + std::to_string(in.width) + "x" + std::to_string(in.height) + " are too small to train on");
  if (in.width == in.source_width && in.height == in.source_height) {
    in.frames = std::move(frames);
  } else {
    in.frames.resize(frames.size());
    parallel_for(pool, frames.size(), [&](std::size_t i) {
      in.frames[i] = resize_area(frames[i], in.width, in.height);
      frames[i] = Image<float, 3>();
    }, 1);
  }
  return in;
}

/// Stages 1-3 (see the file comment). `sfm` is any `SfmBackend` whose result derives from
/// `SfmResult<double>`, e.g. `colmap::ColmapSfm`; it should already have been checked (program present).
/// @throws the back end's and the scheduler's errors, `[run.interrupted]`, `io.*` on write failures.
template <class Sfm>
ReconstructReport reconstruct_video(const ReconstructOptions& o, const PreparedInput& in, Sfm& sfm, const ReconstructHooks& hooks = {},
                                    ThreadPool* pool = nullptr, VideoModelF* model_out = nullptr) {
  static_assert(SfmBackend<Sfm&> && std::derived_from<sfm_result_t<Sfm&>, SfmResult<double>>,
                "video3dgs::pipeline::reconstruct_video: the SfM back end must be callable as sfm(FrameRange) and return a "
                "type derived from video3dgs::SfmResult<double> (e.g. colmap::ColmapSfm)");
  using clock = std::chrono::steady_clock;
  auto since = [](clock::time_point t) { return std::chrono::duration<double>(clock::now() - t).count(); };
  const auto t_total = clock::now();
  const TrainOptions topt = o.train_options();
  const int n = in.frame_count();
  namespace fs = std::filesystem;
  const fs::path model_dir = o.out / "model", train_dir = o.out / "train";
  detail::make_dir(o.out);
  detail::make_dir(model_dir);
  detail::make_dir(train_dir);
  auto emit = [&](const ProgressEvent& e) {
    if (hooks.progress) hooks.progress(e);
  };

  ReconstructReport rep;
  rep.frames = n;
  rep.width = in.width;
  rep.height = in.height;

  // ---- 1. MC-COLMAP ----
  auto t = clock::now();
  ScheduleOptions so;
  so.initial_frames = o.k;
  so.overlap = 1;
  so.max_clip_frames = o.max_clip_frames;
  so.progress = [&](const ScheduleProgress& p) {
    ProgressEvent e;
    e.stage = ProgressEvent::Stage::sfm;
    e.clip = p.clip;
    e.frame = p.frames_done;
    e.frames = p.frame_count;
    e.message = "clip " + std::to_string(p.clip) + " frames " + std::to_string(p.range.first) + "-" + std::to_string(p.range.last) +
                " attempt " + std::to_string(p.attempt) + ": " + to_string(p.status) + (p.message.empty() ? "" : " (" + p.message + ")");
    emit(e);
  };
  auto guarded = [&](FrameRange r) {
    detail::check_stop(hooks, "sfm");
    return sfm(r);
  };
  std::size_t attempts_before = 0;
  if constexpr (requires { sfm.attempts(); }) attempts_before = sfm.attempts().size();
  auto schedule = schedule_clips(n, guarded, so);
  rep.seconds_sfm = since(t);
  detail::check_stop(hooks, "sfm");
  // Recorded SfM seconds per clip: each attempt of this run counts for the first clip whose frames
  // contain its frames (a clip's growth attempts are subsets of its final range).
  // The attempt that made a clip (its range, success) says whether its SfM ran on masked frames.
  std::vector<double> sfm_recorded(schedule.clips.size(), 0.0);
  std::vector<std::optional<bool>> sfm_masked(schedule.clips.size());
  if constexpr (requires { sfm.attempts(); }) {
    const auto& attempts = sfm.attempts();
    for (std::size_t a = attempts_before; a < attempts.size(); ++a)
      for (std::size_t c = 0; c < schedule.clips.size(); ++c) {
        const FrameRange r = schedule.clips[c].range;
        if (attempts[a].range.first >= r.first && attempts[a].range.last <= r.last) {
          sfm_recorded[c] += attempts[a].seconds();
          if constexpr (requires { bool(attempts[a].masked); bool(attempts[a].status == SfmStatus::success); })
            if (attempts[a].range.first == r.first && attempts[a].range.last == r.last && attempts[a].status == SfmStatus::success)
              sfm_masked[c] = bool(attempts[a].masked);
          break;
        }
      }
  } else {
    for (std::size_t c = 0; c < schedule.clips.size(); ++c) sfm_recorded[c] = schedule.clips[c].seconds;
  }

  // ---- 2. Train every clip ----
  t = clock::now();
  VideoModelF video;
  video.frame_count = n;
  video.width = in.width;
  video.height = in.height;
  const std::size_t nclips = schedule.clips.size();
  for (std::size_t c = 0; c < nclips; ++c) {
    const auto& sc = schedule.clips[c];
    const SfmResult<double>& sfmr = sc.result;
    const FrameRange range = sc.range;
    ClipReport cr;
    cr.first = range.first;
    cr.last = range.last;
    cr.sfm_attempts = sc.attempts;
    cr.sfm_points = sfmr.points.size();
    cr.sfm_registered = sfmr.frames.size();
    cr.sfm_seconds = sc.seconds;
    cr.sfm_seconds_recorded = sfm_recorded[c];
    cr.sfm_masked = sfm_masked[c];
    rep.seconds_sfm_recorded += sfm_recorded[c];
    const std::string stem = detail::clip_stem(c);
    const fs::path done_file = train_dir / (stem + ".done"), ckpt = train_dir / (stem + ".ckpt"), ckpt_key = train_dir / (stem + ".ckpt.key"),
                   model_file = model_dir / video_model_clip_file(c);

    // Settings key: what the trained clip depends on.
    std::ostringstream keys;
    keys << "v1|" << range.first << "-" << range.last << "|" << in.width << "x" << in.height << "|it=" << topt.iterations << "|preset=" << o.preset
         << "|seed=" << o.seed << "|pts=" << sfmr.points.size() << "|shell=" << o.model.background.points_per_shell;
    for (int f = range.first; f <= range.last; ++f) {
      const int i = sfmr.index_of(f);
      if (i < 0) throw error("sfm.incomplete", "frame " + std::to_string(f), "the SfM result of its clip does not register it");
      const auto& cam = sfmr.cameras[std::size_t(i)];
      keys << "|" << fs::absolute(in.list.frames[std::size_t(f)]).string() << ":" << detail::json_number(cam.fx) << "," << detail::json_number(cam.t.x());
    }
    const std::string key = std::to_string(std::hash<std::string>{}(keys.str()));

    std::error_code ec;
    const auto done = detail::read_kv(done_file);
    if (o.resume && done.count("key") && done.at("key") == key && fs::is_regular_file(model_file, ec)) {
      auto m = load_clip_model<float>(model_file);
      cr.reused = true;
      cr.iterations = std::stoi(done.at("iterations"));
      cr.psnr = std::stod(done.at("psnr"));
      cr.ssim = std::stod(done.at("ssim"));
      cr.train_seconds = std::stod(done.at("train_seconds"));
      cr.gaussians_frg = m.frg.size();
      cr.gaussians_bkg = m.bkg.size();
      cr.model_bytes = static_cast<std::size_t>(fs::file_size(model_file, ec));
      ProgressEvent e;
      e.stage = ProgressEvent::Stage::train;
      e.clip = static_cast<int>(c);
      e.clips = static_cast<int>(nclips);
      e.iteration = e.iterations = topt.iterations;
      e.psnr = cr.psnr;
      e.reused = true;
      emit(e);
      video.clips.push_back(std::move(m));
      rep.seconds_train_recorded += cr.train_seconds;
      rep.clips.push_back(cr);
      continue;
    }

    const auto t_clip = clock::now();
    std::vector<Image<float, 3>> frames(in.frames.begin() + range.first, in.frames.begin() + range.last + 1);
    std::vector<Camera<float>> cams;
    for (int f = range.first; f <= range.last; ++f) {
      Camera<float> cam = sfmr.cameras[std::size_t(sfmr.index_of(f))].template cast<float>();
      if (cam.width != in.source_width || cam.height != in.source_height)
        throw error("sfm.camera_size", "frame " + std::to_string(f), "SfM camera is " + std::to_string(cam.width) + "x" + std::to_string(cam.height) +
                                                                    ", the frame " + std::to_string(in.source_width) + "x" + std::to_string(in.source_height));
      if (in.width != in.source_width || in.height != in.source_height) {
        const float sx = float(in.width) / float(in.source_width), sy = float(in.height) / float(in.source_height);
        cam.width = in.width, cam.height = in.height;
        cam.fx *= sx, cam.cx *= sx, cam.fy *= sy, cam.cy *= sy;
      }
      cams.push_back(cam);
    }
    std::vector<Image<float, 1>> masks;
    if (!in.masks.empty()) masks.assign(in.masks.begin() + range.first, in.masks.begin() + range.last + 1);

    std::unique_ptr<ClipTrainer<ClipModel<float>>> trainer;
    double prior_seconds = 0;
    if (o.resume && fs::is_regular_file(ckpt, ec) && detail::read_kv(ckpt_key)["key"] == key) {
      trainer = std::make_unique<ClipTrainer<ClipModel<float>>>(ckpt, std::move(frames), topt, pool);
      const auto kv = detail::read_kv(ckpt_key);
      if (kv.count("seconds")) prior_seconds = std::stod(kv.at("seconds"));
    } else {
      ClipModelOptions mo = o.model;
      mo.seed = o.seed + c;
      auto model = make_clip_model<float>(range, std::span<const Camera<float>>(cams), std::span<const SfmPoint<double>>(sfmr.points), mo,
                                          std::span<const Image<float, 1>>(masks), pool);
      trainer = std::make_unique<ClipTrainer<ClipModel<float>>>(std::move(model), std::move(frames), topt, pool);
    }
    auto save_ckpt = [&] {
      trainer->save_checkpoint(ckpt);
      io::write_file_atomic(ckpt_key, "key=" + key + "\nseconds=" + detail::json_number(prior_seconds + since(t_clip)) + "\n");
    };
    ProgressEvent e;
    e.stage = ProgressEvent::Stage::train;
    e.clip = static_cast<int>(c);
    e.clips = static_cast<int>(nclips);
    e.iterations = topt.iterations;
    bool stopped = false;
    trainer->train([&](const IterationInfo& it) {
      e.iteration = it.iteration + 1;
      e.psnr = it.psnr;
      emit(e);
      if (hooks.stop && hooks.stop->load()) {
        stopped = true;
        return false;
      }
      if (o.checkpoint_every > 0 && e.iteration % o.checkpoint_every == 0 && e.iteration < topt.iterations) save_ckpt();
      return true;
    });
    if (stopped || !trainer->done()) {
      save_ckpt();
      detail::check_stop(hooks, "clip " + std::to_string(c) + " (" + ckpt.string() + ")");
      throw error("run.interrupted", stem, "training stopped early");
    }
    const ClipEvaluation ev = trainer->evaluate();
    save_clip_model(model_file, trainer->model());
    cr.iterations = trainer->stats().iterations;
    cr.psnr = ev.psnr;
    cr.ssim = ev.ssim;
    // As clip_NNN.done records it (json_number's digits), so that a resumed run, which reads it back,
    // sums seconds.train_recorded from the same values.
    cr.train_seconds = std::stod(detail::json_number(prior_seconds + since(t_clip)));
    cr.gaussians_frg = trainer->model().frg.size();
    cr.gaussians_bkg = trainer->model().bkg.size();
    cr.model_bytes = static_cast<std::size_t>(fs::file_size(model_file, ec));
    io::write_file_atomic(done_file, "key=" + key + "\nfirst=" + std::to_string(cr.first) + "\nlast=" + std::to_string(cr.last) +
                                         "\niterations=" + std::to_string(cr.iterations) + "\npsnr=" + detail::json_number(cr.psnr) +
                                         "\nssim=" + detail::json_number(cr.ssim) + "\ntrain_seconds=" + detail::json_number(cr.train_seconds) + "\n");
    fs::remove(ckpt, ec);
    fs::remove(ckpt_key, ec);
    video.clips.push_back(std::move(trainer->model()));
    trainer.reset();
    rep.seconds_train_recorded += cr.train_seconds;
    rep.clips.push_back(cr);
    ++rep.trained_clips;
  }
  rep.seconds_train = since(t);
  video.validate(model_dir.string());
  write_video_manifest(model_dir, video.frame_count, video.width, video.height, video.ranges());

  // ---- 3. Render every frame ----
  t = clock::now();
  detail::make_dir(o.out / "renders");
  if (o.write_compare) detail::make_dir(o.out / "compare");
  VideoRenderBuffers<float> buf;
  loss::SsimContext<double, 3> ssim_ctx;
  std::ostringstream csv;
  csv << "frame,psnr,ssim\n";
  double psnr_sum = 0, ssim_sum = 0, base_sum = 0;
  for (int f = 0; f < n; ++f) {
    detail::check_stop(hooks, "render");
    const Image<float, 3>& img = video.render_frame(f, buf, pool);
    const Image<float, 3>& src = in.frames[std::size_t(f)];
    const double p = metrics::psnr<float, 3>(img, src, pool);
    const Image<double, 3> a = img.template cast<double>(), b = src.template cast<double>();
    const double s = loss::ssim_value<double, 3>(a.view(), b.view(), ssim_ctx, pool);
    {
      Image<float, 3> flat(src.width(), src.height());
      double mean[3] = {0, 0, 0};
      for (std::size_t i = 0; i < src.pixel_count(); ++i)
        for (int ch = 0; ch < 3; ++ch) mean[ch] += src.data()[3 * i + std::size_t(ch)];
      for (std::size_t i = 0; i < flat.pixel_count(); ++i)
        for (int ch = 0; ch < 3; ++ch) flat.data()[3 * i + std::size_t(ch)] = float(mean[ch] / double(src.pixel_count()));
      const double pb = metrics::psnr<float, 3>(flat, src, pool);
      base_sum += std::isfinite(pb) ? pb : 100.0;
    }
    rep.psnr_per_frame.push_back(p);
    rep.ssim_per_frame.push_back(s);
    psnr_sum += std::isfinite(p) ? p : 100.0;
    ssim_sum += s;
    csv << f << "," << detail::json_number(p) << "," << detail::json_number(s) << "\n";
    io::write_png(o.out / "renders" / detail::frame_png(f), img);
    if (o.write_compare) {
      const Image<float, 3> heat = error_heat_map(img, src);
      io::write_png(o.out / "compare" / detail::frame_png(f), side_by_side({&src, &img, &heat}));
    }
    ProgressEvent e;
    e.stage = ProgressEvent::Stage::render;
    e.frame = f + 1;
    e.frames = n;
    e.psnr = p;
    emit(e);
  }
  rep.psnr = psnr_sum / n;
  rep.ssim = ssim_sum / n;
  rep.psnr_mean_colour = base_sum / n;
  io::write_file_atomic(o.out / "metrics.csv", csv.str());
  const MetricsPlot plot = plot_metrics(rep.psnr_per_frame, rep.ssim_per_frame);
  io::write_png(o.out / "metrics.png", plot.image);
  if (o.write_ply) {
    detail::make_dir(o.out / "ply");
    for (std::size_t c = 0; c < video.clips.size(); ++c)
      for (GaussianSet s : {GaussianSet::foreground, GaussianSet::background})
        export_ply(video.clips[c], s, 0, o.out / "ply" / (detail::clip_stem(c) + "_" + to_string(s) + ".ply"), pool);
  }
  rep.seconds_render = since(t);
  rep.seconds_total = since(t_total);
  io::write_file_atomic(o.out / "report.json", rep.json() + "\n");
  if (model_out) *model_out = std::move(video);
  return rep;
}

}  // namespace video3dgs::pipeline
