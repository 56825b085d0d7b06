// pipeline/outputs.hpp: area resize (exact block means, mean preserved, identity), heat map ends,
// side by side layout, metrics plot (size, both polylines drawn, non-finite values skipped), the
// gnuplot plot (written whole, with text in its margins; nothing without the program).
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <unistd.h>
#include <vector>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/pipeline/outputs.hpp"

using namespace video3dgs;
using namespace video3dgs::pipeline;

TEST_CASE("resize_area: 2x downscale gives block means; any ratio keeps the mean") {
  Image<float, 1> im(4, 4);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) im(x, y) = float(x + 4 * y);
  const auto half = resize_area(im, 2, 2);
  CHECK(half(0, 0) == doctest::Approx((0 + 1 + 4 + 5) / 4.0));
  CHECK(half(1, 1) == doctest::Approx((10 + 11 + 14 + 15) / 4.0));
  CHECK(resize_area(im, 4, 4).storage() == im.storage());
  Image<double, 3> big(37, 23);
  double mean = 0;
  for (std::size_t i = 0; i < big.size(); ++i) big.data()[i] = std::sin(0.37 * double(i)), mean += big.data()[i];
  mean /= double(big.size());
  const auto small = resize_area(big, 11, 7);
  double m2 = 0;
  for (std::size_t i = 0; i < small.size(); ++i) m2 += small.data()[i];
  CHECK(m2 / double(small.size()) == doctest::Approx(mean).epsilon(1e-9));
  CHECK_THROWS_AS((void)resize_area(big, 0, 7), option_error);
}

TEST_CASE("error_heat_map and side_by_side") {
  Image<float, 3> a(5, 3, 0.5f), b(5, 3, 0.5f);
  b(4, 2, 0) = 1.5f;  // |e| = 1 on one channel -> mean 1/3 > max_error: white
  const auto heat = error_heat_map(a, b);
  CHECK(heat(0, 0, 0) == 0.0f);
  CHECK(heat(0, 0, 2) == 0.0f);
  CHECK(heat(4, 2, 0) == 1.0f);
  CHECK(heat(4, 2, 1) == 1.0f);
  const auto sbs = side_by_side({&a, &b, &heat}, 2);
  CHECK(sbs.width() == 5 * 3 + 2 * 2);
  CHECK(sbs.height() == 3);
  CHECK(sbs(7, 0, 0) == 0.5f);
  CHECK(sbs(5, 0, 0) == 0.0f);  // gap
  Image<float, 3> tall(2, 4);
  CHECK_THROWS_AS((void)side_by_side({&a, &tall}), option_error);
}

TEST_CASE("plot_metrics draws both series and skips non-finite values") {
  std::vector<double> psnr{20, 22, std::numeric_limits<double>::infinity(), 25, 24};
  std::vector<double> ssim{0.8, 0.85, 0.9, 0.88, 0.87};
  const auto p = plot_metrics(psnr, ssim, 200, 100);
  CHECK(p.image.width() == 200);
  CHECK(p.psnr_lo < 20);
  CHECK(p.psnr_hi > 25);
  CHECK(p.ssim_hi < 1.0);
  int blue = 0, red = 0;
  for (int y = 0; y < 100; ++y)
    for (int x = 0; x < 200; ++x) {
      blue += p.image(x, y, 2) > 0.8f && p.image(x, y, 0) < 0.2f;
      red += p.image(x, y, 0) > 0.8f && p.image(x, y, 2) < 0.2f;
    }
  CHECK(blue > 50);
  CHECK(red > 50);
  const auto empty = plot_metrics({}, {}, 64, 48);
  CHECK(empty.image.width() == 64);
}

TEST_CASE("plot_metrics_gnuplot: a whole PNG with axes text, clip lines, odd paths; nothing without gnuplot" *
          doctest::test_suite("needs_program")) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("video3dgs outputs l'été " + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path csv = dir / "metrics.csv", png = dir / "metrics.png";
  {
    std::ofstream out(csv);
    out << "frame,psnr,ssim\n";
    for (int f = 0; f < 30; ++f) {
      if (f == 7) out << f << ",null,0.9\n";  // an identical frame: PSNR written as null
      else out << f << "," << 30 + 2 * std::sin(f * 0.4) << "," << 0.9 + 0.03 * std::cos(f * 0.3) << "\n";
    }
  }
  const std::vector<FrameRange> clips{{0, 9}, {9, 18}, {18, 29}};
  SUBCASE("without the program: false, nothing written") {
    CHECK_FALSE(plot_metrics_gnuplot(csv, png, clips, dir / "no-gnuplot-here"));
    CHECK_FALSE(fs::exists(png));
  }
  SUBCASE("with gnuplot") {
    if (io::find_executable("gnuplot").empty()) {
      test::skip("program 'gnuplot' is not installed");
      return;
    }
    REQUIRE(plot_metrics_gnuplot(csv, png, clips));
    const auto im = io::read_image<3>(png);
    CHECK(im.width() == 960);
    CHECK(im.height() == 360);
    // Text (tick labels, the PSNR axis label) in the left margin, where the plain plot has none.
    int dark = 0;
    for (int y = 40; y < 300; ++y)
      for (int x = 0; x < 50; ++x) dark += im.pixel(x, y)[0] < 0.5f;
    CHECK(dark > 100);
    // The script, the log and the temporary image are gone.
    for (const auto& e : fs::directory_iterator(dir)) CHECK((e.path().filename() == "metrics.csv" || e.path().filename() == "metrics.png"));
  }
  fs::remove_all(dir);
}
