#pragma once
// `video3dgs render --ply FILE --camera CAM.json --out IMG.png [--depth D.png] [--alpha A.png]
//                   [--background r,g,b] [--threads N] [--sh-degree D] [--antialiased]`
// Renders a 3DGS PLY file (any SH degree) with the tile rasterizer (float, 16x16 tiles) and prints one
// JSON line: {"gaussians":N,"visible":V,"width":W,"height":H,"ms":T}.
// The depth PNG is the expected depth (accumulated depth / alpha) mapped linearly from its minimum
// (black) to its maximum (white) over pixels with alpha > 0.5; other pixels are black.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "commands/camera_json.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/io/ply.hpp"
#include "video3dgs/rasterizer/rasterizer.hpp"

namespace video3dgs::cli {

/// Expected depth (depth / alpha) normalised to [0, 1] over pixels with alpha > 0.5.
inline Image<float, 1> depth_for_display(const Image<float, 1>& depth, const Image<float, 1>& alpha) {
  Image<float, 1> out(depth.width(), depth.height());
  float lo = std::numeric_limits<float>::max(), hi = -lo;
  for (std::size_t i = 0; i < depth.size(); ++i)
    if (alpha.data()[i] > 0.5f) {
      const float z = depth.data()[i] / alpha.data()[i];
      lo = std::min(lo, z), hi = std::max(hi, z);
    }
  const float range = hi > lo ? hi - lo : 1.0f;
  for (std::size_t i = 0; i < depth.size(); ++i)
    out.data()[i] = alpha.data()[i] > 0.5f ? (depth.data()[i] / alpha.data()[i] - lo) / range : 0.0f;
  return out;
}

/// Parses "r,g,b" (each finite).
inline std::array<float, 3> parse_rgb(const std::string& s, const char* what) {
  std::array<float, 3> c{};
  std::size_t pos = 0;
  for (int i = 0; i < 3; ++i) {
    const std::size_t comma = s.find(',', pos);
    const std::string tok = s.substr(pos, comma == std::string::npos ? std::string::npos : comma - pos);
    try {
      std::size_t used = 0;
      c[static_cast<std::size_t>(i)] = std::stof(tok, &used);
      if (used != tok.size() || !std::isfinite(c[static_cast<std::size_t>(i)])) throw std::invalid_argument(tok);
    } catch (const std::exception&) {
      throw option_error("option.background", what, "expected three finite numbers r,g,b, got '" + s + "'");
    }
    if ((comma == std::string::npos) != (i == 2)) throw option_error("option.background", what, "expected exactly three numbers r,g,b, got '" + s + "'");
    pos = comma + 1;
  }
  return c;
}

inline void add_render_command(CLI::App& app) {
  struct Options {
    std::string ply, camera, out, depth, alpha, background = "0,0,0";
    unsigned threads = 0;
    int sh_degree = 3;
    bool antialiased = false;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* sub = app.add_subcommand("render", "render a 3DGS PLY file from a camera (PNG)");
  sub->add_option("--ply", opt->ply, "Gaussians in the standard 3DGS PLY layout")->required();
  sub->add_option("--camera", opt->camera, "camera JSON {width,height,fx,fy,cx,cy,R[9] row-major world-to-camera,t[3]}")->required();
  sub->add_option("--out", opt->out, "output colour PNG")->required();
  sub->add_option("--depth", opt->depth, "also write the expected depth (normalised) as a PNG");
  sub->add_option("--alpha", opt->alpha, "also write the accumulated alpha as a PNG");
  sub->add_option("--background", opt->background, "background colour r,g,b in [0,1]")->capture_default_str();
  sub->add_option("--threads", opt->threads, "worker threads (0 = all cores)")->capture_default_str();
  sub->add_option("--sh-degree", opt->sh_degree, "SH bands used (0..3, at most the file's)")->capture_default_str();
  sub->add_flag("--antialiased", opt->antialiased, "antialiased mode (opacity compensation)");

  sub->callback([opt] {
    if (opt->sh_degree < 0 || opt->sh_degree > 3) throw option_error("option.sh_degree", "--sh-degree", "must be in 0..3");
    const auto cloud = io::read_ply<float>(opt->ply);
    const Camera<float> cam = read_camera_json(opt->camera).cast<float>();
    Rasterizer<float, 16> r;
    r.settings.background = parse_rgb(opt->background, "--background");
    r.settings.active_sh_degree = opt->sh_degree;
    r.settings.antialiased = opt->antialiased;
    ThreadPool pool(opt->threads);
    RasterContext<float, 3> ctx;
    const auto t0 = std::chrono::steady_clock::now();
    r.forward(cam, cloud.params(), ctx, &pool);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    io::write_png(opt->out, ctx.image);
    if (!opt->alpha.empty()) io::write_png(opt->alpha, ctx.alpha);
    if (!opt->depth.empty()) io::write_png(opt->depth, depth_for_display(ctx.depth, ctx.alpha));
    nlohmann::json j;
    j["gaussians"] = cloud.count;
    j["visible"] = ctx.stats.visible;
    j["width"] = cam.width;
    j["height"] = cam.height;
    j["ms"] = ms;
    std::cout << j.dump() << std::endl;
  });
}

}  // namespace video3dgs::cli
