#pragma once
// Camera JSON files of the CLI: {"width","height","fx","fy","cx","cy","R": [9 numbers, row-major,
// world-to-camera], "t": [3 numbers]} (COLMAP/OpenCV convention, x_c = R x_w + t).
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

#include "video3dgs/core/camera.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/io/atomic_file.hpp"

namespace video3dgs::cli {

/// @throws io_error (`io.unreadable`, `io.format` naming the field), option_error (`option.camera`).
inline Camera<double> read_camera_json(const std::filesystem::path& path) {
  const std::string where = path.string();
  std::ifstream in(path);
  if (!in) throw io_error("io.unreadable", where, "cannot open camera file");
  nlohmann::json j;
  try {
    in >> j;
  } catch (const nlohmann::json::exception& e) {
    throw io_error("io.format", where, std::string("not valid JSON: ") + e.what());
  }
  auto field = [&](const char* name) -> const nlohmann::json& {
    if (!j.is_object() || !j.contains(name)) throw io_error("io.format", where, std::string("missing field '") + name + "'");
    return j.at(name);
  };
  auto number = [&](const nlohmann::json& v, const std::string& name) {
    if (!v.is_number()) throw io_error("io.format", where, "field '" + name + "' must be a number");
    return v.get<double>();
  };
  auto array = [&](const char* name, std::size_t n) {
    const auto& v = field(name);
    if (!v.is_array() || v.size() != n)
      throw io_error("io.format", where, std::string("field '") + name + "' must be an array of " + std::to_string(n) + " numbers");
    return v;
  };
  Camera<double> cam;
  const double w = number(field("width"), "width"), h = number(field("height"), "height");
  auto pixels = [](double v) { return v >= 1 && v <= (1 << 15) && v == std::floor(v); };  // before any cast to int
  if (!pixels(w) || !pixels(h))
    throw io_error("io.format", where, "width/height must be positive integers (at most 32768)");
  cam.width = static_cast<int>(w);
  cam.height = static_cast<int>(h);
  cam.fx = number(field("fx"), "fx");
  cam.fy = number(field("fy"), "fy");
  cam.cx = number(field("cx"), "cx");
  cam.cy = number(field("cy"), "cy");
  const auto R = array("R", 9), t = array("t", 3);
  for (int i = 0; i < 9; ++i) cam.R(i / 3, i % 3) = number(R[static_cast<std::size_t>(i)], "R");
  for (int i = 0; i < 3; ++i) cam.t[i] = number(t[static_cast<std::size_t>(i)], "t");
  cam.validate(where.c_str());
  return cam;
}

template <class Scalar>
inline nlohmann::json camera_json(const Camera<Scalar>& cam) {
  nlohmann::json j;
  j["width"] = cam.width, j["height"] = cam.height;
  j["fx"] = double(cam.fx), j["fy"] = double(cam.fy), j["cx"] = double(cam.cx), j["cy"] = double(cam.cy);
  j["R"] = nlohmann::json::array();
  for (int i = 0; i < 9; ++i) j["R"].push_back(double(cam.R(i / 3, i % 3)));
  j["t"] = {double(cam.t[0]), double(cam.t[1]), double(cam.t[2])};
  return j;
}

/// Writes a camera JSON file atomically.
template <class Scalar>
inline void write_camera_json(const std::filesystem::path& path, const Camera<Scalar>& cam) {
  io::write_file_atomic(path, camera_json(cam).dump(2) + "\n");
}

}  // namespace video3dgs::cli
