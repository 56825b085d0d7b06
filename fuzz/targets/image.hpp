#pragma once
// Fuzz target `image`: one input read as every image the tool reads: frames (io::decode_image with 1, 3
// and 4 channels: PNG through libpng, JPEG through libjpeg, EXIF orientation applied), masks (io::decode_mask: palette indices,
// thresholds) and headers (io::read_image_info, through a scratch file). Seeds: 8-bit grey / RGB / RGBA
// PNGs from io::encode_png, colour and grey JPEGs from stb_image_write, a 16-bit and an indexed PNG
// from libpng's simplified writer, and libjpeg-written CMYK and EXIF-oriented JPEGs (tests/io/jpeg_writer.hpp).
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <png.h>
#include <stb_image_write.h>

#include "../../tests/io/jpeg_writer.hpp"  // libjpeg-written grey/CMYK JPEGs, EXIF orientation
#include "../common.hpp"
#include "video3dgs/io/image_io.hpp"

namespace video3dgs::fuzz {

inline std::string image(std::string_view bytes) {
  std::string id = run_reader([&] {
    const io::detail::Decoded d = io::detail::decode(bytes, "fuzz.img");
    (void)io::detail::to_float_image<1>(d);
    (void)io::detail::to_float_image<3>(d);
    (void)io::detail::to_float_image<4>(d);
  });
  std::string mask_id = run_reader([&] { (void)io::decode_mask(bytes, "fuzz.img"); });
  const auto path = scratch_file("image", bytes);
  std::string info_id = run_reader([&] { (void)io::read_image_info(path); });
  return !id.empty() ? id : !mask_id.empty() ? mask_id : info_id;
}

namespace detail {
template <int C>
Image<float, C> seed_image(int w, int h) {
  Image<float, C> img(w, h);
  for (std::size_t i = 0; i < img.pixel_count() * C; ++i) img.data()[i] = float((i * 37) % 256) / 255.0f;
  return img;
}
/// A PNG from libpng's simplified API (`format` a PNG_FORMAT_*), or "" if libpng cannot write it.
inline std::string libpng_seed(int w, int h, png_uint_32 format, const void* pixels, const void* colormap, int colours) {
  png_image im{};
  im.version = PNG_IMAGE_VERSION;
  im.width = png_uint_32(w);
  im.height = png_uint_32(h);
  im.format = format;
  im.colormap_entries = png_uint_32(colours);
  png_alloc_size_t size = 0;
  if (!png_image_write_to_memory(&im, nullptr, &size, 0, pixels, 0, colormap)) return {};
  std::string out(size, '\0');
  if (!png_image_write_to_memory(&im, out.data(), &size, 0, pixels, 0, colormap)) return {};
  out.resize(size);
  return out;
}
}  // namespace detail

inline void image_seeds(const std::filesystem::path& dir) {
  write_seed(dir, "grey.png", io::encode_png<float, 1>(detail::seed_image<1>(5, 3).view()));
  write_seed(dir, "rgb.png", io::encode_png<float, 3>(detail::seed_image<3>(4, 4).view()));
  write_seed(dir, "rgba.png", io::encode_png<float, 4>(detail::seed_image<4>(3, 2).view()));
  const auto rgb = io::detail::to_u8<float, 3>(detail::seed_image<3>(8, 8).view(), "seed");
  std::string jpg;
  stbi_write_jpg_to_func(&io::detail::append_bytes, &jpg, 8, 8, 3, rgb.data(), 90);
  write_seed(dir, "rgb.jpg", jpg);
  const auto grey = io::detail::to_u8<float, 1>(detail::seed_image<1>(16, 8).view(), "seed");
  jpg.clear();
  stbi_write_jpg_to_func(&io::detail::append_bytes, &jpg, 16, 8, 1, grey.data(), 75);
  write_seed(dir, "grey.jpg", jpg);
  std::vector<std::uint16_t> grey16(6 * 4);
  for (std::size_t i = 0; i < grey16.size(); ++i) grey16[i] = std::uint16_t(i * 2741);
  write_seed(dir, "grey16.png", detail::libpng_seed(6, 4, PNG_FORMAT_LINEAR_Y, grey16.data(), nullptr, 0));
  std::vector<std::uint8_t> indices(5 * 5), palette{0, 0, 0, 200, 30, 30, 30, 200, 30};
  for (std::size_t i = 0; i < indices.size(); ++i) indices[i] = std::uint8_t(i % 3);
  write_seed(dir, "palette.png", detail::libpng_seed(5, 5, PNG_FORMAT_RGB_COLORMAP, indices.data(), palette.data(), 3));
  const std::vector<std::uint8_t> grey_bytes(grey.begin(), grey.end());
  write_seed(dir, "exif6_le.jpg", test::with_exif_orientation(test::encode_test_jpeg(16, 8, 1, grey_bytes), 6, false));
  write_seed(dir, "exif3_be.jpg", test::with_exif_orientation(test::encode_test_jpeg(16, 8, 1, grey_bytes), 3, true));
  std::vector<std::uint8_t> cmyk(4 * 4 * 4);
  for (std::size_t i = 0; i < cmyk.size(); ++i) cmyk[i] = std::uint8_t(i * 53);
  write_seed(dir, "cmyk.jpg", test::encode_test_jpeg(4, 4, 4, cmyk));
}

}  // namespace video3dgs::fuzz
