#pragma once
// `video3dgs metrics A B [--per-frame] [--threads N]`: PSNR (data range 1, dB) and SSIM (11x11 Gaussian
// window, sigma 1.5) between two images or two frame folders (paired in natural order), printed as one
// JSON line:
//   {"frames":50,"psnr":31.2,"ssim":0.93}
// and with --per-frame also "per_frame":[{"a":"00000.jpg","b":"00000.jpg","psnr":...,"ssim":...},...].
// PSNR of identical images is infinite and printed as null. Folder summaries are per-frame means.
// With `--warp-ssim --source S` (folders only) it adds "warp_ssim_a" and "warp_ssim_b": the WarpSSIM of
// each video through the optical flow of the source video S (built-in estimator, or the Middlebury
// .flo files of --flow-forward / --flow-backward), see video3dgs/metrics/warp_ssim.hpp.
#include <cmath>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>
#include <system_error>
#include <utility>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/io/frame_folder.hpp"
#include "video3dgs/metrics/files.hpp"
#include "video3dgs/metrics/warp_ssim.hpp"

namespace video3dgs::cli {

namespace detail {
inline nlohmann::json finite_or_null(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }
}  // namespace detail

inline void add_metrics_command(CLI::App& app) {
  struct Options {
    std::string a, b;
    bool per_frame = false;
    unsigned threads = 0;
    bool warp_ssim = false;
    std::string source, flow_forward, flow_backward;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* sub = app.add_subcommand("metrics", "PSNR and SSIM between two images or two frame folders (one JSON line)");
  sub->add_option("A", opt->a, "first image or frame folder (e.g. the original video)")->required();
  sub->add_option("B", opt->b, "second image or frame folder (e.g. the render or the edited video)")->required();
  sub->add_flag("--per-frame", opt->per_frame, "also print the values of every frame");
  sub->add_option("--threads", opt->threads, "worker threads (0 = all cores)")->capture_default_str();
  sub->add_flag("--warp-ssim", opt->warp_ssim, "also report the WarpSSIM of A and B (needs --source; folders only)");
  sub->add_option("--source", opt->source, "source video frames whose optical flow WarpSSIM uses");
  sub->add_option("--flow-forward", opt->flow_forward, "folder of .flo files, source frame t -> t+1 (instead of the built-in estimator)");
  sub->add_option("--flow-backward", opt->flow_backward, "folder of .flo files, source frame t+1 -> t");

  sub->callback([opt] {
    namespace fs = std::filesystem;
    const fs::path a = opt->a, b = opt->b;
    std::error_code ec;
    for (const fs::path& p : {a, b})
      if (!fs::exists(p, ec)) throw io_error("io.missing", p.string(), "no such file or folder");
    const bool a_dir = fs::is_directory(a, ec), b_dir = fs::is_directory(b, ec);
    if (a_dir != b_dir)
      throw option_error("option.mismatch", a_dir ? b.string() : a.string(),
                         "compare two images or two folders, not an image with a folder");
    if (opt->warp_ssim && (opt->source.empty() || !a_dir))
      throw option_error("option.warp_ssim", "--warp-ssim", "needs --source DIR and two frame folders");
    if (opt->flow_forward.empty() != opt->flow_backward.empty())
      throw option_error("option.warp_ssim", "--flow-forward", "give both --flow-forward and --flow-backward, or neither");
    ThreadPool pool(opt->threads);
    metrics::SequenceMetrics m;
    if (a_dir) {
      m = metrics::compare_frame_folders(a, b, &pool);
    } else {
      m.a = {a};
      m.b = {b};
      m.per_frame = {metrics::compare_image_files(a, b, &pool)};  // one pair: parallel inside SSIM
      m.psnr = m.per_frame[0].psnr;
      m.ssim = m.per_frame[0].ssim;
    }
    nlohmann::json out;
    out["psnr"] = detail::finite_or_null(m.psnr);
    out["ssim"] = m.ssim;
    out["frames"] = m.frames();
    if (opt->warp_ssim) {
      const auto src = io::read_frames(io::list_frames(opt->source), &pool);
      const metrics::VideoFlows flows = opt->flow_forward.empty() ? metrics::estimate_video_flows(src, {}, &pool)
                                                                  : metrics::read_video_flows(opt->flow_forward, opt->flow_backward);
      for (const auto& [key, dir] : {std::pair<const char*, fs::path>{"warp_ssim_a", a}, {"warp_ssim_b", b}}) {
        const auto frames = io::read_frames(io::list_frames(dir), &pool);
        if (frames.size() != src.size())
          throw io_error("io.count_mismatch", dir.string(),
                         "holds " + std::to_string(frames.size()) + " frames but the source holds " + std::to_string(src.size()));
        if (frames[0].width() != src[0].width() || frames[0].height() != src[0].height())
          throw io_error("io.size_mismatch", dir.string(), "frames differ in size from the source's");
        out[key] = detail::finite_or_null(metrics::warp_ssim(frames, flows, {}, &pool).value);
      }
    }
    if (opt->per_frame) {
      nlohmann::json frames = nlohmann::json::array();
      for (std::size_t i = 0; i < m.frames(); ++i)
        frames.push_back({{"a", m.a[i].filename().string()},
                          {"b", m.b[i].filename().string()},
                          {"psnr", detail::finite_or_null(m.per_frame[i].psnr)},
                          {"ssim", m.per_frame[i].ssim}});
      out["per_frame"] = std::move(frames);
    }
    std::cout << out.dump() << std::endl;
  });
}

}  // namespace video3dgs::cli
