// Tests of include/video3dgs/flow/*: warping, the forward-backward check, .flo I/O, and the
// endpoint error of the built-in Horn-Schunck estimator on synthetic motions with exact flow.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <numbers>

#include <doctest/doctest.h>

#include "video3dgs/flow.hpp"

using namespace video3dgs;

namespace {

/// Smooth procedural texture with several scales (values in ~[0.1, 0.9]).
double texture(double x, double y, int c) {
  const double s = 0.5 + 0.12 * std::sin(0.29 * x + 0.17 * y + c) + 0.1 * std::sin(-0.21 * x + 0.37 * y + 1.0 + 0.5 * c) +
                   0.08 * std::sin(0.11 * x - 0.06 * y + 2.0) + 0.06 * std::cos(0.53 * x + 0.47 * y) +
                   0.05 * std::sin(0.05 * x * std::cos(0.031 * y) + 0.7 * c);
  return s;
}

/// Image whose pixel (x, y) (centre at x, y in pixel-index units) shows texture at map(x, y).
Image<float, 3> render(int w, int h, const std::function<void(double, double, double&, double&)>& map) {
  Image<float, 3> img(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double u, v;
      map(x, y, u, v);
      for (int c = 0; c < 3; ++c) img(x, y, c) = float(texture(u, v, c));
    }
  return img;
}

struct Case {
  const char* name;
  // A maps a's pixel p to its position in b: q = A(p). b(q) = a(A^{-1}(q)).
  std::function<void(double, double, double&, double&)> fwd, inv;
};

}  // namespace

TEST_CASE("warp_bilinear: zero flow is identity, integer shift moves pixels, outside samples are invalid") {
  Image<float, 3> img = render(20, 12, [](double x, double y, double& u, double& v) { u = x, v = y; });
  flow::FlowFieldF zero(20, 12);
  Image<float, 3> out(20, 12);
  Image<float, 1> valid(20, 12);
  flow::warp_bilinear<float, 3, float>(img.view(), zero.view(), out.view(), valid.view());
  CHECK(out.storage() == img.storage());
  for (float v : valid.storage()) CHECK(v == 1.f);
  flow::FlowFieldF shift(20, 12);
  for (int y = 0; y < 12; ++y)
    for (int x = 0; x < 20; ++x) shift(x, y, 0) = 3.f, shift(x, y, 1) = -1.f;
  flow::warp_bilinear<float, 3, float>(img.view(), shift.view(), out.view(), valid.view());
  CHECK(out(4, 5, 1) == img(7, 4, 1));
  CHECK(valid(16, 5) == 1.f);
  CHECK(valid(17, 5) == 0.f);  // 17 + 3 = 20 > 19
  CHECK(valid(4, 0) == 0.f);   // row -1
  shift(2, 2, 0) = std::nanf("");
  flow::warp_bilinear<float, 3, float>(img.view(), shift.view(), out.view(), valid.view());
  CHECK(valid(2, 2) == 0.f);
  CHECK(std::isfinite(out(2, 2, 0)));
}

TEST_CASE_TEMPLATE("consistency_mask: consistent translation is visible; a disagreeing region is occluded", Scalar, float, double) {
  const int w = 32, h = 24;
  flow::FlowField<Scalar> f(w, h), g(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      f(x, y, 0) = Scalar(2.5), f(x, y, 1) = Scalar(1);
      g(x, y, 0) = Scalar(-2.5), g(x, y, 1) = Scalar(-1);
    }
  for (int y = 10; y < 14; ++y)
    for (int x = 10; x < 14; ++x) g(x, y, 0) = Scalar(4);  // disagrees with f
  const auto m = flow::consistency_mask<Scalar>(f.view(), g.view());
  CHECK(m(20, 20) == Scalar(1));
  CHECK(m(11, 11) == Scalar(0));
  CHECK(m(0, 5) == Scalar(0));   // lands outside a (x - 2.5 < 0)
  CHECK(m(3, 5) == Scalar(1));
}

TEST_CASE(".flo round trip, unknown marker, and errors") {
  flow::FlowFieldF f(5, 3);
  for (std::size_t i = 0; i < f.size(); ++i) f.data()[i] = float(i) * 0.25f - 1.f;
  f(1, 1, 0) = std::nanf("");
  const std::string bytes = flow::encode_flo<float>(f.view());
  CHECK(bytes.size() == 12 + 5 * 3 * 8);
  CHECK(bytes.substr(0, 4) == "PIEH");
  const auto g = flow::decode_flo(bytes);
  REQUIRE(g.width() == 5);
  REQUIRE(g.height() == 3);
  for (std::size_t i = 0; i < f.size(); ++i) {
    if (std::isnan(f.data()[i]))
      CHECK(std::isnan(g.data()[i]));
    else
      CHECK(g.data()[i] == f.data()[i]);
  }
  const auto dir = std::filesystem::temp_directory_path() / "video3dgs_flow_test";
  std::filesystem::create_directories(dir);
  flow::write_flo(dir / "00001.flo", f);
  flow::write_flo(dir / "00000.flo", f);
  const auto files = flow::list_flo_files(dir);
  REQUIRE(files.size() == 2);
  CHECK(files[0].filename() == "00000.flo");
  CHECK(flow::read_flo(files[1]).width() == 5);
  std::filesystem::remove_all(dir);

  auto id_of = [](const std::string& b) {
    try {
      (void)flow::decode_flo(b);
    } catch (const io_error& e) {
      return e.id();
    }
    return std::string("none");
  };
  CHECK(id_of("PIEH") == "io.truncated");
  CHECK(id_of(std::string("XXXX") + bytes.substr(4)) == "io.format");
  CHECK(id_of(bytes.substr(0, bytes.size() - 1)) == "io.truncated");
  CHECK(id_of(bytes + "x") == "io.format");
  CHECK_THROWS_AS((void)flow::read_flo("/nonexistent/x.flo"), io_error);
}

TEST_CASE("Horn-Schunck: endpoint error on synthetic motions with exact flow") {
  const int w = 96, h = 80;
  const double cx = w / 2.0, cy = h / 2.0;
  const double th = 3.0 * std::numbers::pi / 180.0, sc = 1.03;
  std::vector<Case> cases = {
      {"translation(1.3,-0.6)", [](double x, double y, double& u, double& v) { u = x + 1.3, v = y - 0.6; },
       [](double x, double y, double& u, double& v) { u = x - 1.3, v = y + 0.6; }},
      {"translation(6.2,3.5)", [](double x, double y, double& u, double& v) { u = x + 6.2, v = y + 3.5; },
       [](double x, double y, double& u, double& v) { u = x - 6.2, v = y - 3.5; }},
      {"rotation3deg+zoom1.03",
       [&](double x, double y, double& u, double& v) {
         const double dx = x - cx, dy = y - cy;
         u = cx + sc * (std::cos(th) * dx - std::sin(th) * dy);
         v = cy + sc * (std::sin(th) * dx + std::cos(th) * dy);
       },
       [&](double x, double y, double& u, double& v) {
         const double dx = (x - cx) / sc, dy = (y - cy) / sc;
         u = cx + (std::cos(th) * dx + std::sin(th) * dy);
         v = cy + (-std::sin(th) * dx + std::cos(th) * dy);
       }},
  };
  for (const Case& k : cases) {
    const Image<float, 3> a = render(w, h, [](double x, double y, double& u, double& v) { u = x, v = y; });
    const Image<float, 3> b = render(w, h, k.inv);
    flow::FlowFieldD gt(w, h);
    Image<float, 1> mask(w, h);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        double u, v;
        k.fwd(x, y, u, v);
        gt(x, y, 0) = u - x, gt(x, y, 1) = v - y;
        // interior: away from the borders where the target leaves the frame
        mask(x, y) = (u >= 8 && v >= 8 && u <= w - 9 && v <= h - 9 && x >= 8 && y >= 8 && x <= w - 9 && y <= h - 9) ? 1.f : 0.f;
      }
    ThreadPool pool(2);
    const auto f = flow::estimate_flow<float>(a, b, {}, &pool);
    const double epe = flow::endpoint_error<float, double>(f.view(), gt.view(), mask.view());
    flow::FlowFieldF zero(w, h);
    const double epe0 = flow::endpoint_error<float, double>(zero.view(), gt.view(), mask.view());
    std::printf("{\"flow_epe_case\":\"%s\",\"epe\":%.4f,\"epe_zero_flow\":%.4f}\n", k.name, epe, epe0);
    CHECK(epe < 0.35);
    CHECK(epe < 0.1 * epe0);
    // determinism across pools
    const auto f1 = flow::estimate_flow<float>(a, b, {}, nullptr);
    CHECK(f1.storage() == f.storage());
  }
}

TEST_CASE("Horn-Schunck: option errors and identical frames") {
  Image<float, 3> a(40, 30, 0.5f);
  for (int y = 0; y < 30; ++y)
    for (int x = 0; x < 40; ++x) a(x, y, 0) = float(texture(x, y, 0));
  const auto f = flow::estimate_flow<float>(a, a);
  for (float v : f.storage()) CHECK(std::fabs(v) < 1e-6f);
  flow::HornSchunckOptions bad;
  bad.alpha = 0;
  CHECK_THROWS_AS((void)flow::estimate_flow<float>(a, a, bad), option_error);
  Image<float, 3> b(41, 30);
  CHECK_THROWS_AS((void)flow::estimate_flow<float>(a, b), option_error);
}
