// The libFuzzer entry shared by every fuzz target. fuzz/CMakeLists.txt compiles it once and links it
// into each executable fuzz_<t> together with a one-line unit that defines `video3dgs_fuzz_target`
// as "<t>": the targets share most of the library, so one compile serves all eight.
//
// With the environment variable VIDEO3DGS_FUZZ_WRITE_SEEDS=DIR the program writes the target's seed
// inputs (made by the library's own writers) into DIR and exits instead of fuzzing. With
// VIDEO3DGS_FUZZ_PRINT_ID=1 it prints each input's outcome (the error id, or "ok"): replaying a file
// (`fuzz_<t> FILE`) shows the id its regression test should expect.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <string>

#include "all_targets.hpp"

extern const char* const video3dgs_fuzz_target;  // the target's name, from the executable's own unit

namespace {

const video3dgs::fuzz::FuzzTarget& the_target() {
  static const video3dgs::fuzz::FuzzTarget* t = video3dgs::fuzz::find_fuzz_target(video3dgs_fuzz_target);
  if (!t) {
    std::fprintf(stderr, "video3dgs fuzz: no target named '%s' (fuzz/all_targets.hpp)\n", video3dgs_fuzz_target);
    std::exit(2);
  }
  return *t;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  const auto& target = the_target();
  if (const char* dir = std::getenv("VIDEO3DGS_FUZZ_WRITE_SEEDS"); dir && *dir) {
    try {
      std::filesystem::create_directories(dir);
      target.seeds(dir);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "writing seeds into %s failed: %s\n", dir, e.what());
      std::exit(1);
    }
    std::exit(0);
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const bool print = std::getenv("VIDEO3DGS_FUZZ_PRINT_ID") != nullptr;
  static const auto& target = the_target();
  const std::string id = target.read(video3dgs::fuzz::as_bytes(data, size));
  if (print) std::fprintf(stderr, "video3dgs fuzz: %s\n", id.empty() ? "ok" : id.c_str());
  return 0;
}
