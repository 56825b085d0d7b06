#pragma once
/// @file
/// Image files <-> float images: PNGs are read through libpng (detail/png.hpp), JPEGs through libjpeg
/// (detail/jpeg.hpp), and PNGs written with stb_image_write (Debian's compiled libstb, linked by
/// video3dgs::video3dgs, so including this header never duplicates stb symbols). Other formats are
/// not read: stb_image's decoders are not meant for untrusted files.
///
/// - `read_image<C>(path)`: PNG (8/16-bit, gray / gray+alpha / RGB / RGBA / palette) and JPEG (8-bit
///   grey, colour or CMYK; turned upright by its EXIF orientation) into `Image<float, C>`, C in
///   {1, 3, 4}, values v / (2^bits - 1) in [0, 1]. Channels are converted: gray -> RGB replicates; RGB -> gray is the Rec. 601 luma
///   0.299 R + 0.587 G + 0.114 B; a missing alpha becomes 1; an alpha is dropped for C < 4.
/// - `read_mask(path)`: a binary foreground mask, values exactly 0 or 1. Foreground = non-zero:
///   * grayscale / RGB(A) PNG (8 or 16 bit, 0/255 or 0/1 or any ids): any colour channel != 0
///     (alpha ignored);
///   * indexed (palette) PNG, e.g. DAVIS annotations: palette index != 0 (the raw indices are read,
///     not the palette colours, so the object ids survive whatever colours the palette has);
///   * JPEG (lossy, so exact zeros are not kept): any colour channel >= 128.
/// - `write_png(path, view)`: values clamped to [0, 1], rounded to 8 bits (round(255 v)), written
///   atomically (temporary file + rename); C in {1, 3, 4}.
///
/// Errors (`io_error`, message names the file): `io.missing` (no such file), `io.unreadable`
/// (cannot open or decode, neither PNG nor JPEG), `io.truncated` (empty file, PNG ending early or too
/// short for its size, JPEG data or end marker missing), `io.unsupported` (more than `kMaxImagePixels` pixels),
/// `io.unwritable`; `numeric.non_finite` (`numeric_error`) when writing NaN/Inf.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include <stb_image_write.h>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/io/detail/jpeg.hpp"
#include "video3dgs/io/detail/png.hpp"

namespace video3dgs::io {

/// What a file's header says.
struct ImageInfo {
  int width = 0;
  int height = 0;
  int channels = 0;   ///< channels stored in the file (palette PNGs report their expanded count)
  int bit_depth = 8;  ///< 8 or 16
  /// EXIF orientation of a JPEG (1..8; 1 for PNGs and JPEGs without the tag). width and height are
  /// those of the upright image that read_image returns; the stored pixels differ when this is not 1.
  int orientation = 1;
};

namespace detail {

/// The whole file. @throws io_error `io.missing`, `io.unreadable`, `io.truncated` (empty file).
[[nodiscard]] inline std::string read_file_bytes(const std::filesystem::path& path) {
  std::error_code ec;
  const std::string where = path.string();
  if (!std::filesystem::exists(path, ec)) throw io_error("io.missing", where, "no such file");
  if (std::filesystem::is_directory(path, ec)) throw io_error("io.unreadable", where, "is a directory, not a file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw io_error("io.unreadable", where, "cannot open the file (permissions?)");
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw io_error("io.unreadable", where, "read error");
  if (bytes.empty()) throw io_error("io.truncated", where, "the file is empty");
  if (bytes.size() > 0x7fffffffu) throw io_error("io.unreadable", where, "file too large for the image decoder");
  return bytes;
}

[[nodiscard]] inline bool is_jpeg(std::string_view b) noexcept {
  return b.size() >= 3 && static_cast<unsigned char>(b[0]) == 0xFF && static_cast<unsigned char>(b[1]) == 0xD8 &&
         static_cast<unsigned char>(b[2]) == 0xFF;
}

/// A JPEG must contain its end-of-image marker (FF D9) in its last 4 KiB (a file cut short).
inline void check_jpeg_complete(std::string_view bytes, const std::string& where) {
  const std::size_t from = bytes.size() > 4096 ? bytes.size() - 4096 : 2;
  if (bytes.find(std::string_view("\xFF\xD9", 2), from) == std::string_view::npos)
    throw io_error("io.truncated", where, "JPEG file has no end-of-image marker (cut short?)");
}

/// Decoded pixels at the file's native channel count, as integers with their full-scale value.
struct Decoded {
  int width = 0, height = 0, channels = 0;
  int max_value = 255;               ///< 255 or 65535
  std::vector<std::uint16_t> values;  ///< width * height * channels, interleaved
};

/// PNGs through libpng (detail/png.hpp, palettes expanded to colours), JPEGs through libjpeg
/// (detail/jpeg.hpp); any other format is io.unreadable.
[[nodiscard]] inline Decoded decode(std::string_view bytes, const std::string& where) {
  if (is_png(bytes)) {
    PngPixels p = decode_png(bytes, where, false);
    return Decoded{p.width, p.height, p.channels, p.max_value, std::move(p.values)};
  }
  if (!is_jpeg(bytes)) throw io_error("io.unreadable", where, "not a PNG or JPEG file (the formats read)");
  check_jpeg_complete(bytes, where);
  JpegPixels p = decode_jpeg(bytes, where);
  Decoded d{p.width, p.height, p.channels, 255, {}};
  d.values.assign(p.bytes.begin(), p.bytes.end());
  return d;
}

/// Converts decoded pixels to C float channels (see the file comment for the rules).
template <int C>
[[nodiscard]] Image<float, C> to_float_image(const Decoded& d) {
  static_assert(C == 1 || C == 3 || C == 4, "video3dgs::io::read_image<C>: C must be 1, 3 or 4");
  Image<float, C> img(d.width, d.height);
  const float full = static_cast<float>(d.max_value);  // v / full, so 8-bit k reads exactly as k / 255.0f
  const std::size_t n = img.pixel_count();
  const int src_c = d.channels;
  const bool has_alpha = src_c == 2 || src_c == 4;
  const bool is_gray = src_c <= 2;
  float* out = img.data();
  const std::uint16_t* in = d.values.data();
  for (std::size_t i = 0; i < n; ++i, in += src_c, out += C) {
    const float r = static_cast<float>(in[0]) / full;
    const float g = is_gray ? r : static_cast<float>(in[1]) / full;
    const float b = is_gray ? r : static_cast<float>(in[2]) / full;
    const float a = has_alpha ? static_cast<float>(in[src_c - 1]) / full : 1.0f;
    if constexpr (C == 1) {
      out[0] = is_gray ? r : 0.299f * r + 0.587f * g + 0.114f * b;
    } else {
      out[0] = r;
      out[1] = g;
      out[2] = b;
      if constexpr (C == 4) out[3] = a;
    }
  }
  return img;
}

/// Quantises to 8 bits: clamp to [0, 1], round(255 v). @throws numeric_error on NaN/Inf.
template <class Scalar, int C>
[[nodiscard]] std::vector<unsigned char> to_u8(ConstImageView<Scalar, C> v, const std::string& where) {
  std::vector<unsigned char> px(v.pixel_count() * C);
  unsigned char* out = px.data();
  for (int y = 0; y < v.height(); ++y) {
    const Scalar* row = v.row(y);
    for (int i = 0; i < v.width() * C; ++i) {
      const Scalar s = row[i];
      if (!std::isfinite(s))
        throw numeric_error("numeric.non_finite", where,
                            "pixel (" + std::to_string(i / C) + ", " + std::to_string(y) + ") channel " +
                                std::to_string(i % C) + " is not finite");
      const double c = s < Scalar(0) ? 0.0 : (s > Scalar(1) ? 1.0 : static_cast<double>(s));
      *out++ = static_cast<unsigned char>(std::lround(c * 255.0));
    }
  }
  return px;
}

inline void append_bytes(void* context, void* data, int size) {
  static_cast<std::string*>(context)->append(static_cast<const char*>(data), static_cast<std::size_t>(size));
}

}  // namespace detail

/// Width, height, channels and bit depth from the file's header (decodes no pixels; PNG and JPEG).
/// @throws io_error `io.missing`, `io.unreadable`, `io.truncated`
[[nodiscard]] inline ImageInfo read_image_info(const std::filesystem::path& path) {
  const std::string where = path.string();
  const std::string bytes = detail::read_file_bytes(path);
  const auto* data = reinterpret_cast<const unsigned char*>(bytes.data());
  ImageInfo info;
  if (detail::is_png(bytes)) {
    detail::PngReader r;
    r.data = data;
    r.size = bytes.size();
    detail::PngPixels p;
    if (!detail::png_read_c(r, false, true, p)) {
      if (r.ran_out) throw io_error("io.truncated", where, "PNG file ends inside its header");
      throw io_error("io.unreadable", where, std::string("cannot read PNG header (") + (r.message[0] ? r.message : "libpng failed") + ")");
    }
    info = ImageInfo{p.width, p.height, p.channels, p.max_value == 65535 ? 16 : 8};
  } else if (detail::is_jpeg(bytes)) {
    detail::JpegErrors e;
    detail::JpegPixels p;
    if (!detail::jpeg_read_c(data, bytes.size(), true, e, p))
      throw io_error("io.unreadable", where, std::string("cannot read JPEG header (") + (e.message[0] ? e.message : "libjpeg failed") + ")");
    const bool swap = detail::orientation_swaps_axes(p.orientation);
    info = ImageInfo{swap ? p.height : p.width, swap ? p.width : p.height, p.channels, 8, p.orientation};
  } else {
    throw io_error("io.unreadable", where, "not a PNG or JPEG file (the formats read)");
  }
  return info;
}

/// Decodes an image file held in memory (see `read_image`); `where` names it in errors.
template <int C = 3>
[[nodiscard]] Image<float, C> decode_image(std::string_view bytes, const std::string& where = "<memory>") {
  return detail::to_float_image<C>(detail::decode(bytes, where));
}

/// Reads an image file into floats in [0, 1] with C channels (C in {1, 3, 4}).
/// @throws io_error `io.missing`, `io.unreadable`, `io.truncated`
template <int C = 3>
[[nodiscard]] Image<float, C> read_image(const std::filesystem::path& path) {
  return decode_image<C>(detail::read_file_bytes(path), path.string());
}

/// The raw palette indices of an indexed PNG (e.g. object ids of a DAVIS annotation), one byte per pixel.
/// @throws io_error `io.missing`, `io.unreadable` (not an indexed PNG, corrupt), `io.truncated`
[[nodiscard]] inline Image<std::uint8_t, 1> read_palette_indices(const std::filesystem::path& path) {
  const std::string bytes = detail::read_file_bytes(path);
  const std::string where = path.string();
  if (!detail::is_png(bytes)) throw io_error("io.unreadable", where, "not a PNG file (palette indices need an indexed PNG)");
  const detail::PngPixels p = detail::decode_png(bytes, where, true);
  if (!p.palette) throw io_error("io.unreadable", where, "not an indexed (palette) PNG");
  Image<std::uint8_t, 1> out(p.width, p.height);
  for (std::size_t i = 0; i < p.values.size(); ++i) out.data()[i] = static_cast<std::uint8_t>(p.values[i]);
  return out;
}

/// Decodes a mask file held in memory (see `read_mask`).
[[nodiscard]] inline Image<float, 1> decode_mask(std::string_view bytes, const std::string& where = "<memory>") {
  detail::Decoded d;
  if (detail::is_png(bytes)) {
    detail::PngPixels p = detail::decode_png(bytes, where, true);  // palette PNGs: the raw indices
    if (p.palette) {
      Image<float, 1> m(p.width, p.height);
      for (std::size_t i = 0; i < p.values.size(); ++i) m.data()[i] = p.values[i] != 0 ? 1.0f : 0.0f;
      return m;
    }
    d = detail::Decoded{p.width, p.height, p.channels, p.max_value, std::move(p.values)};
  } else {
    d = detail::decode(bytes, where);
  }
  // Lossy JPEG masks: threshold at half range; lossless formats: any non-zero colour channel.
  const std::uint16_t threshold = detail::is_jpeg(bytes) ? static_cast<std::uint16_t>(d.max_value / 2 + 1) : 1;
  const int colour = (d.channels == 2 || d.channels == 4) ? d.channels - 1 : d.channels;
  Image<float, 1> m(d.width, d.height);
  const std::uint16_t* in = d.values.data();
  for (std::size_t i = 0; i < m.pixel_count(); ++i, in += d.channels) {
    bool fg = false;
    for (int c = 0; c < colour; ++c) fg = fg || in[c] >= threshold;
    m.data()[i] = fg ? 1.0f : 0.0f;
  }
  return m;
}

/// Reads a foreground mask: 1 = foreground (non-zero), 0 = background; see the file comment for how
/// grayscale, colour, palette and JPEG masks are interpreted.
/// @throws io_error `io.missing`, `io.unreadable`, `io.truncated`
[[nodiscard]] inline Image<float, 1> read_mask(const std::filesystem::path& path) {
  return decode_mask(detail::read_file_bytes(path), path.string());
}

/// Encodes an image as an 8-bit PNG in memory (clamp to [0, 1], round(255 v)); C in {1, 3, 4}.
/// @throws numeric_error `numeric.non_finite`
template <class Scalar, int C>
[[nodiscard]] std::string encode_png(ConstImageView<Scalar, C> image, const std::string& where = "<memory>") {
  static_assert(C == 1 || C == 3 || C == 4, "video3dgs::io::write_png: C must be 1, 3 or 4");
  if (image.empty()) throw io_error("io.unwritable", where, "cannot write an empty image");
  const std::vector<unsigned char> px = detail::to_u8<Scalar, C>(image, where);
  std::string out;
  if (!stbi_write_png_to_func(&detail::append_bytes, &out, image.width(), image.height(), C, px.data(), image.width() * C))
    throw io_error("io.unwritable", where, "PNG encoding failed");
  return out;
}

/// Writes an 8-bit PNG atomically (values clamped to [0, 1], rounded); C in {1, 3, 4}.
/// @throws io_error `io.unwritable`, numeric_error `numeric.non_finite`
template <int C>
void write_png(const std::filesystem::path& path, ConstImageView<float, C> image) {
  write_file_atomic(path, encode_png<float, C>(image, path.string()));
}
/// Same for double images.
template <int C>
void write_png(const std::filesystem::path& path, ConstImageView<double, C> image) {
  write_file_atomic(path, encode_png<double, C>(image, path.string()));
}
/// Same for owning images (template deduction does not see the view conversion).
template <class Scalar, int C>
void write_png(const std::filesystem::path& path, const Image<Scalar, C>& image) {
  write_png<C>(path, image.view());
}
/// Same for mutable views.
template <class Scalar, int C>
void write_png(const std::filesystem::path& path, ImageView<Scalar, C> image) {
  write_png<C>(path, ConstImageView<Scalar, C>(image));
}

}  // namespace video3dgs::io
