#include "video3dgs/io/image_io.hpp"

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "jpeg_writer.hpp"
#include "png_writer.hpp"

using namespace video3dgs;
using video3dgs::test::error_id;
using video3dgs::test::error_where;
namespace fs = std::filesystem;

namespace {

template <int C>
Image<float, C> random_u8_image(int w, int h, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> d(0, 255);
  Image<float, C> img(w, h);
  for (auto& v : img.storage()) v = static_cast<float>(d(rng)) / 255.0f;
  return img;
}

}  // namespace

TEST_CASE_TEMPLATE("image_io: 8-bit PNG round trip is exact", T, std::integral_constant<int, 1>,
                   std::integral_constant<int, 3>, std::integral_constant<int, 4>) {
  constexpr int C = T::value;
  const auto dir = test::fresh_temp_dir("png_roundtrip_" + std::to_string(C));
  const auto img = random_u8_image<C>(37, 23, 7);
  io::write_png(dir / "a.png", img);
  const auto back = io::read_image<C>(dir / "a.png");
  REQUIRE(back.width() == 37);
  REQUIRE(back.height() == 23);
  CHECK(back.storage() == img.storage());
  const auto info = io::read_image_info(dir / "a.png");
  CHECK(info.width == 37);
  CHECK(info.height == 23);
  CHECK(info.channels == C);
  CHECK(info.bit_depth == 8);
  fs::remove_all(dir);
}

TEST_CASE("image_io: write_png clamps and rounds; non-finite values are refused") {
  Image<double, 1> img(4, 1);
  img(0, 0) = -0.5;
  img(1, 0) = 1.7;
  img(2, 0) = 0.5;           // 127.5 rounds to 128
  img(3, 0) = 10.4 / 255.0;  // 10.4 rounds to 10
  const auto back = io::decode_image<1>(io::encode_png<double, 1>(img.view()));
  CHECK(back(0, 0) == 0.0f);
  CHECK(back(1, 0) == 1.0f);
  CHECK(back(2, 0) == 128.0f / 255.0f);
  CHECK(back(3, 0) == 10.0f / 255.0f);
  img(2, 0) = std::numeric_limits<double>::quiet_NaN();
  CHECK(error_id([&] { (void)io::encode_png<double, 1>(img.view()); }) == "numeric.non_finite");
  img(2, 0) = std::numeric_limits<double>::infinity();
  CHECK(error_id([&] { (void)io::encode_png<double, 1>(img.view()); }) == "numeric.non_finite");
}

TEST_CASE("image_io: channel conversions (gray <-> RGB, alpha)") {
  Image<float, 3> rgb(2, 1);
  rgb(0, 0, 0) = 1.0f;  // red
  rgb(1, 0, 1) = 1.0f;  // green
  const std::string png = io::encode_png<float, 3>(rgb.view());
  const auto gray = io::decode_image<1>(png);
  CHECK(gray(0, 0) == doctest::Approx(0.299));
  CHECK(gray(1, 0) == doctest::Approx(0.587));
  const auto rgba = io::decode_image<4>(png);
  CHECK(rgba(0, 0, 3) == 1.0f);
  CHECK(rgba(1, 0, 1) == 1.0f);

  Image<float, 1> g(1, 1, 64.0f / 255.0f);
  const auto g3 = io::decode_image<3>(io::encode_png<float, 1>(g.view()));
  CHECK(g3(0, 0, 0) == 64.0f / 255.0f);
  CHECK(g3(0, 0, 1) == 64.0f / 255.0f);
  CHECK(g3(0, 0, 2) == 64.0f / 255.0f);
}

TEST_CASE("image_io: 16-bit PNGs read at full precision; 16-bit 0/1 masks stay foreground") {
  const std::vector<unsigned> samples = {0, 1, 32768, 65535, 257, 0};
  const std::string png = test::encode_test_png(3, 2, 16, 0, samples);
  const auto img = io::decode_image<1>(png);
  for (std::size_t i = 0; i < samples.size(); ++i) CHECK(img.data()[i] == static_cast<float>(samples[i]) / 65535.0f);
  const auto m = io::decode_mask(png);
  const std::vector<float> expected = {0, 1, 1, 1, 1, 0};
  CHECK(m.storage() == expected);

  const auto dir = test::fresh_temp_dir("png16");
  test::write_bytes(dir / "a.png", png);
  CHECK(io::read_image_info(dir / "a.png").bit_depth == 16);
  fs::remove_all(dir);
}

TEST_CASE("image_io: grayscale masks 0/255 and 0/1 become exact 0/1") {
  for (unsigned on : {255u, 1u, 7u}) {
    const std::vector<unsigned> samples = {0, on, on, 0, 0, on};
    const auto m = io::decode_mask(test::encode_test_png(3, 2, 8, 0, samples));
    const std::vector<float> expected = {0, 1, 1, 0, 0, 1};
    CHECK(m.storage() == expected);
  }
  // RGBA: colour decides, alpha is ignored.
  const std::vector<unsigned> rgba = {0, 0, 0, 255, 0, 9, 0, 0};
  const auto m = io::decode_mask(test::encode_test_png(2, 1, 8, 6, rgba));
  CHECK(m(0, 0) == 0.0f);
  CHECK(m(1, 0) == 1.0f);
}

TEST_CASE("image_io: indexed (palette) PNG masks use the raw indices, any bit depth, interlaced or not") {
  // Palette: index 0 is deliberately NOT black, index 2 IS black: colours must not decide.
  const std::vector<unsigned char> palette = {255, 255, 255, 200, 0, 0, 0, 0, 0, 0, 128, 0};
  const int w = 37, h = 23;
  std::mt19937_64 rng(11);
  for (int depth : {2, 4, 8}) {
    for (bool interlace : {false, true}) {
      INFO("bit depth " << depth << " interlace " << interlace);
      std::vector<unsigned> ids(static_cast<std::size_t>(w) * h);
      for (auto& v : ids) v = static_cast<unsigned>(rng() % 4);
      const std::string png = test::encode_test_png(w, h, depth, 3, ids, palette, interlace);
      const auto dir = test::fresh_temp_dir("palette");
      test::write_bytes(dir / "m.png", png);
      const auto idx = io::read_palette_indices(dir / "m.png");
      const auto mask = io::read_mask(dir / "m.png");
      // stb (an independent decoder) expands the same file to the palette colours.
      const auto colours = io::read_image<3>(dir / "m.png");
      REQUIRE(idx.width() == w);
      REQUIRE(mask.height() == h);
      bool all_ok = true;
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          const unsigned id = ids[static_cast<std::size_t>(y) * w + x];
          all_ok = all_ok && idx(x, y) == id && mask(x, y) == (id != 0 ? 1.0f : 0.0f) &&
                   colours(x, y, 0) == static_cast<float>(palette[3 * id]) / 255.0f &&
                   colours(x, y, 1) == static_cast<float>(palette[3 * id + 1]) / 255.0f;
        }
      CHECK(all_ok);
      fs::remove_all(dir);
    }
  }
  CHECK(error_id([] { (void)io::read_palette_indices("/nonexistent/m.png"); }) == "io.missing");
}

TEST_CASE("image_io: JPEG reads (lossy), JPEG masks threshold at half range") {
  Image<float, 3> img(32, 16, 0.0f);
  for (int y = 0; y < 16; ++y)
    for (int x = 16; x < 32; ++x)
      for (int c = 0; c < 3; ++c) img(x, y, c) = 1.0f;
  std::vector<unsigned char> px(img.size());
  for (std::size_t i = 0; i < px.size(); ++i) px[i] = static_cast<unsigned char>(img.data()[i] * 255.0f);
  std::string jpg;
  REQUIRE(stbi_write_jpg_to_func(&io::detail::append_bytes, &jpg, 32, 16, 3, px.data(), 95));
  const auto back = io::decode_image<3>(jpg);
  CHECK(back(2, 8, 0) < 0.1f);
  CHECK(back(29, 8, 1) > 0.9f);
  const auto m = io::decode_mask(jpg);
  CHECK(m(2, 8) == 0.0f);
  CHECK(m(29, 8) == 1.0f);
  // Cut the file: stb alone would decode it silently.
  CHECK(error_id([&] { (void)io::decode_image<3>(jpg.substr(0, jpg.size() * 2 / 3), "cut.jpg"); }) == "io.truncated");
}

TEST_CASE("image_io: greyscale and CMYK JPEGs (libjpeg-written) read as grey and RGB") {
  // 16x8: two 8x8 blocks, so quality-100 JPEG keeps each block's level within a step or two.
  const std::vector<std::uint8_t> levels = {40, 200};
  std::vector<std::uint8_t> grey(16 * 8);
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 16; ++x) grey[static_cast<std::size_t>(y * 16 + x)] = levels[x / 8];
  const std::string g = test::encode_test_jpeg(16, 8, 1, grey);
  const auto dir = test::fresh_temp_dir("jpeg_kinds");
  test::write_bytes(dir / "grey.jpg", g);
  const auto gi = io::read_image_info(dir / "grey.jpg");
  CHECK(gi.channels == 1);
  CHECK(gi.orientation == 1);
  const auto g3 = io::read_image<3>(dir / "grey.jpg");
  for (int c = 0; c < 3; ++c) {
    CHECK(std::abs(g3(3, 4, c) * 255.0f - 40.0f) <= 2.0f);
    CHECK(std::abs(g3(12, 4, c) * 255.0f - 200.0f) <= 2.0f);
  }
  // Adobe CMYK (inverted: 255 = no ink): R = C K / 255, G = M K / 255, B = Y K / 255.
  const std::uint8_t cmyk_blocks[2][4] = {{255, 0, 255, 255}, {200, 100, 50, 128}};
  std::vector<std::uint8_t> cmyk(16 * 8 * 4);
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 16; ++x)
      for (int c = 0; c < 4; ++c) cmyk[static_cast<std::size_t>((y * 16 + x) * 4 + c)] = cmyk_blocks[x / 8][c];
  test::write_bytes(dir / "cmyk.jpg", test::encode_test_jpeg(16, 8, 4, cmyk));
  CHECK(io::read_image_info(dir / "cmyk.jpg").channels == 3);
  const auto rgb = io::read_image<3>(dir / "cmyk.jpg");
  for (int b = 0; b < 2; ++b)
    for (int c = 0; c < 3; ++c) {
      const float expected = static_cast<float>(cmyk_blocks[b][c] * cmyk_blocks[b][3] / 255);
      CHECK(std::abs(rgb(3 + 8 * b, 4, c) * 255.0f - expected) <= 3.0f);
    }
  // As masks: the grey block at 200 is foreground, at 40 background.
  const auto m = io::read_mask(dir / "grey.jpg");
  CHECK(m(3, 4) == 0.0f);
  CHECK(m(12, 4) == 1.0f);
  fs::remove_all(dir);
}

TEST_CASE("image_io: JPEGs with an EXIF orientation are read upright (all eight, both byte orders)") {
  // Stored pixels: 24x16 in 8x8 blocks of six distinct grey levels, so every turn and mirror is visible.
  Image<float, 1> stored(24, 16);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 24; ++x) stored(x, y) = static_cast<float>(40 + 60 * (x / 8) + 30 * (y / 8)) / 255.0f;
  const std::string plain = test::encode_test_jpeg(24, 16, 1, test::to_bytes(stored));
  const auto dir = test::fresh_temp_dir("jpeg_exif");
  for (int o = 1; o <= 8; ++o)
    for (const bool big_endian : {false, true}) {
      CAPTURE(o);
      CAPTURE(big_endian);
      const auto path = dir / ("o" + std::to_string(o) + (big_endian ? "mm" : "ii") + ".jpg");
      test::write_bytes(path, test::with_exif_orientation(plain, o, big_endian));
      const auto expected = test::as_displayed(stored, o);
      const auto info = io::read_image_info(path);
      CHECK(info.orientation == o);
      CHECK(info.width == expected.width());
      CHECK(info.height == expected.height());
      const auto img = io::read_image<1>(path);
      REQUIRE(img.width() == expected.width());
      REQUIRE(img.height() == expected.height());
      for (int y = 4; y < img.height(); y += 8)  // block centres
        for (int x = 4; x < img.width(); x += 8) CHECK(std::abs(img(x, y) - expected(x, y)) * 255.0f <= 2.0f);
      const auto mask = io::read_mask(path);  // masks turn with their frames
      CHECK(mask.width() == expected.width());
    }
  // Malformed Exif payloads are ignored (orientation 1), never read out of bounds.
  std::string bad = test::with_exif_orientation(plain, 6, false);
  bad[4 + 2 + 6 + 4] = static_cast<char>(0xF0);  // IFD0 offset far past the segment
  test::write_bytes(dir / "bad.jpg", bad);
  CHECK(io::read_image_info(dir / "bad.jpg").orientation == 1);
  CHECK(io::read_image<1>(dir / "bad.jpg").width() == 24);
  test::write_bytes(dir / "nine.jpg", test::with_exif_orientation(plain, 9, true));  // outside 1..8
  CHECK(io::read_image_info(dir / "nine.jpg").orientation == 1);
  fs::remove_all(dir);
}

TEST_CASE("image_io: missing, empty, truncated and corrupt files raise their ids and name the file") {
  const auto dir = test::fresh_temp_dir("bad_files");
  CHECK(error_id([&] { (void)io::read_image<3>(dir / "nope.png"); }) == "io.missing");
  CHECK(error_id([&] { (void)io::read_mask(dir / "nope.png"); }) == "io.missing");
  CHECK(error_id([&] { (void)io::read_image_info(dir / "nope.png"); }) == "io.missing");

  test::write_bytes(dir / "empty.png", "");
  CHECK(error_id([&] { (void)io::read_image<3>(dir / "empty.png"); }) == "io.truncated");

  const std::string png = io::encode_png<float, 3>(random_u8_image<3>(37, 23, 3).view());
  for (std::size_t cut : {png.size() / 2, png.size() - 5, std::size_t(20), std::size_t(8)}) {
    INFO("cut at " << cut);
    test::write_bytes(dir / "cut.png", png.substr(0, cut));
    CHECK(error_id([&] { (void)io::read_image<3>(dir / "cut.png"); }) == "io.truncated");
    CHECK(error_id([&] { (void)io::read_mask(dir / "cut.png"); }) == "io.truncated");
  }
  test::write_bytes(dir / "cut.png", png.substr(0, png.size() / 2));
  try {
    (void)io::read_image<3>(dir / "cut.png");
  } catch (const io_error& e) {
    CHECK(e.where() == (dir / "cut.png").string());
    CHECK(std::string(e.what()).rfind("[io.truncated] ", 0) == 0);
  }

  test::write_bytes(dir / "garbage.png", "this is not an image at all");
  CHECK(error_id([&] { (void)io::read_image<3>(dir / "garbage.png"); }) == "io.unreadable");
  CHECK(error_id([&] { (void)io::read_image<3>(dir); }) == "io.unreadable");
  // Another format behind a .png name (a BMP here): unreadable, and the message names the formats read.
  test::write_bytes(dir / "bitmap.png", std::string("BM\x46\0\0\0\0\0\0\0\x36\0\0\0", 14) + std::string(56, '\x7f'));
  try {
    (void)io::read_image<3>(dir / "bitmap.png");
    FAIL("a BMP was read");
  } catch (const io_error& e) {
    CHECK(std::string(e.id()) == "io.unreadable");
    CHECK(std::string(e.what()).find("not a PNG or JPEG") != std::string::npos);
  }

  // A palette PNG whose compressed data is damaged.
  std::string bad = test::encode_test_png(4, 4, 8, 3, std::vector<unsigned>(16, 1), {0, 0, 0, 9, 9, 9});
  const auto idat = bad.find("IDAT");
  bad[idat + 4] = 0x7f;  // break the zlib header
  CHECK(error_id([&] { (void)io::decode_mask(bad); }) == "io.unreadable");
  fs::remove_all(dir);
}

TEST_CASE("image_io: real DAVIS frame and mask" * doctest::test_suite("shared_data")) {
  const auto frames = test::shared_data_or_skip("blackswan/frames");
  if (frames.empty()) return;
  const auto img = io::read_image<3>(frames / "00000.jpg");
  CHECK(img.width() == 854);
  CHECK(img.height() == 480);
  const auto m = io::read_mask(frames.parent_path() / "masks" / "00000.png");
  double fg = 0;
  bool binary = true;
  for (float v : m.storage()) {
    fg += v;
    binary = binary && (v == 0.0f || v == 1.0f);
  }
  CHECK(binary);
  CHECK(fg / static_cast<double>(m.pixel_count()) > 0.01);
  CHECK(fg / static_cast<double>(m.pixel_count()) < 0.5);
}
