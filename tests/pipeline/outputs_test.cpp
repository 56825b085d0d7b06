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

TEST_CASE("stack_vertical: top rows then bottom rows; widths must agree") {
  Image<float, 3> a(4, 2, 0.25f), b(4, 3, 0.75f);
  const auto s = stack_vertical(a, b);
  CHECK(s.width() == 4);
  CHECK(s.height() == 5);
  CHECK(s.pixel(3, 1)[2] == 0.25f);
  CHECK(s.pixel(0, 2)[0] == 0.75f);
  CHECK(s.pixel(3, 4)[1] == 0.75f);
  CHECK_THROWS_AS((void)stack_vertical(a, Image<float, 3>(5, 1)), option_error);
}

TEST_CASE("compare_header: panel names over each panel, the heat map's ramp and scale; nullopt without gnuplot" *
          doctest::test_suite("needs_program")) {
  namespace fs = std::filesystem;
  CHECK(compare_header_font(96) == 7);  // small panels: 7 points, large ones 14
  CHECK(compare_header_font(854) == 14);
  CHECK(compare_header_height(854) > compare_header_height(96));
  const fs::path scratch = fs::temp_directory_path() / ("video3dgs_compare_header_" + std::to_string(::getpid()) + ".png");
  CHECK_FALSE(compare_header(200, 2, 0.25, scratch, "/nonexistent/gnuplot"));
  if (io::find_executable("gnuplot").empty()) {
    test::skip("program 'gnuplot' is not installed");
    return;
  }
  const auto h = compare_header(200, 2, 0.25, scratch);
  REQUIRE(h);
  const int font = compare_header_font(200);
  CHECK(h->width() == 604);
  CHECK(h->height() == compare_header_height(200));
  CHECK_FALSE(fs::exists(scratch));
  // Text over each panel: dark pixels above the ramp around each panel's centre.
  for (int centre : {100, 302, 504}) {
    int dark = 0;
    for (int y = 0; y < 2 * font; ++y)
      for (int x = centre - 30; x < centre + 30; ++x) dark += h->pixel(x, y)[1] < 0.5f;
    CHECK(dark > 15);
  }
  // The ramp under the third panel is heat_colour from 0 (black) to 1 (white), left to right.
  const int x0 = 404 + 40, x1 = x0 + 120, y = 2 * font + 2;
  const auto first = heat_colour(0.0), last = heat_colour(double(x1 - 1 - x0) / (x1 - x0));
  for (int k = 0; k < 3; ++k) {
    CHECK(h->pixel(x0, y)[k] == doctest::Approx(first[std::size_t(k)]));
    CHECK(h->pixel(x1 - 1, y)[k] == doctest::Approx(last[std::size_t(k)]));
  }
  // Stacked on a compare frame of the same panels.
  Image<float, 3> p(200, 10, 0.5f);
  const auto frame = stack_vertical(*h, side_by_side({&p, &p, &p}));
  CHECK(frame.height() == h->height() + 10);
}
