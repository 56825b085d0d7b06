#pragma once
// Fuzz target `checkpoint`: resuming a ClipTrainer from a checkpoint file (the clip model record, then
// the optimiser, schedule and densification state), through a scratch file, with the frames and
// options of the run that wrote the seeds. Seeds: save_checkpoint before any iteration and after 3.
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "../common.hpp"
#include "../fuzz_model.hpp"
#include "video3dgs/training/clip_trainer.hpp"

namespace video3dgs::fuzz {

namespace detail {
using FuzzTrainer = ClipTrainer<FuzzModel>;
inline std::vector<Image<float, 3>> fuzz_frames() {
  std::vector<Image<float, 3>> frames;
  for (int f = 0; f < 3; ++f) {
    Image<float, 3> img(kFuzzWidth, kFuzzHeight);
    for (std::size_t i = 0; i < img.pixel_count() * 3; ++i) img.data()[i] = float((i * 7 + std::size_t(f)) % 10) / 10.0f;
    frames.push_back(std::move(img));
  }
  return frames;
}
inline TrainOptions fuzz_train_options() {
  TrainOptions o = TrainOptions::preset("3k");
  o.iterations = 8;
  return o;
}
}  // namespace detail

inline std::string checkpoint(std::string_view bytes) {
  const auto path = scratch_file("clip.ckpt", bytes);
  return run_reader([&] { detail::FuzzTrainer t(path, detail::fuzz_frames(), detail::fuzz_train_options()); });
}

inline void checkpoint_seeds(const std::filesystem::path& dir) {
  detail::FuzzTrainer t(make_fuzz_model({0, 2}), detail::fuzz_frames(), detail::fuzz_train_options());
  const auto tmp = scratch_dir() / "seed.ckpt";
  t.save_checkpoint(tmp);
  write_seed(dir, "start.ckpt", read_bytes(tmp));
  for (int k = 0; k < 3; ++k) (void)t.step();
  t.save_checkpoint(tmp);
  write_seed(dir, "step3.ckpt", read_bytes(tmp));
}

}  // namespace video3dgs::fuzz
