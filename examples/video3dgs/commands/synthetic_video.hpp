#pragma once
// `video3dgs synthetic-video --out DIR [--frames 30] [--width 192] [--height 144] [--seed 1]
//                            [--texture 4] [--sweep 0] [--threads N]`
// Writes a seeded synthetic video with exact foreground masks (video3dgs::synthetic::make_synthetic_clip:
// a textured sphere moving and spinning in front of a textured dome, camera on an arc) as
//   DIR/frames/00000.png ...   RGB frames
//   DIR/masks/00000.png ...    foreground masks (255 = object)
// so that the whole pipeline (`video3dgs reconstruct`, real COLMAP) can run on an input the project
// makes itself. `--texture` scales the texture frequency: real SIFT needs detail, so the default is
// finer than the generator's. `--sweep S` makes the camera and the object sweep back and forth every S
// frames instead of once over the whole video, so a long video moves as much per frame as a short one
// (SfM then sees the same parallax in every clip). Frames are written as they are rendered, never held
// together. Prints one JSON line (out, frames, width, height, mean mask area, the camera's focal length in
// pixels).
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/synthetic/clip.hpp"

namespace video3dgs::cli {

struct SyntheticVideoOptions {
  std::filesystem::path out;
  int frames = 30, width = 192, height = 144;
  unsigned long long seed = 1;
  double texture = 4.0;
  int sweep = 0;
  unsigned threads = 0;
};

/// The generator options the command uses (shared with tests and the benchmark).
[[nodiscard]] inline synthetic::SyntheticClipOptions synthetic_video_clip_options(const SyntheticVideoOptions& o) {
  synthetic::SyntheticClipOptions so;
  so.frames = o.frames;
  so.width = o.width;
  so.height = o.height;
  so.seed = o.seed;
  so.texture_frequency = o.texture;
  // A denser object and dome than the generator's defaults so that fine texture is resolved.
  so.object_gaussians = 6000;
  so.background_gaussians = 20000;
  so.motion = 0.5;
  so.spin_degrees = 25;
  so.arc_degrees = 24;
  so.sweep_frames = o.sweep;
  return so;
}

inline void run_synthetic_video(const SyntheticVideoOptions& o) {
  namespace fs = std::filesystem;
  if (o.frames < 1 || o.frames > 10000) throw option_error("option.frames", "--frames", "must be in 1..10000");
  if (o.width < 16 || o.height < 16 || o.width > 8192 || o.height > 8192)
    throw option_error("option.size", "--width/--height", "must be in 16..8192");
  if (!(o.texture > 0 && o.texture < 100)) throw option_error("option.range", "--texture", "must be in (0, 100)");
  if (o.sweep < 0 || o.sweep == 1) throw option_error("option.range", "--sweep", "must be 0 (the whole video) or >= 2");
  std::error_code ec;
  if (fs::exists(o.out, ec) && !fs::is_directory(o.out, ec))
    throw io_error("io.not_a_folder", o.out.string(), "the output exists and is not a folder");
  fs::create_directories(o.out / "frames", ec);
  fs::create_directories(o.out / "masks", ec);
  if (ec) throw io_error("io.unwritable", o.out.string(), "cannot create folder: " + ec.message());
  ThreadPool pool(o.threads);
  double area = 0;
  auto write = [&](int f, const Image<float, 3>& frame, const Image<float, 1>& mask) {
    char name[32];
    std::snprintf(name, sizeof(name), "%05d.png", f);
    io::write_png(o.out / "frames" / name, frame);
    io::write_png(o.out / "masks" / name, mask);
    double s = 0;
    for (std::size_t p = 0; p < mask.size(); ++p) s += mask.data()[p];
    area += s / double(mask.size());
  };
  (void)synthetic::make_synthetic_clip<float>(synthetic_video_clip_options(o), &pool, write);
  nlohmann::json j;
  j["out"] = o.out.string();
  j["frames"] = o.frames;
  j["width"] = o.width;
  j["height"] = o.height;
  j["mask_area"] = area / o.frames;
  j["focal"] = synthetic::synthetic_clip_camera<double>(synthetic_video_clip_options(o), 0).fx;  // pixels (--focal of sfm/reconstruct)
  std::cout << j.dump() << std::endl;
}

inline void add_synthetic_video_command(CLI::App& app) {
  auto opt = std::make_shared<SyntheticVideoOptions>();
  CLI::App* sub = app.add_subcommand("synthetic-video", "write a seeded synthetic video (frames/ + masks/) into DIR");
  sub->add_option("--out", opt->out, "output folder")->required();
  sub->add_option("--frames", opt->frames, "frames")->capture_default_str();
  sub->add_option("--width", opt->width, "frame width")->capture_default_str();
  sub->add_option("--height", opt->height, "frame height")->capture_default_str();
  sub->add_option("--seed", opt->seed, "seed")->capture_default_str();
  sub->add_option("--texture", opt->texture, "texture frequency (detail for SIFT)")->capture_default_str();
  sub->add_option("--sweep", opt->sweep, "frames of one back-and-forth sweep of camera and object (0 = once over the whole video)")
      ->capture_default_str();
  sub->add_option("--threads", opt->threads, "worker threads (0 = all cores)")->capture_default_str();
  sub->callback([opt] { run_synthetic_video(*opt); });
}

}  // namespace video3dgs::cli
