#pragma once
// A tiny, independent PNG encoder for tests: any colour type / bit depth, optional palette, optional
// Adam7 interlacing, every filter type (row r of a pass uses filter r % 5), zlib "stored" blocks.
// It lets the tests build indexed and 16-bit PNGs that stb_image_write cannot produce.
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace video3dgs::test {

inline std::uint32_t crc32(const std::string& s) {
  std::uint32_t c = 0xffffffffu;
  for (unsigned char b : s) {
    c ^= b;
    for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
  }
  return c ^ 0xffffffffu;
}

inline void put_be32(std::string& s, std::uint32_t v) {
  for (int k = 3; k >= 0; --k) s.push_back(static_cast<char>((v >> (8 * k)) & 0xff));
}

inline void put_chunk(std::string& png, const std::string& type, const std::string& data) {
  put_be32(png, static_cast<std::uint32_t>(data.size()));
  const std::string body = type + data;
  png += body;
  put_be32(png, crc32(body));
}

/// zlib stream of stored (uncompressed) deflate blocks.
inline std::string zlib_stored(const std::string& raw) {
  std::string z = "\x78\x01";
  std::size_t pos = 0;
  do {
    const std::size_t n = std::min<std::size_t>(65535, raw.size() - pos);
    const bool last = pos + n == raw.size();
    z.push_back(last ? 1 : 0);
    z.push_back(static_cast<char>(n & 0xff));
    z.push_back(static_cast<char>(n >> 8));
    z.push_back(static_cast<char>(~n & 0xff));
    z.push_back(static_cast<char>((~n >> 8) & 0xff));
    z += raw.substr(pos, n);
    pos += n;
  } while (pos < raw.size());
  std::uint32_t a = 1, b = 0;
  for (unsigned char c : raw) {
    a = (a + c) % 65521;
    b = (b + a) % 65521;
  }
  put_be32(z, (b << 16) | a);
  return z;
}

inline int paeth_predict(int a, int b, int c) {
  const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  if (pa <= pb && pa <= pc) return a;
  return pb <= pc ? b : c;
}

/// samples: width*height*channels values (each < 2^bit_depth), row-major.
/// color_type: 0 gray, 2 RGB, 3 palette, 4 gray+alpha, 6 RGBA. palette: RGB triplets.
inline std::string encode_test_png(int width, int height, int bit_depth, int color_type,
                                   const std::vector<unsigned>& samples, const std::vector<unsigned char>& palette = {},
                                   bool interlace = false) {
  const int channels = color_type == 2 ? 3 : color_type == 4 ? 2 : color_type == 6 ? 4 : 1;
  const int bits_pp = bit_depth * channels;
  const int bpp = std::max(1, bits_pp / 8);
  struct Pass { int x0, y0, dx, dy; };
  const std::vector<Pass> passes = interlace
      ? std::vector<Pass>{{0, 0, 8, 8}, {4, 0, 8, 8}, {0, 4, 4, 8}, {2, 0, 4, 4}, {0, 2, 2, 4}, {1, 0, 2, 2}, {0, 1, 1, 2}}
      : std::vector<Pass>{{0, 0, 1, 1}};
  std::string raw;
  for (const Pass& p : passes) {
    const int pw = width > p.x0 ? (width - p.x0 + p.dx - 1) / p.dx : 0;
    const int ph = height > p.y0 ? (height - p.y0 + p.dy - 1) / p.dy : 0;
    if (pw == 0 || ph == 0) continue;
    const std::size_t row_bytes = (static_cast<std::size_t>(pw) * bits_pp + 7) / 8;
    std::vector<unsigned char> prev(row_bytes, 0);
    for (int r = 0; r < ph; ++r) {
      std::vector<unsigned char> line(row_bytes, 0);
      for (int x = 0; x < pw; ++x) {
        const std::size_t px = static_cast<std::size_t>(p.y0 + r * p.dy) * width + (p.x0 + x * p.dx);
        for (int c = 0; c < channels; ++c) {
          const unsigned v = samples[px * channels + c];
          const std::size_t bit = (static_cast<std::size_t>(x) * channels + c) * bit_depth;
          if (bit_depth == 16) {
            line[bit / 8] = static_cast<unsigned char>(v >> 8);
            line[bit / 8 + 1] = static_cast<unsigned char>(v & 0xff);
          } else {
            line[bit / 8] |= static_cast<unsigned char>(v << (8 - bit_depth - bit % 8));
          }
        }
      }
      const int filter = r % 5;
      raw.push_back(static_cast<char>(filter));
      for (std::size_t i = 0; i < row_bytes; ++i) {
        const int a = i >= static_cast<std::size_t>(bpp) ? line[i - bpp] : 0;
        const int b = r > 0 ? prev[i] : 0;
        const int c = (r > 0 && i >= static_cast<std::size_t>(bpp)) ? prev[i - bpp] : 0;
        const int pred = filter == 0 ? 0 : filter == 1 ? a : filter == 2 ? b : filter == 3 ? (a + b) / 2 : paeth_predict(a, b, c);
        raw.push_back(static_cast<char>((line[i] - pred) & 0xff));
      }
      prev = line;
    }
  }
  std::string png("\x89PNG\r\n\x1a\n", 8);
  std::string ihdr;
  put_be32(ihdr, static_cast<std::uint32_t>(width));
  put_be32(ihdr, static_cast<std::uint32_t>(height));
  ihdr.push_back(static_cast<char>(bit_depth));
  ihdr.push_back(static_cast<char>(color_type));
  ihdr.push_back(0);
  ihdr.push_back(0);
  ihdr.push_back(interlace ? 1 : 0);
  put_chunk(png, "IHDR", ihdr);
  if (color_type == 3) put_chunk(png, "PLTE", std::string(palette.begin(), palette.end()));
  put_chunk(png, "IDAT", zlib_stored(raw));
  put_chunk(png, "IEND", "");
  return png;
}

inline void write_bytes(const std::filesystem::path& p, const std::string& bytes) {
  std::ofstream(p, std::ios::binary) << bytes;
}

/// A fresh empty folder under the system temp dir, unique per process (removed first if it exists).
inline std::filesystem::path fresh_temp_dir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("video3dgs_test_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace video3dgs::test
