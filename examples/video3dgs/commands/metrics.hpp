#pragma once
// `video3dgs metrics A B [--per-frame] [--threads N]`: PSNR (data range 1, dB) and SSIM (11x11 Gaussian
// window, sigma 1.5) between two images or two frame folders (paired in natural order), printed as one
// JSON line:
//   {"frames":50,"psnr":31.2,"ssim":0.93}
// and with --per-frame also "per_frame":[{"a":"00000.jpg","b":"00000.jpg","psnr":...,"ssim":...},...].
// PSNR of identical images is infinite and printed as null. Folder summaries are per-frame means.
#include <cmath>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>
#include <system_error>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "commands/common.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/metrics/files.hpp"

namespace video3dgs::cli {

namespace detail {
inline nlohmann::json finite_or_null(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }
}  // namespace detail

inline void add_metrics_command(CLI::App& app) {
  struct Options {
    std::string a, b;
    bool per_frame = false;
    unsigned threads = 0;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* sub = app.add_subcommand("metrics", "PSNR and SSIM between two images or two frame folders (one JSON line)");
  sub->add_option("A", opt->a, "first image or frame folder (e.g. the original video)")->required();
  sub->add_option("B", opt->b, "second image or frame folder (e.g. the render or the edited video)")->required();
  sub->add_flag("--per-frame", opt->per_frame, "also print the values of every frame");
  sub->add_option("--threads", opt->threads, "worker threads (0 = all cores)")->capture_default_str();

  on_run(sub, [opt] {
    namespace fs = std::filesystem;
    const fs::path a = opt->a, b = opt->b;
    std::error_code ec;
    for (const fs::path& p : {a, b})
      if (!fs::exists(p, ec)) throw io_error("io.missing", p.string(), "no such file or folder");
    const bool a_dir = fs::is_directory(a, ec), b_dir = fs::is_directory(b, ec);
    if (a_dir != b_dir)
      throw option_error("option.mismatch", a_dir ? b.string() : a.string(),
                         "compare two images or two folders, not an image with a folder");
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
