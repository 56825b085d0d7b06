#pragma once
/// @file
/// PNG decoding through libpng (used by image_io.hpp for every PNG). libpng rather than stb_image for
/// PNGs because it can return the raw palette indices of indexed PNGs (DAVIS annotations: object ids),
/// which stb always expands to colours, and because a read callback that runs out of bytes tells a
/// truncated file (`io.truncated`) from a corrupt one (`io.unreadable`: bad CRC, bad zlib data).
///
/// libpng reports errors by longjmp; `png_read_c` is the only function that calls setjmp, and it
/// holds nothing with a destructor between setjmp and any libpng call (its buffers belong to the
/// caller's `PngPixels`).

#include <csetjmp>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <string_view>
#include <vector>

#include <png.h>

#include "video3dgs/core/error.hpp"

namespace video3dgs::io {

/// The largest image the readers decode, in pixels: 2^25 (8K UHD, 7680x4320, fits). A file whose header
/// says more raises `io.unsupported` before any pixel buffer is allocated. The fuzz targets define
/// VIDEO3DGS_MAX_IMAGE_PIXELS lower (the same checks, but small inputs cannot make every execution
/// allocate and fill hundreds of megabytes); a program must use one value in all its files.
#ifndef VIDEO3DGS_MAX_IMAGE_PIXELS
#define VIDEO3DGS_MAX_IMAGE_PIXELS (std::size_t(1) << 25)
#endif
inline constexpr std::size_t kMaxImagePixels = VIDEO3DGS_MAX_IMAGE_PIXELS;

}  // namespace video3dgs::io

namespace video3dgs::io::detail {

inline constexpr std::string_view kPngSignature{"\x89PNG\r\n\x1a\n", 8};

[[nodiscard]] inline bool is_png(std::string_view bytes) noexcept { return bytes.substr(0, 8) == kPngSignature; }

/// A decoded PNG: samples widened to 8 bits (bit depth <= 8; `max_value` 255) or 16 bits (65535),
/// interleaved, host order. Palette images: the indices (1 channel) when read raw, else RGB or RGBA
/// (with a tRNS chunk); a tRNS chunk of a grey or RGB image becomes an alpha channel (as stb_image does).
struct PngPixels {
  int width = 0, height = 0, channels = 0;
  int max_value = 255;
  bool palette = false;                 ///< the file is an indexed (colour type 3) PNG
  std::vector<std::uint16_t> values;    ///< width * height * channels
  // Scratch owned here so that a longjmp out of libpng never skips a destructor.
  std::vector<unsigned char> bytes;
  std::vector<unsigned char*> rows;
};

struct PngReader {
  const unsigned char* data = nullptr;
  std::size_t size = 0, pos = 0;
  bool ran_out = false;   ///< the file ended before libpng was done: truncated
  bool too_large = false; ///< more than kMaxImagePixels pixels
  char message[200] = {};
};

inline void png_read_bytes(png_structp png, png_bytep out, std::size_t n) {
  auto* r = static_cast<PngReader*>(png_get_io_ptr(png));
  if (n > r->size - r->pos) {
    r->ran_out = true;
    png_error(png, "the file ends early");
  }
  std::memcpy(out, r->data + r->pos, n);
  r->pos += n;
}

inline void png_on_error(png_structp png, png_const_charp message) {
  auto* r = static_cast<PngReader*>(png_get_error_ptr(png));
  std::snprintf(r->message, sizeof(r->message), "%s", message);
  png_longjmp(png, 1);
}

inline void png_on_warning(png_structp, png_const_charp) {}

/// The libpng calls. Returns false on any error (message in `r`); `out` is then unspecified.
/// `header_only`: stops after the header and sets only width, height, channels (as a decode without raw
/// indices returns them, a tRNS chunk counted as alpha), max_value and palette; no size checks.
inline bool png_read_c(PngReader& r, bool raw_indices, bool header_only, PngPixels& out) {
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &r, png_on_error, png_on_warning);
  if (png == nullptr) return false;
  png_infop info = png_create_info_struct(png);
  if (info == nullptr) {
    png_destroy_read_struct(&png, nullptr, nullptr);
    return false;
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    return false;
  }
  png_set_read_fn(png, &r, png_read_bytes);
  png_read_info(png, info);
  const int colour = png_get_color_type(png, info), depth = png_get_bit_depth(png, info);
  const bool trns = png_get_valid(png, info, PNG_INFO_tRNS) != 0;
  out.palette = colour == PNG_COLOR_TYPE_PALETTE;
  if (header_only) {
    out.width = static_cast<int>(png_get_image_width(png, info));
    out.height = static_cast<int>(png_get_image_height(png, info));
    out.channels = out.palette ? (trns ? 4 : 3) : png_get_channels(png, info) + (trns ? 1 : 0);
    out.max_value = depth == 16 ? 65535 : 255;
    png_destroy_read_struct(&png, &info, nullptr);
    return true;
  }
  {
    const std::uint64_t w = png_get_image_width(png, info), h = png_get_image_height(png, info);
    if (w * h > kMaxImagePixels) {
      r.too_large = true;
      png_error(png, "image too large");
    }
    // Deflate expands at most 1032:1, so the file must hold at least 1/1032 of the raw rows' bytes.
    if (h * png_get_rowbytes(png, info) / 1032 > r.size) {
      r.ran_out = true;
      png_error(png, "the file is too short for its image size");
    }
  }
  if (out.palette && raw_indices) {
    png_set_packing(png);  // 1, 2, 4-bit indices -> one byte each, values unchanged
  } else {
    if (out.palette) png_set_palette_to_rgb(png);
    if (colour == PNG_COLOR_TYPE_GRAY && depth < 8) png_set_expand_gray_1_2_4_to_8(png);  // scaled to 0..255
    if (trns) png_set_tRNS_to_alpha(png);
  }
  (void)png_set_interlace_handling(png);  // Adam7: png_read_image runs every pass
  png_read_update_info(png, info);
  out.width = static_cast<int>(png_get_image_width(png, info));
  out.height = static_cast<int>(png_get_image_height(png, info));
  out.channels = png_get_channels(png, info);
  out.max_value = png_get_bit_depth(png, info) == 16 ? 65535 : 255;
  const std::size_t row_bytes = png_get_rowbytes(png, info);
  out.bytes.resize(row_bytes * static_cast<std::size_t>(out.height));
  out.rows.resize(static_cast<std::size_t>(out.height));
  for (std::size_t y = 0; y < out.rows.size(); ++y) out.rows[y] = out.bytes.data() + y * row_bytes;
  png_read_image(png, out.rows.data());
  png_read_end(png, nullptr);  // up to IEND: a file cut after its image data is still truncated
  png_destroy_read_struct(&png, &info, nullptr);
  return true;
}

/// Decodes a PNG held in memory. @throws io_error `io.truncated` (ends early), `io.unreadable`.
[[nodiscard]] inline PngPixels decode_png(std::string_view bytes, const std::string& where, bool raw_indices) {
  PngReader r;
  r.data = reinterpret_cast<const unsigned char*>(bytes.data());
  r.size = bytes.size();
  PngPixels p;
  if (!png_read_c(r, raw_indices, false, p)) {
    if (r.too_large)
      throw io_error("io.unsupported", where, "image larger than " + std::to_string(kMaxImagePixels) + " pixels (8K UHD is the limit)");
    if (r.ran_out) throw io_error("io.truncated", where, "PNG file ends early (cut short?)");
    throw io_error("io.unreadable", where, std::string("cannot decode PNG (") + (r.message[0] ? r.message : "libpng failed") + ")");
  }
  const std::size_t n = static_cast<std::size_t>(p.width) * static_cast<std::size_t>(p.height) * static_cast<std::size_t>(p.channels);
  p.values.resize(n);
  if (p.max_value == 65535) {
    for (std::size_t i = 0; i < n; ++i)  // PNG stores 16-bit samples big-endian
      p.values[i] = static_cast<std::uint16_t>((p.bytes[2 * i] << 8) | p.bytes[2 * i + 1]);
  } else {
    for (std::size_t i = 0; i < n; ++i) p.values[i] = p.bytes[i];
  }
  p.bytes = {};
  p.rows = {};
  return p;
}

}  // namespace video3dgs::io::detail
