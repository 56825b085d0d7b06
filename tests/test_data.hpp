#pragma once
// Shared helpers for tests: where ../shared/data is, and a seeded RNG that says its seed.
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>

#include <doctest/doctest.h>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"

namespace video3dgs::test {

/// The shared real data folder (`../shared/data` beside the repository), or empty if absent.
inline std::filesystem::path shared_data() {
  std::filesystem::path p = VIDEO3DGS_SHARED_DATA;
  if (const char* env = std::getenv("VIDEO3DGS_SHARED_DATA")) p = env;
  std::error_code ec;
  return std::filesystem::is_directory(p, ec) ? p : std::filesystem::path{};
}

/// `shared_data()/rel` if present; otherwise prints why the test is skipped and returns empty.
inline std::filesystem::path shared_data_or_skip(const std::string& rel) {
  const auto root = shared_data();
  std::error_code ec;
  if (root.empty() || !std::filesystem::exists(root / rel, ec)) {
    MESSAGE("skipped: shared data '" << rel << "' not found");
    return {};
  }
  return root / rel;
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
