// The fuzz targets (fuzz/targets/*.hpp) without clang: every target's seeds read back without error,
// and every input in fuzz/regressions/<target>/ (inputs that once broke a reader) raises the error id
// its file name ends with: `<what>--<id>`, e.g. `ascii_count_overflow--io.truncated` (`--` alone: the
// input is valid and must read without error).
#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include <doctest/doctest.h>

#include "all_targets.hpp"

namespace {

using video3dgs::fuzz::FuzzTarget;
using video3dgs::fuzz::kFuzzTargets;

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
    const FuzzTarget* target = video3dgs::fuzz::find_fuzz_target(dir.filename().string());
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
