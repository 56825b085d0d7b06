#pragma once
// Fuzz target `colmap`: the COLMAP model readers, through scratch files. The first input byte selects
// what the rest is (value % 8):
//   0 cameras.bin   1 images.bin   2 points3D.bin   3 cameras.txt   4 images.txt   5 points3D.txt
//   6 / 7 a whole binary / text model: u32 size of cameras, cameras, u32 size of images, images,
//         points3D (little-endian sizes), read by read_model (cross-references validated) and converted
//         by to_sfm_result with the SfM back end's image-name -> frame rule, as a resumed run does.
// Seeds: a two-camera, three-image model written by write_model in both formats.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <string>
#include <string_view>

#include "../common.hpp"
#include "video3dgs/colmap/convert.hpp"
#include "video3dgs/colmap/model_io.hpp"
#include "video3dgs/colmap/sfm.hpp"

namespace video3dgs::fuzz {

namespace detail {
inline const char* const kColmapFiles[6] = {"cameras.bin", "images.bin", "points3D.bin",
                                             "cameras.txt", "images.txt", "points3D.txt"};

/// Splits a whole-model input into its three files (false if the sizes run past the end).
inline bool split_colmap_model(std::string_view rest, std::string_view (&files)[3]) {
  for (int k = 0; k < 2; ++k) {
    std::uint32_t n = 0;
    if (rest.size() < 4) return false;
    std::memcpy(&n, rest.data(), 4);
    rest.remove_prefix(4);
    if (n > rest.size()) return false;
    files[k] = rest.substr(0, n);
    rest.remove_prefix(n);
  }
  files[2] = rest;
  return true;
}
}  // namespace detail

inline std::string colmap(std::string_view bytes) {
  if (bytes.empty()) return {};
  const int which = static_cast<unsigned char>(bytes[0]) % 8;
  const std::string_view rest = bytes.substr(1);
  return run_reader([&] {
    if (which < 6) {
      const auto path = scratch_file(detail::kColmapFiles[which], rest);
      switch (which) {
        case 0: (void)colmap::read_cameras_binary(path); break;
        case 1: (void)colmap::read_images_binary(path); break;
        case 2: (void)colmap::read_points3D_binary(path); break;
        case 3: (void)colmap::read_cameras_text(path); break;
        case 4: (void)colmap::read_images_text(path); break;
        default: (void)colmap::read_points3D_text(path); break;
      }
      return;
    }
    std::string_view files[3];
    if (!detail::split_colmap_model(rest, files)) return;
    const int base = which == 6 ? 0 : 3;
    const auto dir = scratch_dir() / "model";
    std::filesystem::create_directories(dir);
    for (int k = 0; k < 6; ++k) std::filesystem::remove(dir / detail::kColmapFiles[k]);
    for (int k = 0; k < 3; ++k) scratch_file(std::string("model/") + detail::kColmapFiles[base + k], files[k]);
    const colmap::Model m = colmap::read_model(dir, which == 6 ? colmap::Format::binary : colmap::Format::text);
    (void)colmap::to_sfm_result<double>(m, FrameRange{0, 2}, &colmap::ColmapSfm::frame_of_name);
  });
}

namespace detail {
inline colmap::Model seed_colmap_model() {
  colmap::Model m;
  colmap::CameraRecord c1;
  c1.id = 1, c1.model_id = 0, c1.width = 64, c1.height = 48, c1.params = {50.0, 32.0, 24.0};  // SIMPLE_PINHOLE
  colmap::CameraRecord c2;
  c2.id = 2, c2.model_id = 1, c2.width = 32, c2.height = 24, c2.params = {30.0, 31.0, 16.0, 12.0};  // PINHOLE
  m.cameras = {{1, c1}, {2, c2}};
  for (std::uint32_t i = 1; i <= 3; ++i) {
    colmap::ImageRecord im;
    im.id = i;
    im.qvec = {std::cos(0.1 * i), 0.0, std::sin(0.1 * i), 0.0};
    im.tvec = {0.1 * i, -0.2, 3.0};
    im.camera_id = i == 3 ? 2 : 1;
    char name[32];
    std::snprintf(name, sizeof(name), "%05u.png", i - 1);
    im.name = name;
    im.points2D = {{10.5, 20.25}, {30.0, 5.0}};
    im.point3D_ids = {7, i == 2 ? colmap::kNoPoint3D : std::int64_t{8}};
    m.images.emplace(i, im);
  }
  colmap::Point3DRecord p7;
  p7.id = 7, p7.xyz = {0.1, 0.2, 0.3}, p7.rgb = {200, 100, 50}, p7.error = 0.5, p7.track = {{1, 0}, {2, 0}, {3, 0}};
  colmap::Point3DRecord p8;
  p8.id = 8, p8.xyz = {-0.1, 0.0, 0.4}, p8.rgb = {1, 2, 3}, p8.error = 1.25, p8.track = {{1, 1}, {3, 1}};
  m.points = {{7, p7}, {8, p8}};
  return m;
}
inline void put_u32(std::string& out, std::size_t n) {
  const auto v = static_cast<std::uint32_t>(n);
  out.append(reinterpret_cast<const char*>(&v), 4);
}
}  // namespace detail

inline void colmap_seeds(const std::filesystem::path& dir) {
  const colmap::Model m = detail::seed_colmap_model();
  const auto tmp = scratch_dir() / "seed_model";
  colmap::write_model(tmp, m, colmap::Format::binary);
  colmap::write_model(tmp, m, colmap::Format::text);
  std::string file[6];
  for (int k = 0; k < 6; ++k) {
    file[k] = read_bytes(tmp / detail::kColmapFiles[k]);
    write_seed(dir, std::to_string(k) + "_" + detail::kColmapFiles[k], std::string(1, char(k)) + file[k]);
  }
  for (int which : {6, 7}) {
    const int base = which == 6 ? 0 : 3;
    std::string s(1, char(which));
    detail::put_u32(s, file[base].size());
    s += file[base];
    detail::put_u32(s, file[base + 1].size());
    s += file[base + 1] + file[base + 2];
    write_seed(dir, std::to_string(which) + "_model", s);
  }
  std::filesystem::remove_all(tmp);
}

}  // namespace video3dgs::fuzz
