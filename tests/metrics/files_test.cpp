#include "video3dgs/metrics/files.hpp"

#include <cmath>
#include <filesystem>
#include <limits>
#include <random>
#include <string>

#include <unistd.h>

#include <doctest/doctest.h>

#include "../test_data.hpp"

using namespace video3dgs;
using video3dgs::test::error_id;
using video3dgs::test::error_where;
namespace fs = std::filesystem;

namespace {
fs::path fresh_dir(const std::string& name) {
  const auto dir = fs::temp_directory_path() / ("video3dgs_test_metrics_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}
Image<float, 3> random_u8(int w, int h, unsigned seed) {
  std::mt19937 rng(seed);
  Image<float, 3> img(w, h);
  for (auto& v : img.storage()) v = static_cast<float>(rng() % 256) / 255.0f;
  return img;
}
}  // namespace

TEST_CASE("metrics files: 8-bit files give the metrics of their k/255 images") {
  const auto dir = fresh_dir("pairs");
  const auto a = random_u8(33, 21, 1);
  auto b = a;
  for (auto& v : b.storage()) v = std::round(std::min(1.0f, v * 0.8f + 0.1f) * 255.0f) / 255.0f;
  io::write_png(dir / "a.png", a);
  io::write_png(dir / "b.png", b);
  const auto m = metrics::compare_image_files(dir / "a.png", dir / "b.png");
  CHECK(m.psnr == doctest::Approx(metrics::psnr(a.cast<double>(), b.cast<double>())).epsilon(1e-12));
  CHECK(m.ssim == doctest::Approx(metrics::ssim(a, b)).epsilon(1e-12));
  const auto same = metrics::compare_image_files(dir / "a.png", dir / "a.png");
  CHECK(same.psnr == std::numeric_limits<double>::infinity());
  CHECK(same.ssim == 1.0);

  io::write_png(dir / "small.png", random_u8(8, 8, 2));
  CHECK(error_id([&] { (void)metrics::compare_image_files(dir / "a.png", dir / "small.png"); }) == "io.size_mismatch");
  CHECK(error_id([&] { (void)metrics::compare_image_files(dir / "a.png", dir / "none.png"); }) == "io.missing");
  fs::remove_all(dir);
}

TEST_CASE("metrics files: frame folders are paired in natural order; counts must match") {
  const auto dir = fresh_dir("folders");
  fs::create_directories(dir / "a");
  fs::create_directories(dir / "b");
  for (int i : {1, 2, 10}) {
    const auto img = random_u8(16, 12, static_cast<unsigned>(i));
    io::write_png(dir / "a" / (std::to_string(i) + ".png"), img);
    std::string b_name = "f";  // (not "f" + std::string: GCC 12 warns falsely, -Wrestrict)
    b_name += std::to_string(i) + ".png";
    io::write_png(dir / "b" / b_name, i == 10 ? random_u8(16, 12, 99) : img);
  }
  ThreadPool two(2);
  const auto m = metrics::compare_frame_folders(dir / "a", dir / "b", &two);
  REQUIRE(m.frames() == 3);
  CHECK(m.per_frame[0].ssim == 1.0);
  CHECK(m.per_frame[1].ssim == 1.0);
  CHECK(m.per_frame[2].ssim < 0.5);
  CHECK(m.b[2].filename() == "f10.png");
  CHECK(m.psnr == std::numeric_limits<double>::infinity());
  CHECK(m.ssim == doctest::Approx((2.0 + m.per_frame[2].ssim) / 3.0));
  const auto serial = metrics::compare_frame_folders(dir / "a", dir / "b", nullptr);
  CHECK(serial.per_frame[2].psnr == m.per_frame[2].psnr);

  io::write_png(dir / "b" / "f11.png", random_u8(16, 12, 3));
  CHECK(error_id([&] { (void)metrics::compare_frame_folders(dir / "a", dir / "b"); }) == "io.count_mismatch");
  CHECK(error_id([&] { (void)metrics::compare_frame_folders(dir / "a", dir / "missing"); }) == "io.missing");
  fs::remove_all(dir);
}

TEST_CASE("metrics files: real frames (blackswan) against themselves and a shifted neighbour" *
          doctest::test_suite("shared_data")) {
  const auto frames = test::shared_data_or_skip("blackswan/frames");
  if (frames.empty()) return;
  const auto same = metrics::compare_image_files(frames / "00000.jpg", frames / "00000.jpg");
  CHECK(same.ssim == 1.0);
  const auto next = metrics::compare_image_files(frames / "00000.jpg", frames / "00001.jpg");
  CHECK(next.psnr > 10.0);
  CHECK(next.psnr < 40.0);
  CHECK(next.ssim > 0.2);
  CHECK(next.ssim < 1.0);
}
