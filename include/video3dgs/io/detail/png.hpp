#pragma once
/// @file
/// Minimal PNG container parsing used by image_io.hpp: the chunk walker (detects truncated files
/// precisely), the IHDR fields, and a decoder of the raw palette indices of indexed PNGs (colour
/// type 3), which stb_image would expand to RGB. Decompression uses stb's zlib
/// (`stbi_zlib_decode_malloc_guesssize_headerflag`); unfiltering and Adam7 de-interlacing follow the
/// PNG specification (ISO/IEC 15948, sections 9 and 8.2). CRCs are not verified (as in stb_image).

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <stb_image.h>

#include "video3dgs/core/error.hpp"

namespace video3dgs::io::detail {

inline constexpr std::string_view kPngSignature{"\x89PNG\r\n\x1a\n", 8};

[[nodiscard]] inline bool is_png(std::string_view bytes) noexcept { return bytes.substr(0, 8) == kPngSignature; }

[[nodiscard]] inline std::uint32_t read_be32(const char* p) noexcept {
  const auto* u = reinterpret_cast<const unsigned char*>(p);
  return (std::uint32_t(u[0]) << 24) | (std::uint32_t(u[1]) << 16) | (std::uint32_t(u[2]) << 8) | std::uint32_t(u[3]);
}

struct PngChunk {
  std::string_view type;  ///< 4 characters, e.g. "IHDR"
  std::string_view data;  ///< the chunk payload (without length, type and CRC)
};

/// The fields of the IHDR chunk.
struct PngHeader {
  int width = 0;
  int height = 0;
  int bit_depth = 0;   ///< 1, 2, 4, 8 or 16
  int color_type = 0;  ///< 0 gray, 2 RGB, 3 palette, 4 gray+alpha, 6 RGBA
  int interlace = 0;   ///< 0 none, 1 Adam7
};

/// Every chunk of a PNG file, in file order, up to and including IEND.
/// @throws io_error `io.unreadable` (not a PNG, no IHDR first) or `io.truncated` (a chunk runs past
///         the end of the file, or the file ends before IEND).
[[nodiscard]] inline std::vector<PngChunk> png_chunks(std::string_view bytes, const std::string& where) {
  if (!is_png(bytes)) throw io_error("io.unreadable", where, "not a PNG file (bad signature)");
  std::vector<PngChunk> chunks;
  std::size_t pos = 8;
  for (;;) {
    if (bytes.size() - pos < 12)
      throw io_error("io.truncated", where, "PNG file ends before its IEND chunk (" + std::to_string(bytes.size()) + " bytes)");
    const std::uint32_t len = read_be32(bytes.data() + pos);
    if (len > 0x7fffffffu || bytes.size() - pos - 12 < len)
      throw io_error("io.truncated", where,
                     "PNG chunk '" + std::string(bytes.substr(pos + 4, 4)) + "' at byte " + std::to_string(pos) +
                         " runs past the end of the file (" + std::to_string(bytes.size()) + " bytes)");
    PngChunk c{bytes.substr(pos + 4, 4), bytes.substr(pos + 8, len)};
    chunks.push_back(c);
    pos += 12 + static_cast<std::size_t>(len);
    if (c.type == "IEND") break;
  }
  if (chunks.front().type != "IHDR" || chunks.front().data.size() != 13)
    throw io_error("io.unreadable", where, "PNG file does not start with a valid IHDR chunk");
  return chunks;
}

[[nodiscard]] inline PngHeader png_header(const std::vector<PngChunk>& chunks) {
  const char* d = chunks.front().data.data();
  PngHeader h;
  h.width = static_cast<int>(read_be32(d));
  h.height = static_cast<int>(read_be32(d + 4));
  h.bit_depth = static_cast<unsigned char>(d[8]);
  h.color_type = static_cast<unsigned char>(d[9]);
  h.interlace = static_cast<unsigned char>(d[12]);
  return h;
}

/// Paeth predictor (PNG spec 9.4).
[[nodiscard]] inline int paeth(int a, int b, int c) noexcept {
  const int p = a + b - c;
  const int pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  if (pa <= pb && pa <= pc) return a;
  return pb <= pc ? b : c;
}

/// Reverses the PNG filters of one (sub-)image in place: `data` holds `rows` scanlines of
/// 1 + `row_bytes` bytes (filter type byte first); `bpp` = bytes per complete pixel (>= 1).
/// @return false on an unknown filter type.
inline bool png_unfilter(unsigned char* data, std::size_t rows, std::size_t row_bytes, std::size_t bpp) {
  const unsigned char* prev = nullptr;
  for (std::size_t r = 0; r < rows; ++r) {
    unsigned char* line = data + r * (row_bytes + 1);
    const int filter = line[0];
    unsigned char* cur = line + 1;
    for (std::size_t i = 0; i < row_bytes; ++i) {
      const int a = i >= bpp ? cur[i - bpp] : 0;
      const int b = prev ? prev[i] : 0;
      const int c = (prev && i >= bpp) ? prev[i - bpp] : 0;
      int pred = 0;
      switch (filter) {
        case 0: pred = 0; break;
        case 1: pred = a; break;
        case 2: pred = b; break;
        case 3: pred = (a + b) / 2; break;
        case 4: pred = paeth(a, b, c); break;
        default: return false;
      }
      cur[i] = static_cast<unsigned char>(cur[i] + pred);
    }
    prev = cur;
  }
  return true;
}

/// The palette index of every pixel of an indexed PNG (colour type 3, bit depth 1/2/4/8, plain or
/// Adam7-interlaced), row-major, `width * height` entries.
/// @throws io_error `io.unreadable` (not indexed, corrupt data) or `io.truncated` (too little data).
[[nodiscard]] inline std::vector<std::uint8_t> png_palette_indices(const std::vector<PngChunk>& chunks,
                                                                   const std::string& where) {
  const PngHeader h = png_header(chunks);
  if (h.color_type != 3) throw io_error("io.unreadable", where, "not an indexed (palette) PNG");
  if (h.bit_depth != 1 && h.bit_depth != 2 && h.bit_depth != 4 && h.bit_depth != 8)
    throw io_error("io.unreadable", where, "invalid bit depth " + std::to_string(h.bit_depth) + " for a palette PNG");
  if (h.width <= 0 || h.height <= 0 || h.width > (1 << 24) || h.height > (1 << 24))
    throw io_error("io.unreadable", where, "invalid PNG size");
  std::string idat;
  for (const auto& c : chunks)
    if (c.type == "IDAT") idat.append(c.data);
  if (idat.empty()) throw io_error("io.truncated", where, "PNG file has no image data (IDAT)");

  struct Pass { int x0, y0, dx, dy; };
  static constexpr Pass kAdam7[7] = {{0, 0, 8, 8}, {4, 0, 8, 8}, {0, 4, 4, 8}, {2, 0, 4, 4},
                                     {0, 2, 2, 4}, {1, 0, 2, 2}, {0, 1, 1, 2}};
  static constexpr Pass kSingle[1] = {{0, 0, 1, 1}};
  const Pass* passes = h.interlace ? kAdam7 : kSingle;
  const int pass_count = h.interlace ? 7 : 1;
  auto pass_size = [](int n, int start, int step) { return n > start ? (n - start + step - 1) / step : 0; };

  std::size_t expected = 0;
  for (int p = 0; p < pass_count; ++p) {
    const std::size_t pw = static_cast<std::size_t>(pass_size(h.width, passes[p].x0, passes[p].dx));
    const std::size_t ph = static_cast<std::size_t>(pass_size(h.height, passes[p].y0, passes[p].dy));
    if (pw && ph) expected += ph * (1 + (pw * static_cast<std::size_t>(h.bit_depth) + 7) / 8);
  }
  if (expected > 0x7fffffff) throw io_error("io.unreadable", where, "PNG too large");

  int out_len = 0;
  std::unique_ptr<char, void (*)(void*)> raw(
      stbi_zlib_decode_malloc_guesssize_headerflag(idat.data(), static_cast<int>(idat.size()),
                                                   static_cast<int>(expected) + 1, &out_len, 1),
      stbi_image_free);
  if (!raw) throw io_error("io.unreadable", where, "corrupt compressed PNG image data");
  if (static_cast<std::size_t>(out_len) < expected)
    throw io_error("io.truncated", where,
                   "PNG image data is short: " + std::to_string(out_len) + " of " + std::to_string(expected) + " bytes");

  std::vector<std::uint8_t> indices(static_cast<std::size_t>(h.width) * static_cast<std::size_t>(h.height));
  auto* bytes = reinterpret_cast<unsigned char*>(raw.get());
  std::size_t offset = 0;
  const unsigned mask = (1u << h.bit_depth) - 1u;
  for (int p = 0; p < pass_count; ++p) {
    const int pw = pass_size(h.width, passes[p].x0, passes[p].dx);
    const int ph = pass_size(h.height, passes[p].y0, passes[p].dy);
    if (pw == 0 || ph == 0) continue;
    const std::size_t row_bytes = (static_cast<std::size_t>(pw) * static_cast<std::size_t>(h.bit_depth) + 7) / 8;
    unsigned char* sub = bytes + offset;
    if (!png_unfilter(sub, static_cast<std::size_t>(ph), row_bytes, 1))
      throw io_error("io.unreadable", where, "invalid PNG filter type");
    for (int y = 0; y < ph; ++y) {
      const unsigned char* line = sub + static_cast<std::size_t>(y) * (row_bytes + 1) + 1;
      const std::size_t out_row = static_cast<std::size_t>(passes[p].y0 + y * passes[p].dy) * static_cast<std::size_t>(h.width);
      for (int x = 0; x < pw; ++x) {
        const std::size_t bit = static_cast<std::size_t>(x) * static_cast<std::size_t>(h.bit_depth);
        const unsigned byte = line[bit / 8];
        const unsigned shift = 8u - static_cast<unsigned>(h.bit_depth) - static_cast<unsigned>(bit % 8);
        indices[out_row + static_cast<std::size_t>(passes[p].x0 + x * passes[p].dx)] =
            static_cast<std::uint8_t>((byte >> shift) & mask);
      }
    }
    offset += static_cast<std::size_t>(ph) * (row_bytes + 1);
  }
  return indices;
}

}  // namespace video3dgs::io::detail
