#pragma once
/// @file
/// Versioned little-endian binary records for checkpoints and models.
///
/// A file is a header `magic (8 bytes) | u32 version` followed by fields written in order. Every
/// read is bounds-checked: a short file raises `[io.truncated] <file>: <field> ...`, a wrong magic
/// `[io.format]`, a newer version `[io.version]`, always naming the file and the field being read.

#include <bit>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "video3dgs/core/error.hpp"

namespace video3dgs::io {

static_assert(std::endian::native == std::endian::little,
              "video3dgs: the binary formats are little-endian; add byte swapping for this platform");

/// Appends fields to an in-memory buffer (write it with write_file_atomic).
class BinaryWriter {
 public:
  BinaryWriter(std::string_view magic, std::uint32_t version) {
    std::string m(magic);
    m.resize(8, '\0');
    buf_ += m;
    put(version);
  }
  template <class T>
    requires std::is_trivially_copyable_v<T>
  void put(const T& v) {
    buf_.append(reinterpret_cast<const char*>(&v), sizeof(T));
  }
  /// A length-prefixed array of trivially copyable values.
  template <class T>
    requires std::is_trivially_copyable_v<T>
  void put_array(std::span<const T> v) {
    put<std::uint64_t>(v.size());
    if (!v.empty()) buf_.append(reinterpret_cast<const char*>(v.data()), v.size_bytes());
  }
  template <class T>
  void put_vector(const std::vector<T>& v) {
    put_array(std::span<const T>(v));
  }
  void put_string(std::string_view s) {
    put<std::uint64_t>(s.size());
    buf_ += s;
  }
  [[nodiscard]] const std::string& bytes() const noexcept { return buf_; }

 private:
  std::string buf_;
};

/// Reads fields back with bounds checks; `file` is used in error messages.
class BinaryReader {
 public:
  /// Checks the magic and that the version is <= `max_version`; the version read is `version()`.
  BinaryReader(std::string_view bytes, std::string file, std::string_view magic, std::uint32_t max_version)
      : bytes_(bytes), file_(std::move(file)) {
    std::string m(magic);
    m.resize(8, '\0');
    if (bytes_.size() < 12 || bytes_.substr(0, 8) != m)
      throw io_error("io.format", file_, "not a " + std::string(magic) + " file (bad magic)");
    pos_ = 8;
    version_ = get<std::uint32_t>("version");
    if (version_ > max_version)
      throw io_error("io.version", file_,
                     "format version " + std::to_string(version_) + " is newer than supported (" +
                         std::to_string(max_version) + ")");
  }
  [[nodiscard]] std::uint32_t version() const noexcept { return version_; }
  [[nodiscard]] std::size_t remaining() const noexcept { return bytes_.size() - pos_; }
  [[nodiscard]] const std::string& file() const noexcept { return file_; }

  template <class T>
    requires std::is_trivially_copyable_v<T>
  [[nodiscard]] T get(std::string_view field) {
    need(sizeof(T), field);
    T v;
    std::memcpy(&v, bytes_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  /// Reads a length-prefixed array; a count larger than the bytes left raises io.truncated before
  /// anything is allocated.
  template <class T>
    requires std::is_trivially_copyable_v<T>
  [[nodiscard]] std::vector<T> get_vector(std::string_view field) {
    const auto n = get<std::uint64_t>(field);
    if (n > remaining() / sizeof(T))
      throw io_error("io.truncated", file_,
                     "file ends inside field '" + std::string(field) + "' (" + std::to_string(n) +
                         " elements announced, " + std::to_string(remaining()) + " bytes left)");
    std::vector<T> v(static_cast<std::size_t>(n));
    if (n) std::memcpy(v.data(), bytes_.data() + pos_, static_cast<std::size_t>(n) * sizeof(T));
    pos_ += static_cast<std::size_t>(n) * sizeof(T);
    return v;
  }
  [[nodiscard]] std::string get_string(std::string_view field) {
    const auto v = get_vector<char>(field);
    return std::string(v.begin(), v.end());
  }
  /// Throws `io.format` unless the whole buffer was consumed.
  void expect_end() const {
    if (pos_ != bytes_.size())
      throw io_error("io.format", file_, std::to_string(bytes_.size() - pos_) + " unexpected trailing bytes");
  }

 private:
  void need(std::size_t n, std::string_view field) const {
    if (n > bytes_.size() - pos_)
      throw io_error("io.truncated", file_,
                     "file ends inside field '" + std::string(field) + "' (needs " + std::to_string(n) +
                         " bytes at offset " + std::to_string(pos_) + ", has " + std::to_string(bytes_.size() - pos_) + ")");
  }
  std::string_view bytes_;
  std::string file_;
  std::size_t pos_ = 0;
  std::uint32_t version_ = 0;
};

}  // namespace video3dgs::io
