#pragma once
/// @file
/// zlib streams (RFC 1950: deflate + Adler-32) for the compact model format
/// (model/compact_io.hpp). `deflate_bytes` is deterministic for a given zlib build and level;
/// `inflate_bytes` decodes into a buffer of the announced size and checks, before allocating, that the
/// size is one deflate can produce from the bytes given:
///
///     raw <= kMaxInflateRatio * packed + kInflateSlack
///
/// (a deflate block expands at most 1032:1, RFC 1951's longest match 258 bytes in 2 bits; 1100:1 keeps
/// a margin), so a few corrupt length bytes can never make the reader allocate gigabytes.
///
/// Errors (naming the file): `io.format` for a size beyond that bound, a corrupt stream (bad header,
/// data or checksum), a stream that ends early or decodes to another size than announced.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <string_view>

#include <zlib.h>

#include "video3dgs/core/error.hpp"

namespace video3dgs::io::detail {

/// CRC-32 (zlib's crc32: ISO-HDLC polynomial 0xEDB88320 reflected) of `bytes`. Unlike Adler-32 it
/// detects every error burst of up to 32 bits (Adler-32 misses, for example, +a, -2a, +a in three
/// consecutive bytes, which leaves both of its sums unchanged).
[[nodiscard]] inline std::uint32_t crc32_of(std::string_view bytes) {
  uLong c = crc32(0L, Z_NULL, 0);
  std::size_t at = 0;
  while (at < bytes.size()) {  // crc32 takes a uInt length
    const std::size_t n = std::min<std::size_t>(bytes.size() - at, std::numeric_limits<uInt>::max());
    c = crc32(c, reinterpret_cast<const Bytef*>(bytes.data() + at), static_cast<uInt>(n));
    at += n;
  }
  return static_cast<std::uint32_t>(c);
}

inline constexpr std::uint64_t kMaxInflateRatio = 1100;
inline constexpr std::uint64_t kInflateSlack = 1024;

/// One zlib stream of `raw` at `level` (0..9). @throws io_error `io.unwritable` if zlib fails
/// (out of memory), naming `what`.
[[nodiscard]] inline std::string deflate_bytes(std::string_view raw, int level, const std::string& what) {
  uLongf size = compressBound(static_cast<uLong>(raw.size()));
  std::string out(static_cast<std::size_t>(size), '\0');
  const int rc = compress2(reinterpret_cast<Bytef*>(out.data()), &size, reinterpret_cast<const Bytef*>(raw.data()),
                           static_cast<uLong>(raw.size()), level);
  if (rc != Z_OK) throw io_error("io.unwritable", what, "zlib compression failed (code " + std::to_string(rc) + ")");
  out.resize(static_cast<std::size_t>(size));
  return out;
}

/// Decodes the zlib stream `packed`, which must hold exactly `raw_size` bytes and nothing after it.
/// `file` and `what` (the part being read) name the place in errors. @throws io_error `io.format`.
[[nodiscard]] inline std::string inflate_bytes(std::string_view packed, std::uint64_t raw_size, const std::string& file,
                                               const std::string& what) {
  auto bad = [&](const std::string& why) { throw io_error("io.format", file, what + ": " + why); };
  if (raw_size > kMaxInflateRatio * std::uint64_t(packed.size()) + kInflateSlack)
    bad("announced size " + std::to_string(raw_size) + " is more than a zlib stream of " + std::to_string(packed.size()) +
        " bytes can hold");
  std::string out(static_cast<std::size_t>(raw_size), '\0');
  z_stream z{};
  if (inflateInit(&z) != Z_OK) throw io_error("io.format", file, what + ": zlib cannot start (out of memory)");
  // uInt is 32-bit: feed input and output in pieces.
  constexpr std::size_t kPiece = std::size_t(std::numeric_limits<uInt>::max());
  std::size_t in_pos = 0, out_pos = 0;
  int rc = Z_OK;
  while (rc == Z_OK) {
    const std::size_t in_n = std::min(kPiece, packed.size() - in_pos);
    const std::size_t out_n = std::min(kPiece, out.size() - out_pos);
    z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(packed.data() + in_pos));
    z.avail_in = static_cast<uInt>(in_n);
    z.next_out = reinterpret_cast<Bytef*>(out.data() + out_pos);
    z.avail_out = static_cast<uInt>(out_n);
    rc = inflate(&z, Z_NO_FLUSH);
    in_pos += in_n - z.avail_in;
    out_pos += out_n - z.avail_out;
    // No progress with input left and output room left cannot happen in a valid stream.
    if (rc == Z_BUF_ERROR || (rc == Z_OK && in_n == z.avail_in && out_n == z.avail_out)) break;
  }
  inflateEnd(&z);
  if (rc == Z_STREAM_END) {
    if (out_pos != out.size()) bad("decodes to " + std::to_string(out_pos) + " bytes, " + std::to_string(raw_size) + " announced");
    if (in_pos != packed.size()) bad(std::to_string(packed.size() - in_pos) + " bytes after the end of the zlib stream");
    return out;
  }
  if (rc == Z_DATA_ERROR || rc == Z_NEED_DICT || rc == Z_STREAM_ERROR) bad("corrupt zlib stream");
  if (out_pos == out.size()) bad("decodes to more than the " + std::to_string(raw_size) + " bytes announced");
  throw io_error("io.format", file, what + ": the zlib stream ends early");
}

}  // namespace video3dgs::io::detail
