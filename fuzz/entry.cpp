// The libFuzzer entry of one fuzz target, compiled once per target (fuzz/CMakeLists.txt defines
// VIDEO3DGS_FUZZ_HEADER "targets/<t>.hpp", VIDEO3DGS_FUZZ_FUNCTION <t> and VIDEO3DGS_FUZZ_SEEDS <t>_seeds).
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

#include VIDEO3DGS_FUZZ_HEADER

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = std::getenv("VIDEO3DGS_FUZZ_WRITE_SEEDS"); dir && *dir) {
    try {
      std::filesystem::create_directories(dir);
      video3dgs::fuzz::VIDEO3DGS_FUZZ_SEEDS(dir);
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
  const std::string id = video3dgs::fuzz::VIDEO3DGS_FUZZ_FUNCTION(video3dgs::fuzz::as_bytes(data, size));
  if (print) std::fprintf(stderr, "video3dgs fuzz: %s\n", id.empty() ? "ok" : id.c_str());
  return 0;
}
