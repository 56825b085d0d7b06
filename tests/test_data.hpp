#pragma once
// Shared helpers for tests: where ../shared/data is, skipping (or failing) when it is missing, and a
// seeded RNG that says its seed.
#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>

#include <unistd.h>

#include <doctest/doctest.h>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"

namespace video3dgs::test {

/// The shared real data folder (`../shared/data` beside the repository, or env VIDEO3DGS_SHARED_DATA),
/// or empty if absent.
inline std::filesystem::path shared_data_dir() {
  std::filesystem::path p = VIDEO3DGS_SHARED_DATA;
  if (const char* env = std::getenv("VIDEO3DGS_SHARED_DATA")) p = env;
  return p;
}
inline std::filesystem::path shared_data() {
  const auto p = shared_data_dir();
  std::error_code ec;
  return std::filesystem::is_directory(p, ec) ? p : std::filesystem::path{};
}

// Tests that need what the test environment provides (../shared/data, or a program scripts/setup.sh
// installs such as colmap) are tagged `* doctest::test_suite("shared_data")` (data) or
// `* doctest::test_suite("needs_program")` (a program only); tests/CMakeLists.txt runs them as their own
// ctest entry <folder>_shared_data. When what they need is missing they call skip():
//  - with env VIDEO3DGS_REQUIRE_SHARED_DATA=1 (set by .ci/run) that is a test FAILURE naming it;
//  - otherwise skip() prints "skipped: ..." and counts it, and tests/main.cpp then returns 77 (ctest's
//    SKIP_RETURN_CODE) when no test failed: ctest reports the entry as skipped, never as passed.

/// True when env VIDEO3DGS_REQUIRE_SHARED_DATA is set to anything but "" or "0".
inline bool shared_data_required() {
  const char* env = std::getenv("VIDEO3DGS_REQUIRE_SHARED_DATA");
  return env && *env && std::string(env) != "0";
}

/// How many times skip() was called in this run (read by tests/main.cpp).
inline std::atomic<int> skipped_count{0};

/// Skips the rest of what needs `what` (the caller returns): FAILs under VIDEO3DGS_REQUIRE_SHARED_DATA.
inline void skip(const std::string& what) {
  if (shared_data_required()) FAIL(what << " (required: VIDEO3DGS_REQUIRE_SHARED_DATA is set)");
  ++skipped_count;
  MESSAGE("skipped: " << what);
}

/// `shared_data()/rel` if present; otherwise skip()s ("shared data 'rel' not found") and returns empty.
inline std::filesystem::path shared_data_or_skip(const std::string& rel) {
  const auto p = shared_data_dir() / rel;
  std::error_code ec;
  if (!std::filesystem::exists(p, ec)) {
    skip("shared data '" + rel + "' not found (looked for " + p.string() + ")");
    return {};
  }
  return p;
}

/// A fresh, empty folder temp/video3dgs_<name>_<pid> (what was there is removed).
inline std::filesystem::path fresh_dir(const std::string& name) {
  const std::filesystem::path p = std::filesystem::temp_directory_path() / ("video3dgs_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(p);
  std::filesystem::create_directories(p);
  return p;
}

/// A seeded engine for property tests; write `INFO("seed " << seed)` in the test so a failure
/// prints the seed to replay.
inline std::mt19937_64 seeded_rng(std::uint64_t seed) { return std::mt19937_64(seed); }

/// The id (or the place at fault) of the video3dgs::error that f() throws, or "<no error>".
template <class F>
std::string error_id(F&& f) {
  try {
    f();
  } catch (const video3dgs::error& e) {
    return e.id();
  }
  return "<no error>";
}

template <class F>
std::string error_where(F&& f) {
  try {
    f();
  } catch (const video3dgs::error& e) {
    return e.where();
  }
  return "<no error>";
}

/// A w x h image of values drawn uniformly from [lo, hi) by a seeded engine.
template <class Scalar, int C>
Image<Scalar, C> random_image(int w, int h, std::uint64_t seed, double lo = 0.0, double hi = 1.0) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> d(lo, hi);
  Image<Scalar, C> img(w, h);
  for (auto& v : img.storage()) v = static_cast<Scalar>(d(rng));
  return img;
}

}  // namespace video3dgs::test
