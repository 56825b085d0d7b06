#pragma once
// `video3dgs render-video --model DIR --out DIR [--frames DIR] [--threads N]`
// Re-renders every frame of a saved VideoModel (the model/ folder of `video3dgs reconstruct`; clip
// overlaps blended, model/video_model.hpp) into OUT/renders/00000.png ... With --frames (the source
// frames), also OUT/compare/ (source | render | error), OUT/metrics.csv and PSNR/SSIM means (frames are
// resized to the model's size). Prints one JSON line.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/io/frame_folder.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/loss/ssim.hpp"
#include "video3dgs/metrics/psnr.hpp"
#include "video3dgs/model/video_model.hpp"
#include "video3dgs/pipeline/outputs.hpp"

namespace video3dgs::cli {

inline void add_render_video_command(CLI::App& app) {
  struct Options {
    std::filesystem::path model, out, frames;
    unsigned threads = 0;
  };
  auto o = std::make_shared<Options>();
  CLI::App* sub = app.add_subcommand("render-video", "render every frame of a saved video model (reconstruct's model/ folder)");
  sub->add_option("--model", o->model, "video model folder (with manifest.txt)")->required();
  sub->add_option("--out", o->out, "output folder (renders/, and compare/ + metrics.csv with --frames)")->required();
  sub->add_option("--frames", o->frames, "source frames to compare against (optional)");
  sub->add_option("--threads", o->threads, "worker threads (0 = all cores)")->capture_default_str();
  sub->callback([o] {
    namespace fs = std::filesystem;
    std::error_code ec;
    if (fs::exists(o->out, ec) && !fs::is_directory(o->out, ec))
      throw io_error("io.not_a_folder", o->out.string(), "the output path exists and is not a folder");
    const auto t0 = std::chrono::steady_clock::now();
    ThreadPool pool(o->threads);
    // One clip at a time (two at an overlap): memory does not grow with the video's length.
    VideoModelFolder<float> video(o->model);
    io::FrameList list;
    if (!o->frames.empty()) {
      list = io::list_frames(o->frames);
      if (static_cast<int>(list.size()) != video.frame_count())
        throw io_error("io.count_mismatch", o->frames.string(),
                       std::to_string(list.size()) + " frames, the model has " + std::to_string(video.frame_count()));
    }
    fs::create_directories(o->out / "renders", ec);
    if (!o->frames.empty()) fs::create_directories(o->out / "compare", ec);
    if (ec) throw io_error("io.unwritable", o->out.string(), "cannot create folder: " + ec.message());
    VideoRenderBuffers<float> buf;
    loss::SsimContext<double, 3> sctx;
    std::string csv = "frame,psnr,ssim\n";
    double ps = 0, ss = 0;
    for (int f = 0; f < video.frame_count(); ++f) {
      char name[32];
      std::snprintf(name, sizeof(name), "%05d.png", f);
      const auto& img = video.render_frame(f, buf, &pool);
      io::write_png(o->out / "renders" / name, img);
      if (!o->frames.empty()) {
        const auto src = pipeline::resize_area(io::read_image<3>(list.frames[std::size_t(f)]), video.width(), video.height());
        const double p = metrics::psnr<float, 3>(img, src, &pool);
        const Image<double, 3> a = img.cast<double>(), b = src.cast<double>();
        const double s = loss::ssim_value<double, 3>(a.view(), b.view(), sctx, &pool);
        ps += std::isfinite(p) ? p : 100.0;
        ss += s;
        csv += std::to_string(f) + "," + std::to_string(p) + "," + std::to_string(s) + "\n";
        const auto heat = pipeline::error_heat_map(img, src);
        io::write_png(o->out / "compare" / name, pipeline::side_by_side({&src, &img, &heat}));
      }
    }
    nlohmann::json j;
    j["frames"] = video.frame_count();
    j["width"] = video.width();
    j["height"] = video.height();
    j["clips"] = video.clip_count();
    if (!o->frames.empty()) {
      io::write_file_atomic(o->out / "metrics.csv", csv);
      j["psnr"] = ps / video.frame_count();
      j["ssim"] = ss / video.frame_count();
    }
    j["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::cout << j.dump() << std::endl;
  });
}

}  // namespace video3dgs::cli
