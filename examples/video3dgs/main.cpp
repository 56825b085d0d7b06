// The `video3dgs` command-line tool. Each subcommand lives in commands/<name>.hpp: its
// `add_<name>_command(CLI::App&)` registers the options and a CLI11 callback, which CLI11 runs after
// parsing. Errors from the library are printed as their message (which starts with a stable id) and
// exit with status 2.
#include <cstdio>
#include <exception>
#include <iostream>

#include <CLI/CLI.hpp>

#include "video3dgs/core/error.hpp"
// Subcommands (keep sorted):
#include "commands/compact.hpp"
#include "commands/demo.hpp"
#include "commands/export.hpp"
#include "commands/metrics.hpp"
#include "commands/reconstruct.hpp"
#include "commands/refine.hpp"
#include "commands/render.hpp"
#include "commands/render_video.hpp"
#include "commands/sfm.hpp"
#include "commands/synthetic_video.hpp"
#include "commands/trade.hpp"

int main(int argc, char** argv) {
  CLI::App app{"video3dgs: reconstruct a video with deformable 3D Gaussians, refine edited videos"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "video3dgs 0.1.0");
  // Subcommand registration (keep sorted):
  video3dgs::cli::add_compact_command(app);
  video3dgs::cli::add_demo_command(app);
  video3dgs::cli::add_export_command(app);
  video3dgs::cli::add_metrics_command(app);
  video3dgs::cli::add_reconstruct_command(app);
  video3dgs::cli::add_refine_command(app);
  video3dgs::cli::add_render_command(app);
  video3dgs::cli::add_render_video_command(app);
  video3dgs::cli::add_sfm_command(app);
  video3dgs::cli::add_synthetic_video_command(app);
  video3dgs::cli::add_trade_command(app);

  try {
    app.parse(argc, argv);  // runs the selected subcommand's callback
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const video3dgs::error& e) {
    std::cerr << "video3dgs: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "video3dgs: [internal] " << e.what() << "\n";
    return 3;
  }
  return 0;
}
