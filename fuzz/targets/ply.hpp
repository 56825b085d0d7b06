#pragma once
// Fuzz target `ply`: io::decode_ply (ascii, binary little- and big-endian), then the conversion to a
// degree-3 cloud. Seeds: clouds of SH degree 0 and 3 written by io::ply_bytes, and the same files
// re-encoded as ascii and as big-endian.
#include <bit>
#include <cstring>
#include <filesystem>
#include <string>
#include <string_view>

#include "../common.hpp"
#include "video3dgs/io/ply.hpp"

namespace video3dgs::fuzz {

inline std::string ply(std::string_view bytes) {
  return run_reader([&] {
    const auto c = io::decode_ply<float>(bytes, "fuzz.ply");
    (void)c.to_cloud<3>();
  });
}

namespace detail {
template <int D>
GaussianCloud<float, D> seed_cloud(std::size_t n) {
  GaussianCloud<float, D> c(n);
  for (std::size_t i = 0; i < c.mean.size(); ++i) c.mean[i] = 0.25f * float(i % 7) - 0.5f;
  for (std::size_t i = 0; i < c.log_scale.size(); ++i) c.log_scale[i] = -2.0f - 0.1f * float(i % 3);
  for (std::size_t i = 0; i < c.rotation.size(); ++i) c.rotation[i] = i % 4 == 0 ? 1.0f : 0.1f;
  for (std::size_t i = 0; i < c.opacity_logit.size(); ++i) c.opacity_logit[i] = 0.5f;
  for (std::size_t i = 0; i < c.sh.size(); ++i) c.sh[i] = 0.01f * float(i % 11);
  return c;
}

/// The same file with its float32 body re-encoded: big-endian, or ascii (one vertex per line).
inline std::string reencode_ply(const std::string& le, bool ascii) {
  const std::size_t body = le.find("end_header\n") + 11;
  std::string header = le.substr(0, body);
  const std::string from = "binary_little_endian";
  header.replace(header.find(from), from.size(), ascii ? "ascii" : "binary_big_endian");
  std::size_t props = 0;
  for (std::size_t p = header.find("property "); p != std::string::npos; p = header.find("property ", p + 1)) ++props;
  std::string out = header;
  for (std::size_t i = body, k = 0; i + 4 <= le.size(); i += 4, ++k) {
    if (ascii) {
      float v;
      std::memcpy(&v, le.data() + i, 4);
      out += std::to_string(v);
      out += (k + 1) % props == 0 ? "\n" : " ";
    } else {
      for (int b = 3; b >= 0; --b) out.push_back(le[i + std::size_t(b)]);
    }
  }
  return out;
}
}  // namespace detail

/// Writes the seed inputs of `ply` into `dir`.
inline void ply_seeds(const std::filesystem::path& dir) {
  const std::string d0 = io::ply_bytes(detail::seed_cloud<0>(3).params());
  const std::string d3 = io::ply_bytes(detail::seed_cloud<3>(2).params());
  write_seed(dir, "d0_le.ply", d0);
  write_seed(dir, "d3_le.ply", d3);
  write_seed(dir, "d0_ascii.ply", detail::reencode_ply(d0, true));
  write_seed(dir, "d3_ascii.ply", detail::reencode_ply(d3, true));
  write_seed(dir, "d0_be.ply", detail::reencode_ply(d0, false));
}

}  // namespace video3dgs::fuzz
