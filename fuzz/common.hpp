#pragma once
// Shared by the fuzz targets (fuzz/fuzz_*.cpp), the seed generator and the regression test
// (tests/fuzz): the contract every reader is fuzzed against, and per-process scratch files for readers
// that only take a path.
//
// Contract: a reader given any bytes either returns or throws an exception derived from
// video3dgs::error. Any other exception escapes `run_reader` (libFuzzer then reports it as a crash);
// crashes, out-of-bounds reads, leaks and undefined behaviour are caught by the sanitizers, and
// allocations larger than libFuzzer's -malloc_limit_mb are reported by it.
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <string_view>
#include <system_error>

#include <unistd.h>

#include "video3dgs/core/error.hpp"

namespace video3dgs::fuzz {

/// Runs `read`; returns "" when it returns normally, else the id of the video3dgs::error it threw.
template <class Read>
std::string run_reader(Read&& read) {
  try {
    read();
  } catch (const video3dgs::error& e) {
    return e.id();
  }
  return {};
}

/// The bytes of a fuzz input.
inline std::string_view as_bytes(const std::uint8_t* data, std::size_t size) {
  return {reinterpret_cast<const char*>(data), size};
}

/// A folder private to this process (under /dev/shm when it exists: no disk writes per input),
/// created on first use and removed at exit.
inline const std::filesystem::path& scratch_dir() {
  struct Dir {
    std::filesystem::path path;
    Dir() {
      std::error_code ec;
      std::filesystem::path base = "/dev/shm";
      if (!std::filesystem::is_directory(base, ec)) base = std::filesystem::temp_directory_path();
      path = base / ("video3dgs_fuzz_" + std::to_string(::getpid()));
      std::filesystem::create_directories(path);
    }
    ~Dir() {
      std::error_code ec;
      std::filesystem::remove_all(path, ec);
    }
  };
  static const Dir dir;
  return dir.path;
}

/// Writes `bytes` to scratch_dir()/name (replacing it) and returns the path.
inline std::filesystem::path scratch_file(const std::string& name, std::string_view bytes) {
  const auto p = scratch_dir() / name;
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) std::fprintf(stderr, "video3dgs fuzz: cannot write %s\n", p.string().c_str());
  return p;
}

/// The whole content of a file ("" if it cannot be read).
inline std::string read_bytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

/// Writes one seed input `dir/name` (the seed generator, fuzz/make_seeds.cpp).
inline void write_seed(const std::filesystem::path& dir, const std::string& name, std::string_view bytes) {
  std::ofstream out(dir / name, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

}  // namespace video3dgs::fuzz
