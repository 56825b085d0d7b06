#pragma once
// JPEG files for tests, written with libjpeg: greyscale (1 component), RGB (3) and Adobe CMYK (4)
// inputs, which stb_image_write cannot produce, and an EXIF orientation tag spliced in after SOI.
#include <cstdint>
#include <cstdio>  // jpeglib.h uses FILE without including it
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <vector>

#include <jpeglib.h>

#include "video3dgs/core/image.hpp"

namespace video3dgs::test {

/// Encodes `samples` (w * h * components bytes, interleaved) at quality 100 without chroma subsampling.
/// components: 1 greyscale, 3 RGB, 4 CMYK (stored as given: Adobe's inverted convention, 255 = no ink).
inline std::string encode_test_jpeg(int w, int h, int components, const std::vector<std::uint8_t>& samples) {
  if (samples.size() != static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * static_cast<std::size_t>(components))
    throw std::invalid_argument("encode_test_jpeg: sample count");
  jpeg_compress_struct cinfo;
  jpeg_error_mgr err;
  cinfo.err = jpeg_std_error(&err);
  jpeg_create_compress(&cinfo);
  unsigned char* buf = nullptr;
  unsigned long size = 0;
  jpeg_mem_dest(&cinfo, &buf, &size);
  cinfo.image_width = static_cast<JDIMENSION>(w);
  cinfo.image_height = static_cast<JDIMENSION>(h);
  cinfo.input_components = components;
  cinfo.in_color_space = components == 1 ? JCS_GRAYSCALE : (components == 4 ? JCS_CMYK : JCS_RGB);
  jpeg_set_defaults(&cinfo);
  jpeg_set_quality(&cinfo, 100, TRUE);
  for (int c = 0; c < cinfo.num_components; ++c) cinfo.comp_info[c].h_samp_factor = cinfo.comp_info[c].v_samp_factor = 1;
  jpeg_start_compress(&cinfo, TRUE);
  while (cinfo.next_scanline < cinfo.image_height) {
    JSAMPROW row = const_cast<JSAMPROW>(samples.data() + std::size_t(cinfo.next_scanline) * std::size_t(w) * std::size_t(components));
    jpeg_write_scanlines(&cinfo, &row, 1);
  }
  jpeg_finish_compress(&cinfo);
  jpeg_destroy_compress(&cinfo);
  std::string out(reinterpret_cast<const char*>(buf), size);
  std::free(buf);
  return out;
}

/// An 8-bit image as interleaved bytes, round(255 v).
template <int C>
std::vector<std::uint8_t> to_bytes(const Image<float, C>& img) {
  std::vector<std::uint8_t> b(img.size());
  for (std::size_t i = 0; i < b.size(); ++i) b[i] = static_cast<std::uint8_t>(img.data()[i] * 255.0f + 0.5f);
  return b;
}

/// `jpeg` with an APP1 Exif segment right after SOI whose IFD0 holds Orientation = `orientation`
/// (TIFF byte order little-endian "II", or big-endian "MM"), preceded by an unrelated tag.
inline std::string with_exif_orientation(const std::string& jpeg, int orientation, bool big_endian) {
  std::string t = big_endian ? std::string("MM") : std::string("II");
  auto u16 = [&](unsigned v) {
    if (big_endian) t += {static_cast<char>(v >> 8), static_cast<char>(v & 0xff)};
    else t += {static_cast<char>(v & 0xff), static_cast<char>(v >> 8)};
  };
  auto u32 = [&](std::uint32_t v) {
    if (big_endian) { u16(v >> 16); u16(v & 0xffff); }
    else { u16(v & 0xffff); u16(v >> 16); }
  };
  u16(42);
  u32(8);  // IFD0 right after the header
  u16(2);  // two entries
  u16(0x010F); u16(2); u32(4); t += std::string("cam", 4);      // Make, ASCII, inline "cam\0"
  u16(0x0112); u16(3); u32(1); u16(static_cast<unsigned>(orientation)); u16(0);  // Orientation, SHORT
  u32(0);  // no next IFD
  const std::string payload = std::string("Exif\0\0", 6) + t;
  const std::size_t len = payload.size() + 2;
  std::string seg = {static_cast<char>(0xFF), static_cast<char>(0xE1), static_cast<char>(len >> 8), static_cast<char>(len & 0xff)};
  return jpeg.substr(0, 2) + seg + payload + jpeg.substr(2);
}

/// A quarter turn clockwise (W x H -> H x W): output (x', y') = input (y', H-1-x').
template <int C>
Image<float, C> rotate_cw(const Image<float, C>& in) {
  Image<float, C> out(in.height(), in.width());
  for (int y = 0; y < in.height(); ++y)
    for (int x = 0; x < in.width(); ++x)
      for (int c = 0; c < C; ++c) out(in.height() - 1 - y, x, c) = in(x, y, c);
  return out;
}

/// Mirror left-right (`horizontal`) or top-bottom.
template <int C>
Image<float, C> mirror(const Image<float, C>& in, bool horizontal) {
  Image<float, C> out(in.width(), in.height());
  for (int y = 0; y < in.height(); ++y)
    for (int x = 0; x < in.width(); ++x)
      for (int c = 0; c < C; ++c)
        out(horizontal ? in.width() - 1 - x : x, horizontal ? y : in.height() - 1 - y, c) = in(x, y, c);
  return out;
}

/// The image a viewer shows for `stored` pixels tagged with EXIF orientation o, composed from the
/// tag's definition (2 mirror, 3 half turn, 4 flip, 5 transpose, 6 quarter turn clockwise,
/// 7 transverse, 8 quarter turn counter-clockwise).
template <int C>
Image<float, C> as_displayed(const Image<float, C>& stored, int o) {
  switch (o) {
    case 2: return mirror(stored, true);
    case 3: return mirror(mirror(stored, true), false);
    case 4: return mirror(stored, false);
    case 5: return mirror(rotate_cw(stored), true);
    case 6: return rotate_cw(stored);
    case 7: return mirror(rotate_cw(stored), false);
    case 8: return rotate_cw(rotate_cw(rotate_cw(stored)));
    default: return stored;
  }
}

}  // namespace video3dgs::test
