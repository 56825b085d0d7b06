#pragma once
/// @file
/// JPEG decoding through libjpeg (libjpeg-turbo on Debian), used by image_io.hpp for every JPEG.
/// libjpeg rather than stb_image because stb_image is not meant for untrusted input (its header says
/// so; a fuzzed JPEG crashed Debian's libstb 0.0~git20220908 inside stbi_load_from_memory), while
/// libjpeg-turbo is fuzzed continuously upstream.
///
/// libjpeg reports errors by longjmp; `jpeg_decode_c` is the only function that calls setjmp, and it
/// holds nothing with a destructor between setjmp and any libjpeg call (the pixels belong to the
/// caller's `JpegPixels`).

#include <csetjmp>
#include <cstddef>
#include <cstdint>
#include <cstdio>  // jpeglib.h uses FILE without including it
#include <string>
#include <string_view>
#include <vector>

#include <jpeglib.h>
#include <jerror.h>  // message codes (JWRN_JPEG_EOF)

#include "video3dgs/core/error.hpp"
#include "video3dgs/io/detail/png.hpp"  // kMaxImagePixels

namespace video3dgs::io::detail {

/// A decoded JPEG: 8-bit samples, interleaved; 1 channel for greyscale files, else 3 (RGB; CMYK files
/// are converted as Adobe's inverted CMYK, R = C K / 255, ...).
struct JpegPixels {
  int width = 0, height = 0, channels = 0;
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

/// The libjpeg calls. Returns false on any error (reason in `e`); `out` is then unspecified.
inline bool jpeg_decode_c(const unsigned char* data, std::size_t size, JpegErrors& e, JpegPixels& out) {
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
  jpeg_read_header(&cinfo, TRUE);
  if (static_cast<std::uint64_t>(cinfo.image_width) * cinfo.image_height > kMaxImagePixels) {
    e.too_large = true;
    jpeg_destroy_decompress(&cinfo);
    return false;
  }
  const bool cmyk = cinfo.jpeg_color_space == JCS_CMYK || cinfo.jpeg_color_space == JCS_YCCK;
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

/// Width, height and channels (1 for greyscale files, else 3) from a JPEG's header. Returns false on
/// any error (reason in `e`).
inline bool jpeg_header_c(const unsigned char* data, std::size_t size, JpegErrors& e, int (&whc)[3]) {
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
  jpeg_read_header(&cinfo, TRUE);
  whc[0] = static_cast<int>(cinfo.image_width);
  whc[1] = static_cast<int>(cinfo.image_height);
  whc[2] = cinfo.jpeg_color_space == JCS_GRAYSCALE ? 1 : 3;
  jpeg_destroy_decompress(&cinfo);
  return true;
}

/// Decodes a JPEG held in memory. @throws io_error `io.truncated` (data ends inside the image),
/// `io.unsupported` (more than kMaxImagePixels pixels), `io.unreadable` (anything else).
[[nodiscard]] inline JpegPixels decode_jpeg(std::string_view bytes, const std::string& where) {
  JpegErrors e;
  JpegPixels p;
  if (!jpeg_decode_c(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), e, p)) {
    if (e.too_large)
      throw io_error("io.unsupported", where, "image larger than " + std::to_string(kMaxImagePixels) + " pixels (8K UHD is the limit)");
    if (e.truncated) throw io_error("io.truncated", where, "JPEG data ends inside the image (cut short?)");
    throw io_error("io.unreadable", where, std::string("cannot decode JPEG (") + (e.message[0] ? e.message : "libjpeg failed") + ")");
  }
  p.row = {};
  return p;
}

}  // namespace video3dgs::io::detail
