#pragma once
// `video3dgs sfm`: MC-COLMAP on a video (frame folder + optional mask folder). Splits the video into
// clips with video3dgs::schedule_clips, reconstructs each clip with COLMAP (video3dgs::colmap::ColmapSfm)
// and writes
//   OUT/clips.json                 {"frames": N, "clips": [{"first", "last", "attempts", "registered",
//                                   "points", ...}], "attempts": ...}: what was decided, no timings, so
//                                   two runs on the same input write the same bytes (deterministic SfM)
//   OUT/timings.json               {"clips": [{"seconds", "tries": [{"seconds", "seconds_extract", ...}]}],
//                                   "seconds", "wall_seconds"}: COLMAP's seconds, clip by clip
//   OUT/clip_000/sparse/0/*.bin    one COLMAP model per clip (binary), clip_001, ...
//   OUT/work/frames_a_b/           one COLMAP work folder per attempt (reused by a re-run)
// Re-running with the same inputs and options reuses every finished attempt instead of running COLMAP.
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <system_error>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "video3dgs/colmap.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/io/frame_folder.hpp"
#include "video3dgs/scheduling.hpp"

namespace video3dgs::cli {

struct SfmCommandOptions {
  std::filesystem::path frames, masks, out;
  int k = 10;
  int overlap = 1;
  int max_clip_frames = 0;
  int join_tail = 0;
  int max_attempts = 0;
  bool keep_failed = false;
  colmap::ColmapSfmOptions colmap;
  bool delete_work = false;
  bool no_relaxed = false;
};

/// How masks steer SfM (ColmapSfm::use_masks, min_mask_area, the two fallbacks): the options
/// `sfm` and `reconstruct` share. `no_masks_flag` names the switch that keeps masks away from COLMAP.
inline void add_sfm_mask_options(CLI::App* sub, colmap::ColmapSfmOptions& c, const std::string& no_masks_flag) {
  sub->add_option("--min-mask-area", c.min_mask_area,
                  "masked SfM first when the mean mask area is at least this (1 = whole frames first; the method's: 0.1)")
      ->capture_default_str();
  sub->add_flag(no_masks_flag, [&c](std::int64_t) { c.use_masks = false; }, "ignore --masks for feature extraction (whole frames)");
  sub->add_flag("--no-full-frame-fallback", [&c](std::int64_t) { c.full_frame_fallback = false; },
                "do not redo a failed masked clip on the full frames");
  sub->add_option("--masked-fallback-min-area", c.masked_fallback_min_area,
                  "redo a failed full-frame clip with its masks when their area is at least this (0 = never)")
      ->capture_default_str();
  sub->add_option("--masked-fallback-after", c.masked_fallback_after,
                  "try the masks only once the clip has grown from this many failed whole-frame attempts (0 = at once, the method's)")
      ->capture_default_str();
}

/// The camera, when it is known (`--focal`, ColmapSfm::focal), what cameras must rest on
/// (`--min-points-per-frame`, `--max-reprojection-error`) and whether they must be reproducible (`--nondeterministic-sfm`),
/// shared by `sfm` and `reconstruct`.
inline void add_sfm_camera_options(CLI::App* sub, colmap::ColmapSfmOptions& c) {
  sub->add_option("--focal", c.focal,
                  "the camera's focal length in pixels at the frames' size, fixed for every clip (0 = estimated by COLMAP); "
                  "width / (2 tan(horizontal field of view / 2))")
      ->capture_default_str();
  sub->add_option("--min-points-per-frame", c.min_points_per_frame,
                  "a clip's SfM succeeds only with at least this many 3D points per frame (else retries, the other pass, growth; "
                  "0 = one point, the method's rule)")
      ->check(CLI::Range(0.0, 1e6))
      ->capture_default_str();
  sub->add_option("--max-reprojection-error", c.max_reprojection_error,
                  "a clip's SfM succeeds only if its points' mean reprojection error is at most this many pixels (else retries, "
                  "the other pass, growth; 0 = no limit, the method's rule)")
      ->check(CLI::Range(0.0, 1e6))
      ->capture_default_str();
  sub->add_flag("--nondeterministic-sfm", [&c](std::int64_t) { c.deterministic = false; },
                "faster on many cores but not reproducible: COLMAP's own (randomised) matcher and every COLMAP step on --threads; "
                "by default the same input gives the same clips and cameras");
}

inline void run_sfm_command(const SfmCommandOptions& o) {
  const io::FrameList list = io::list_frames(o.frames, o.masks);
  colmap::ColmapSfmOptions copt = o.colmap;
  copt.work_dir = o.out / "work";
  copt.keep_work = !o.delete_work;
  copt.relaxed_retry = !o.no_relaxed;
  std::error_code ec;
  std::filesystem::create_directories(copt.work_dir, ec);
  if (ec) throw io_error("io.unwritable", copt.work_dir.string(), "cannot create folder: " + ec.message());
  colmap::ColmapSfm sfm(list.frames, list.masks, copt);
  sfm.require_colmap();

  ScheduleOptions so;
  so.initial_frames = o.k;
  so.overlap = o.overlap;
  so.max_clip_frames = o.max_clip_frames;
  so.join_tail = o.join_tail;
  so.max_attempts = o.max_attempts;
  so.on_failure = o.keep_failed ? ClipFailurePolicy::keep_failed_clip : ClipFailurePolicy::throw_error;
  so.progress = [&](const ScheduleProgress& p) {
    const auto& a = sfm.attempts().back();
    std::fprintf(stderr, "[sfm] clip %d frames %d-%d attempt %d: %s, %d/%d registered, %zu points, %.1f s%s%s%s\n", p.clip,
                 p.range.first, p.range.last, p.attempt, to_string(p.status), a.registered, p.range.size(), a.points,
                 a.seconds(), a.reused ? " (reused)" : "", a.fallback_succeeded ? (a.masked ? " (masked fallback)" : " (full-frame fallback)") : a.relaxed_succeeded ? " (relaxed init)" : "",
                 p.status == SfmStatus::success ? "" : (" - " + p.message).c_str());
  };
  const auto t0 = std::chrono::steady_clock::now();
  const auto schedule = schedule_clips(static_cast<int>(list.size()), sfm, so);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  nlohmann::json clips = nlohmann::json::array(), clip_times = nlohmann::json::array();
  std::size_t next_attempt = 0;
  double total = 0;
  int relaxed_total = 0;
  for (std::size_t i = 0; i < schedule.clips.size(); ++i) {
    const auto& c = schedule.clips[i];
    double secs = 0;
    int relaxed = 0;
    nlohmann::json tries = nlohmann::json::array(), try_times = nlohmann::json::array();
    for (int a = 0; a < c.attempts; ++a, ++next_attempt) {
      const auto& at = sfm.attempts().at(next_attempt);
      secs += at.seconds();
      relaxed += at.relaxed_succeeded ? 1 : 0;
      tries.push_back({{"first", at.range.first}, {"last", at.range.last}, {"status", to_string(at.status)},
                       {"registered", at.registered}, {"points", at.points},
                       {"mean_reprojection_error", at.mean_reprojection_error}, {"message", at.message},
                       {"masked", at.masked}, {"mask_area", at.mask_area}, {"relaxed_tried", at.relaxed_tried},
                       {"relaxed_succeeded", at.relaxed_succeeded}, {"relaxed_runs", at.relaxed_runs},
                       {"fallback_tried", at.fallback_tried}, {"fallback_succeeded", at.fallback_succeeded},
                       {"databases_reused", at.databases_reused}, {"reused", at.reused}});
      try_times.push_back({{"first", at.range.first}, {"last", at.range.last}, {"seconds", at.seconds()},
                           {"seconds_extract", at.seconds_extract}, {"seconds_match", at.seconds_match},
                           {"seconds_map", at.seconds_map + at.seconds_map_relaxed}, {"reused", at.reused}});
    }
    total += secs;
    relaxed_total += relaxed;
    char name[32];
    std::snprintf(name, sizeof(name), "clip_%03zu", i);
    const auto model_dir = o.out / name / "sparse" / "0";
    if (!c.result.model.images.empty()) colmap::write_model(model_dir, c.result.model, colmap::Format::binary);
    clips.push_back({{"first", c.range.first}, {"last", c.range.last}, {"attempts", c.attempts},
                     {"registered", c.result.frames.size()}, {"points", c.result.points.size()},
                     {"succeeded", c.succeeded}, {"model", c.result.model.images.empty() ? "" : (std::string(name) + "/sparse/0")},
                     {"tries", tries}});
    clip_times.push_back({{"first", c.range.first}, {"last", c.range.last}, {"seconds", secs}, {"tries", try_times}});
  }
  nlohmann::json doc = {{"frames", list.size()},
                        {"clips", clips},
                        {"attempts", schedule.stats.attempts},
                        {"soft_failures", schedule.stats.soft_failures},
                        {"relaxed_successes", relaxed_total},
                        {"k", o.k},
                        {"overlap", o.overlap},
                        {"max_clip_frames", o.max_clip_frames},
                        {"join_tail", o.join_tail},
                        {"masks", !list.masks.empty() && copt.use_masks},
                        {"relaxed_retry", !o.no_relaxed},
                        {"full_frame_fallback", copt.full_frame_fallback},
                        {"min_mask_area", copt.min_mask_area},
                        {"masked_fallback_min_area", copt.masked_fallback_min_area},
                        {"masked_fallback_after", copt.masked_fallback_after},
                        {"min_points_per_frame", copt.min_points_per_frame},
                        {"max_reprojection_error", copt.max_reprojection_error},
                        {"deterministic", copt.deterministic}};
  io::write_file_atomic(o.out / "timings.json",
                        nlohmann::json{{"clips", clip_times}, {"seconds", total}, {"wall_seconds", wall}}.dump(2) + "\n");
  io::write_file_atomic(o.out / "clips.json", doc.dump(2) + "\n");
  std::fprintf(stderr, "[sfm] %zu clips, %d attempts, %.1f s of COLMAP (%.1f s wall) -> %s\n", schedule.clips.size(),
               schedule.stats.attempts, total, wall, (o.out / "clips.json").c_str());
}

inline void add_sfm_command(CLI::App& app) {
  auto opts = std::make_shared<SfmCommandOptions>();
  CLI::App* sub = app.add_subcommand("sfm", "MC-COLMAP: split a video into clips and reconstruct each with COLMAP");
  sub->add_option("--frames", opts->frames, "folder of frames (natural order)")->required()->check(CLI::ExistingDirectory);
  sub->add_option("--masks", opts->masks, "folder of foreground masks, matched to frames by file stem")->check(CLI::ExistingDirectory);
  sub->add_option("--out", opts->out, "output folder (clips.json, clip_NNN/sparse/0, work/)")->required();
  sub->add_option("-k,--initial-frames", opts->k, "frames of a new clip")->capture_default_str();
  sub->add_option("--overlap", opts->overlap, "frames shared by consecutive clips")->capture_default_str();
  sub->add_option("--max-clip-frames", opts->max_clip_frames, "longest clip (0 = whole video)")->capture_default_str();
  sub->add_option("--join-tail", opts->join_tail, "a clip whose first attempt would leave at most this many frames after it takes them in (0 = the tail gets a clip of its own; at most k - overlap - 1)")
      ->capture_default_str();
  sub->add_option("--max-attempts", opts->max_attempts, "SfM attempts allowed in total (0 = no budget)")->capture_default_str();
  sub->add_flag("--keep-failed", opts->keep_failed, "keep clips that never succeed (marked failed) instead of stopping");
  sub->add_option("--threads", opts->colmap.threads, "threads of the matcher, and of every COLMAP step with --nondeterministic-sfm (0 = all cores)")->capture_default_str();
  sub->add_option("--colmap", opts->colmap.executable, "the colmap program")->capture_default_str();
  sub->add_option("--timeout", opts->colmap.step_timeout_seconds, "seconds allowed per COLMAP step (0 = none)")->capture_default_str();
  sub->add_option("--max-image-size", opts->colmap.max_image_size, "SIFT on images downscaled to this longest side (0 = COLMAP default)")
      ->capture_default_str();
  sub->add_option("--max-features", opts->colmap.max_num_features, "SIFT features per frame at most (0 = COLMAP default 8192)")
      ->capture_default_str();
  add_sfm_mask_options(sub, opts->colmap, "--no-masks");
  add_sfm_camera_options(sub, opts->colmap);
  sub->add_flag("--no-relaxed-retry", opts->no_relaxed, "do not retry a failed mapper with a relaxed initialisation");
  sub->add_option("--relaxed-tries", opts->colmap.relaxed_tries, "relaxed mapper runs (different seeds) before giving up on a clip")
      ->capture_default_str();
  sub->add_flag("--delete-work", opts->delete_work, "after each attempt delete its images, masks, database (logs and chosen model stay for re-runs)");
  sub->callback([opts] { run_sfm_command(*opts); });
}

}  // namespace video3dgs::cli
