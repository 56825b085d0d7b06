// `video3dgs refine`: stage 2, temporal-consistency refinement of an edited video; the job is
// pipeline::refine_edited_video (include/video3dgs/pipeline/refine.hpp, which describes the outputs and
// report.json), this file maps flags to its options.
//
//   video3dgs refine --model OUT --source DIR --edited DIR [--edited DIR2 ...] --out DIR
//                    [--iterations N] [--train-alpha] [--freeze-opacity] [--lr-sh-dc X] [--lr-sh-rest X]
//                    [--lr-opacity X] [--lr-alpha X] [--lambda-dssim X]
//                    [--editor-cmd "prog args {input} {output}" --phases 2]
//
// --editor-cmd is an argument vector split like a shell would split words, but never run by a shell.
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "video3dgs/core/parallel.hpp"
#include "video3dgs/pipeline/refine.hpp"

namespace video3dgs::cli {

inline void add_refine_command(CLI::App& app) {
  struct Options {
    pipeline::RefineJobOptions job;
    std::string editor_cmd;
    bool freeze_opacity = false;
    unsigned threads = 0;
  };
  auto opt = std::make_shared<Options>();
  pipeline::RefineJobOptions& job = opt->job;
  RefineOptions& ro = job.refine;
  CLI::App* sub = app.add_subcommand("refine", "stage 2: refine an edited video with the reconstructed source (temporal consistency)");
  sub->add_option("--model", job.model, "reconstruction folder of the source video (or its model/ folder)")->required();
  sub->add_option("--source", job.source, "frames of the source video")->required();
  sub->add_option("--edited", job.edited, "frames of an edited video (repeat for an ensemble)");
  sub->add_option("--out", job.out, "output folder")->required();
  sub->add_option("--iterations", ro.iterations, "iterations per clip (and per phase)")->capture_default_str();
  sub->add_flag("--train-alpha", ro.train_alpha, "also fine-tune the per-frame alpha maps");
  sub->add_flag("--freeze-opacity", opt->freeze_opacity, "fine-tune colours only (opacity logits stay as in the model)");
  sub->add_option("--lr-sh-dc", ro.lr_sh_dc, "learning rate of the SH DC coefficients")->capture_default_str();
  sub->add_option("--lr-sh-rest", ro.lr_sh_rest, "learning rate of the higher SH bands (0 = view-independent refinement)")
      ->capture_default_str();
  sub->add_option("--lr-opacity", ro.lr_opacity, "learning rate of the opacity logits")->capture_default_str();
  sub->add_option("--lr-alpha", ro.lr_alpha, "learning rate of the alpha maps (with --train-alpha)")->capture_default_str();
  sub->add_option("--lambda-dssim", ro.lambda_dssim, "loss (1 - lambda) L1 + lambda D-SSIM")->capture_default_str();
  sub->add_option("--overlap-anchor", ro.overlap_anchor, "weight of the previous clip's render on shared frames, [0, 1)")
      ->capture_default_str();
  sub->add_option("--editor-cmd", opt->editor_cmd,
                  "recursive refinement with an external editor: program and arguments ({input} {output} {phase} {phases})");
  sub->add_option("--phases", job.phases, "phases of recursive refinement (N_r)")->capture_default_str();
  sub->add_option("--editor-timeout", job.editor_timeout, "seconds allowed per editor call (0 = none)")->capture_default_str();
  sub->add_option("--flow-forward", job.flow_forward, "folder of .flo files, source t -> t+1 (default: built-in estimator)");
  sub->add_option("--flow-backward", job.flow_backward, "folder of .flo files, source t+1 -> t");
  sub->add_option("--threads", opt->threads, "worker threads (0 = all cores)")->capture_default_str();
  sub->add_option("--seed", ro.seed, "seed of the frame order")->capture_default_str();

  sub->callback([opt] {
    pipeline::RefineJobOptions& job = opt->job;
    job.refine.train_opacity = !opt->freeze_opacity;
    if (!opt->editor_cmd.empty()) job.editor_command = split_command_line(opt->editor_cmd);
    ThreadPool pool(opt->threads);
    auto input = pipeline::prepare_refine_input(job, &pool);
    const auto report = pipeline::refine_edited_video(job, input, &pool);
    std::cout << report.json() << std::endl;
  });
}

}  // namespace video3dgs::cli
