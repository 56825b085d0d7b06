#pragma once
// `video3dgs compact --model DIR [--out DIR] [--codebook K] [--alpha-downscale D] [--field-bits B]
//                    [--scale-bits B] [--dc-bits B] [--threads N]`
// Writes the compact file (model/compact_io.hpp) of every clip of a saved video model (reconstruct's
// model/ folder), or of one clip model file (save_clip_model's, e.g. `bench_train_clip --save`), as
// <clip file stem>.compact beside it, or into --out. For each clip, prints one JSON
// line: the file's bytes per part and in total, the full record's bytes, the raw frames' bytes
// (W x H x 3 x frames), and the PSNR between renders of the original and of the reloaded compact model
// at full size (mean and minimum over the clip's frames; null where they are identical).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/metrics/psnr.hpp"
#include "video3dgs/model/compact_io.hpp"
#include "video3dgs/model/render_clip.hpp"
#include "video3dgs/model/video_model.hpp"

namespace video3dgs::cli {

inline void add_compact_command(CLI::App& app) {
  struct Options {
    std::filesystem::path model, out;
    CompactOptions compact;
    unsigned threads = 0;
  };
  auto o = std::make_shared<Options>();
  CLI::App* sub = app.add_subcommand("compact", "write a compact file per clip of a saved video model and report its size and PSNR");
  sub->add_option("--model", o->model, "video model folder (with manifest.txt), or one clip model file")->required();
  sub->add_option("--out", o->out, "folder for the .compact files (default: the model folder)");
  sub->add_option("--codebook", o->compact.sh_codebook, "SH rest codewords per set (1..65536)")->capture_default_str();
  sub->add_option("--alpha-downscale", o->compact.alpha_downscale, "alpha maps stored at 1/D of the size (1..16)")->capture_default_str();
  sub->add_option("--field-bits", o->compact.field_bits, "bits per hash-table value (8 or 16)")->capture_default_str();
  sub->add_option("--scale-bits", o->compact.scale_bits, "bits per log-scale (8 or 16)")->capture_default_str();
  sub->add_option("--dc-bits", o->compact.dc_bits, "bits per SH DC value (8 or 16)")->capture_default_str();
  sub->add_option("--threads", o->threads, "worker threads (0 = all cores)")->capture_default_str();
  sub->callback([o] {
    namespace fs = std::filesystem;
    o->compact.validate();
    // One clip file, or every clip of a video model folder.
    std::vector<fs::path> files;
    if (fs::is_regular_file(o->model)) {
      files.push_back(o->model);
    } else {
      for (const auto& f : read_video_manifest(o->model).files) files.push_back(o->model / f);
    }
    fs::path out = !o->out.empty() ? o->out : fs::is_regular_file(o->model) ? o->model.parent_path() : o->model;
    if (out.empty()) out = ".";
    std::error_code ec;
    fs::create_directories(out, ec);
    if (ec) throw io_error("io.unwritable", out.string(), "cannot create folder: " + ec.message());
    ThreadPool pool(o->threads);
    for (std::size_t c = 0; c < files.size(); ++c) {
      const auto t0 = std::chrono::steady_clock::now();
      const fs::path& file = files[c];
      auto model = load_clip_model<float>(file);
      const fs::path target = out / (file.stem().string() + ".compact");
      const CompactSizes sizes = save_compact_clip_model(target, model, o->compact, &pool);
      const double save_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const auto back = load_compact_clip_model<float>(target);
      ClipRenderBuffers<float, DefaultDeformationField<float>> a, b;
      double sum = 0, worst = std::numeric_limits<double>::infinity();
      for (int i = 0; i < model.frame_count(); ++i) {
        render_clip_frame(model, i, a, &pool);
        render_clip_frame(back, i, b, &pool);
        const double p = metrics::psnr<float, 3>(a.merged, b.merged, &pool);
        sum += p;
        worst = std::min(worst, p);
      }
      nlohmann::json j;
      j["clip"] = c;
      j["frames"] = model.frame_count();
      j["width"] = model.width();
      j["height"] = model.height();
      j["gaussians"] = {{"frg", model.frg.size()}, {"bkg", model.bkg.size()}};
      j["file"] = target.string();
      j["bytes"] = {{"gaussians", sizes.gaussians}, {"fields", sizes.fields}, {"alpha", sizes.alpha}, {"other", sizes.other},
                    {"total", sizes.total}};
      j["model_bytes"] = fs::file_size(file);
      j["raw_frame_bytes"] = std::uint64_t(model.width()) * std::uint64_t(model.height()) * 3u * std::uint64_t(model.frame_count());
      const double mean = sum / std::max(model.frame_count(), 1);
      j["psnr"] = std::isfinite(mean) ? nlohmann::json(mean) : nlohmann::json();
      j["psnr_min"] = std::isfinite(worst) ? nlohmann::json(worst) : nlohmann::json();
      j["save_seconds"] = save_seconds;
      j["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      std::cout << j.dump() << std::endl;
    }
  });
}

}  // namespace video3dgs::cli
