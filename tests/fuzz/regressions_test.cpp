// The fuzz targets (fuzz/targets/*.hpp) without clang: every target's seeds read back without error,
// and every input in fuzz/regressions/<target>/ (inputs that once broke a reader) raises the error id
// its file name ends with: `<what>--<id>`, e.g. `ascii_count_overflow--io.truncated` (`--` alone: the
// input is valid and must read without error).
#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include <doctest/doctest.h>

#include "targets/camera_json.hpp"
#include "targets/checkpoint.hpp"
#include "targets/colmap.hpp"
#include "targets/flo.hpp"
#include "targets/image.hpp"
#include "targets/model.hpp"
#include "targets/ply.hpp"
#include "targets/state.hpp"

namespace {

using Reader = std::string (*)(std::string_view);
using Seeds = void (*)(const std::filesystem::path&);
struct FuzzTarget {
  const char* name;
  Reader read;
  Seeds seeds;
};
const FuzzTarget kFuzzTargets[] = {
    {"ply", video3dgs::fuzz::ply, video3dgs::fuzz::ply_seeds},
    {"colmap", video3dgs::fuzz::colmap, video3dgs::fuzz::colmap_seeds},
    {"model", video3dgs::fuzz::model, video3dgs::fuzz::model_seeds},
    {"checkpoint", video3dgs::fuzz::checkpoint, video3dgs::fuzz::checkpoint_seeds},
    {"flo", video3dgs::fuzz::flo, video3dgs::fuzz::flo_seeds},
    {"image", video3dgs::fuzz::image, video3dgs::fuzz::image_seeds},
    {"camera_json", video3dgs::fuzz::camera_json, video3dgs::fuzz::camera_json_seeds},
    {"state", video3dgs::fuzz::state, video3dgs::fuzz::state_seeds},
};

std::vector<std::filesystem::path> files_in(const std::filesystem::path& dir) {
  std::vector<std::filesystem::path> out;
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) return out;
  for (const auto& e : std::filesystem::directory_iterator(dir)) out.push_back(e.path());
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

TEST_CASE("fuzz targets: every seed reads back without error") {
  for (const auto& t : kFuzzTargets) {
    const auto dir = video3dgs::fuzz::scratch_dir() / ("seeds_" + std::string(t.name));
    std::filesystem::create_directories(dir);
    t.seeds(dir);
    const auto files = files_in(dir);
    CAPTURE(t.name);
    CHECK(files.size() >= 2);
    for (const auto& f : files) {
      CAPTURE(f.filename().string());
      CHECK(t.read(video3dgs::fuzz::read_bytes(f)) == "");
    }
  }
}

TEST_CASE("fuzz regressions: each input raises the id its name ends with") {
  const std::filesystem::path root = std::filesystem::path(VIDEO3DGS_SOURCE_DIR) / "fuzz" / "regressions";
  int replayed = 0;
  for (const auto& dir : files_in(root)) {
    const FuzzTarget* target = nullptr;
    for (const auto& t : kFuzzTargets)
      if (dir.filename() == t.name) target = &t;
    CAPTURE(dir.string());
    REQUIRE_MESSAGE(target != nullptr, "fuzz/regressions/ holds a folder that names no fuzz target");
    for (const auto& f : files_in(dir)) {
      const std::string name = f.filename().string();
      const auto sep = name.rfind("--");
      CAPTURE(name);
      REQUIRE_MESSAGE(sep != std::string::npos, "regression inputs are named <what>--<error id>");
      CHECK(target->read(video3dgs::fuzz::read_bytes(f)) == name.substr(sep + 2));
      ++replayed;
    }
  }
  MESSAGE(replayed << " regression inputs replayed");
}
