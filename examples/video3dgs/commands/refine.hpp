#pragma once
// `video3dgs refine`: stage 2, temporal-consistency refinement of an edited video
// (include/video3dgs/training/refine.hpp).
//
//   video3dgs refine --model OUT --source DIR --edited DIR [--edited DIR2 ...] --out DIR
//                    [--iterations N] [--train-alpha] [--freeze-opacity] [--lr-sh-dc X] [--lr-sh-rest X]
//                    [--lr-opacity X] [--lr-alpha X] [--lambda-dssim X]
//                    [--editor-cmd "prog args {input} {output}" --phases 2]
//
// --model is a `video3dgs reconstruct` output folder (or its model/ subfolder). Source and edited
// frames are paired with the model's frames in natural order and resampled (area) to the model's
// render size. Several --edited folders form an ensemble (loss summed). With --editor-cmd (an argument
// vector split like a shell would split words, but never run by a shell) the refinement is recursive:
// phase 0 edits the source, each later phase edits the previous refined video (--phases N_r); given
// --edited folders are then ignored.
//
// The model, the source and every --edited folder are read and checked (frame counts:
// io.count_mismatch) before anything is written. Writes OUT/refined/00000.png..., OUT/compare/00000.png
// (source | edited | refined), OUT/model/ (the refined model) and, last, OUT/report.json:
//   {"warp_ssim_edited":..,"warp_ssim_refined":..,"psnr_refined_vs_edited":..,"seconds":.., ...}
// warp_ssim_* use the source video's optical flow (built-in estimator, or --flow-forward/--flow-backward
// .flo folders); for an ensemble, warp_ssim_edited and psnr_refined_vs_edited are means over the edits
// (each edit's values are under "edits"); for recursive refinement they refer to phase 0's edit.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "commands/common.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/io/frame_folder.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/metrics/psnr.hpp"
#include "video3dgs/metrics/warp_ssim.hpp"
#include "video3dgs/model/video_model.hpp"
#include "video3dgs/pipeline/outputs.hpp"
#include "video3dgs/training/editor.hpp"
#include "video3dgs/training/refine.hpp"

namespace video3dgs::cli {

namespace detail {

/// Frames of a folder resampled to w x h; `expect` frames (throws io.count_mismatch otherwise).
inline std::vector<Image<float, 3>> read_video_at(const std::filesystem::path& dir, int w, int h, int expect, ThreadPool* pool) {
  auto frames = io::read_frames(io::list_frames(dir), pool);
  if (int(frames.size()) != expect)
    throw io_error("io.count_mismatch", dir.string(),
                   "holds " + std::to_string(frames.size()) + " frames but the model has " + std::to_string(expect));
  for (auto& f : frames) f = pipeline::resize_area(f, w, h);
  return frames;
}

inline double mean_psnr(const std::vector<Image<float, 3>>& a, const std::vector<Image<float, 3>>& b) {
  double s = 0;
  for (std::size_t i = 0; i < a.size(); ++i) s += metrics::psnr<float, 3>(a[i], b[i]);
  return a.empty() ? 0.0 : s / double(a.size());
}

inline nlohmann::json json_number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

}  // namespace detail

inline void add_refine_command(CLI::App& app) {
  struct Options {
    std::string model, source, out, editor_cmd, flow_forward, flow_backward;
    std::vector<std::string> edited;
    int iterations = 1000, phases = 2;
    bool train_alpha = false, freeze_opacity = false;
    double overlap_anchor = 0.5, editor_timeout = 0;
    RefineOptions defaults{};
    unsigned threads = 0;
    std::uint64_t seed = 0;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* sub = app.add_subcommand("refine", "stage 2: refine an edited video with the reconstructed source (temporal consistency)");
  sub->add_option("--model", opt->model, "reconstruction folder of the source video (or its model/ folder)")->required();
  sub->add_option("--source", opt->source, "frames of the source video")->required();
  sub->add_option("--edited", opt->edited, "frames of an edited video (repeat for an ensemble)");
  sub->add_option("--out", opt->out, "output folder")->required();
  sub->add_option("--iterations", opt->iterations, "iterations per clip (and per phase)")->capture_default_str();
  sub->add_flag("--train-alpha", opt->train_alpha, "also fine-tune the per-frame alpha maps");
  sub->add_flag("--freeze-opacity", opt->freeze_opacity, "fine-tune colours only (opacity logits stay as in the model)");
  sub->add_option("--lr-sh-dc", opt->defaults.lr_sh_dc, "learning rate of the SH DC coefficients")->capture_default_str();
  sub->add_option("--lr-sh-rest", opt->defaults.lr_sh_rest, "learning rate of the higher SH bands (0 = view-independent refinement)")
      ->capture_default_str();
  sub->add_option("--lr-opacity", opt->defaults.lr_opacity, "learning rate of the opacity logits")->capture_default_str();
  sub->add_option("--lr-alpha", opt->defaults.lr_alpha, "learning rate of the alpha maps (with --train-alpha)")->capture_default_str();
  sub->add_option("--lambda-dssim", opt->defaults.lambda_dssim, "loss (1 - lambda) L1 + lambda D-SSIM")->capture_default_str();
  sub->add_option("--overlap-anchor", opt->overlap_anchor, "weight of the previous clip's render on shared frames, [0, 1)")
      ->capture_default_str();
  sub->add_option("--editor-cmd", opt->editor_cmd,
                  "recursive refinement with an external editor: program and arguments ({input} {output} {phase} {phases})");
  sub->add_option("--phases", opt->phases, "phases of recursive refinement (N_r)")->capture_default_str();
  sub->add_option("--editor-timeout", opt->editor_timeout, "seconds allowed per editor call (0 = none)")->capture_default_str();
  sub->add_option("--flow-forward", opt->flow_forward, "folder of .flo files, source t -> t+1 (default: built-in estimator)");
  sub->add_option("--flow-backward", opt->flow_backward, "folder of .flo files, source t+1 -> t");
  sub->add_option("--threads", opt->threads, "worker threads (0 = all cores)")->capture_default_str();
  sub->add_option("--seed", opt->seed, "seed of the frame order")->capture_default_str();

  on_run(sub, [opt] {
    namespace fs = std::filesystem;
    const auto t0 = std::chrono::steady_clock::now();
    if (opt->edited.empty() && opt->editor_cmd.empty())
      throw option_error("option.refine", "--edited", "give at least one --edited folder or an --editor-cmd");
    if (opt->flow_forward.empty() != opt->flow_backward.empty())
      throw option_error("option.warp_ssim", "--flow-forward", "give both --flow-forward and --flow-backward, or neither");
    RefineOptions ro = opt->defaults;
    ro.iterations = opt->iterations;
    ro.train_opacity = !opt->freeze_opacity;
    ro.train_alpha = opt->train_alpha;
    ro.overlap_anchor = opt->overlap_anchor;
    ro.seed = opt->seed;
    ro.validate();
    if (!opt->editor_cmd.empty() && opt->phases < 1) throw option_error("option.refine", "--phases", "must be >= 1");

    ThreadPool pool(opt->threads);
    fs::path model_dir = opt->model;
    std::error_code ec;
    if (!fs::exists(model_dir / kVideoModelManifest, ec) && fs::exists(model_dir / "model" / kVideoModelManifest, ec)) model_dir /= "model";
    const VideoModel<float> model = load_video_model<float>(model_dir);
    const int n = model.frame_count, w = model.width, h = model.height;
    const auto source = detail::read_video_at(opt->source, w, h, n, &pool);
    // Every input is read and checked before anything is written.
    std::vector<std::vector<Image<float, 3>>> edits;
    std::vector<std::string> edit_names;
    if (opt->editor_cmd.empty())
      for (const auto& d : opt->edited) {
        edits.push_back(detail::read_video_at(d, w, h, n, &pool));
        edit_names.push_back(d);
      }
    const fs::path out = opt->out;
    if (fs::exists(out, ec) && !fs::is_directory(out, ec)) throw io_error("io.not_a_folder", out.string(), "--out must be a folder");
    const metrics::VideoFlows flows = opt->flow_forward.empty() ? metrics::estimate_video_flows(source, {}, &pool)
                                                                : metrics::read_video_flows(opt->flow_forward, opt->flow_backward);
    const double w_src = metrics::warp_ssim(source, flows, {}, &pool).value;  // also checks the flows' count and size
    fs::create_directories(out / "refined", ec);
    fs::create_directories(out / "compare", ec);
    if (ec) throw io_error("io.unwritable", out.string(), "cannot create folder: " + ec.message());

    VideoModel<float> refined;
    RefineStats stats;
    nlohmann::json phases = nlohmann::json::array();
    if (!opt->editor_cmd.empty()) {
      CommandEditor editor;
      editor.command = split_command_line(opt->editor_cmd);
      editor.work_dir = out / "editor";
      editor.timeout_seconds = opt->editor_timeout;
      RecursiveRefineOptions rr;
      rr.phases = opt->phases;
      rr.refine = ro;
      auto r = refine_recursive(model, source, editor, rr, &pool);
      for (int p = 0; p < opt->phases; ++p)
        phases.push_back({{"phase", p},
                          {"warp_ssim_edited", detail::json_number(metrics::warp_ssim(r.edited[std::size_t(p)], flows, {}, &pool).value)},
                          {"warp_ssim_refined", detail::json_number(metrics::warp_ssim(r.refined[std::size_t(p)], flows, {}, &pool).value)}});
      edits.push_back(std::move(r.edited.front()));
      edit_names.push_back((editor.work_dir / "phase_0" / "output").string());
      refined = std::move(r.model);
      stats = std::move(r.stats.back());
    } else {
      refined = refine_video(model, edits, ro, &pool, &stats);
    }
    const auto frames = render_video(refined, &pool);
    for (int f = 0; f < n; ++f) {
      char name[32];
      std::snprintf(name, sizeof(name), "%05d.png", f);
      io::write_png(out / "refined" / name, frames[std::size_t(f)]);
      io::write_png(out / "compare" / name,
                    pipeline::side_by_side({&source[std::size_t(f)], &edits.front()[std::size_t(f)], &frames[std::size_t(f)]}));
    }
    save_video_model(out / "model", refined);

    const double w_ref = metrics::warp_ssim(frames, flows, {}, &pool).value;
    double w_edit = 0, p_ref = 0;
    nlohmann::json per_edit = nlohmann::json::array();
    for (std::size_t e = 0; e < edits.size(); ++e) {
      const double we = metrics::warp_ssim(edits[e], flows, {}, &pool).value;
      const double pe = detail::mean_psnr(frames, edits[e]);
      w_edit += we / double(edits.size());
      p_ref += pe / double(edits.size());
      per_edit.push_back({{"dir", edit_names[e]}, {"warp_ssim", detail::json_number(we)}, {"psnr_refined_vs_edited", detail::json_number(pe)}});
    }
    nlohmann::json clips = nlohmann::json::array();
    for (const auto& c : stats.clips)
      clips.push_back({{"iterations", c.iterations}, {"skipped_steps", c.skipped_steps}, {"first_loss", detail::json_number(c.first_loss)},
                       {"last_loss", detail::json_number(c.last_loss)}, {"seconds", c.seconds}});
    nlohmann::json report;
    report["warp_ssim_edited"] = detail::json_number(w_edit);
    report["warp_ssim_refined"] = detail::json_number(w_ref);
    report["psnr_refined_vs_edited"] = detail::json_number(p_ref);
    report["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    report["warp_ssim_source"] = detail::json_number(w_src);
    report["warp_ssim_gain_percent"] = detail::json_number(100.0 * (w_ref - w_edit) / w_edit);
    report["frames"] = n;
    report["width"] = w;
    report["height"] = h;
    report["iterations"] = opt->iterations;
    report["options"] = {{"train_alpha", ro.train_alpha}, {"train_opacity", ro.train_opacity}, {"lr_sh_dc", ro.lr_sh_dc},
                         {"lr_sh_rest", ro.lr_sh_rest}, {"lr_opacity", ro.lr_opacity}, {"lr_alpha", ro.lr_alpha},
                         {"lambda_dssim", ro.lambda_dssim}, {"overlap_anchor", ro.overlap_anchor}};
    report["edits"] = per_edit;
    report["clips"] = clips;
    if (!phases.empty()) report["phases"] = phases;
    io::write_file_atomic(out / "report.json", report.dump(1) + "\n");
    std::cout << report.dump() << std::endl;
  });
}

}  // namespace video3dgs::cli
