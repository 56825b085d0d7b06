#pragma once
// `video3dgs demo --out DIR [--frames N] [--width W] [--height H] [--seed S] [--threads N]`
// Generates the seeded synthetic demo scene (a striped sphere of Gaussians in front of a checkered
// backdrop), writes DIR/scene.ply (standard 3DGS layout) and DIR/camera.json (first frame), renders
// N frames from a camera moving on an arc into DIR/frames/00000.png ..., then re-reads the PLY and
// re-renders the first frame to check the round trip. Prints one JSON line.
#include <chrono>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "commands/camera_json.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/io/ply.hpp"
#include "video3dgs/rasterizer/rasterizer.hpp"
#include "video3dgs/synthetic/scene.hpp"

namespace video3dgs::cli {

inline void add_demo_command(CLI::App& app) {
  struct Options {
    std::string out;
    int frames = 8, width = 854, height = 480;
    unsigned long long seed = 1;
    unsigned threads = 0;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* sub = app.add_subcommand("demo", "synthetic demo: scene PLY + camera JSON + rendered frames into DIR");
  sub->add_option("--out", opt->out, "output folder")->required();
  sub->add_option("--frames", opt->frames, "frames to render")->capture_default_str();
  sub->add_option("--width", opt->width, "frame width")->capture_default_str();
  sub->add_option("--height", opt->height, "frame height")->capture_default_str();
  sub->add_option("--seed", opt->seed, "scene seed")->capture_default_str();
  sub->add_option("--threads", opt->threads, "worker threads (0 = all cores)")->capture_default_str();

  sub->callback([opt] {
    namespace fs = std::filesystem;
    if (opt->frames < 1 || opt->frames > 100000) throw option_error("option.frames", "--frames", "must be in 1..100000");
    if (opt->width < 1 || opt->height < 1 || opt->width > 16384 || opt->height > 16384)
      throw option_error("option.size", "--width/--height", "must be in 1..16384");
    const fs::path dir = opt->out;
    std::error_code ec;
    fs::create_directories(dir / "frames", ec);
    if (ec) throw io_error("io.unwritable", (dir / "frames").string(), "cannot create folder: " + ec.message());

    const auto t0 = std::chrono::steady_clock::now();
    const auto cloud = synthetic::demo_scene<float>(opt->seed);
    io::write_ply(dir / "scene.ply", cloud);
    write_camera_json(dir / "camera.json", synthetic::demo_camera<double>(opt->width, opt->height, 0, opt->frames));

    Rasterizer<float, 16> r;
    r.settings.background = {0.02f, 0.02f, 0.03f};
    ThreadPool pool(opt->threads);
    RasterContext<float, 3> ctx;  // reused for every frame
    std::vector<float> first;
    for (int f = 0; f < opt->frames; ++f) {
      // Cameras are made in double and cast, exactly as `render` does with the camera JSON.
      const auto cam = synthetic::demo_camera<double>(opt->width, opt->height, f, opt->frames).cast<float>();
      r.forward(cam, cloud.params(), ctx, &pool);
      char name[32];
      std::snprintf(name, sizeof(name), "%05d.png", f);
      io::write_png(dir / "frames" / name, ctx.image);
      if (f == 0) first = ctx.image.storage();
    }
    // PLY round trip: the file renders the same pixels.
    const auto back = io::read_ply<float>(dir / "scene.ply");
    r.forward(synthetic::demo_camera<double>(opt->width, opt->height, 0, opt->frames).cast<float>(), back.params(), ctx, &pool);
    const bool identical = ctx.image.storage() == first;
    if (!identical) throw io_error("io.roundtrip", (dir / "scene.ply").string(), "re-read PLY renders different pixels");
    nlohmann::json j;
    j["out"] = dir.string();
    j["gaussians"] = cloud.size();
    j["frames"] = opt->frames;
    j["width"] = opt->width;
    j["height"] = opt->height;
    j["ply_roundtrip_identical"] = identical;
    j["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::cout << j.dump() << std::endl;
  });
}

}  // namespace video3dgs::cli
