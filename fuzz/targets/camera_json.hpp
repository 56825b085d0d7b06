#pragma once
// Fuzz target `camera_json`: cli::read_camera_json (the camera file of `video3dgs render`), through a
// scratch file. Seeds: cameras in cli::camera_json's text.
#include <filesystem>
#include <string>
#include <string_view>

#include "../common.hpp"
#include "commands/camera_json.hpp"

namespace video3dgs::fuzz {

inline std::string camera_json(std::string_view bytes) {
  const auto path = scratch_file("camera.json", bytes);
  return run_reader([&] { (void)cli::read_camera_json(path); });
}

inline void camera_json_seeds(const std::filesystem::path& dir) {
  auto a = Camera<double>::from_fov(64, 48, 1.0);
  a.look_at({0.5, -0.2, -3.0}, {0, 0, 0});
  auto b = Camera<double>::from_fov(1, 1, 0.5);
  write_seed(dir, "camera0.json", cli::camera_json(a).dump(2) + "\n");  // what write_camera_json writes
  write_seed(dir, "camera1.json", cli::camera_json(b).dump());
}

}  // namespace video3dgs::fuzz
