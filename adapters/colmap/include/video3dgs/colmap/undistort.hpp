#pragma once
/// @file
/// Undistorting a COLMAP model with `colmap image_undistorter`, so that its cameras become PINHOLE
/// and convert exactly to `video3dgs::Camera` (convert.hpp rejects distorted cameras instead of
/// pretending they are pinhole).
///
///     auto sparse = video3dgs::colmap::undistort_model({.image_dir = "images", .model_dir = "sparse/0",
///                                                       .output_dir = "undistorted"});
///     auto model = video3dgs::colmap::read_model(sparse);   // PINHOLE cameras, undistorted 2D points
///     // undistorted images: output_dir / "images"

#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include "video3dgs/colmap/model_io.hpp"
#include "video3dgs/colmap/process.hpp"
#include "video3dgs/core/error.hpp"

namespace video3dgs::colmap {

struct UndistortOptions {
  std::filesystem::path executable = "colmap";
  std::filesystem::path image_dir;   ///< the model's images
  std::filesystem::path model_dir;   ///< the distorted model (.bin or .txt)
  std::filesystem::path output_dir;  ///< receives images/ and sparse/ (and COLMAP's MVS scripts)
  int max_image_size = 0;            ///< longest side of the undistorted images; 0 = keep the size
  double timeout_seconds = 3600;     ///< 0 = none
};

/// Runs `colmap image_undistorter --output_type COLMAP` and returns the folder of the undistorted
/// model (output_dir / "sparse"). The log is output_dir / "undistort.log".
/// @throws external_error `colmap.missing`, `colmap.failed`, `colmap.timeout`; io_error `colmap.missing`
///         if the input model is absent
inline std::filesystem::path undistort_model(const UndistortOptions& o) {
  (void)detect_format(o.model_dir);  // fails early, naming the folder, if there is no model
  if (find_executable(o.executable).empty())
    throw external_error("colmap.missing", o.executable.string(),
                         "the COLMAP program was not found; install it (Debian/Ubuntu: `sudo apt-get install colmap`)");
  std::error_code ec;
  std::filesystem::create_directories(o.output_dir, ec);
  if (ec) throw io_error("io.unwritable", o.output_dir.string(), "cannot create folder: " + ec.message());
  const auto log = o.output_dir / "undistort.log";
  std::vector<std::string> argv{o.executable.string(), "image_undistorter", "--image_path", o.image_dir.string(), "--input_path",
                                o.model_dir.string(), "--output_path", o.output_dir.string(), "--output_type", "COLMAP"};
  if (o.max_image_size > 0) argv.insert(argv.end(), {"--max_image_size", std::to_string(o.max_image_size)});
  const ProcessResult pr = run_process(argv, log, o.timeout_seconds, {"QT_QPA_PLATFORM=offscreen"});
  if (pr.timed_out) throw external_error("colmap.timeout", log.string(), "colmap image_undistorter exceeded the timeout and was killed");
  if (!pr.ok())
    throw external_error("colmap.failed", log.string(),
                         "colmap image_undistorter exited with status " + std::to_string(pr.exit_code) + ": " + log_tail(log));
  return o.output_dir / "sparse";
}

}  // namespace video3dgs::colmap
