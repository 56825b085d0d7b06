#pragma once
/// @file
/// Middlebury `.flo` files (the format RAFT, PWC-Net and FlowNet write):
///
///   float32 202021.25 ("PIEH" as bytes), int32 width, int32 height,
///   then width x height x 2 float32 (u, v interleaved, row-major), all little-endian.
///
/// Values >= 1e9 in magnitude mark unknown flow (Middlebury convention); they are read as NaN so
/// that warping marks those pixels invalid.

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/flow/warp.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/io/frame_folder.hpp"
#include "video3dgs/io/image_io.hpp"

namespace video3dgs::flow {

inline constexpr float kFloMagic = 202021.25f;

namespace detail {
template <class T>
T load_le(const char* p) noexcept {
  static_assert(sizeof(T) == 4, "32-bit fields only");
  std::uint32_t u;
  std::memcpy(&u, p, 4);
  if constexpr (std::endian::native == std::endian::big) u = (u >> 24) | ((u >> 8) & 0xff00u) | ((u << 8) & 0xff0000u) | (u << 24);
  T v;
  std::memcpy(&v, &u, 4);
  return v;
}
template <class T>
void store_le(std::string& out, T v) {
  static_assert(sizeof(T) == 4, "32-bit fields only");
  std::uint32_t u;
  std::memcpy(&u, &v, 4);
  if constexpr (std::endian::native == std::endian::big) u = (u >> 24) | ((u >> 8) & 0xff00u) | ((u << 8) & 0xff0000u) | (u << 24);
  char b[4];
  std::memcpy(b, &u, 4);
  out.append(b, 4);
}
}  // namespace detail

/// Decodes a .flo file held in memory. @throws io_error `io.format` (bad magic, size), `io.truncated`
[[nodiscard]] inline FlowFieldF decode_flo(std::string_view bytes, const std::string& where = "<memory>") {
  if (bytes.size() < 12) throw io_error("io.truncated", where, "shorter than the 12-byte .flo header");
  if (detail::load_le<float>(bytes.data()) != kFloMagic) throw io_error("io.format", where, "not a .flo file (bad magic)");
  const std::int32_t w = detail::load_le<std::int32_t>(bytes.data() + 4);
  const std::int32_t h = detail::load_le<std::int32_t>(bytes.data() + 8);
  if (w <= 0 || h <= 0 || w > (1 << 16) || h > (1 << 16))
    throw io_error("io.format", where, "implausible size " + std::to_string(w) + "x" + std::to_string(h));
  const std::size_t need = 12 + std::size_t(w) * std::size_t(h) * 8;
  if (bytes.size() < need)
    throw io_error("io.truncated", where, "holds " + std::to_string(bytes.size()) + " bytes, needs " + std::to_string(need));
  if (bytes.size() > need) throw io_error("io.format", where, "has " + std::to_string(bytes.size() - need) + " trailing bytes");
  FlowFieldF f(w, h);
  const char* p = bytes.data() + 12;
  for (std::size_t i = 0; i < f.size(); ++i, p += 4) {
    const float v = detail::load_le<float>(p);
    f.data()[i] = std::fabs(v) >= 1e9f ? std::numeric_limits<float>::quiet_NaN() : v;
  }
  return f;
}

/// Reads a .flo file. @throws io_error `io.missing`, `io.unreadable`, `io.format`, `io.truncated`
[[nodiscard]] inline FlowFieldF read_flo(const std::filesystem::path& path) {
  return decode_flo(io::detail::read_file_bytes(path), path.string());
}

/// Encodes a flow field as .flo bytes (non-finite values are written as the 1e10 "unknown" marker).
template <class Scalar>
[[nodiscard]] std::string encode_flo(ConstImageView<Scalar, 2> f) {
  std::string out;
  out.reserve(12 + f.pixel_count() * 8);
  detail::store_le<float>(out, kFloMagic);
  detail::store_le<std::int32_t>(out, f.width());
  detail::store_le<std::int32_t>(out, f.height());
  for (int y = 0; y < f.height(); ++y)
    for (int x = 0; x < 2 * f.width(); ++x) {
      const float v = static_cast<float>(f.row(y)[x]);
      detail::store_le<float>(out, std::isfinite(v) ? v : 1e10f);
    }
  return out;
}

/// Writes a .flo file atomically. @throws io_error `io.unwritable`
template <class Scalar>
void write_flo(const std::filesystem::path& path, const FlowField<Scalar>& f) {
  io::write_file_atomic(path, encode_flo<Scalar>(f.view()));
}

/// Every `.flo` file of a folder in natural order (`00000.flo`, `00001.flo`, ...).
/// @throws io_error `io.missing` (no folder), `io.empty` (no .flo file)
[[nodiscard]] inline std::vector<std::filesystem::path> list_flo_files(const std::filesystem::path& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw io_error("io.missing", dir.string(), "no such folder");
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    if (e.is_regular_file(ec) && e.path().extension() == ".flo" && !name.empty() && name[0] != '.') files.push_back(e.path());
  }
  if (files.empty()) throw io_error("io.empty", dir.string(), "holds no .flo file");
  std::sort(files.begin(), files.end(),
            [](const fs::path& a, const fs::path& b) { return io::natural_less(a.filename().string(), b.filename().string()); });
  return files;
}

}  // namespace video3dgs::flow
