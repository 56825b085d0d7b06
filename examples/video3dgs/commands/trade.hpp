#pragma once
// `video3dgs trade --frames DIR [--masks DIR] --sparse DIR [--first A --last B] --out DIR [--scale F]
//                  [--preset P] [--iterations N,N,...] [--resolution-schedule S;S;...] [--budget G,G,...]
//                  [--log2-table N,N,...] [--grid-levels L,L,...] [--alpha-downscale D,D,...]
//                  [--presets P,P,...] [--seed S] [--shell-points N] [--static-background] [--alpha-mask A] [--keep-unseen]
//                  [--bkg-colour random|frames] [--threads T] [--gnuplot PROG] [--no-resume] [--include-stored]`
// The speed/accuracy/size trade of stage 1 on one clip (pipeline/trade.hpp): every combination of the
// listed values (an axis not given keeps the preset's value), plus each of --presets as is, trained on
// the clip's frames with the cameras of a finished COLMAP model (--sparse: `video3dgs sfm`'s
// clip_NNN/sparse/0, or reconstruct's OUT/sfm/frames_A_B/model), so SfM is not run again. Writes
//   OUT/runs/<hash>.json   one result per configuration (a re-run reuses them: resumable)
//   OUT/trade.csv, OUT/trade.json    every configuration's settings and figures, frontier flags
//   OUT/trade_time.png     PSNR against CPU seconds of training, the Pareto frontier marked
//   OUT/trade_bytes.png    the compact file's PSNR against its megabytes, its frontier marked
//   (OUT/*.png.dat: the plotted points, for other tools)
// and prints trade.json's configurations as one JSON line each. --include-stored adds every result that
// earlier sweeps left in OUT/runs/ to the tables and plots (a grid grown in steps). A bar (or, without a terminal, a line
// per tenth) shows the configuration and iteration being trained. --static-background, --alpha-mask,
// --bkg-colour and --keep-unseen start every configuration's model as `reconstruct`'s flags of those names do.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include <unistd.h>

#include <CLI/CLI.hpp>

#include "commands/model_options.hpp"
#include "video3dgs/colmap/clip_input.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/pipeline/trade.hpp"

namespace video3dgs::cli {

struct TradeCommandOptions {
  std::filesystem::path frames, masks, sparse, out;
  int first = 0, last = -1;
  double scale = 1.0;
  pipeline::TradeAxes axes;
  std::vector<std::string> resolutions;
  std::uint64_t seed = 0;
  std::size_t shell_points = 30000;
  ClipModelOptions model = recommended_model_options();  ///< every configuration's start: reconstruct's default, then the flags
  unsigned threads = 0;
  std::filesystem::path gnuplot = "gnuplot";
  bool no_resume = false;
  bool include_stored = false;
};

inline void run_trade_command(TradeCommandOptions o) {
  for (const auto& text : o.resolutions) o.axes.resolutions.push_back(TrainOptions::parse_resolution_schedule(text));
  const auto configs = pipeline::trade_grid(o.axes);
  pipeline::TradeOptions to;
  to.out = o.out, to.seed = o.seed, to.shell_points = o.shell_points, to.resume = !o.no_resume;
  to.static_background = o.model.static_background;
  to.alpha_mask = o.model.alpha_mask, to.alpha_outside = o.model.alpha_outside;
  to.background_colour = o.model.background_colour;
  to.cull_unseen = o.model.cull_unseen;
  for (const auto& c : configs) (void)c.train_options(o.seed);  // bad settings fail before the frames are read
  ThreadPool pool(o.threads);
  ThreadPool* p = pool.size() > 1 ? &pool : nullptr;
  auto in = colmap::load_clip_input(o.frames, o.masks, o.sparse, FrameRange{o.first, o.last}, o.scale, p);
  pipeline::TradeClip clip{std::move(in.sfm), std::move(in.frames), std::move(in.masks)};
  const bool tty = ::isatty(2) == 1;
  const auto t0 = std::chrono::steady_clock::now();
  auto last = t0;
  auto progress = [&](const pipeline::TradeProgress& e) {
    const double frac = (double(e.config) + double(e.iteration) / std::max(1, e.iterations)) / double(std::max<std::size_t>(e.configs, 1));
    char msg[160];
    std::snprintf(msg, sizeof(msg), "configuration %zu/%zu  it %d/%d  psnr %.2f dB", e.config + 1, e.configs, e.iteration, e.iterations, e.psnr);
    const auto now = std::chrono::steady_clock::now();
    if (tty) {
      if (std::chrono::duration<double>(now - last).count() < 0.2 && e.iteration != e.iterations) return;
      last = now;
      const int w = 30, k = static_cast<int>(std::clamp(frac, 0.0, 1.0) * w);
      std::fprintf(stderr, "\r[%.*s%.*s] %3d%%  %s\033[K", k, "##############################", w - k, "------------------------------",
                   static_cast<int>(frac * 100), msg);
      if (e.iteration == e.iterations) std::fputc('\n', stderr);
    } else if (e.iteration == e.iterations || e.iteration % std::max(1, e.iterations / 10) == 0) {
      std::fprintf(stderr, "[trade] %s\n", msg);
    }
  };
  auto results = pipeline::run_trade(configs, clip, to, progress, p);
  if (o.include_stored) results = pipeline::with_stored_results(std::move(results), o.out, pipeline::trade_run_key(clip, to));
  const bool plotted = pipeline::write_trade_outputs(o.out, results, o.gnuplot);
  if (!plotted) std::fprintf(stderr, "[trade] gnuplot is missing or failed: trade.csv and trade.json written, no plots\n");
  for (const auto& r : results) {
    auto j = r.to_json();
    j["reused"] = r.reused;
    std::cout << j.dump() << std::endl;
  }
}

inline void add_trade_command(CLI::App& app) {
  auto o = std::make_shared<TradeCommandOptions>();
  CLI::App* sub = app.add_subcommand("trade", "train one clip under a grid of configurations and plot PSNR against time and bytes (Pareto frontiers)");
  sub->add_option("--frames", o->frames, "folder of the video's frames (natural order)")->required();
  sub->add_option("--masks", o->masks, "foreground masks matched by file stem");
  sub->add_option("--sparse", o->sparse, "a COLMAP model registering every frame of the clip (sfm's clip_NNN/sparse/0, reconstruct's sfm/frames_A_B/model)")
      ->required();
  sub->add_option("--out", o->out, "output folder")->required();
  sub->add_option("--first", o->first, "first frame of the clip")->capture_default_str();
  sub->add_option("--last", o->last, "last frame of the clip (-1: the folder's last)")->capture_default_str();
  sub->add_option("--scale", o->scale, "train at this fraction of the frame size, (0, 1]")->capture_default_str();
  sub->add_option("--preset", o->axes.preset, "the preset every grid configuration starts from")->capture_default_str();
  sub->add_option("--iterations", o->axes.iterations, "axis: iterations (the preset's schedules scaled), comma-separated")->delimiter(',');
  sub->add_option("--resolution-schedule", o->resolutions,
                  "axis: coarse-to-fine schedules K:S,K:S,... in the preset's iterations, separated by ';' (0:1 = full size throughout)")
      ->delimiter(';');
  sub->add_option("--budget", o->axes.budgets, "axis: Gaussians per frame pixel (0 = no budget), comma-separated")->delimiter(',');
  sub->add_option("--log2-table", o->axes.log2_tables, "axis: hash-table entries per level 2^N of both fields, comma-separated")->delimiter(',');
  sub->add_option("--grid-levels", o->axes.grid_levels, "axis: hash-grid levels of both fields (1-16, same resolutions), comma-separated")
      ->delimiter(',');
  sub->add_option("--alpha-downscale", o->axes.alpha_downscales, "axis: the compact file's alpha-map downscale, comma-separated")->delimiter(',');
  sub->add_option("--presets", o->axes.presets, "also train these presets as they are, labelled in the plots, comma-separated")->delimiter(',');
  sub->add_option("--seed", o->seed, "seed")->capture_default_str();
  sub->add_option("--shell-points", o->shell_points, "background points per shell (2 shells; those no clip camera sees are then dropped, unless --keep-unseen)")->capture_default_str();
  add_model_start_options(sub, o->model);
  sub->add_option("--threads", o->threads, "worker threads (0 = all cores)")->capture_default_str();
  sub->add_option("--gnuplot", o->gnuplot, "the gnuplot program (without it: no plots)")->capture_default_str();
  sub->add_flag("--no-resume", o->no_resume, "train every configuration again instead of reusing OUT/runs/");
  sub->add_flag("--include-stored", o->include_stored,
                "the tables and plots also show every result earlier sweeps stored in OUT/runs/ (a sweep grown in steps)");
  sub->callback([o] { run_trade_command(*o); });
}

}  // namespace video3dgs::cli
