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
/// `reconstruct_video` is the composition of stage functions a user may also call alone:
/// `sfm_stage` (1), `train_stage` (2; per clip `clip_key`, `load_finished_clip`, `train_clip`),
/// `render_stage` (3) and `export_ply_stage`; by default (`train_during_sfm`) stages 1 and 2 run at
/// once through `sfm_and_train_stage`: a clip trains while MC-COLMAP works on the next ones.
///
/// Stages:
///   0. `prepare_input`: options; the output folder (not a file; an earlier reconstruction in it is
///      only touched with `resume` or `overwrite`); the frame list (`io.empty`, `io.mask_missing`, ...);
///      every frame and mask decoded once up front and dropped (corrupt files, `io.size_mismatch`).
///      Nothing is written before all of it passed. Later stages decode a clip's frames when they
///      need them, resized by `scale` (area-weighted): no stage holds the whole video, so peak
///      memory follows the clip length and the frame size, not the number of frames.
///   1. MC-COLMAP: `schedule_clips` over the back end (whose results must derive from SfmResult<double>,
///      cameras in pixels of the original frames; they are rescaled to the training size).
///   2. Each clip: `make_clip_model` + `ClipTrainer` with `TrainOptions::preset(preset)`
///      (iterations overridable, the preset's schedules scaled with them). A finished clip
///      is written to OUT/model/clip_NNN.model plus OUT/train/clip_NNN.done, a JSON object {"key",
///      "first", "last", "iterations", "psnr", "ssim", "train_seconds", "psnr_frg", "psnr_bkg"}; an unfinished one to
///      OUT/train/clip_NNN.ckpt (every `checkpoint_every` iterations and when stopped) with
///      clip_NNN.ckpt.key {"key", "seconds"}. The key is a stable hash of the clip's settings
///      (`clip_key`). With `resume`, a clip whose .done key matches is loaded, not retrained, and a
///      matching .ckpt continues where it stopped. With `compact`, every clip of the run (trained or
///      reused) is also written as OUT/model/clip_NNN.compact (model/compact_io.hpp) and its bytes per
///      part go to the report.
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
#include <array>
#include <atomic>
#include <bit>
#include <charconv>
#include <chrono>
#include <cmath>
#include <concepts>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <deque>
#include <exception>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <sstream>
#include <string>
#include <system_error>
#include <thread>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/hash.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/core/resample.hpp"
#include "video3dgs/core/stopwatch.hpp"
#include "video3dgs/gaussian/activations.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/io/frame_folder.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/loss/ssim.hpp"
#include "video3dgs/metrics/psnr.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/model/clip_model_io.hpp"
#include "video3dgs/model/compact_io.hpp"
#include "video3dgs/model/video_model.hpp"
#include "video3dgs/pipeline/outputs.hpp"
#include "video3dgs/scheduling/schedule_clips.hpp"
#include "video3dgs/scheduling/sfm_result.hpp"
#include "video3dgs/training/capacity.hpp"
#include "video3dgs/training/clip_trainer.hpp"
#include "video3dgs/training/extend.hpp"
#include "video3dgs/training/train_options.hpp"

namespace video3dgs::pipeline {

using VideoModelF = VideoModel<float>;
using VideoModelFolderF = VideoModelFolder<float>;

struct ReconstructOptions {
  std::filesystem::path frames_dir;  ///< required: folder of frames (natural order)
  std::filesystem::path masks_dir;   ///< optional: foreground masks matched by file stem
  std::filesystem::path out;         ///< required: output folder
  std::string preset = "balanced";   ///< TrainOptions::preset_names(): balanced | fast | best | reference (= 3k) | 3k | 5k | 10k
  int iterations = 0;                ///< > 0 overrides the preset's iterations
  double scale = 1.0;                ///< training / render size = round(scale x frame size), (0, 1]
  std::uint64_t seed = 0;
  int k = 10;                        ///< MC-COLMAP: frames of a new clip
  int max_clip_frames = 0;           ///< MC-COLMAP: longest clip (0 = whole video)
  int join_tail = 0;                 ///< MC-COLMAP: ScheduleOptions::join_tail (0 = the method's tail clip)
  static constexpr int overlap = 1;  ///< MC-COLMAP: frames shared by consecutive clips (the method's)
  bool resume = false;               ///< reuse finished clips / checkpoints in `out`
  bool overwrite = false;            ///< allow replacing an earlier reconstruction in `out`
  int checkpoint_every = 1000;       ///< iterations between trainer checkpoints (0 = only when stopped)
  /// initialisation (background shells, static background, ...); `recommended_model_options()`: the
  /// background's first colours from the frames (BackgroundColour::random gives the method's draw) and
  /// the initial Gaussians no camera sees dropped (cull_unseen = false keeps them)
  ClipModelOptions model = recommended_model_options();
  bool sparse_adam = false;          ///< TrainOptions::sparse_adam (lazy Adam rows)
  /// TrainOptions::resolution_schedule, for the preset's iterations (scaled with `iterations`);
  /// empty: the preset's. A coarse-to-fine preset's fine phase (lr_fine_from, lr_alpha_fine) moves
  /// with it (TrainOptions::with_resolution_schedule); fine_position_lr / fine_alpha_lr still win.
  std::vector<TrainOptions::ResolutionStep> resolution_schedule;
  /// TrainOptions::prune_weight; unset: the preset's.
  std::optional<double> prune_weight;
  /// TrainOptions::prune_weight_from (iterations of the preset, scaled with `iterations`); unset: the preset's.
  std::optional<int> prune_weight_from;
  /// TrainOptions::prune_efficiency; unset: the preset's (balanced and fast prune at 0.01, the
  /// others not); 0 turns the prune off.
  std::optional<double> prune_efficiency;
  /// TrainOptions::prune_efficiency_at (iterations of the preset, scaled with `iterations`); unset:
  /// the preset's, or for a preset without the prune 50 iterations after its last densification
  /// event (inside the run). Ignored while the prune is off (prune_efficiency and the preset's).
  std::optional<int> prune_efficiency_at;
  /// TrainOptions::prune_efficiency_from (iterations of the preset, scaled with `iterations`): the
  /// efficiency prune also at every densification event from it on; set, an unset
  /// prune_efficiency_at means no one-shot prune. Ignored while the prune is off.
  std::optional<int> prune_efficiency_from;
  /// TrainOptions::prune_efficiency_bkg: the background set's own threshold in that prune; unset: the
  /// foreground's. Ignored while the prune is off.
  std::optional<double> prune_efficiency_bkg;
  /// TrainOptions::crop; unset: the preset's.
  std::optional<double> crop;
  /// TrainOptions::lr_camera_rotation / lr_camera_translation (camera refinement; {0, 0}: off); unset:
  /// the preset's.
  std::optional<std::array<double, 2>> camera_lr;
  /// TrainOptions::gaussians_per_pixel (0: no budget but max_gaussians); each clip's foreground
  /// share is its masks' coverage (1 without masks) unless `foreground_share` is set.
  double gaussians_per_pixel = 0;
  /// TrainOptions::foreground_share for every clip, in (0, 1]; unset: each clip's masks' coverage.
  std::optional<double> foreground_share;
  /// TrainOptions::lr_deformation_init (the fields' starting rate; the decay to lr_deformation_final
  /// is the preset's); unset: the preset's.
  std::optional<double> deformation_lr;
  /// TrainOptions::lr_sh_dc for the whole run, and lr_sh_rest = lr_sh_dc / 20 (the paper's ratio of the
  /// other bands' rate to the DC band's); the fine phase's step (lr_sh_fine) multiplies both. Unset:
  /// the preset's.
  std::optional<double> sh_lr;
  /// TrainOptions::lr_position_fine (the Gaussians' position rate x this from the preset's first
  /// full-size iteration, TrainOptions::lr_fine_from); unset: the preset's.
  std::optional<double> fine_position_lr;
  /// TrainOptions::lr_alpha_fine (the alpha maps' rate x this from the preset's first full-size
  /// iteration); unset: the preset's.
  std::optional<double> fine_alpha_lr;
  /// TrainOptions::lr_sh_fine (the colour coefficients' rates x this from the preset's first full-size
  /// iteration); unset: the preset's.
  std::optional<double> fine_sh_lr;
  /// TrainOptions::lambda_dssim_fine (the loss's D-SSIM weight from the preset's first full-size
  /// iteration on); unset: the preset's.
  std::optional<double> fine_dssim;
  /// TrainOptions::lr_anneal_factor (every rate falls log-linearly to this factor of itself at the
  /// run's end); 1 turns the anneal off (and clears its start). Unset: the preset's.
  std::optional<double> anneal_lr;
  /// TrainOptions::lr_anneal_from (iterations of the preset, scaled with `iterations`); unset: the
  /// preset's, or with `anneal_lr` on a preset without one `TrainOptions::default_lr_anneal_from()`.
  /// Refused while no anneal is on.
  std::optional<int> anneal_from;
  /// A quality floor (training/extend.hpp): a clip whose PSNR after the preset's iterations is below
  /// `extend.below_psnr` trains on in steps of `extend.step`, at most `extend.max_iterations` more,
  /// until it reaches it. Off by default (below_psnr 0).
  ExtendOptions extend;
  /// Set: also write each clip's compact file (model/compact_io.hpp) with these options; the report
  /// gives its bytes per part (ClipReport::compact_bytes).
  std::optional<CompactOptions> compact;
  /// Set: each clip's model is sized by `plan_capacity` (training/capacity.hpp) from its training size,
  /// frame count, SfM points and viewpoints: both fields' grids, a Gaussian budget (with the
  /// foreground's share fixed at 1) and the highest SH degree. Sizes given here explicitly win: a
  /// resized grid, `gaussians_per_pixel` > 0, `foreground_share`. The report gives each clip's plan.
  std::optional<CapacityRules> capacity;
  bool write_compare = true;
  std::filesystem::path gnuplot = "gnuplot";  ///< draws metrics.png (plot_metrics_gnuplot); missing: the plain plot
  bool write_ply = true;
  /// Stages for schedulers (cluster recipes): `sfm_only` stops after MC-COLMAP; `train_clips`
  /// {first, last} (inclusive, last = -1: to the end) trains only those clips of the schedule, skipping
  /// finished ones (needs `resume` when the folder holds the SfM stage's work), and stops before the
  /// manifest, renders and report. Workers on disjoint ranges write disjoint files; a final run with
  /// `resume` and neither option combines the clips into the outputs a single run writes.
  bool sfm_only = false;
  std::optional<std::pair<int, int>> train_clips;
  /// Stages 1 and 2 at once: MC-COLMAP runs on a second thread and each clip trains as soon as the
  /// scheduler has made it final (clips are final in order; training does not depend on later clips).
  /// The models, renders and report figures are the same either way; only wall times change.
  bool train_during_sfm = true;

  /// The training options these settings give. @throws option_error
  [[nodiscard]] TrainOptions train_options() const {
    TrainOptions t = TrainOptions::preset(preset);
    // In the preset's iterations; a coarse-to-fine preset's fine phase moves with it.
    if (!resolution_schedule.empty()) t = t.with_resolution_schedule(resolution_schedule);
    if (prune_weight_from) t.prune_weight_from = *prune_weight_from;
    // Before the scaling: the iterations are the preset's. The prune's settings apply when it is on,
    // by its own flag or by the preset (balanced's).
    if (prune_efficiency) t.prune_efficiency = *prune_efficiency;
    if (t.prune_efficiency > 0) {
      if (prune_efficiency_from) t.prune_efficiency_from = *prune_efficiency_from;
      if (prune_efficiency_bkg) t.prune_efficiency_bkg = *prune_efficiency_bkg;
      if (prune_efficiency_at) t.prune_efficiency_at = *prune_efficiency_at;
      else if (prune_efficiency_from) t.prune_efficiency_at = 0;
      else if (t.prune_efficiency_at <= 0) t.prune_efficiency_at = t.default_prune_efficiency_at();
    } else {
      t.prune_efficiency_at = t.prune_efficiency_from = 0, t.prune_efficiency_bkg = 0;  // off: nothing of it is kept
    }
    // Likewise before the scaling.
    if (anneal_lr) t.lr_anneal_factor = *anneal_lr;
    if (anneal_from) t.lr_anneal_from = *anneal_from;
    if (t.lr_anneal_factor == 1) {
      if (anneal_from) throw option_error("option.train", "anneal_from", "needs an anneal: --anneal-lr below 1, or a preset with one");
      t.lr_anneal_from = 0;  // off: nothing of it is kept
    } else if (t.lr_anneal_from <= 0) {
      t.lr_anneal_from = t.default_lr_anneal_from();
    }
    if (iterations > 0) t = t.with_iterations(iterations);  // the preset's proportions
    t.seed = seed;
    t.sparse_adam = sparse_adam;
    t.gaussians_per_pixel = gaussians_per_pixel;
    if (prune_weight) t.prune_weight = *prune_weight;
    if (crop) t.crop = *crop;
    if (camera_lr) t.lr_camera_rotation = (*camera_lr)[0], t.lr_camera_translation = (*camera_lr)[1];
    if (foreground_share) t.foreground_share = *foreground_share;
    if (deformation_lr) t.lr_deformation_init = *deformation_lr;
    if (sh_lr) t.lr_sh_dc = *sh_lr, t.lr_sh_rest = *sh_lr / 20;
    if (fine_position_lr) t.lr_position_fine = *fine_position_lr;
    if (fine_alpha_lr) t.lr_alpha_fine = *fine_alpha_lr;
    if (fine_sh_lr) t.lr_sh_fine = *fine_sh_lr;
    if (fine_dssim) t.lambda_dssim_fine = *fine_dssim;
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
    if (max_clip_frames != 0 && max_clip_frames < k) throw option_error("option.range", "--max-clip-frames", "must be 0 (no limit) or >= k (-k) = " + std::to_string(k));
    if (join_tail < 0 || (join_tail > 0 && join_tail > k - overlap - 1))
      throw option_error("option.range", "--join-tail", "must be in 0..k - 2 = " + std::to_string(k - overlap - 1) + " (0 = off)");
    if (checkpoint_every < 0) throw option_error("option.range", "checkpoint_every", "must be >= 0");
    if (train_clips && (train_clips->first < 0 || (train_clips->second >= 0 && train_clips->second < train_clips->first)))
      throw option_error("option.range", "--clips", "must be A:B with 0 <= A <= B (B = -1 or empty: to the last clip)");
    if (train_clips && sfm_only) throw option_error("option.range", "--clips", "cannot be combined with --sfm-only");
    if (capacity) capacity->validate();
    extend.validate();
    (void)train_options();
  }
};

/// The validated input. Frames and masks are not held: each clip decodes its own (`frames`, `masks`),
/// so memory follows the clip's length and the frame size, not the video's length.
struct PreparedInput {
  io::FrameList list;
  int source_width = 0, source_height = 0;
  int width = 0, height = 0;            ///< training / render size
  [[nodiscard]] int frame_count() const noexcept { return static_cast<int>(list.frames.size()); }
  [[nodiscard]] bool has_masks() const noexcept { return list.has_masks(); }

  /// Frames r.first..r.last at the training size (area-weighted resize from the source size).
  /// @throws option_error `option.range`; the errors of `io::read_image`.
  [[nodiscard]] std::vector<Image<float, 3>> frames(FrameRange r, ThreadPool* pool = nullptr) const {
    auto f = io::read_frames(list, r.first, r.last, pool);
    if (width != source_width || height != source_height)
      parallel_for(pool, f.size(), [&](std::size_t i) { f[i] = resize_area(f[i], width, height); }, 1);
    return f;
  }
  /// Frame f at the training size.
  [[nodiscard]] Image<float, 3> frame(int f) const { return std::move(frames({f, f}).front()); }
  /// Masks r.first..r.last at the source size (empty without masks). @throws as `frames`.
  [[nodiscard]] std::vector<Image<float, 1>> masks(FrameRange r, ThreadPool* pool = nullptr) const {
    return io::read_masks(list, r.first, r.last, pool);
  }
};

/// A progress report of the job.
struct ProgressEvent {
  enum class Stage { sfm, train, render } stage = Stage::sfm;
  int clip = 0, clips = 0;            ///< clip being worked on (sfm: clips so far)
  /// train: iterations done of this clip / its run's length (the preset's, lengthened when a quality
  /// floor extends the clip, ReconstructOptions::extend)
  int iteration = 0, iterations = 0;
  int frame = 0, frames = 0;          ///< render: frames done; sfm: frames covered
  double psnr = 0;                    ///< train: last iteration's PSNR; render: this frame's
  bool reused = false;                ///< train: the clip was loaded from an earlier run
  /// train: false while MC-COLMAP may still add clips (`train_during_sfm`); `clips` is then the
  /// number made final so far.
  bool clips_final = true;
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
  /// Each set's deformation hash grid as trained: entries per hashed level (log2) and levels in use
  /// (model.frg_grid / bkg_grid; a static background's field is the unused 2^2 x 1).
  int log2_table_frg = 0, log2_table_bkg = 0, grid_levels_frg = 0, grid_levels_bkg = 0;
  /// Each set's cap on cells along time (HashGridOptions::max_cells of t; 0: none).
  int time_cells_frg = 0, time_cells_bkg = 0;
  /// Bytes per part of the clip's compact file (ReconstructOptions::compact; null in JSON without it).
  std::optional<CompactSizes> compact_bytes;
  /// The clip's capacity plan and the view spread it read (ReconstructOptions::capacity; null in JSON
  /// without it).
  struct Capacity {
    CapacityPlan plan;
    double view_spread = 0;  ///< radians
  };
  std::optional<Capacity> capacity;
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
  /// Mean over the clip's SfM points of their mean reprojection error, pixels (null without points).
  std::optional<double> sfm_reprojection_error;
  /// PSNR over the clip's frames of each set rendered alone (the trainer's evaluation; null for a clip
  /// without foreground, and for a clip reused from a .done file written before these were recorded).
  std::optional<double> psnr_frg, psnr_bkg;
  /// Mean merge weight A = sigmoid(alpha logit) over the clip's pixels inside (mask >= 1/2) and outside
  /// the masks at the training size: where the alpha map gives the foreground set the pixel (null
  /// without masks, without foreground, or with no pixel on that side).
  std::optional<double> alpha_inside, alpha_outside;
};

struct ReconstructReport {
  int frames = 0, width = 0, height = 0;
  std::string preset;     ///< ReconstructOptions::preset
  TrainOptions training;  ///< what each clip was trained with (ReconstructOptions::train_options())
  ExtendOptions extend;   ///< the quality floor (ReconstructOptions::extend); a clip's `iterations` says what it took
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

  /// The report.json text (one object; see `to_json` below).
  [[nodiscard]] std::string json() const;
};

/// The settings key of a clip's state files: what a trained clip depends on, as canonical text
/// hashed by `stable_key` (core/hash.hpp).
struct ClipKey {
  std::string text;  ///< the canonical text
  std::string key;   ///< stable_key(text), written to the state files
  /// What versions up to 0.1 wrote (`std::hash` of the same text, decimal): recognised when reading,
  /// so their finished clips and checkpoints still resume on the machine that wrote them; never written.
  std::string legacy_key;
};

/// Stage 1's product for one clip: its frames, its SfM result and what SfM cost.
struct SfmClip {
  FrameRange range;
  SfmResult<double> result;
  int attempts = 0;
  double seconds = 0;           ///< this run's SfM wall time for the clip
  double seconds_recorded = 0;  ///< as recorded by the attempts that made it (see ClipReport)
  std::optional<bool> masked;   ///< see ClipReport::sfm_masked
};

struct SfmStage {
  std::vector<SfmClip> clips;
  double seconds = 0;
};

/// Stage 2's result. The clips' models are not held: each is in OUT/model/clip_NNN.model once trained
/// (`VideoModelFolderF(o.out / "model")` reads them one clip at a time, `load_video_model` all).
struct TrainStage {
  int frame_count = 0, width = 0, height = 0;
  std::vector<FrameRange> ranges;  ///< each trained or loaded clip's frames, in clip order
  std::vector<ClipReport> clips;
  int trained_clips = 0;
  double seconds = 0;
};

struct RenderStage {
  std::vector<double> psnr_per_frame, ssim_per_frame;
  double psnr = 0, ssim = 0, psnr_mean_colour = 0;  ///< means (non-finite PSNR counted as 100 dB)
  double seconds = 0;
};

namespace detail {

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

/// A state file (clip_NNN.done, clip_NNN.ckpt.key) as a JSON object; an empty object if it is missing
/// or unreadable (the clip is then redone). Files of versions up to 0.1 held key=value lines: they
/// are read as an object of strings with "legacy": true.
inline nlohmann::json read_state(const std::filesystem::path& p) {
  std::ifstream in(p);
  if (!in) return nlohmann::json::object();
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (auto j = nlohmann::json::parse(text, nullptr, false); !j.is_discarded() && j.is_object()) return j;
  nlohmann::json kv = nlohmann::json::object();
  std::istringstream lines(text);
  std::string line;
  while (std::getline(lines, line))
    if (const auto eq = line.find('='); eq != std::string::npos) kv[line.substr(0, eq)] = line.substr(eq + 1);
  if (!kv.empty()) kv["legacy"] = true;
  return kv;
}

/// A number of a state file, whether written as a JSON number or as legacy text; `where` names the file.
/// @throws io_error `io.format` naming the field when it is missing or not a finite number.
inline double state_number(const nlohmann::json& s, const char* field, const std::string& where) {
  double v = std::numeric_limits<double>::quiet_NaN();
  if (const auto it = s.find(field); it != s.end()) {
    if (it->is_number()) {
      v = it->get<double>();
    } else if (it->is_string()) {
      const std::string& text = it->get_ref<const std::string&>();
      const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
      if (ec != std::errc{} || end != text.data() + text.size()) v = std::numeric_limits<double>::quiet_NaN();
    }
  }
  if (!std::isfinite(v)) throw io_error("io.format", where, std::string("field '") + field + "' is missing or not a finite number");
  return v;
}

/// The figures a clip_NNN.done state records (iterations, PSNR, SSIM, training seconds), as the report
/// of a reused clip; `where` names the file. @throws io_error `io.format` naming the field at fault.
inline ClipReport finished_clip_report(const nlohmann::json& done, const std::string& where) {
  ClipReport cr;
  cr.reused = true;
  const double iterations = state_number(done, "iterations", where);
  if (!(iterations >= 0 && iterations <= std::numeric_limits<int>::max() && iterations == std::floor(iterations)))
    throw io_error("io.format", where, "field 'iterations' must be a count");
  cr.iterations = static_cast<int>(iterations);
  cr.psnr = state_number(done, "psnr", where);
  cr.ssim = state_number(done, "ssim", where);
  cr.train_seconds = state_number(done, "train_seconds", where);
  for (auto [field, value] : {std::pair{"psnr_frg", &cr.psnr_frg}, std::pair{"psnr_bkg", &cr.psnr_bkg}})
    if (done.contains(field) && !done[field].is_null()) *value = state_number(done, field, where);  // absent in older files
  return cr;
}

/// Whether state `s` was written under `key` (legacy files: under its legacy spelling).
inline bool state_matches(const nlohmann::json& s, const ClipKey& key) {
  if (!s.contains("key") || !s["key"].is_string()) return false;
  const bool legacy = s.contains("legacy") && s["legacy"].is_boolean() && s["legacy"].get<bool>();
  return s["key"].get<std::string>() == (legacy ? key.legacy_key : key.key);
}

inline void write_json_atomic(const std::filesystem::path& p, const nlohmann::ordered_json& j) { io::write_file_atomic(p, j.dump(1) + "\n"); }

inline void check_stop(const ReconstructHooks& h, const std::string& where) {
  if (h.stop && h.stop->load())
    throw error("run.interrupted", where,
                "stopped on request; finished clips and the running clip's checkpoint are kept, rerun with --resume to continue");
}

/// Mean PSNR floor of a frame: each pixel replaced by the frame's mean colour.
inline double mean_colour_psnr(const Image<float, 3>& src, ThreadPool* pool) {
  double mean[3] = {0, 0, 0};
  for (std::size_t i = 0; i < src.pixel_count(); ++i)
    for (int ch = 0; ch < 3; ++ch) mean[ch] += src.data()[3 * i + std::size_t(ch)];
  Image<float, 3> flat(src.width(), src.height());
  for (std::size_t i = 0; i < flat.pixel_count(); ++i)
    for (int ch = 0; ch < 3; ++ch) flat.data()[3 * i + std::size_t(ch)] = float(mean[ch] / double(src.pixel_count()));
  return metrics::psnr<float, 3>(flat, src, pool);
}

/// A final clip's SfM seconds as its attempts recorded them, and whether the attempt that made it ran
/// on masked frames: the back end's attempts from index `from` on (those since the previous clip was
/// final; the scheduler is sequential) whose frames lie in the clip (growth attempts are subsets of
/// its final range). Back ends without `attempts()`: this run's seconds.
template <class Sfm>
void attribute_attempts(Sfm& sfm, std::size_t from, SfmClip& clip) {
  if constexpr (requires { sfm.attempts(); }) {
    const auto& attempts = sfm.attempts();
    const FrameRange r = clip.range;
    for (std::size_t a = from; a < attempts.size(); ++a) {
      if (attempts[a].range.first < r.first || attempts[a].range.last > r.last) continue;
      clip.seconds_recorded += attempts[a].seconds();
      if constexpr (requires { bool(attempts[a].masked); bool(attempts[a].status == SfmStatus::success); })
        if (attempts[a].range.first == r.first && attempts[a].range.last == r.last && attempts[a].status == SfmStatus::success)
          clip.masked = bool(attempts[a].masked);
    }
  } else {
    clip.seconds_recorded = clip.seconds;
  }
}

/// The figures of stage 1 in a clip's report.
inline void add_sfm_figures(ClipReport& cr, const SfmClip& clip) {
  cr.first = clip.range.first;
  cr.last = clip.range.last;
  cr.sfm_attempts = clip.attempts;
  cr.sfm_points = clip.result.points.size();
  cr.sfm_registered = clip.result.frames.size();
  cr.sfm_seconds = clip.seconds;
  cr.sfm_seconds_recorded = clip.seconds_recorded;
  cr.sfm_masked = clip.masked;
  cr.sfm_reprojection_error.reset();
  if (!clip.result.points.empty()) cr.sfm_reprojection_error = mean_reprojection_error(clip.result.points);
}

/// Gaussians per set and each set's hash-grid size of model `m` into `cr`.
template <class Model>
void add_model_figures(ClipReport& cr, const Model& m) {
  cr.gaussians_frg = m.frg.size();
  cr.gaussians_bkg = m.bkg.size();
  auto log2 = [](std::size_t n) { return static_cast<int>(std::bit_width(n)) - 1; };  // table sizes are powers of two
  cr.log2_table_frg = log2(m.field(GaussianSet::foreground).grid().table_size());
  cr.log2_table_bkg = log2(m.field(GaussianSet::background).grid().table_size());
  cr.grid_levels_frg = m.field(GaussianSet::foreground).grid().active_levels();
  cr.grid_levels_bkg = m.field(GaussianSet::background).grid().active_levels();
  cr.time_cells_frg = int(m.field(GaussianSet::foreground).grid().options().max_cells[3]);
  cr.time_cells_bkg = int(m.field(GaussianSet::background).grid().options().max_cells[3]);
}

/// Mean merge weight of model `m` inside and outside its masks into `cr` (`alpha_inside_outside`; see ClipReport).
template <class Model>
void add_alpha_figures(ClipReport& cr, const Model& m, const std::vector<Image<float, 1>>& masks) {
  const auto a = alpha_inside_outside(m, std::span<const Image<float, 1>>(masks));
  cr.alpha_inside = a[0], cr.alpha_outside = a[1];
}

/// The clip's cameras at the training size. @throws error `sfm.incomplete`, `sfm.camera_size`
inline std::vector<Camera<float>> clip_cameras(const PreparedInput& in, const SfmClip& clip) {
  std::vector<Camera<float>> cams;
  for (int f = clip.range.first; f <= clip.range.last; ++f) {
    const int i = clip.result.index_of(f);
    if (i < 0) throw error("sfm.incomplete", "frame " + std::to_string(f), "the SfM result of its clip does not register it");
    Camera<float> cam = clip.result.cameras[std::size_t(i)].template cast<float>();
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
  return cams;
}

}  // namespace detail

/// An optional figure as JSON: null when absent (or not finite).
inline nlohmann::ordered_json optional_number(const std::optional<double>& v) {
  return v && std::isfinite(*v) ? nlohmann::ordered_json(*v) : nlohmann::ordered_json(nullptr);
}

/// One serialiser per report type (nlohmann/json; numbers that are not finite are written as null).
inline void to_json(nlohmann::ordered_json& j, const ClipReport& r) {
  j = {{"first", r.first}, {"last", r.last}, {"iterations", r.iterations}, {"psnr", r.psnr}, {"ssim", r.ssim},
       {"gaussians_frg", r.gaussians_frg}, {"gaussians_bkg", r.gaussians_bkg}, {"model_bytes", r.model_bytes},
       {"log2_table_frg", r.log2_table_frg}, {"log2_table_bkg", r.log2_table_bkg}, {"grid_levels_frg", r.grid_levels_frg},
       {"grid_levels_bkg", r.grid_levels_bkg}, {"time_cells_frg", r.time_cells_frg}, {"time_cells_bkg", r.time_cells_bkg},
       {"compact_bytes", r.compact_bytes ? nlohmann::ordered_json{{"gaussians", r.compact_bytes->gaussians}, {"fields", r.compact_bytes->fields},
                                                                  {"alpha", r.compact_bytes->alpha}, {"other", r.compact_bytes->other},
                                                                  {"total", r.compact_bytes->total}}
                                         : nlohmann::ordered_json(nullptr)},
       {"capacity", r.capacity ? nlohmann::ordered_json{{"log2_table", r.capacity->plan.log2_table},
                                                        {"gaussians_per_pixel", r.capacity->plan.gaussians_per_pixel},
                                                        {"max_sh_degree", r.capacity->plan.max_sh_degree},
                                                        {"view_spread_degrees", r.capacity->view_spread * 180 / 3.14159265358979323846}}
                               : nlohmann::ordered_json(nullptr)},
       {"train_seconds", r.train_seconds}, {"reused", r.reused}, {"sfm_attempts", r.sfm_attempts}, {"sfm_points", r.sfm_points},
       {"sfm_registered", r.sfm_registered}, {"sfm_seconds", r.sfm_seconds}, {"sfm_seconds_recorded", r.sfm_seconds_recorded},
       {"sfm_masked", r.sfm_masked ? nlohmann::ordered_json(*r.sfm_masked) : nlohmann::ordered_json(nullptr)},
       {"sfm_reprojection_error", optional_number(r.sfm_reprojection_error)}, {"psnr_frg", optional_number(r.psnr_frg)},
       {"psnr_bkg", optional_number(r.psnr_bkg)}, {"alpha_inside", optional_number(r.alpha_inside)},
       {"alpha_outside", optional_number(r.alpha_outside)}};
}

inline void to_json(nlohmann::ordered_json& j, const ReconstructReport& r) {
  nlohmann::ordered_json schedule = nlohmann::ordered_json::array();
  for (const auto& s : r.training.resolution_schedule) schedule.push_back({{"from_iteration", s.from_iteration}, {"scale", s.scale}});
  j = {{"frames", r.frames}, {"width", r.width}, {"height", r.height}, {"psnr", r.psnr}, {"ssim", r.ssim},
       {"psnr_mean_colour", r.psnr_mean_colour},
       {"training", {{"preset", r.preset}, {"iterations", r.training.iterations}, {"resolution_schedule", schedule},
                     {"resolution_min_size", r.training.resolution_min_size}, {"prune_weight", r.training.prune_weight}, {"prune_weight_from", r.training.prune_weight_from}, {"prune_efficiency", r.training.prune_efficiency}, {"prune_efficiency_at", r.training.prune_efficiency_at}, {"prune_efficiency_from", r.training.prune_efficiency_from}, {"prune_efficiency_bkg", r.training.prune_efficiency_bkg}, {"crop", r.training.crop}, {"budget", r.training.gaussians_per_pixel},
                     {"sparse_adam", r.training.sparse_adam},
                     {"camera_lr", {r.training.lr_camera_rotation, r.training.lr_camera_translation}},
                     {"lr_deformation", r.training.lr_deformation_init},
                     {"lr_sh", {{"dc", r.training.lr_sh_dc}, {"rest", r.training.lr_sh_rest}}},
                     {"lr_position_fine", {{"factor", r.training.lr_position_fine}, {"from", r.training.lr_fine_from}}},
                     {"lr_alpha_fine", {{"factor", r.training.lr_alpha_fine}, {"from", r.training.lr_fine_from}}},
                     {"lr_sh_fine", {{"factor", r.training.lr_sh_fine}, {"from", r.training.lr_fine_from}}},
                     {"lr_anneal", r.training.lr_anneal_from > 0 ? nlohmann::json{{"factor", r.training.lr_anneal_factor}, {"from", r.training.lr_anneal_from}} : nlohmann::json()},
                     {"lambda_dssim", r.training.lambda_dssim},
                     {"lambda_dssim_fine", r.training.lambda_dssim_fine ? nlohmann::json{{"value", *r.training.lambda_dssim_fine}, {"from", r.training.lr_fine_from}} : nlohmann::json()},
                     {"extend", {{"below_psnr", r.extend.below_psnr}, {"max_iterations", r.extend.max_iterations}, {"step", r.extend.step}}}}},
       {"seconds", {{"sfm", r.seconds_sfm}, {"train", r.seconds_train}, {"render", r.seconds_render}, {"total", r.seconds_total},
                    {"sfm_recorded", r.seconds_sfm_recorded}, {"train_recorded", r.seconds_train_recorded}}},
       {"trained_clips", r.trained_clips}, {"clips", r.clips}};
}

inline std::string ReconstructReport::json() const { return nlohmann::ordered_json(*this).dump(); }

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
  const io::ImageInfo first = io::check_frames(in.list, pool);  // decodes every frame and mask: corrupt files fail here
  in.source_width = first.width;
  in.source_height = first.height;
  in.width = std::max(1, static_cast<int>(std::lround(in.source_width * o.scale)));
  in.height = std::max(1, static_cast<int>(std::lround(in.source_height * o.scale)));
  if (in.width < 8 || in.height < 8)
    throw option_error("option.range", "--scale", "frames of " + std::to_string(in.width) + "x" + std::to_string(in.height) + " are too small to train on");
  return in;
}

namespace detail {
/// `topt` with the foreground share of a clip whose masks are `masks` (none: 1), floored at 1e-3;
/// `fixed`: topt's share as it is (ReconstructOptions::foreground_share).
[[nodiscard]] inline TrainOptions with_clip_share(TrainOptions topt, const std::vector<Image<float, 1>>& masks, bool fixed = false) {
  if (!masks.empty() && !fixed) topt.foreground_share = std::max(1e-3, mask_coverage<float>(std::span<const Image<float, 1>>(masks)));
  return topt;
}

/// The options clip `clip` trains with: `o` and `topt` with its capacity plan applied
/// (ReconstructOptions::capacity; unchanged without it), and the plan.
struct ClipSettings {
  ReconstructOptions o;
  TrainOptions topt;
  std::optional<ClipReport::Capacity> capacity;
};
[[nodiscard]] inline ClipSettings clip_settings(const ReconstructOptions& o, const PreparedInput& in, const TrainOptions& topt, const SfmClip& clip) {
  ClipSettings cs{o, topt, std::nullopt};
  if (!o.capacity) return cs;
  const std::vector<Camera<float>> cams = clip_cameras(in, clip);
  const ClipShape shape = clip_shape(in.width, in.height, std::span<const Camera<float>>(cams), std::span<const SfmPoint<double>>(clip.result.points));
  const CapacityPlan plan = plan_capacity(shape, *o.capacity);
  for (auto [grid, planned] : {std::pair{&cs.o.model.frg_grid, plan.frg_grid}, std::pair{&cs.o.model.bkg_grid, plan.bkg_grid}})
    if (!grid->resized()) grid->log2_table_size = planned.log2_table_size, grid->levels = planned.levels, grid->finest = planned.finest;
  if (!(o.gaussians_per_pixel > 0) && plan.gaussians_per_pixel > 0) {
    cs.topt.gaussians_per_pixel = plan.gaussians_per_pixel;
    if (!o.foreground_share) cs.o.foreground_share = cs.topt.foreground_share = 1.0;
  }
  cs.topt.max_sh_degree = std::min(cs.topt.max_sh_degree, plan.max_sh_degree);
  cs.capacity = ClipReport::Capacity{plan, shape.view_spread};
  return cs;
}
}  // namespace detail

/// The settings key of clip `clip` trained with `topt` (see ClipKey).
[[nodiscard]] inline ClipKey clip_key(const ReconstructOptions& o, const PreparedInput& in, const TrainOptions& topt, const SfmClip& clip) {
  std::ostringstream t;
  t << "v1|" << clip.range.first << "-" << clip.range.last << "|" << in.width << "x" << in.height << "|it=" << topt.iterations << "|preset=" << o.preset
    << "|seed=" << o.seed << "|pts=" << clip.result.points.size() << "|shell=" << o.model.background.points_per_shell;
  // Options added later enter the text only when set, so earlier runs' keys stay valid.
  if (topt.sparse_adam) t << "|sparse_adam";
  auto exact = [](double v) {  // round-trips the double
    char num[32];
    std::snprintf(num, sizeof(num), "%.17g", v);
    return std::string(num);
  };
  if (topt.gaussians_per_pixel > 0) t << "|budget=" << exact(topt.gaussians_per_pixel);
  t << o.model.departures_key();
  if (topt.prune_weight > 0) t << "|prune=" << exact(topt.prune_weight);
  if (topt.prune_efficiency > 0) t << "|prune_eff=" << exact(topt.prune_efficiency) << "@" << topt.prune_efficiency_at;
  if (topt.prune_efficiency > 0 && topt.prune_efficiency_from > 0) t << "|prune_eff_from=" << topt.prune_efficiency_from;
  if (topt.prune_efficiency > 0 && topt.prune_efficiency_bkg > 0) t << "|prune_eff_bkg=" << exact(topt.prune_efficiency_bkg);
  if (topt.refines_cameras()) t << "|cameras=" << exact(topt.lr_camera_rotation) << "," << exact(topt.lr_camera_translation);
  if (o.foreground_share && topt.gaussians_per_pixel > 0) t << "|frg_share=" << exact(*o.foreground_share);  // only a budget reads it
  const TrainOptions preset = TrainOptions::preset(o.preset);
  if (topt.lr_deformation_init != preset.lr_deformation_init) t << "|lr_def=" << exact(topt.lr_deformation_init);
  if (topt.lr_sh_dc != preset.lr_sh_dc || topt.lr_sh_rest != preset.lr_sh_rest)
    t << "|lr_sh=" << exact(topt.lr_sh_dc) << "," << exact(topt.lr_sh_rest);
  // Whenever the rate steps (not only where it departs from the preset), so that a run of a version
  // whose presets did not step it is not taken for this one.
  if (topt.lr_position_fine != 1) t << "|lr_pos_fine=" << exact(topt.lr_position_fine) << "@" << topt.lr_fine_from;
  if (topt.lr_alpha_fine != 1) t << "|lr_alpha_fine=" << exact(topt.lr_alpha_fine) << "@" << topt.lr_fine_from;
  if (topt.lr_sh_fine != 1) t << "|lr_sh_fine=" << exact(topt.lr_sh_fine) << "@" << topt.lr_fine_from;
  if (topt.lambda_dssim_fine) t << "|dssim_fine=" << exact(*topt.lambda_dssim_fine) << "@" << topt.lr_fine_from;
  if (topt.lr_anneal_from > 0) t << "|anneal=" << exact(topt.lr_anneal_factor) << "@" << topt.lr_anneal_from;
  if (!topt.resolution_schedule.empty()) {
    t << "|res=";
    for (const auto& r : topt.resolution_schedule) t << r.from_iteration << ":" << r.scale << ";";
  }
  if (!topt.resolution_schedule.empty() && topt.resolution_min_size > 0) t << "|res_min=" << topt.resolution_min_size;
  if (topt.crop > 0 && topt.crop < 1) t << "|crop=" << exact(topt.crop);
  if (topt.max_sh_degree < 3) t << "|sh_max=" << topt.max_sh_degree;
  if (o.extend.active()) t << "|extend=" << exact(o.extend.below_psnr) << ":" << o.extend.max_iterations << ":" << o.extend.step;
  // Every training setting, hashed (the items above name the ones a reader looks for): a clip trained
  // before a preset changed any of its values is retrained, not reused. (Keys of earlier versions lack
  // it: their clips are retrained once.)
  t << "|train=" << stable_key(topt.settings_text());
  for (const auto& [name, g] : {std::pair{"frg_grid", o.model.frg_grid}, std::pair{"bkg_grid", o.model.bkg_grid}}) {
    if (g.resized()) t << "|" << name << "=" << g.log2_table_size << ":" << g.levels << ":" << exact(g.finest);
    // Grids without a time cap (the only kind before it existed) keep their earlier keys.
    if (g.time_cells != 0) t << "|" << name << "_time=" << g.time_cells_text();
  }
  for (int f = clip.range.first; f <= clip.range.last; ++f) {
    const int i = clip.result.index_of(f);
    if (i < 0) throw error("sfm.incomplete", "frame " + std::to_string(f), "the SfM result of its clip does not register it");
    const auto& cam = clip.result.cameras[std::size_t(i)];
    char num[64];
    std::snprintf(num, sizeof(num), "%.6g,%.6g", cam.fx, cam.t.x());
    t << "|" << std::filesystem::absolute(in.list.frames[std::size_t(f)]).string() << ":" << num;
  }
  // The masks split the points between the sets and set the foreground share (and, when asked, the
  // alpha maps' start and the background colours), so a clip trained with other masks, or none, is
  // not reused. (Keys of masked runs written before the masks entered the text no longer match:
  // such a clip is retrained, never reused wrongly.)
  if (in.has_masks()) {
    t << "|masks";
    for (int f = clip.range.first; f <= clip.range.last; ++f) t << "|" << std::filesystem::absolute(in.list.masks[std::size_t(f)]).string();
  }
  ClipKey k;
  k.text = t.str();
  k.key = stable_key(k.text);
  k.legacy_key = std::to_string(std::hash<std::string>{}(k.text));
  return k;
}

/// Stage 1, MC-COLMAP: `schedule_clips` over the back end (see the file comment of reconstruct_video).
/// `on_clip`, if given, receives each clip as soon as it is final (on the calling thread, before the
/// next SfM attempt), so stage 2 may start on it (see `sfm_and_train_stage`).
template <class Sfm>
[[nodiscard]] SfmStage sfm_stage(const ReconstructOptions& o, const PreparedInput& in, Sfm& sfm, const ReconstructHooks& hooks = {},
                                 const std::function<void(const SfmClip&)>& on_clip = {}) {
  static_assert(SfmBackend<Sfm&> && std::derived_from<sfm_result_t<Sfm&>, SfmResult<double>>,
                "video3dgs::pipeline: the SfM back end must be callable as sfm(FrameRange) and return a "
                "type derived from video3dgs::SfmResult<double> (e.g. colmap::ColmapSfm)");
  SfmStage st;
  ScopedTimer timer(st.seconds);
  ScheduleOptions so;
  so.initial_frames = o.k;
  so.overlap = ReconstructOptions::overlap;
  so.max_clip_frames = o.max_clip_frames;
  so.join_tail = o.join_tail;
  so.progress = [&](const ScheduleProgress& p) {
    if (!hooks.progress) return;
    ProgressEvent e;
    e.stage = ProgressEvent::Stage::sfm;
    e.clip = p.clip;
    e.frame = p.frames_done;
    e.frames = p.frame_count;
    e.message = "clip " + std::to_string(p.clip) + " frames " + std::to_string(p.range.first) + "-" + std::to_string(p.range.last) +
                " attempt " + std::to_string(p.attempt) + ": " + to_string(p.status) + (p.message.empty() ? "" : " (" + p.message + ")");
    hooks.progress(e);
  };
  SfmResult<double> last;  // the back end's last result: a clip's result once on_clip says it is final
  auto guarded = [&](FrameRange r) {
    detail::check_stop(hooks, "sfm");
    auto result = sfm(r);
    last = static_cast<const SfmResult<double>&>(result);
    return result;
  };
  std::size_t attempts_from = 0;  // the back end's attempts (if it lists them) since the last final clip
  if constexpr (requires { sfm.attempts(); }) attempts_from = sfm.attempts().size();
  so.on_clip = [&](const ScheduledClipInfo& info) {
    SfmClip c;
    c.range = info.range;
    c.result = last;
    c.attempts = info.attempts;
    c.seconds = info.seconds;
    detail::attribute_attempts(sfm, attempts_from, c);
    if constexpr (requires { sfm.attempts(); }) attempts_from = sfm.attempts().size();
    st.clips.push_back(std::move(c));
    if (on_clip) on_clip(st.clips.back());
  };
  const auto schedule = schedule_clips(in.frame_count(), guarded, so);
  if (schedule.clips.size() != st.clips.size()) throw error("internal.schedule", "sfm_stage", "the scheduler reported a different clip count");
  detail::check_stop(hooks, "sfm");
  return st;
}

/// A clip finished by an earlier run under the same key (OUT/train/clip_NNN.done and its model
/// file), with its report as recorded then; nothing if there is none.
[[nodiscard]] inline std::optional<std::pair<ClipModel<float>, ClipReport>> load_finished_clip(const ReconstructOptions& o, std::size_t c,
                                                                                               const ClipKey& key) {
  namespace fs = std::filesystem;
  const fs::path done_file = o.out / "train" / (detail::clip_stem(c) + ".done"), model_file = o.out / "model" / video_model_clip_file(c);
  std::error_code ec;
  const nlohmann::json done = detail::read_state(done_file);
  if (!detail::state_matches(done, key) || !fs::is_regular_file(model_file, ec)) return std::nullopt;
  auto m = load_clip_model<float>(model_file);
  ClipReport cr = detail::finished_clip_report(done, done_file.string());
  detail::add_model_figures(cr, m);
  cr.model_bytes = static_cast<std::size_t>(fs::file_size(model_file, ec));
  return std::pair{std::move(m), cr};
}

/// Trains clip `c` of stage 1 (or continues its checkpoint with `resume`), then writes its model and
/// OUT/train/clip_NNN.done. @throws `[run.interrupted]` after saving the checkpoint when stopped.
[[nodiscard]] inline std::pair<ClipModel<float>, ClipReport> train_clip(const ReconstructOptions& o, const PreparedInput& in, const TrainOptions& topt,
                                                                        std::size_t c, std::size_t clips, const SfmClip& clip, const ClipKey& key,
                                                                        const ReconstructHooks& hooks = {}, ThreadPool* pool = nullptr) {
  namespace fs = std::filesystem;
  const std::string stem = detail::clip_stem(c);
  const fs::path ckpt = o.out / "train" / (stem + ".ckpt"), ckpt_key = o.out / "train" / (stem + ".ckpt.key");
  const auto t0 = std::chrono::steady_clock::now();
  auto seconds = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  std::vector<Image<float, 3>> frames = in.frames(clip.range, pool);
  std::unique_ptr<ClipTrainer<ClipModel<float>>> trainer;
  double prior_seconds = 0;
  std::error_code ec;
  {  // The masks place the first Gaussians and set the foreground's share; training does not read them,
     // so they are dropped before it starts.
    const std::vector<Image<float, 1>> masks = in.masks(clip.range, pool);
    const TrainOptions clip_topt = detail::with_clip_share(topt, masks, o.foreground_share.has_value());
    if (const auto state = detail::read_state(ckpt_key); o.resume && fs::is_regular_file(ckpt, ec) && detail::state_matches(state, key)) {
      trainer = std::make_unique<ClipTrainer<ClipModel<float>>>(ckpt, std::move(frames), clip_topt, pool);
      if (state.contains("seconds")) prior_seconds = detail::state_number(state, "seconds", ckpt_key.string());
    } else {
      const std::vector<Camera<float>> cams = detail::clip_cameras(in, clip);
      ClipModelOptions mo = o.model;
      mo.seed = o.seed + c;
      auto model = make_clip_model<float>(clip.range, std::span<const Camera<float>>(cams), std::span<const SfmPoint<double>>(clip.result.points),
                                          mo, std::span<const Image<float, 1>>(masks), pool, std::span<const Image<float, 3>>(frames));
      trainer = std::make_unique<ClipTrainer<ClipModel<float>>>(std::move(model), std::move(frames), clip_topt, pool);
    }
  }
  auto save_ckpt = [&] {
    trainer->save_checkpoint(ckpt);
    detail::write_json_atomic(ckpt_key, {{"key", key.key}, {"seconds", prior_seconds + seconds()}});
  };
  ProgressEvent e;
  e.stage = ProgressEvent::Stage::train;
  e.clip = static_cast<int>(c);
  e.clips = static_cast<int>(clips);
  e.iterations = topt.iterations;
  bool stopped = false;
  // Periodic checkpoints stop short of the longest the run can be (the model file then follows at
  // once). With a floor that is not the preset's length: a checkpoint there may be one write too many
  // (the clip clears the floor), but without it an extension of 2,000 iterations would have none.
  const int longest = topt.iterations + (o.extend.active() ? o.extend.max_iterations : 0);
  const std::optional<ClipEvaluation> evaluated = train_with_extension(*trainer, o.extend, [&](const IterationInfo& it) {
    e.iteration = it.iteration + 1;
    e.iterations = trainer->options().iterations;
    e.psnr = it.psnr;
    if (hooks.progress) hooks.progress(e);
    if (hooks.stop && hooks.stop->load()) {
      stopped = true;
      return false;
    }
    if (o.checkpoint_every > 0 && e.iteration % o.checkpoint_every == 0 && e.iteration < longest) save_ckpt();
    return true;
  });
  if (stopped || !evaluated) {
    save_ckpt();
    detail::check_stop(hooks, "clip " + std::to_string(c) + " (" + ckpt.string() + ")");
    throw error("run.interrupted", stem, "training stopped early");
  }
  const ClipEvaluation& ev = *evaluated;
  const fs::path model_file = o.out / "model" / video_model_clip_file(c);
  save_clip_model(model_file, trainer->model());
  ClipReport cr;
  cr.iterations = trainer->stats().iterations;
  cr.psnr = ev.psnr;
  cr.ssim = ev.ssim;
  cr.psnr_bkg = ev.psnr_bkg;
  if (trainer->model().has_foreground) cr.psnr_frg = ev.psnr_frg;
  cr.train_seconds = prior_seconds + seconds();
  detail::add_model_figures(cr, trainer->model());
  cr.model_bytes = static_cast<std::size_t>(fs::file_size(model_file, ec));
  detail::write_json_atomic(o.out / "train" / (stem + ".done"), {{"key", key.key}, {"first", clip.range.first}, {"last", clip.range.last},
                                                                 {"iterations", cr.iterations}, {"psnr", cr.psnr}, {"ssim", cr.ssim},
                                                                 {"train_seconds", cr.train_seconds}, {"psnr_frg", optional_number(cr.psnr_frg)},
                                                                 {"psnr_bkg", optional_number(cr.psnr_bkg)}});
  fs::remove(ckpt, ec);
  fs::remove(ckpt_key, ec);
  return {std::move(trainer->model()), cr};
}

namespace detail {

/// Whether clip `c` is in a worker's share (`train_clips`; every clip without it).
inline bool in_share(const ReconstructOptions& o, std::size_t c) {
  return !o.train_clips || (int(c) >= o.train_clips->first && (o.train_clips->second < 0 || int(c) <= o.train_clips->second));
}

inline void begin_train_stage(const ReconstructOptions& o, const PreparedInput& in, TrainStage& st) {
  make_dir(o.out / "model");
  make_dir(o.out / "train");
  st.frame_count = in.frame_count();
  st.width = in.width;
  st.height = in.height;
}

/// Clip `c` of stage 2 (`clips`: clips known so far, for progress): loaded with `resume` when an
/// earlier run finished it under the same key, else trained; added to `st`.
inline void train_or_load(const ReconstructOptions& o, const PreparedInput& in, const TrainOptions& topt, std::size_t c, std::size_t clips,
                          const SfmClip& clip, TrainStage& st, const ReconstructHooks& hooks, ThreadPool* pool);

/// The manifest of the trained clips (not for a worker's share: the combining run writes it).
inline void finish_train_stage(const ReconstructOptions& o, TrainStage& st) {
  if (o.train_clips) return;
  validate_clip_ranges(st.ranges, st.frame_count, (o.out / "model").string());
  write_video_manifest(o.out / "model", st.frame_count, st.width, st.height, st.ranges);
}

}  // namespace detail

/// Stage 2: every clip of stage 1 trained (or, with `resume`, loaded) into OUT/model/, then the
/// manifest that makes OUT/model/ a video model folder.
[[nodiscard]] inline TrainStage train_stage(const ReconstructOptions& o, const PreparedInput& in, const SfmStage& sfm,
                                            const ReconstructHooks& hooks = {}, ThreadPool* pool = nullptr) {
  TrainStage st;
  ScopedTimer timer(st.seconds);
  const TrainOptions topt = o.train_options();
  detail::begin_train_stage(o, in, st);
  for (std::size_t c = 0; c < sfm.clips.size(); ++c)
    if (detail::in_share(o, c)) detail::train_or_load(o, in, topt, c, sfm.clips.size(), sfm.clips[c], st, hooks, pool);
  detail::finish_train_stage(o, st);
  return st;
}

inline void detail::train_or_load(const ReconstructOptions& o_video, const PreparedInput& in, const TrainOptions& topt_video, std::size_t c,
                                  std::size_t clips, const SfmClip& clip, TrainStage& st, const ReconstructHooks& hooks, ThreadPool* pool) {
  const ClipSettings cs = clip_settings(o_video, in, topt_video, clip);
  const ReconstructOptions& o = cs.o;
  const TrainOptions& topt = cs.topt;
  const ClipKey key = clip_key(o, in, topt, clip);
  auto finished = o.resume ? load_finished_clip(o, c, key) : std::nullopt;
  if (finished && hooks.progress) {
    ProgressEvent e;
    e.stage = ProgressEvent::Stage::train;
    e.clip = static_cast<int>(c);
    e.clips = static_cast<int>(clips);
    e.iteration = e.iterations = finished->second.iterations;
    e.psnr = finished->second.psnr;
    e.reused = true;
    hooks.progress(e);
  }
  auto [model, cr] = finished ? std::move(*finished) : train_clip(o, in, topt, c, clips, clip, key, hooks, pool);
  cr.capacity = cs.capacity;
  add_sfm_figures(cr, clip);
  if (in.has_masks()) add_alpha_figures(cr, model, in.masks(clip.range, pool));
  st.trained_clips += cr.reused ? 0 : 1;
  // Rewritten for a reused clip too: the same model and options give the same bytes.
  if (o.compact) cr.compact_bytes = save_compact_clip_model(o.out / "model" / (detail::clip_stem(c) + ".compact"), model, *o.compact, pool);
  // The model is on disk: stage 3 reads it back one clip at a time.
  st.ranges.push_back(clip.range);
  st.clips.push_back(cr);
}

/// Stages 1 and 2 at once (`ReconstructOptions::train_during_sfm`): `sfm_stage` runs on a second
/// thread while this one trains each clip as soon as it is final, in order. The back end is only
/// called from that thread, `pool` only from this one; progress events of both are serialised.
/// Returns after both stages ended. A failure of either stops the other: after an SfM error the clips
/// already final are still trained (they are kept for `resume`), then the error is rethrown; after a
/// training error or a stop request the SfM attempt under way finishes, nothing more starts. SfM's
/// seconds are its thread's wall time, training's the sum of its clips' (waits excluded), so they
/// may add up to more than the total.
template <class Sfm>
[[nodiscard]] std::pair<SfmStage, TrainStage> sfm_and_train_stage(const ReconstructOptions& o, const PreparedInput& in, Sfm& sfm,
                                                                  const ReconstructHooks& hooks = {}, ThreadPool* pool = nullptr) {
  const TrainOptions topt = o.train_options();
  std::mutex m, progress_m;
  std::condition_variable ready_cv;
  std::deque<SfmClip> ready;
  std::size_t known = 0;  // clips made final so far
  bool sfm_done = false;
  std::exception_ptr sfm_error;
  std::atomic<bool> stop_sfm{false};
  ReconstructHooks serial = hooks;
  if (hooks.progress)
    serial.progress = [&](const ProgressEvent& ev) {
      ProgressEvent e = ev;
      if (e.stage == ProgressEvent::Stage::train) {
        const std::lock_guard lock(m);
        e.clips = static_cast<int>(known);
        e.clips_final = sfm_done;
      }
      const std::lock_guard lock(progress_m);
      hooks.progress(e);
    };
  // The SfM thread stops between attempts once this is set: by a failed or stopped training (the
  // training loop polls `hooks.stop` every iteration and while waiting for a clip).
  ReconstructHooks sfm_hooks = serial;
  sfm_hooks.stop = &stop_sfm;
  SfmStage sfm_out;
  TrainStage st;
  std::thread sfm_thread([&] {
    try {
      sfm_out = sfm_stage(o, in, sfm, sfm_hooks, [&](const SfmClip& c) {
        {
          const std::lock_guard lock(m);
          ready.push_back(c);
          ++known;
        }
        ready_cv.notify_one();
      });
    } catch (...) {
      const std::lock_guard lock(m);
      sfm_error = std::current_exception();
    }
    {
      const std::lock_guard lock(m);
      sfm_done = true;
    }
    ready_cv.notify_one();
  });
  try {
    detail::begin_train_stage(o, in, st);
    for (std::size_t c = 0;; ++c) {
      detail::check_stop(hooks, "train");
      SfmClip clip;
      std::size_t clips = 0;
      {
        std::unique_lock lock(m);
        while (ready.empty() && !sfm_done) {
          ready_cv.wait_for(lock, std::chrono::milliseconds(100));
          if (hooks.stop && hooks.stop->load()) stop_sfm = true;
        }
        if (ready.empty()) break;  // SfM ended (and every final clip was taken)
        clip = std::move(ready.front());
        ready.pop_front();
        clips = known;
      }
      if (!detail::in_share(o, c)) continue;
      ScopedTimer timer(st.seconds);  // adds this clip's seconds
      detail::train_or_load(o, in, topt, c, clips, clip, st, serial, pool);
    }
  } catch (...) {
    stop_sfm = true;
    sfm_thread.join();
    throw;
  }
  sfm_thread.join();
  if (sfm_error) std::rethrow_exception(sfm_error);
  detail::finish_train_stage(o, st);
  return {std::move(sfm_out), std::move(st)};
}

/// Stage 3: every frame rendered from `video` (a `VideoModelF`, or a `VideoModelFolderF` that holds only
/// the clips of the frame at hand) and compared with its source: OUT/renders/, OUT/compare/ (with
/// `write_compare`: source | render | error heat map, under compare_header's strip when gnuplot is
/// installed), OUT/metrics.csv and OUT/metrics.png.
template <class Video>
[[nodiscard]] RenderStage render_stage(const ReconstructOptions& o, const PreparedInput& in, Video&& video, const ReconstructHooks& hooks = {},
                                       ThreadPool* pool = nullptr) {
  RenderStage st;
  ScopedTimer timer(st.seconds);
  const int n = in.frame_count();
  detail::make_dir(o.out / "renders");
  if (o.write_compare) detail::make_dir(o.out / "compare");
  VideoRenderBuffers<float> buf;
  loss::SsimContext<double, 3> ssim_ctx;
  std::ostringstream csv;
  csv << "frame,psnr,ssim\n";
  // compare/ frames get a strip naming their panels, with the heat map's scale, when gnuplot is there.
  std::optional<Image<float, 3>> header;
  if (o.write_compare) header = compare_header(in.width, kSideBySideGap, kHeatMapMaxError, o.out / "compare_header.png", o.gnuplot);
  for (int f = 0; f < n; ++f) {
    detail::check_stop(hooks, "render");
    const Image<float, 3>& img = video.render_frame(f, buf, pool);
    const Image<float, 3> src = in.frame(f);
    const double p = metrics::psnr<float, 3>(img, src, pool);
    const Image<double, 3> a = img.template cast<double>(), b = src.template cast<double>();
    const double s = loss::ssim_value<double, 3>(a.view(), b.view(), ssim_ctx, pool);
    const double pb = detail::mean_colour_psnr(src, pool);
    st.psnr_per_frame.push_back(p);
    st.ssim_per_frame.push_back(s);
    st.psnr += (std::isfinite(p) ? p : 100.0) / n;
    st.ssim += s / n;
    st.psnr_mean_colour += (std::isfinite(pb) ? pb : 100.0) / n;
    csv << f << "," << nlohmann::json(p).dump() << "," << nlohmann::json(s).dump() << "\n";
    io::write_png(o.out / "renders" / detail::frame_png(f), img);
    if (o.write_compare) {
      const Image<float, 3> heat = error_heat_map(img, src);
      const Image<float, 3> panels = side_by_side({&src, &img, &heat});
      io::write_png(o.out / "compare" / detail::frame_png(f), header ? stack_vertical(*header, panels) : panels);
    }
    if (hooks.progress) {
      ProgressEvent e;
      e.stage = ProgressEvent::Stage::render;
      e.frame = f + 1;
      e.frames = n;
      e.psnr = p;
      hooks.progress(e);
    }
  }
  io::write_file_atomic(o.out / "metrics.csv", csv.str());
  // gnuplot when installed (axes, units, legend); else the plain plot, and the command-line tool says so.
  if (!plot_metrics_gnuplot(o.out / "metrics.csv", o.out / "metrics.png", std::span<const FrameRange>(video.ranges()), o.gnuplot))
    io::write_png(o.out / "metrics.png", plot_metrics(st.psnr_per_frame, st.ssim_per_frame).image);
  return st;
}

namespace detail {
template <class Clip>
void export_clip_ply(const ReconstructOptions& o, const Clip& m, std::size_t c, ThreadPool* pool) {
  for (GaussianSet s : {GaussianSet::foreground, GaussianSet::background})
    export_ply(m, s, 0, o.out / "ply" / (clip_stem(c) + "_" + to_string(s) + ".ply"), pool);
}
}  // namespace detail

/// OUT/ply/clip_NNN_{frg,bkg}.ply: each clip's Gaussians at its first frame.
inline void export_ply_stage(const ReconstructOptions& o, const VideoModelF& video, ThreadPool* pool = nullptr) {
  detail::make_dir(o.out / "ply");
  for (std::size_t c = 0; c < video.clips.size(); ++c) detail::export_clip_ply(o, video.clips[c], c, pool);
}

/// The same from a model folder, one clip at a time (releases the folder's loaded clips).
inline void export_ply_stage(const ReconstructOptions& o, VideoModelFolderF& video, ThreadPool* pool = nullptr) {
  detail::make_dir(o.out / "ply");
  for (std::size_t c = 0; c < video.clip_count(); ++c) {
    video.release();
    detail::export_clip_ply(o, video.clip(c), c, pool);
  }
  video.release();
}

/// Stages 1-3 in order, then the PLY export and OUT/report.json (written last); with `sfm_only` or
/// `train_clips` only the stages they name (see ReconstructOptions), returning without report.json. `sfm` is any
/// `SfmBackend` whose result derives from `SfmResult<double>`, e.g. `colmap::ColmapSfm`; it should
/// already have been checked (program present).
/// @throws the back end's and the scheduler's errors, `[run.interrupted]`, `io.*` on write failures.
template <class Sfm>
ReconstructReport reconstruct_video(const ReconstructOptions& o, const PreparedInput& in, Sfm& sfm, const ReconstructHooks& hooks = {},
                                    ThreadPool* pool = nullptr, VideoModelF* model_out = nullptr) {
  ReconstructReport rep;
  {
    ScopedTimer total(rep.seconds_total);
    rep.training = o.train_options();  // options fail before any work
    rep.extend = o.extend;
    if (o.compact) o.compact->validate();
    rep.preset = o.preset;
    detail::make_dir(o.out);
    rep.frames = in.frame_count();
    rep.width = in.width;
    rep.height = in.height;
    TrainStage trained;
    if (o.train_during_sfm && !o.sfm_only) {
      auto [sfm_out, t] = sfm_and_train_stage(o, in, sfm, hooks, pool);
      rep.seconds_sfm = sfm_out.seconds;
      trained = std::move(t);
    } else {
      const SfmStage sfm_out = sfm_stage(o, in, sfm, hooks);
      rep.seconds_sfm = sfm_out.seconds;
      if (o.sfm_only) {  // stage 1 only: the schedule's clips (SfM figures), no report.json
        for (const SfmClip& clip : sfm_out.clips) detail::add_sfm_figures(rep.clips.emplace_back(), clip);
        return rep;
      }
      trained = train_stage(o, in, sfm_out, hooks, pool);
    }
    if (o.train_clips) {  // a worker: its clips' reports, no renders, no report.json
      rep.clips = trained.clips;
      rep.trained_clips = trained.trained_clips;
      rep.seconds_train = trained.seconds;
      return rep;
    }
    VideoModelFolderF video(o.out / "model");
    const RenderStage rendered = render_stage(o, in, video, hooks, pool);
    rep.psnr = rendered.psnr, rep.ssim = rendered.ssim, rep.psnr_mean_colour = rendered.psnr_mean_colour;
    rep.psnr_per_frame = rendered.psnr_per_frame, rep.ssim_per_frame = rendered.ssim_per_frame;
    rep.seconds_train = trained.seconds, rep.seconds_render = rendered.seconds;
    if (o.write_ply) {
      ScopedTimer ply(rep.seconds_render);
      export_ply_stage(o, video, pool);
    }
    rep.clips = trained.clips;
    rep.trained_clips = trained.trained_clips;
    for (const auto& c : rep.clips) rep.seconds_sfm_recorded += c.sfm_seconds_recorded, rep.seconds_train_recorded += c.train_seconds;
    video.release();
    if (model_out) *model_out = load_video_model<float>(o.out / "model");
  }
  io::write_file_atomic(o.out / "report.json", rep.json() + "\n");
  return rep;
}

}  // namespace video3dgs::pipeline
