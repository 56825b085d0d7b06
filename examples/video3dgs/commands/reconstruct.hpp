#pragma once
// `video3dgs reconstruct --frames DIR|VIDEO [--masks DIR] --out DIR [--preset balanced|fast|best|3k|5k|10k] [--iterations N]
//                        [--scale S] [--threads N] [--seed S] [-k 10] [--resume] [--overwrite] ...`
// The whole job (video3dgs::pipeline, include/video3dgs/pipeline/reconstruct.hpp): every input check,
// MC-COLMAP with the `colmap` program, each clip trained, every frame rendered. Writes into OUT:
//   renders/00000.png ...  compare/ (source | render | error heat map)  model/ (VideoModel folder)
//   ply/clip_NNN_{frg,bkg}.ply  metrics.csv  metrics.png  report.json  report.html  (+ renders.mp4, compare.mp4
//   when ffmpeg is installed)  and the job's own sfm/ and train/ folders (reused by --resume).
// A video file as --frames (ffmpeg needed) is extracted into OUT/input_frames/ (kept so that --resume
// sees the same frames). Progress: a bar with ETA on a terminal, plain lines otherwise. Ctrl-C stops
// after the current iteration, keeps finished clips and a checkpoint of the running one, exits 2 with
// `[run.interrupted]`. Prints report.json's text as one line on stdout.
//
// Stages for schedulers (scripts/slurm_reconstruct.sh, scripts/parallel_reconstruct.sh): --sfm-only
// stops after MC-COLMAP; --clips A:B (A:, or A) trains only those clips of the schedule and stops
// (workers on disjoint ranges, sharing OUT, with --resume); a last run with --resume combines them.
// Both print the partial report on stdout and write no report.json.
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>
#include <utility>
#include <system_error>

#include <CLI/CLI.hpp>

#include "commands/model_options.hpp"
#include "commands/sfm.hpp"
#include "video3dgs/colmap/process.hpp"
#include "video3dgs/colmap/sfm.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/pipeline/reconstruct.hpp"
#include "video3dgs/pipeline/report_html.hpp"

namespace video3dgs::cli {

struct ReconstructCommandOptions {
  pipeline::ReconstructOptions job;
  unsigned threads = 0;
  std::filesystem::path colmap = "colmap";
  std::filesystem::path ffmpeg = "ffmpeg";
  int shell_points = 30000;
  int fps = 10;
  bool no_video = false;
  double colmap_timeout = 3600;
  colmap::ColmapSfmOptions sfm;  ///< set by add_sfm_mask_options and add_sfm_camera_options; the command sets the rest (program, folder, threads, ...)
  std::string clips;             ///< --clips A:B
};

/// "A:B", "A:" (to the last clip) or "A" as a clip range. @throws option_error `option.range`
inline std::pair<int, int> parse_clip_range(const std::string& text) {
  auto number = [&](const std::string& t) {
    if (t.empty() || t.find_first_not_of("0123456789") != std::string::npos || t.size() > 6)
      throw option_error("option.range", "--clips", "expected A:B, A: or A with clip numbers, got '" + text + "'");
    return std::stoi(t);
  };
  const auto colon = text.find(':');
  if (colon == std::string::npos) return {number(text), number(text)};
  const std::string b = text.substr(colon + 1);
  return {number(text.substr(0, colon)), b.empty() ? -1 : number(b)};
}

inline std::atomic<bool>& interrupt_flag() {
  static std::atomic<bool> flag{false};
  return flag;
}

inline void video3dgs_cli_on_sigint(int) { interrupt_flag().store(true); }

/// Terminal progress: a bar with ETA when stderr is a terminal, else plain lines.
class ProgressPrinter {
 public:
  explicit ProgressPrinter(int iterations) : iterations_(iterations), tty_(::isatty(2) == 1), t0_(clock::now()) {}

  void operator()(const pipeline::ProgressEvent& e) {
    using S = pipeline::ProgressEvent::Stage;
    if (e.stage == S::sfm) {
      end_bar();
      std::fprintf(stderr, "[sfm] %s\n", e.message.c_str());
      return;
    }
    if (e.stage == S::train) {
      if (!train_started_) train_started_ = true, t_train_ = clock::now();
      clips_ = e.clips;
      // A quality floor may lengthen a clip beyond the preset's iterations (e.iterations grows): the
      // bar and the ETA count the preset's, the message the clip's run as it stands.
      const double done = double(e.clip) * iterations_ + std::min(e.iteration, iterations_);
      const double total = double(e.clips) * iterations_;
      if (e.reused) {
        reused_iters_ += iterations_;
        end_bar();
        std::fprintf(stderr, "[train] clip %d/%d reused from an earlier run (PSNR %.2f dB)\n", e.clip + 1, e.clips, e.psnr);
        return;
      }
      const double elapsed = secs(t_train_);
      const double run = done - reused_iters_;
      const double eta = run > 0 ? std::max(0.0, elapsed / run * (total - done)) : 0;
      char msg[160];
      // While SfM still adds clips (SfM and training at once) the count and the ETA cover the clips
      // known so far: "clip 2/3+  ... ETA >= 4m10s".
      std::snprintf(msg, sizeof(msg), "clip %d/%d%s  it %d/%d  psnr %.2f dB  ETA %s%s", e.clip + 1, e.clips, e.clips_final ? "" : "+",
                    e.iteration, e.iterations, e.psnr, e.clips_final ? "" : ">= ", hms(eta).c_str());
      if (tty_) {
        if (secs(last_) < 0.2 && e.iteration != e.iterations) return;
        last_ = clock::now();
        bar(done / std::max(total, 1.0), msg);
      } else if (e.iteration == e.iterations || e.iteration % std::max(1, e.iterations / 10) == 0) {
        std::fprintf(stderr, "[train] %s\n", msg);
      }
      if (e.iteration == e.iterations) end_bar();
      return;
    }
    char msg[96];
    std::snprintf(msg, sizeof(msg), "frame %d/%d  psnr %.2f dB", e.frame, e.frames, e.psnr);
    if (tty_) {
      bar(double(e.frame) / std::max(e.frames, 1), msg);
      if (e.frame == e.frames) end_bar();
    } else if (e.frame == e.frames || e.frame % std::max(1, e.frames / 5) == 0) {
      std::fprintf(stderr, "[render] %s\n", msg);
    }
  }

 private:
  using clock = std::chrono::steady_clock;
  static double secs(clock::time_point t) { return std::chrono::duration<double>(clock::now() - t).count(); }
  static std::string hms(double s) {
    const long v = static_cast<long>(s + 0.5);
    char b[32];
    if (v >= 3600) std::snprintf(b, sizeof(b), "%ldh%02ldm", v / 3600, (v / 60) % 60);
    else std::snprintf(b, sizeof(b), "%ldm%02lds", v / 60, v % 60);
    return b;
  }
  void bar(double frac, const char* msg) {
    const int w = 30, k = static_cast<int>(std::clamp(frac, 0.0, 1.0) * w);
    std::fprintf(stderr, "\r[%.*s%.*s] %3d%%  %s\033[K", k, "##############################", w - k, "------------------------------",
                 static_cast<int>(frac * 100), msg);
    open_ = true;
  }
  void end_bar() {
    if (open_) std::fputc('\n', stderr);
    open_ = false;
  }
  int iterations_;
  bool tty_;
  bool open_ = false, train_started_ = false;
  int clips_ = 0;
  double reused_iters_ = 0;
  clock::time_point t0_, t_train_, last_{};
};

/// Encodes OUT/<name>/%05d.png as OUT/<name>.mp4 (H.264, even size), atomically. Returns false (and
/// says why on stderr) if ffmpeg fails; missing ffmpeg is checked by the caller.
inline bool encode_mp4(const std::filesystem::path& ffmpeg, const std::filesystem::path& out, const std::string& name, int fps) {
  const auto tmp = out / ("." + name + ".tmp.mp4"), dst = out / (name + ".mp4");
  const auto pr = colmap::run_process({ffmpeg.string(), "-y", "-loglevel", "error", "-framerate", std::to_string(fps), "-i",
                                       (out / name / "%05d.png").string(), "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-c:v", "libx264",
                                       "-pix_fmt", "yuv420p", "-f", "mp4", tmp.string()},
                                      out / "ffmpeg.log", 600);
  std::error_code ec;
  if (!pr.ok()) {
    std::filesystem::remove(tmp, ec);
    std::fprintf(stderr, "[video] ffmpeg could not encode %s.mp4 (see %s)\n", name.c_str(), (out / "ffmpeg.log").c_str());
    return false;
  }
  std::filesystem::rename(tmp, dst, ec);
  return !ec;
}

/// A video file given as --frames: frames extracted into OUT/input_frames (reused if complete).
inline std::filesystem::path extract_video(const std::filesystem::path& ffmpeg, const std::filesystem::path& video,
                                           const std::filesystem::path& out) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (colmap::find_executable(ffmpeg).empty())
    throw external_error("ffmpeg.missing", video.string(),
                         "a video file as --frames needs ffmpeg (Debian/Ubuntu: `sudo apt-get install ffmpeg`), or give a folder of frames");
  if (fs::exists(out, ec) && !fs::is_directory(out, ec))
    throw io_error("io.not_a_folder", out.string(), "the output path exists and is not a folder; choose another --out");
  const fs::path dir = out / "input_frames", done = dir / ".complete";
  if (fs::is_regular_file(done, ec)) return dir;
  fs::remove_all(dir, ec);
  fs::create_directories(dir, ec);
  if (ec) throw io_error("io.unwritable", dir.string(), "cannot create folder: " + ec.message());
  std::fprintf(stderr, "[input] extracting the frames of %s with ffmpeg\n", video.c_str());
  // `-vsync passthrough`: every decoded frame is written once, in order. The image-sequence muxer would
  // otherwise resample a variable-frame-rate video (phones record those) to a constant rate, duplicating
  // and dropping frames. (-vsync rather than 5.1's -fps_mode: older ffmpeg releases know only -vsync.)
  const auto pr = colmap::run_process({ffmpeg.string(), "-y", "-loglevel", "error", "-i", video.string(), "-vsync", "passthrough",
                                       "-start_number", "0", (dir / "%05d.png").string()},
                                      out / "ffmpeg.log", 3600);
  if (!pr.ok())
    throw external_error("ffmpeg.failed", video.string(), "ffmpeg could not decode the video (see " + (out / "ffmpeg.log").string() + ")");
  io::write_file_atomic(done, "ok\n");
  return dir;
}

inline void run_reconstruct_command(ReconstructCommandOptions o) {
  namespace fs = std::filesystem;
  auto& job = o.job;
  job.model.background.points_per_shell = o.shell_points;
  if (o.shell_points < 1) throw option_error("option.range", "--shell-points", "must be >= 1");
  if (o.fps < 1 || o.fps > 240) throw option_error("option.range", "--fps", "must be in 1..240");
  if (!o.clips.empty()) job.train_clips = parse_clip_range(o.clips);
  job.validate();
  std::error_code ec;
  // The output folder first: nothing may be written into a file's place.
  if (fs::exists(job.out, ec) && !fs::is_directory(job.out, ec))
    throw io_error("io.not_a_folder", job.out.string(), "the output path exists and is not a folder; choose another --out");
  // COLMAP present (cheap) before decoding anything.
  colmap::ColmapSfmOptions copt = o.sfm;
  copt.executable = o.colmap;
  copt.work_dir = job.out / "sfm";
  copt.threads = static_cast<int>(o.threads);
  copt.keep_work = false;
  copt.reuse_finished = true;
  copt.step_timeout_seconds = o.colmap_timeout;
  colmap::ColmapSfm({}, {}, copt).require_colmap();

  ThreadPool pool(o.threads);
  const auto t0 = std::chrono::steady_clock::now();
  if (fs::is_regular_file(job.frames_dir, ec)) {
    // Same "earlier output" rule as prepare_input, before extracting anything.
    if (!job.resume && !job.overwrite && fs::exists(job.out / "report.json", ec))
      throw io_error("io.output_exists", job.out.string(), "holds an earlier reconstruction; pass --resume to continue it or --overwrite to replace it");
    job.frames_dir = extract_video(o.ffmpeg, job.frames_dir, job.out);
  }
  const pipeline::PreparedInput input = pipeline::prepare_input(job, &pool);
  std::fprintf(stderr, "[input] %d frames %dx%d%s, training at %dx%d, %s\n", input.frame_count(), input.source_width, input.source_height,
               input.has_masks() ? " with masks" : "", input.width, input.height, job.out.c_str());

  fs::create_directories(copt.work_dir, ec);
  if (ec) throw io_error("io.unwritable", copt.work_dir.string(), "cannot create folder: " + ec.message());
  colmap::ColmapSfm sfm(input.list.frames, input.list.masks, copt);

  interrupt_flag().store(false);
  auto previous = std::signal(SIGINT, video3dgs_cli_on_sigint);
  ProgressPrinter printer(job.train_options().iterations);
  pipeline::ReconstructHooks hooks;
  hooks.stop = &interrupt_flag();
  hooks.progress = [&](const pipeline::ProgressEvent& e) { printer(e); };
  pipeline::ReconstructReport rep;
  try {
    rep = pipeline::reconstruct_video(job, input, sfm, hooks, &pool);
  } catch (const video3dgs::error& e) {
    std::signal(SIGINT, previous);
    std::fputc('\n', stderr);
    if (interrupt_flag().load() && e.id() != "run.interrupted")  // e.g. COLMAP killed by the same Ctrl-C
      throw error("run.interrupted", e.where(), "stopped on request (" + std::string(e.what()) + "); rerun with --resume to continue");
    throw;
  }
  std::signal(SIGINT, previous);
  if (job.sfm_only || job.train_clips) {  // a stage for a scheduler: no renders, videos or report.json
    std::cout << rep.json() << std::endl;
    if (job.sfm_only) std::fprintf(stderr, "[done] MC-COLMAP: %zu clips\n", rep.clips.size());
    else std::fprintf(stderr, "[done] worker: %d clips trained, %zu reused\n", rep.trained_clips, rep.clips.size() - std::size_t(rep.trained_clips));
    return;
  }

  bool videos = false;
  if (!o.no_video && !colmap::find_executable(o.ffmpeg).empty()) {
    videos = encode_mp4(o.ffmpeg, job.out, "renders", o.fps);
    if (job.write_compare) videos = encode_mp4(o.ffmpeg, job.out, "compare", o.fps) && videos;
  }
  pipeline::write_report_html(job.out, rep);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::cout << rep.json() << std::endl;
  if (colmap::find_executable(job.gnuplot).empty())
    std::fprintf(stderr, "[plot] metrics.png has no axes or legend: '%s' is not installed (Debian: apt-get install gnuplot-nox)\n",
                 job.gnuplot.c_str());
  std::fprintf(stderr,
               "[done] %d frames, %zu clips (%d trained, %zu reused), mean PSNR %.2f dB, SSIM %.4f, %.0f s\n"
               "       look at: %s  (source | render | error)\n"
               "                %s  (per-frame PSNR/SSIM; plot metrics.png)\n"
               "                %s\n"
               "                %s  (all of it on one page)\n",
               rep.frames, rep.clips.size(), rep.trained_clips, rep.clips.size() - std::size_t(rep.trained_clips), rep.psnr, rep.ssim, wall,
               (job.out / (videos ? "compare.mp4" : "compare/")).c_str(), (job.out / "metrics.csv").c_str(), (job.out / "report.json").c_str(),
               (job.out / "report.html").c_str());
}

/// TrainOptions::preset_names() as strings (CLI11's IsMember takes a container).
inline std::vector<std::string> preset_name_list() {
  const auto names = TrainOptions::preset_names();
  return {names.begin(), names.end()};
}

// `--NAME V`, V in [0, hi]: sets the job's optional training override `field` (unset: the preset's value).
inline void add_training_number(CLI::App* sub, const std::shared_ptr<ReconstructCommandOptions>& o, const std::string& name,
                                std::optional<double> pipeline::ReconstructOptions::*field, double hi, const std::string& help) {
  sub->add_option_function<double>(name, [o, field](double v) { o->job.*field = v; }, help)->check(CLI::Range(0.0, hi));
}

inline void add_reconstruct_command(CLI::App& app) {
  auto o = std::make_shared<ReconstructCommandOptions>();
  CLI::App* sub = app.add_subcommand("reconstruct", "video -> MC-COLMAP -> per-clip training -> every frame rendered (+ report.json)");
  sub->add_option("--frames", o->job.frames_dir, "folder of frames (natural order), or a video file (needs ffmpeg)")->required();
  sub->add_option("--masks", o->job.masks_dir, "folder of foreground masks, matched to frames by file stem");
  sub->add_option("--out", o->job.out, "output folder")->required();
  sub->add_option("--preset", o->job.preset,
                  "training preset: balanced (3k iterations, coarse to fine), fast (balanced over 2000 iterations), best (5k "
                  "iterations, coarse to fine), or the paper's 3k, 5k, 10k (reference = 3k); no preset prunes (--prune-weight)")
      ->check(CLI::IsMember(preset_name_list()))
      ->capture_default_str();
  sub->add_option("--iterations", o->job.iterations, "iterations per clip (0 = the preset's; schedules scale with it)")->capture_default_str();
  sub->add_option("--scale", o->job.scale, "train and render at this fraction of the frame size, (0, 1]")->capture_default_str();
  sub->add_option("--threads", o->threads, "worker threads, also for COLMAP (0 = all cores)")->capture_default_str();
  sub->add_option("--seed", o->job.seed, "seed")->capture_default_str();
  sub->add_option("-k", o->job.k, "MC-COLMAP: frames of a new clip")->capture_default_str();
  sub->add_option("--max-clip-frames", o->job.max_clip_frames, "MC-COLMAP: longest clip (0 = whole video)")->capture_default_str();
  sub->add_option("--join-tail", o->job.join_tail,
                  "MC-COLMAP: a clip whose first attempt would leave at most this many frames after it takes them in (0 = the tail gets a clip of its own; at most k - 2)")
      ->capture_default_str();
  sub->add_flag("--resume", o->job.resume, "reuse finished SfM attempts, trained clips and checkpoints in --out");
  sub->add_flag("--overwrite", o->job.overwrite, "replace an earlier reconstruction in --out (files are replaced one by one)");
  sub->add_option("--shell-points", o->shell_points, "background points per shell (2 shells; those no clip camera sees are then dropped, unless --keep-unseen)")->capture_default_str();
  sub->add_option("--checkpoint-every", o->job.checkpoint_every, "iterations between checkpoints (0 = only on Ctrl-C)")->capture_default_str();
  sub->add_flag("--no-compare", [o](std::int64_t) { o->job.write_compare = false; }, "do not write compare/ (source | render | error)");
  sub->add_flag("--no-video", o->no_video, "do not encode renders.mp4 / compare.mp4");
  sub->add_option("--fps", o->fps, "frame rate of the mp4 files")->capture_default_str();
  sub->add_option("--colmap", o->colmap, "the colmap program")->capture_default_str();
  sub->add_option("--colmap-timeout", o->colmap_timeout, "seconds allowed per COLMAP step (0 = none)")->capture_default_str();
  sub->add_option("--ffmpeg", o->ffmpeg, "the ffmpeg program")->capture_default_str();
  sub->add_option("--gnuplot", o->job.gnuplot, "the gnuplot program (draws metrics.png; without it the plot has no text)")
      ->capture_default_str();
  add_sfm_mask_options(sub, o->sfm, "--no-sfm-masks");
  add_sfm_camera_options(sub, o->sfm);
  add_model_start_options(sub, o->job.model);
  sub->add_option_function<int>(
         "--log2-table", [o](int n) { o->job.model.frg_grid.log2_table_size = o->job.model.bkg_grid.log2_table_size = n; },
         "deformation fields: 2^N entries per hashed level of both hash grids (default 16)")
      ->check(CLI::Range(2, 30));
  sub->add_option_function<int>(
         "--grid-levels", [o](int n) { o->job.model.frg_grid.levels = o->job.model.bkg_grid.levels = n; },
         "deformation fields: levels of both hash grids, spanning the same resolutions (1-16, default 16)")
      ->check(CLI::Range(1, 16));
  sub->add_option_function<double>(
         "--grid-finest", [o](double r) { o->job.model.frg_grid.finest = o->job.model.bkg_grid.finest = r; },
         "deformation fields: cells per axis of the finest level of both grids (default 2006; >= 16)")
      ->check(CLI::Range(16.0, 1e8));
  sub->add_option_function<std::string>(
         "--grid-time-cells",
         [o](const std::string& v) {
           o->job.model.frg_grid.time_cells = o->job.model.bkg_grid.time_cells = GridSize::parse_time_cells(v);
         },
         "deformation fields: cap on every level's cells along time, both grids: N, `frames` (the default: a clip's "
         "frames - 1, one time slice per frame) or `none` (the grids of earlier versions)")
      ->check([](const std::string& v) {
        try {
          (void)GridSize::parse_time_cells(v);
          return std::string();
        } catch (const option_error&) {
          return std::string("must be a positive integer, `frames` or `none`");
        }
      });
  sub->add_option_function<int>(
         "--bkg-log2-table", [o](int n) { o->job.model.bkg_grid.log2_table_size = n; }, "the background field's 2^N (overrides --log2-table)")
      ->check(CLI::Range(2, 30));
  sub->add_option_function<int>(
         "--bkg-grid-levels", [o](int n) { o->job.model.bkg_grid.levels = n; }, "the background field's levels (overrides --grid-levels)")
      ->check(CLI::Range(1, 16));
  sub->add_flag("--sparse-adam", o->job.sparse_adam, "lazy Adam: Gaussians and hash entries an iteration did not touch keep their values and moments");
  sub->add_flag(
      "--compact", [o](std::int64_t) { if (!o->job.compact) o->job.compact = CompactOptions{}; },
      "also write each clip as model/clip_NNN.compact (quantised, deflated; `video3dgs compact` for other settings); report.json gives its bytes per part");
  sub->add_option_function<std::string>(
      "--compact-preset", [o](const std::string& name) { o->job.compact = CompactOptions::preset(name); },
      "--compact with these settings: default, or small (5-bit hash tables, 16 SH codewords, 16-bit foreground positions; "
      "see `video3dgs compact --preset`)");
  sub->add_option_function<std::string>(
      "--resolution-schedule", [o](const std::string& text) { o->job.resolution_schedule = TrainOptions::parse_resolution_schedule(text); },
      "coarse to fine: K:S,K:S,... trains from iteration K on at S x the size (iterations of the preset; scaled with --iterations; "
      "default: the preset's; 0:1 = none)");
  sub->add_option_function<double>(
         "--prune-weight", [o](double w) { o->job.prune_weight = w; },
         "prune Gaussians whose mean blend weight over the views that saw them is below this many pixels (0 = off; default: the preset's)")
      ->check(CLI::Range(0.0, 1e6));
  sub->add_option_function<int>(
         "--prune-weight-from", [o](int k) { o->job.prune_weight_from = k; },
         "the weight prune acts only at the densification events from iteration K on (iterations of the preset, scaled with "
         "--iterations; 0 = every event, the default; the preset's last densification = one prune before the full-size phase)")
      ->check(CLI::Range(0, 1000000));
  sub->add_option_function<double>(
         "--prune-efficiency", [o](double e) { o->job.prune_efficiency = e; },
         "one prune of the Gaussians whose blend weight per evaluation is below E (0 = off; default: the preset's, 0.01 for "
         "balanced and fast, off for the others; docs/training.md)")
      ->check(CLI::Range(0.0, 1.0));
  sub->add_option_function<int>(
         "--prune-efficiency-at", [o](int k) { o->job.prune_efficiency_at = k; },
         "the efficiency prune acts after iteration K, judged from the last densification event on (iterations of the preset, "
         "scaled with --iterations; default: 50 after the preset's last densification event, 2050 for balanced; none with "
         "--prune-efficiency-from)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option_function<int>(
         "--prune-efficiency-from", [o](int k) { o->job.prune_efficiency_from = k; },
         "the efficiency prune also just before every densification event from iteration F on, over the statistics since "
         "the event before (iterations of the preset, scaled with --iterations; default: off)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option_function<double>(
         "--prune-efficiency-bkg", [o](double e) { o->job.prune_efficiency_bkg = e; },
         "the background set's own threshold in the efficiency prunes (0 or unset: --prune-efficiency's; docs/training.md)")
      ->check(CLI::Range(0.0, 1.0));
  sub->add_option_function<double>(
         "--crop", [o](double c) { o->job.crop = c; },
         "full-size iterations train on one random cell of a jittered ceil(1/C) x ceil(1/C) cut of the frame (0 or 1 = whole "
         "frames; default: the preset's)")
      ->check(CLI::Range(0.0, 1.0));
  sub->add_flag(
      "--refine-cameras", [o](std::int64_t) { o->job.camera_lr = std::array<double, 2>{2e-5, 2e-5}; },
      "refine each clip's cameras while training (every frame but the first; learning rates 2e-5 rad and 2e-5 x scene radius "
      "per Adam step, constant, not scaled with --iterations; --camera-lr for others)");
  sub->add_option_function<std::vector<double>>(
         "--camera-lr",
         [o](const std::vector<double>& v) {
           if (v.size() != 2 || !(v[0] >= 0 && v[0] <= 1) || !(v[1] >= 0 && v[1] <= 1))
             throw option_error("option.range", "--camera-lr", "needs ROT,TRANS, each in [0, 1] (0,0 = no refinement)");
           o->job.camera_lr = std::array<double, 2>{v[0], v[1]};
         },
         "camera refinement's learning rates ROT,TRANS: radians and x scene radius per Adam step (0,0 = off; default: the preset's)")
      ->delimiter(',')
      ->expected(2)
      ->excludes("--refine-cameras");
  sub->add_option("--budget", o->job.gaussians_per_pixel,
                  "Gaussian budget per set: this many per frame pixel (the foreground's times its mask coverage or --frg-share); 0 = none")
      ->check(CLI::Range(0.0, 1e6))
      ->capture_default_str();
  sub->add_option_function<double>(
         "--frg-share", [o](double f) { o->job.foreground_share = f; },
         "the foreground's share of --budget in every clip, 0.001..1 (default: each clip's masks' coverage)")
      ->check(CLI::Range(1e-3, 1.0));
  sub->add_option_function<std::string>(
         "--capacity",
         [o](const std::string& v) {
           if (v == "auto") o->job.capacity = CapacityRules{};
           else if (v == "none") o->job.capacity.reset();
           else throw option_error("option.capacity", "--capacity", "auto or none, got '" + v + "'");
         },
         "auto: size each clip's model from its pixels, frames, SfM points and viewpoints (hash tables, Gaussian budget, SH degree; "
         "report.json gives each clip's plan; --log2-table, --budget, --frg-share given win); none (default): the same size for every clip");
  const auto from_full_size = std::string(" from the preset's first full-size iteration on (the whole run for 3k, 5k, 10k; default: the preset's");
  add_training_number(sub, o, "--deformation-lr", &pipeline::ReconstructOptions::deformation_lr, 1.0,
                      "the deformation fields' starting learning rate, decaying as the preset's does (default: the preset's, 8e-4)");
  add_training_number(sub, o, "--sh-lr", &pipeline::ReconstructOptions::sh_lr, 1.0,
                      "the colour (SH) DC coefficients' learning rate for the whole run, the other bands' 1/20 of it; --fine-sh-lr "
                      "multiplies both (default: the preset's, the paper's 2.5e-3 in every preset)");
  add_training_number(sub, o, "--fine-position-lr", &pipeline::ReconstructOptions::fine_position_lr, 1e3,
                      "the Gaussians' position learning rate x this" + from_full_size + ")");
  add_training_number(sub, o, "--fine-alpha-lr", &pipeline::ReconstructOptions::fine_alpha_lr, 1e3,
                      "the alpha maps' learning rate x this" + from_full_size + ": 3 for balanced and fast, 2.5 for best, 1 for 3k, 5k and 10k)");
  add_training_number(sub, o, "--fine-sh-lr", &pipeline::ReconstructOptions::fine_sh_lr, 1e3,
                      "the colour (SH) coefficients' learning rates x this" + from_full_size +
                          ": 8 for balanced, fast and best, 1 for 3k, 5k and 10k)");
  add_training_number(sub, o, "--fine-dssim", &pipeline::ReconstructOptions::fine_dssim, 1.0,
                      "the loss's D-SSIM weight lambda" + from_full_size + "; L = (1 - lambda) L1 + lambda D-SSIM)");
  add_training_number(sub, o, "--anneal-lr", &pipeline::ReconstructOptions::anneal_lr, 1.0,
                      "every learning rate falls log-linearly from --anneal-from on to A times itself at the run's end (1 = no "
                      "anneal; default: the preset's)");
  sub->add_option_function<int>(
         "--anneal-from", [o](int k) { o->job.anneal_from = k; },
         "where the anneal starts (iterations of the preset, scaled with --iterations; default: the preset's, else half way "
         "through the fine phase; needs an anneal)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--extend-below", o->job.extend.below_psnr,
                  "quality floor: a clip whose PSNR after the preset's iterations is below this many dB trains on (at the schedule's last size), "
                  "--extend-step iterations at a time, at most --extend-max more, until it reaches it (0 = off)")
      ->check(CLI::Range(0.0, 200.0))
      ->capture_default_str();
  sub->add_option("--extend-max", o->job.extend.max_iterations, "quality floor: most iterations a clip may add")
      ->check(CLI::Range(0, 1000000))
      ->capture_default_str();
  sub->add_option("--extend-step", o->job.extend.step, "quality floor: iterations between two evaluations of the clip")
      ->check(CLI::Range(1, 1000000))
      ->capture_default_str();
  sub->add_flag("--stages-in-turn", [o](std::int64_t) { o->job.train_during_sfm = false; },
                "finish MC-COLMAP before training the first clip (default: a clip trains as soon as its SfM is final)");
  sub->add_flag("--sfm-only", o->job.sfm_only, "stage 1 only: run MC-COLMAP and stop (cluster recipes)");
  sub->add_option("--clips", o->clips, "worker: train only clips A:B of the schedule (A: = to the last; with --resume), then stop");
  sub->callback([o] { run_reconstruct_command(*o); });
}

}  // namespace video3dgs::cli
