#pragma once
// Fuzz target `model`: the saved models. First byte (value % 2): 0 = the rest is a clip model file
// (load_clip_model), 1 = the rest is the manifest of a video model folder whose two clip files
// (frames 0-2 and 2-4) are valid (load_video_model: manifest, clip files, cross-checks).
// Seeds: a clip model saved by save_clip_model and the manifest save_video_model writes.
#include <filesystem>
#include <string>
#include <string_view>

#include "../common.hpp"
#include "../fuzz_model.hpp"
#include "video3dgs/model/clip_model_io.hpp"
#include "video3dgs/model/video_model.hpp"

namespace video3dgs::fuzz {

namespace detail {
using FuzzVideo = VideoModel<float, 1, FuzzField>;
inline FuzzVideo make_fuzz_video() {
  FuzzVideo v;
  v.frame_count = 5, v.width = kFuzzWidth, v.height = kFuzzHeight;
  v.clips.push_back(make_fuzz_model({0, 2}, 1));
  v.clips.push_back(make_fuzz_model({2, 4}, 2));
  return v;
}
/// scratch_dir()/video: the two clip files of make_fuzz_video (written once per process).
inline const std::filesystem::path& fuzz_video_dir() {
  static const std::filesystem::path dir = [] {
    auto v = make_fuzz_video();
    const auto d = scratch_dir() / "video";
    save_video_model(d, v);
    return d;
  }();
  return dir;
}
}  // namespace detail

inline std::string model(std::string_view bytes) {
  if (bytes.empty()) return {};
  const std::string_view rest = bytes.substr(1);
  if (static_cast<unsigned char>(bytes[0]) % 2 == 0) {
    const auto path = scratch_file("clip.model", rest);
    return run_reader([&] { (void)load_clip_model<float, 1, FuzzField>(path); });
  }
  const auto& dir = detail::fuzz_video_dir();
  scratch_file("video/" + std::string(kVideoModelManifest), rest);
  return run_reader([&] { (void)load_video_model<float, 1, FuzzField>(dir); });
}

inline void model_seeds(const std::filesystem::path& out) {
  auto m = make_fuzz_model({0, 2}, 3);
  const auto tmp = scratch_dir() / "seed_model";
  save_clip_model(tmp, m);
  write_seed(out, "0_clip.model", std::string(1, '\0') + read_bytes(tmp));
  const auto& dir = detail::fuzz_video_dir();
  write_seed(out, "1_manifest.txt", std::string(1, '\1') + read_bytes(dir / kVideoModelManifest));
}

}  // namespace video3dgs::fuzz
