#pragma once
// The fuzz targets by name: the fuzzers' entry (fuzz/entry.cpp) and the regression test (tests/fuzz)
// both dispatch through this table. A target is a reader run on the input's bytes (returning "" or the
// error id it raised, fuzz/common.hpp) and a writer of seed inputs made by the library's own writers.
#include <filesystem>
#include <string>
#include <string_view>

#include "targets/camera_json.hpp"
#include "targets/checkpoint.hpp"
#include "targets/colmap.hpp"
#include "targets/flo.hpp"
#include "targets/image.hpp"
#include "targets/model.hpp"
#include "targets/ply.hpp"
#include "targets/state.hpp"

namespace video3dgs::fuzz {

struct FuzzTarget {
  const char* name;
  std::string (*read)(std::string_view bytes);
  void (*seeds)(const std::filesystem::path& dir);
};

/// Every target, in the order scripts/fuzz.sh lists them.
inline constexpr FuzzTarget kFuzzTargets[] = {
    {"ply", ply, ply_seeds},
    {"colmap", colmap, colmap_seeds},
    {"model", model, model_seeds},
    {"checkpoint", checkpoint, checkpoint_seeds},
    {"flo", flo, flo_seeds},
    {"image", image, image_seeds},
    {"camera_json", camera_json, camera_json_seeds},
    {"state", state, state_seeds},
};

/// The target called `name`, or nullptr.
inline const FuzzTarget* find_fuzz_target(std::string_view name) {
  for (const auto& t : kFuzzTargets)
    if (name == t.name) return &t;
  return nullptr;
}

}  // namespace video3dgs::fuzz
