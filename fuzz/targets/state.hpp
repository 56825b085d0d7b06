#pragma once
// Fuzz target `state`: the state files `reconstruct --resume` reads back (JSON objects, or the text
// lines of version 0.1), through a scratch file. The first byte (value % 4) says which the rest is:
//   0 OUT/train/clip_NNN.done (read, matched against a clip key, read as a finished clip's report)
//   1 OUT/train/clip_NNN.ckpt.key (read, matched, its recorded seconds read)
//   2 / 3 an SfM attempt's outcome.json / legacy outcome.txt, in a folder whose model/ is a valid
//     COLMAP model of frames 0-2 (ColmapSfm::load_finished: outcome, then the model when it says so). Seeds: both files as train_clip writes them (write_json_atomic), and the legacy
// key=value spelling.
#include <filesystem>
#include <string>
#include <string_view>

#include "../common.hpp"
#include "colmap.hpp"
#include "video3dgs/colmap/sfm.hpp"
#include "video3dgs/pipeline/reconstruct.hpp"

namespace video3dgs::fuzz {

namespace detail {
inline const pipeline::ClipKey& fuzz_clip_key() {
  static const pipeline::ClipKey key = [] {
    pipeline::ClipKey k;
    k.text = "fuzz|clip 0-9";
    k.key = stable_key(k.text);
    k.legacy_key = "1234567890";
    return k;
  }();
  return key;
}
/// scratch_dir()/attempt holding model/ (the colmap target's seed model, binary); written once.
inline const std::filesystem::path& fuzz_attempt_dir() {
  static const std::filesystem::path dir = [] {
    const auto d = scratch_dir() / "attempt";
    colmap::write_model(d / "model", seed_colmap_model(), colmap::Format::binary);
    return d;
  }();
  return dir;
}
}  // namespace detail

inline std::string state(std::string_view bytes) {
  if (bytes.empty()) return {};
  const int which = static_cast<unsigned char>(bytes[0]) % 4;
  const auto& key = detail::fuzz_clip_key();
  if (which >= 2) {
    const auto& dir = detail::fuzz_attempt_dir();
    std::filesystem::remove(dir / "outcome.json");
    std::filesystem::remove(dir / "outcome.txt");
    scratch_file(which == 2 ? "attempt/outcome.json" : "attempt/outcome.txt", bytes.substr(1));
    return run_reader([&] { (void)colmap::ColmapSfm::load_finished(dir, FrameRange{0, 2}, key.key, key.legacy_key); });
  }
  const bool done = which == 0;
  const auto path = scratch_file(done ? "clip_000.done" : "clip_000.ckpt.key", bytes.substr(1));
  return run_reader([&] {
    const nlohmann::json s = pipeline::detail::read_state(path);
    if (!pipeline::detail::state_matches(s, key)) return;
    if (done) (void)pipeline::detail::finished_clip_report(s, path.string());
    else if (s.contains("seconds")) (void)pipeline::detail::state_number(s, "seconds", path.string());
  });
}

inline void state_seeds(const std::filesystem::path& dir) {
  const auto& key = detail::fuzz_clip_key();
  const auto tmp = scratch_dir() / "seed.json";
  pipeline::detail::write_json_atomic(tmp, {{"key", key.key}, {"first", 0}, {"last", 9}, {"iterations", 3000}, {"psnr", 31.5},
                                            {"ssim", 0.93}, {"train_seconds", 812.25}});
  write_seed(dir, "0_clip.done", std::string(1, '\0') + read_bytes(tmp));
  pipeline::detail::write_json_atomic(tmp, {{"key", key.key}, {"seconds", 42.5}});
  write_seed(dir, "1_clip.ckpt.key", std::string(1, '\1') + read_bytes(tmp));
  colmap::ColmapAttempt a;
  a.status = SfmStatus::success;
  a.masked = true, a.mask_area = 0.25, a.relaxed_runs = 1, a.seconds_extract = 1.5, a.seconds_map = 3.25;
  const auto out = scratch_dir() / "seed_attempt";
  std::filesystem::create_directories(out);
  colmap::ColmapSfm::write_outcome(out, key.key, a);
  write_seed(dir, "2_outcome.json", std::string(1, '\2') + read_bytes(out / "outcome.json"));
  a.status = SfmStatus::soft_failure;
  a.message = "2 of 3 frames registered";
  colmap::ColmapSfm::write_outcome(out, key.key, a);
  write_seed(dir, "2_outcome_soft.json", std::string(1, '\2') + read_bytes(out / "outcome.json"));
  write_seed(dir, "3_outcome.txt", std::string(1, '\3') + "key " + key.legacy_key + "\nstatus success\nmasked 1\nmask_area 0.25\nrelaxed_runs 2\n");
  write_seed(dir, "0_legacy.done", std::string(1, '\0') + "key=" + key.legacy_key + "\niterations=3000\npsnr=31.5\nssim=0.93\ntrain_seconds=812.25\n");
}

}  // namespace video3dgs::fuzz
