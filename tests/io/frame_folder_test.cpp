#include "video3dgs/io/frame_folder.hpp"

#include <algorithm>
#include <filesystem>
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

void write_gray(const fs::path& p, int w, int h, float v) { io::write_png(p, Image<float, 1>(w, h, v)); }

}  // namespace

TEST_CASE("frame_folder: natural_less") {
  CHECK(io::natural_less("2", "10"));
  CHECK_FALSE(io::natural_less("10", "2"));
  CHECK(io::natural_less("frame2.png", "frame10.png"));
  CHECK(io::natural_less("00009.jpg", "00010.jpg"));
  CHECK(io::natural_less("a", "B"));       // case-insensitive
  CHECK(io::natural_less("img1", "img1a"));
  CHECK(io::natural_less("x7", "x007"));    // equal numbers: fewer leading zeros first
  CHECK_FALSE(io::natural_less("x007", "x7"));
  CHECK_FALSE(io::natural_less("same", "same"));
  CHECK(io::natural_less("99999999999999999999999", "100000000000000000000000"));  // longer than 64 bits

  std::vector<std::string> names = {"f10", "f2", "F1", "f1", "f02", "g", "f", "f2b", "f100"};
  std::mt19937 rng(3);
  for (int round = 0; round < 5; ++round) {
    std::shuffle(names.begin(), names.end(), rng);
    std::sort(names.begin(), names.end(), io::natural_less);
    const std::vector<std::string> expected = {"f", "F1", "f1", "f2", "f02", "f2b", "f10", "f100", "g"};
    CHECK(names == expected);
  }
}

TEST_CASE("frame_folder: lists images in natural order, matches masks by stem, ignores other files") {
  const auto dir = test::fresh_temp_dir("frames_ok");
  const auto frames = dir / "frames", masks = dir / "masks";
  fs::create_directories(frames);
  fs::create_directories(masks);
  const std::vector<std::string> stems = {"1", "2", "10"};
  write_gray(frames / "10.PNG", 5, 3, 0.1f);
  write_gray(frames / "2.png", 5, 3, 0.2f);
  write_gray(frames / "1.png", 5, 3, 0.3f);
  write_gray(frames / ".hidden.png", 5, 3, 0.3f);
  test::write_bytes(frames / "notes.txt", "not an image");
  fs::create_directories(frames / "sub.png");
  for (const auto& s : stems) write_gray(masks / (s + ".png"), 5, 3, s == "2" ? 0.0f : 1.0f);

  const io::FrameList list = io::list_frames(frames, masks);
  REQUIRE(list.size() == 3);
  CHECK(list.frames[0].filename() == "1.png");
  CHECK(list.frames[1].filename() == "2.png");
  CHECK(list.frames[2].filename() == "10.PNG");
  REQUIRE(list.masks.size() == 3);
  for (std::size_t i = 0; i < 3; ++i) CHECK(list.masks[i].stem() == list.frames[i].stem());
  CHECK(io::list_frames(frames).masks.empty());

  ThreadPool pool(2);
  const auto a = io::read_frames(list, nullptr);
  const auto b = io::read_frames(list, &pool);
  REQUIRE(a.size() == 3);
  for (std::size_t i = 0; i < 3; ++i) CHECK(a[i].storage() == b[i].storage());
  CHECK(a[1](0, 0, 2) == 51.0f / 255.0f);  // 2.png, gray replicated
  const auto m = io::read_masks(list, &pool);
  REQUIRE(m.size() == 3);
  CHECK(m[0](4, 2) == 1.0f);
  CHECK(m[1](4, 2) == 0.0f);
  CHECK(io::read_masks(io::list_frames(frames)).empty());
  fs::remove_all(dir);
}

TEST_CASE("frame_folder: bad folders raise their documented ids and name the culprit") {
  const auto dir = test::fresh_temp_dir("frames_bad");
  const auto frames = dir / "frames", masks = dir / "masks", empty = dir / "empty";
  fs::create_directories(frames);
  fs::create_directories(masks);
  fs::create_directories(empty);
  for (const char* s : {"00000", "00001", "00002"}) write_gray(frames / (std::string(s) + ".jpg.png"), 6, 4, 0.5f);

  CHECK(error_id([&] { (void)io::list_frames(dir / "missing"); }) == "io.missing");
  CHECK(error_id([&] { (void)io::list_frames(frames / "00000.jpg.png"); }) == "io.missing");  // a file
  CHECK(error_id([&] { (void)io::list_frames(empty); }) == "io.empty");
  CHECK(error_id([&] { (void)io::list_frames(frames, dir / "no_masks"); }) == "io.missing");
  CHECK(error_id([&] { (void)io::list_frames(frames, empty); }) == "io.empty");

  // A frame without a mask.
  write_gray(masks / "00000.jpg.png", 6, 4, 1.0f);
  write_gray(masks / "00001.jpg.png", 6, 4, 1.0f);
  CHECK(error_id([&] { (void)io::list_frames(frames, masks); }) == "io.mask_missing");
  CHECK(error_where([&] { (void)io::list_frames(frames, masks); }) == (frames / "00002.jpg.png").string());
  // More masks than frames.
  write_gray(masks / "00002.jpg.png", 6, 4, 1.0f);
  write_gray(masks / "00003.jpg.png", 6, 4, 1.0f);
  CHECK(error_id([&] { (void)io::list_frames(frames, masks); }) == "io.count_mismatch");
  fs::remove(masks / "00003.jpg.png");
  // Two images with one stem.
  write_gray(masks / "00002.jpg.jpeg", 6, 4, 1.0f);
  CHECK(error_id([&] { (void)io::list_frames(frames, masks); }) == "io.duplicate_stem");
  fs::remove(masks / "00002.jpg.jpeg");

  // Mask of the wrong size.
  write_gray(masks / "00001.jpg.png", 7, 4, 1.0f);
  const auto list = io::list_frames(frames, masks);
  CHECK(error_id([&] { (void)io::read_masks(list); }) == "io.size_mismatch");
  CHECK(error_where([&] { (void)io::read_masks(list); }) == (masks / "00001.jpg.png").string());
  // Frame of the wrong size.
  write_gray(frames / "00002.jpg.png", 6, 5, 0.5f);
  CHECK(error_id([&] { (void)io::read_frames(list); }) == "io.size_mismatch");
  CHECK(error_where([&] { (void)io::read_frames(list); }) == (frames / "00002.jpg.png").string());
  // A truncated frame: the lowest failing index is reported whatever the thread timing.
  test::write_bytes(frames / "00001.jpg.png", "\x89PNG\r\n\x1a\n");
  ThreadPool pool(2);
  CHECK(error_id([&] { (void)io::read_frames(list, &pool); }) == "io.truncated");
  CHECK(error_where([&] { (void)io::read_frames(list, &pool); }) == (frames / "00001.jpg.png").string());
  fs::remove_all(dir);
}

TEST_CASE("frame_folder: check_frames validates without holding; ranged reads equal the whole read's slice") {
  const auto dir = test::fresh_temp_dir("frames_stream");
  const auto frames = dir / "frames", masks = dir / "masks";
  fs::create_directories(frames);
  fs::create_directories(masks);
  for (int i = 0; i < 5; ++i) {
    const std::string s = "0000" + std::to_string(i) + ".png";
    write_gray(frames / s, 6, 4, 0.1f * float(i + 1));
    write_gray(masks / s, 6, 4, i % 2 ? 1.0f : 0.0f);
  }
  ThreadPool pool(2);
  auto list = io::list_frames(frames, masks);
  const io::ImageInfo info = io::check_frames(list, &pool);
  CHECK(info.width == 6);
  CHECK(info.height == 4);
  const auto all = io::read_frames(list, &pool);
  const auto all_masks = io::read_masks(list, &pool);
  const auto part = io::read_frames(list, 1, 3, &pool);
  const auto part_masks = io::read_masks(list, 1, 3);
  REQUIRE(part.size() == 3);
  REQUIRE(part_masks.size() == 3);
  for (std::size_t i = 0; i < 3; ++i) {
    CHECK(part[i].storage() == all[i + 1].storage());
    CHECK(part_masks[i].storage() == all_masks[i + 1].storage());
  }
  CHECK(io::read_frames(list, 4, 4).size() == 1);
  CHECK(error_id([&] { (void)io::read_frames(list, 3, 5); }) == "option.range");
  CHECK(error_id([&] { (void)io::read_masks(list, -1, 2); }) == "option.range");
  CHECK(error_id([&] { (void)io::read_frames(list, 2, 1); }) == "option.range");
  CHECK(io::read_masks(io::list_frames(frames), 0, 4).empty());

  // The same errors as the whole reads: a mask of the wrong size, then a truncated frame (lowest index).
  write_gray(masks / "00003.png", 7, 4, 1.0f);
  CHECK(error_id([&] { (void)io::check_frames(list, &pool); }) == "io.size_mismatch");
  CHECK(error_where([&] { (void)io::check_frames(list, &pool); }) == (masks / "00003.png").string());
  write_gray(frames / "00004.png", 6, 5, 0.5f);
  CHECK(error_where([&] { (void)io::check_frames(list, &pool); }) == (frames / "00004.png").string());  // frames before masks
  test::write_bytes(frames / "00002.png", "\x89PNG\r\n\x1a\n");
  CHECK(error_id([&] { (void)io::check_frames(list, &pool); }) == "io.truncated");
  CHECK(error_where([&] { (void)io::check_frames(list, &pool); }) == (frames / "00002.png").string());
  fs::remove_all(dir);
}

TEST_CASE("frame_folder: inputs people have (mixed formats and extensions, EXIF turns, odd paths, symlinks)") {
  // A 16x8 upright picture: left half level 60, right half 180 (8x8 blocks survive quality-100 JPEG).
  Image<float, 1> upright(16, 8);
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 16; ++x) upright(x, y) = (x < 8 ? 60.0f : 180.0f) / 255.0f;
  // Spaces and non-ASCII characters in every folder name.
  const auto dir = test::fresh_temp_dir("frames_real_world") / "vidéo du chien ü";
  const auto frames = dir / "cadres 1", masks = dir / "masques é", elsewhere = dir / "autre dossier";
  fs::create_directories(frames);
  fs::create_directories(masks);
  fs::create_directories(elsewhere);
  // 0: 8-bit grey PNG; 1: greyscale JPEG (.jpg); 2: the picture stored turned, EXIF orientation 6 (.JPEG);
  // 3: 16-bit RGB PNG; 4: RGBA PNG (alpha dropped); 5: a symlink to a PNG in another folder.
  io::write_png(frames / "0.png", upright);
  test::write_bytes(frames / "1.jpg", test::encode_test_jpeg(16, 8, 1, test::to_bytes(upright)));
  const auto turned = test::as_displayed(upright, 8);  // stored a quarter turn counter-clockwise: shown with tag 6
  test::write_bytes(frames / "2.JPEG",
                    test::with_exif_orientation(test::encode_test_jpeg(8, 16, 1, test::to_bytes(turned)), 6, false));
  std::vector<unsigned> rgb16, rgba8;
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 16; ++x) {
      const unsigned v = x < 8 ? 60u : 180u;
      rgb16.insert(rgb16.end(), {v * 257u, v * 257u, v * 257u});
      rgba8.insert(rgba8.end(), {v, v, v, 17u});
    }
  test::write_bytes(frames / "3.png", test::encode_test_png(16, 8, 16, 2, rgb16));
  test::write_bytes(frames / "4.png", test::encode_test_png(16, 8, 8, 6, rgba8));
  io::write_png(elsewhere / "linked.png", upright);
  fs::create_symlink(elsewhere / "linked.png", frames / "5.png");
  for (int i = 0; i < 6; ++i) io::write_png(masks / (std::to_string(i) + (i % 2 ? ".PNG" : ".png")), upright);
  // The frames folder reached through a symlinked folder.
  fs::create_directory_symlink(frames, dir / "lien vers cadres");

  ThreadPool pool(2);
  for (const auto& folder : {frames, dir / "lien vers cadres"}) {
    CAPTURE(folder);
    const auto list = io::list_frames(folder, masks);
    REQUIRE(list.size() == 6);
    const auto info = io::check_frames(list, &pool);
    CHECK(info.width == 16);
    CHECK(info.height == 8);
    const auto imgs = io::read_frames(list, &pool);
    for (std::size_t i = 0; i < imgs.size(); ++i) {
      CAPTURE(i);
      REQUIRE(imgs[i].width() == 16);
      for (int c = 0; c < 3; ++c) {
        CHECK(std::abs(imgs[i](3, 4, c) * 255.0f - 60.0f) <= 2.0f);
        CHECK(std::abs(imgs[i](12, 4, c) * 255.0f - 180.0f) <= 2.0f);
      }
    }
    CHECK(io::read_masks(list, &pool).size() == 6);
  }
  // A frame whose symlink leads nowhere is an error naming it, not a frame silently dropped.
  fs::remove(elsewhere / "linked.png");
  CHECK(error_id([&] { (void)io::list_frames(frames, masks); }) == "io.missing");
  CHECK(error_where([&] { (void)io::list_frames(frames, masks); }) == (frames / "5.png").string());
  fs::remove_all(dir.parent_path());
}

TEST_CASE("frame_folder: real DAVIS folder (blackswan)" * doctest::test_suite("shared_data")) {
  const auto frames = test::shared_data_or_skip("blackswan/frames");
  if (frames.empty()) return;
  const auto list = io::list_frames(frames, frames.parent_path() / "masks");
  CHECK(list.size() == 50);
  CHECK(list.frames.front().filename() == "00000.jpg");
  CHECK(list.masks.back().filename() == "00049.png");
  io::FrameList few;
  few.frames = {list.frames[0], list.frames[49]};
  few.masks = {list.masks[0], list.masks[49]};
  ThreadPool pool(2);
  const auto m = io::read_masks(few, &pool);
  REQUIRE(m.size() == 2);
  CHECK(m[1].width() == 854);
}
