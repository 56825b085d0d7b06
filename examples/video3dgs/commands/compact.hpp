#pragma once
// `video3dgs compact --model DIR [--out DIR] [--preset NAME] [--codebook K] [--alpha-downscale D] [--alpha-tolerance T] [--field-bits B]
//                    [--scale-bits B] [--position-bits B] [--frg-position-bits B] [--dc-bits B] [--threads N]`
// Writes the compact file (model/compact_io.hpp) of every clip of a saved video model (reconstruct's
// model/ folder), or of one clip model file (save_clip_model's, e.g. `bench_train_clip --save`), as
// <clip file stem>.compact beside it, or into --out. For each clip, prints one JSON
// line: the file's bytes per part and in total, the full record's bytes, the raw frames' bytes
// (W x H x 3 x frames), and the PSNR between renders of the original and of the reloaded compact model
// at full size (mean and minimum over the clip's frames; null where they are identical). --preset
// starts from CompactOptions::preset(NAME); the settings given as flags replace the preset's. With
// --frames (the source frames, natural order, frame f of the video = the f-th file), also the PSNR of
// each model's renders against the frames: `psnr_source` {"model", "compact", "loss"} (means over the
// clip's frames; loss = model - compact, in dB).
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
#include "video3dgs/core/resample.hpp"
#include "video3dgs/io/frame_folder.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/metrics/psnr.hpp"
#include "video3dgs/model/compact_io.hpp"
#include "video3dgs/model/render_clip.hpp"
#include "video3dgs/model/video_model.hpp"

namespace video3dgs::cli {

inline void add_compact_command(CLI::App& app) {
  struct Options {
    std::filesystem::path model, out, frames;
    CompactOptions compact;
    std::string preset = "default";
    unsigned threads = 0;
  };
  auto o = std::make_shared<Options>();
  CLI::App* sub = app.add_subcommand("compact", "write a compact file per clip of a saved video model and report its size and PSNR");
  sub->add_option("--model", o->model, "video model folder (with manifest.txt), or one clip model file")->required();
  sub->add_option("--out", o->out, "folder for the .compact files (default: the model folder)");
  sub->add_option("--frames", o->frames, "source frames: also report each model's PSNR against them (resized to the model's size)");
  sub->add_option("--preset", o->preset, "named settings, default or small (5-bit hash tables, 16 SH codewords, 16-bit foreground positions); flags below replace its values")
      ->capture_default_str();
  sub->add_option("--codebook", o->compact.sh_codebook, "SH rest codewords per set (1..65536)")->capture_default_str();
  sub->add_option("--alpha-downscale", o->compact.alpha_downscale, "alpha maps stored at 1/D of the size (1..16)")->capture_default_str();
  sub->add_option("--alpha-tolerance", o->compact.alpha_tolerance,
                  "full-size alpha maps: codes may move the merged render by this much (colour units 0..1) where that stores smaller; 0: nearest codes")
      ->capture_default_str();
  sub->add_option("--field-bits", o->compact.field_bits, "bits per hash-table value (2..8 or 16)")->capture_default_str();
  sub->add_option("--scale-bits", o->compact.scale_bits, "bits per log-scale (8 or 16)")->capture_default_str();
  sub->add_option("--position-bits", o->compact.position_bits, "bits per background position coordinate (8, 16 or 24)")->capture_default_str();
  sub->add_option("--frg-position-bits", o->compact.frg_position_bits, "bits per foreground position coordinate (8, 16 or 24)")
      ->capture_default_str();
  sub->add_option("--dc-bits", o->compact.dc_bits, "bits per SH DC value (8 or 16)")->capture_default_str();
  sub->add_option("--threads", o->threads, "worker threads (0 = all cores)")->capture_default_str();
  sub->callback([o, sub] {
    namespace fs = std::filesystem;
    // The preset, then every setting given as a flag.
    const CompactOptions given = o->compact;
    o->compact = CompactOptions::preset(o->preset);
    const auto set = [&](const char* flag, auto member) {
      if (sub->count(flag) > 0) o->compact.*member = given.*member;
    };
    set("--codebook", &CompactOptions::sh_codebook);
    set("--alpha-downscale", &CompactOptions::alpha_downscale);
    set("--alpha-tolerance", &CompactOptions::alpha_tolerance);
    set("--field-bits", &CompactOptions::field_bits);
    set("--scale-bits", &CompactOptions::scale_bits);
    set("--position-bits", &CompactOptions::position_bits);
    set("--frg-position-bits", &CompactOptions::frg_position_bits);
    set("--dc-bits", &CompactOptions::dc_bits);
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
    const io::FrameList sources = o->frames.empty() ? io::FrameList{} : io::list_frames(o->frames);
    for (std::size_t c = 0; c < files.size(); ++c) {
      const auto t0 = std::chrono::steady_clock::now();
      const fs::path& file = files[c];
      auto model = load_clip_model<float>(file);
      const fs::path target = out / (file.stem().string() + ".compact");
      const CompactSizes sizes = save_compact_clip_model(target, model, o->compact, &pool);
      const double save_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const auto back = load_compact_clip_model<float>(target);
      ClipRenderBuffers<float, DefaultDeformationField<float>> a, b;
      double sum = 0, worst = std::numeric_limits<double>::infinity(), src_model = 0, src_compact = 0;
      for (int i = 0; i < model.frame_count(); ++i) {
        render_clip_frame(model, i, a, &pool);
        render_clip_frame(back, i, b, &pool);
        const double p = metrics::psnr<float, 3>(a.merged, b.merged, &pool);
        sum += p;
        worst = std::min(worst, p);
        if (!o->frames.empty()) {
          const std::size_t f = std::size_t(model.range.first + i);
          if (f >= sources.size())
            throw io_error("io.count_mismatch", o->frames.string(), "no frame " + std::to_string(f) + " for the clip's frames " +
                                                                         std::to_string(model.range.first) + "-" + std::to_string(model.range.last));
          Image<float, 3> src = io::read_image<3>(sources.frames[f]);
          if (src.width() != model.width() || src.height() != model.height()) src = resize_area(src, model.width(), model.height());
          src_model += metrics::psnr<float, 3>(a.merged, src, &pool);
          src_compact += metrics::psnr<float, 3>(b.merged, src, &pool);
        }
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
      if (!o->frames.empty()) {
        const double n = std::max(model.frame_count(), 1);
        j["psnr_source"] = {{"model", src_model / n}, {"compact", src_compact / n}, {"loss", (src_model - src_compact) / n}};
      }
      j["save_seconds"] = save_seconds;
      j["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      std::cout << j.dump() << std::endl;
    }
  });
}

}  // namespace video3dgs::cli
