#pragma once
/// @file
/// JPEG decoding through libjpeg (libjpeg-turbo on Debian), used by image_io.hpp for every JPEG.
/// libjpeg rather than stb_image because stb_image is not meant for untrusted input (its header says
/// so; a fuzzed JPEG crashed Debian's libstb 0.0~git20220908 inside stbi_load_from_memory), while
/// libjpeg-turbo is fuzzed continuously upstream.
///
/// libjpeg reports errors by longjmp; `jpeg_read_c` is the only function that calls setjmp, and it
/// holds nothing with a destructor between setjmp and any libjpeg call (the pixels belong to the
/// caller's `JpegPixels`).

#include <csetjmp>
#include <cstddef>
#include <cstdint>
#include <cstdio>  // jpeglib.h uses FILE without including it
#include <cstring>
#include <string>
#include <string_view>
#include <vector>

#include <jpeglib.h>
#include <jerror.h>  // message codes (JWRN_JPEG_EOF)

#include "video3dgs/core/error.hpp"
#include "video3dgs/io/detail/png.hpp"  // kMaxImagePixels

namespace video3dgs::io::detail {

/// A decoded JPEG: 8-bit samples, interleaved; 1 channel for greyscale files, else 3 (RGB; CMYK files
/// are converted as Adobe's inverted CMYK, R = C K / 255, ...). After `decode_jpeg` the pixels are
/// upright (the EXIF orientation applied, width and height swapped for orientations 5-8).
struct JpegPixels {
  int width = 0, height = 0, channels = 0;
  int orientation = 1;              ///< EXIF orientation tag 1..8 (1: stored upright, or no/invalid tag)
  std::vector<std::uint8_t> bytes;  ///< width * height * channels
  std::vector<std::uint8_t> row;    ///< scratch: one CMYK row
};

struct JpegErrors {
  jpeg_error_mgr mgr;  // first member: libjpeg hands `&mgr` back as `cinfo->err`
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX] = {};
  bool truncated = false;  ///< the data ended before the image did
  bool too_large = false;  ///< more than kMaxImagePixels pixels
};

inline void jpeg_on_error(j_common_ptr cinfo) {
  auto* e = reinterpret_cast<JpegErrors*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, e->message);
  std::longjmp(e->jump, 1);
}

/// Warnings are ignored (as djpeg does), except the end of the data inside the image: truncated.
inline void jpeg_on_message(j_common_ptr cinfo, int level) {
  if (level < 0 && cinfo->err->msg_code == JWRN_JPEG_EOF) {
    reinterpret_cast<JpegErrors*>(cinfo->err)->truncated = true;
    jpeg_on_error(cinfo);
  }
}

/// The orientation tag (0x0112) of IFD0 in an APP1 "Exif" payload (TIFF layout, either byte order),
/// or 1 when there is none or the payload is malformed or the value is outside 1..8.
[[nodiscard]] inline int exif_orientation(const unsigned char* p, std::size_t n) noexcept {
  if (n < 14 || std::memcmp(p, "Exif\0\0", 6) != 0) return 1;
  p += 6;
  n -= 6;
  const bool le = p[0] == 'I' && p[1] == 'I';
  if (!le && !(p[0] == 'M' && p[1] == 'M')) return 1;
  auto u16 = [&](std::size_t at) { return le ? unsigned(p[at]) | unsigned(p[at + 1]) << 8 : unsigned(p[at]) << 8 | unsigned(p[at + 1]); };
  auto u32 = [&](std::size_t at) { return le ? u16(at) | std::uint32_t(u16(at + 2)) << 16 : std::uint32_t(u16(at)) << 16 | u16(at + 2); };
  if (u16(2) != 42) return 1;
  const std::uint32_t ifd = u32(4);
  if (std::size_t(ifd) + 2 > n) return 1;
  const std::size_t count = u16(ifd);
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t at = ifd + 2 + 12 * i;
    if (at + 12 > n) return 1;
    if (u16(at) == 0x0112) {
      const unsigned v = u16(at + 8);  // type SHORT, count 1: the value sits in the first two bytes
      return u16(at + 2) == 3 && v >= 1 && v <= 8 ? static_cast<int>(v) : 1;
    }
  }
  return 1;
}

/// The libjpeg calls. Returns false on any error (reason in `e`); `out` is then unspecified.
/// `header_only`: stops after the header and sets only width, height (as stored), channels and orientation.
inline bool jpeg_read_c(const unsigned char* data, std::size_t size, bool header_only, JpegErrors& e, JpegPixels& out) {
  jpeg_decompress_struct cinfo;
  cinfo.err = jpeg_std_error(&e.mgr);
  e.mgr.error_exit = jpeg_on_error;
  e.mgr.emit_message = jpeg_on_message;
  if (setjmp(e.jump)) {
    jpeg_destroy_decompress(&cinfo);
    return false;
  }
  jpeg_create_decompress(&cinfo);
  jpeg_mem_src(&cinfo, data, static_cast<unsigned long>(size));
  jpeg_save_markers(&cinfo, JPEG_APP0 + 1, 0xFFFF);
  jpeg_read_header(&cinfo, TRUE);
  out.orientation = 1;
  for (jpeg_saved_marker_ptr m = cinfo.marker_list; m != nullptr && out.orientation == 1; m = m->next)
    if (m->marker == JPEG_APP0 + 1) out.orientation = exif_orientation(m->data, m->data_length);
  const bool cmyk = cinfo.jpeg_color_space == JCS_CMYK || cinfo.jpeg_color_space == JCS_YCCK;
  if (header_only) {
    out.width = static_cast<int>(cinfo.image_width);
    out.height = static_cast<int>(cinfo.image_height);
    out.channels = cinfo.jpeg_color_space == JCS_GRAYSCALE ? 1 : 3;
    jpeg_destroy_decompress(&cinfo);
    return true;
  }
  if (static_cast<std::uint64_t>(cinfo.image_width) * cinfo.image_height > kMaxImagePixels) {
    e.too_large = true;
    jpeg_destroy_decompress(&cinfo);
    return false;
  }
  cinfo.out_color_space = cinfo.jpeg_color_space == JCS_GRAYSCALE ? JCS_GRAYSCALE : (cmyk ? JCS_CMYK : JCS_RGB);
  jpeg_start_decompress(&cinfo);
  out.width = static_cast<int>(cinfo.output_width);
  out.height = static_cast<int>(cinfo.output_height);
  out.channels = cmyk ? 3 : cinfo.output_components;
  const std::size_t w = cinfo.output_width, in_c = static_cast<std::size_t>(cinfo.output_components);
  const std::size_t c = static_cast<std::size_t>(out.channels);
  out.bytes.resize(w * cinfo.output_height * c);
  out.row.resize(w * in_c);
  while (cinfo.output_scanline < cinfo.output_height) {
    unsigned char* dst = out.bytes.data() + std::size_t(cinfo.output_scanline) * w * c;
    JSAMPROW row = cmyk ? out.row.data() : dst;
    jpeg_read_scanlines(&cinfo, &row, 1);
    if (cmyk)
      for (std::size_t x = 0; x < w; ++x) {
        const unsigned k = out.row[4 * x + 3];
        for (std::size_t ch = 0; ch < 3; ++ch) dst[3 * x + ch] = static_cast<std::uint8_t>(out.row[4 * x + ch] * k / 255);
      }
  }
  jpeg_finish_decompress(&cinfo);
  jpeg_destroy_decompress(&cinfo);
  return true;
}

/// Width and height of an image shown with EXIF orientation `o` (5-8 turn it by a quarter).
[[nodiscard]] constexpr bool orientation_swaps_axes(int o) noexcept { return o >= 5 && o <= 8; }

/// Applies EXIF orientation `p.orientation` to the stored pixels, so that they are as displayed:
/// output pixel (x', y') of the W' x H' result is stored pixel (x, y) of the W x H input with
///   2: (W-1-x', y')   3: (W-1-x', H-1-y')   4: (x', H-1-y')   5: (y', x')
///   6: (y', H-1-x')   7: (W-1-y', H-1-x')   8: (W-1-y', x')
/// (6 is a quarter turn clockwise, 8 counter-clockwise; 5 and 7 transpose and anti-transpose).
inline void apply_orientation(JpegPixels& p) {
  const int o = p.orientation;
  if (o <= 1 || o > 8) return;
  const std::size_t W = static_cast<std::size_t>(p.width), H = static_cast<std::size_t>(p.height);
  const std::size_t c = static_cast<std::size_t>(p.channels);
  const bool swap = orientation_swaps_axes(o);
  const std::size_t W2 = swap ? H : W, H2 = swap ? W : H;
  std::vector<std::uint8_t> out(p.bytes.size());
  for (std::size_t y2 = 0; y2 < H2; ++y2)
    for (std::size_t x2 = 0; x2 < W2; ++x2) {
      std::size_t x = x2, y = y2;
      switch (o) {
        case 2: x = W - 1 - x2; break;
        case 3: x = W - 1 - x2; y = H - 1 - y2; break;
        case 4: y = H - 1 - y2; break;
        case 5: x = y2; y = x2; break;
        case 6: x = y2; y = H - 1 - x2; break;
        case 7: x = W - 1 - y2; y = H - 1 - x2; break;
        default: x = W - 1 - y2; y = x2; break;  // 8
      }
      std::memcpy(&out[(y2 * W2 + x2) * c], &p.bytes[(y * W + x) * c], c);
    }
  p.bytes = std::move(out);
  p.width = static_cast<int>(W2);
  p.height = static_cast<int>(H2);
  p.orientation = 1;
}

/// Decodes a JPEG held in memory, upright (EXIF orientation applied). @throws io_error `io.truncated`
/// (data ends inside the image), `io.unsupported` (more than kMaxImagePixels pixels), `io.unreadable`
/// (anything else).
[[nodiscard]] inline JpegPixels decode_jpeg(std::string_view bytes, const std::string& where) {
  JpegErrors e;
  JpegPixels p;
  if (!jpeg_read_c(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), false, e, p)) {
    if (e.too_large)
      throw io_error("io.unsupported", where, "image larger than " + std::to_string(kMaxImagePixels) + " pixels (8K UHD is the limit)");
    if (e.truncated) throw io_error("io.truncated", where, "JPEG data ends inside the image (cut short?)");
    throw io_error("io.unreadable", where, std::string("cannot decode JPEG (") + (e.message[0] ? e.message : "libjpeg failed") + ")");
  }
  p.row = {};
  apply_orientation(p);
  return p;
}

}  // namespace video3dgs::io::detail
