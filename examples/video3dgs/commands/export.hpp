#pragma once
// `video3dgs export --model DIR --frame F --out FILE.ply [--set all|frg|bkg]`
// Writes the Gaussians of video frame F of a saved VideoModel (reconstruct's model/ folder) as a
// standard 3DGS PLY: the clip with the largest blend weight at F (model/video_model.hpp), its sets
// deformed to F; `all` (default) concatenates foreground and background. Prints one JSON line.
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "video3dgs/core/error.hpp"
#include "video3dgs/io/ply.hpp"
#include "video3dgs/model/video_model.hpp"

namespace video3dgs::cli {

inline void add_export_command(CLI::App& app) {
  struct Options {
    std::filesystem::path model, out;
    int frame = 0;
    std::string set = "all";
  };
  auto o = std::make_shared<Options>();
  CLI::App* sub = app.add_subcommand("export", "write the Gaussians of one frame of a saved video model as a 3DGS PLY");
  sub->add_option("--model", o->model, "video model folder (with manifest.txt)")->required();
  sub->add_option("--frame", o->frame, "video frame (0-based)")->required();
  sub->add_option("--out", o->out, "PLY file to write")->required();
  sub->add_option("--set", o->set, "all, frg or bkg")->capture_default_str();
  sub->callback([o] {
    if (o->set != "all" && o->set != "frg" && o->set != "bkg") throw option_error("option.set", "--set", "must be all, frg or bkg");
    std::error_code ec;
    if (std::filesystem::is_directory(o->out, ec)) throw io_error("io.unwritable", o->out.string(), "is a folder; give a .ply file name");
    const auto video = load_video_model<float>(o->model);
    if (o->frame < 0 || o->frame >= video.frame_count)
      throw option_error("option.frame", "--frame", std::to_string(o->frame) + " is outside the model's " + std::to_string(video.frame_count) + " frames");
    GaussianCloud<float, 3> cloud;
    if (o->set != "bkg") cloud = video.frame_gaussians(o->frame, GaussianSet::foreground);
    if (o->set != "frg") {
      const auto bkg = video.frame_gaussians(o->frame, GaussianSet::background);
      for (std::size_t i = 0; i < bkg.size(); ++i) cloud.push_back(bkg.get(i));
    }
    io::write_ply(o->out, cloud);
    nlohmann::json j;
    j["out"] = o->out.string();
    j["frame"] = o->frame;
    j["clip"] = video.main_clip(o->frame);
    j["gaussians"] = cloud.size();
    std::cout << j.dump() << std::endl;
  });
}

}  // namespace video3dgs::cli
