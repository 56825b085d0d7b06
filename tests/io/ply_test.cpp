#include "video3dgs/io/ply.hpp"

#include <filesystem>
#include <fstream>
#include <string>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "video3dgs/rasterizer/rasterizer.hpp"
#include "video3dgs/synthetic/scene.hpp"

using namespace video3dgs;
namespace fs = std::filesystem;

namespace {
fs::path temp_dir() {
  const fs::path d = fs::temp_directory_path() / ("video3dgs_ply_test_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}
void write_text(const fs::path& p, const std::string& s) {
  std::ofstream(p, std::ios::binary) << s;
}
std::string error_id(const fs::path& p) {
  try {
    (void)io::read_ply<float>(p);
  } catch (const io_error& e) {
    return e.id();
  }
  return "none";
}
}  // namespace

TEST_CASE_TEMPLATE("ply: binary round trip for every SH degree", Scalar, float, double) {
  const auto dir = temp_dir();
  const auto cam = Camera<Scalar>::from_fov(64, 48, Scalar(1));
  auto check = [&](auto cloud) {
    constexpr int D = decltype(cloud)::sh_degree;
    const auto path = dir / ("deg" + std::to_string(D) + ".ply");
    io::write_ply(path, cloud);
    const auto back = io::read_ply<Scalar>(path);
    REQUIRE(back.count == cloud.size());
    CHECK(back.sh_degree == D);
    auto same = [](const std::vector<Scalar>& a, const std::vector<Scalar>& b) {
      if (a.size() != b.size()) return false;
      for (std::size_t i = 0; i < a.size(); ++i)
        if (static_cast<float>(a[i]) != static_cast<float>(b[i])) return false;
      return true;
    };
    CHECK(same(back.mean, cloud.mean));
    CHECK(same(back.log_scale, cloud.log_scale));
    CHECK(same(back.rotation, cloud.rotation));
    CHECK(same(back.opacity_logit, cloud.opacity_logit));
    CHECK(same(back.sh, cloud.sh));
    // Conversion to degree 3 pads, to degree 0 keeps the DC band.
    const auto c3 = back.template to_cloud<3>();
    if (!cloud.empty()) CHECK(static_cast<float>(c3.sh[0]) == static_cast<float>(cloud.sh[0]));
    const auto c0 = back.template to_cloud<0>();
    CHECK(c0.sh.size() == 3 * cloud.size());
  };
  check(synthetic::random_view_cloud<Scalar, 0>(cam, 17, 1));
  check(synthetic::random_view_cloud<Scalar, 1>(cam, 17, 2));
  check(synthetic::random_view_cloud<Scalar, 2>(cam, 17, 3));
  check(synthetic::random_view_cloud<Scalar, 3>(cam, 17, 4));
  check(GaussianCloud<Scalar, 3>());
}

TEST_CASE("ply: the header is the standard 3DGS layout (channel-major f_rest)") {
  GaussianCloud<float, 1> c(1);
  for (int k = 0; k < 4; ++k)
    for (int ch = 0; ch < 3; ++ch) c.sh[3 * k + ch] = float(10 * ch + k);  // value = 10 c + k
  const std::string b = io::ply_bytes(c.params());
  CHECK(b.find("format binary_little_endian 1.0") != std::string::npos);
  CHECK(b.find("property float f_rest_8\nproperty float opacity\nproperty float scale_0") != std::string::npos);
  const std::size_t body = b.find("end_header\n") + 11;
  float row[3 + 3 + 3 + 9 + 1 + 3 + 4];
  REQUIRE(b.size() - body == sizeof(row));
  std::memcpy(row, b.data() + body, sizeof(row));
  CHECK(row[6] == 0.f);    // f_dc_0 = channel 0, k 0
  CHECK(row[7] == 10.f);   // f_dc_1
  CHECK(row[9] == 1.f);    // f_rest_0 = channel 0, k 1
  CHECK(row[11] == 3.f);   // f_rest_2 = channel 0, k 3
  CHECK(row[12] == 11.f);  // f_rest_3 = channel 1, k 1
  CHECK(row[22] == 1.f);   // rot_0 (w) of the identity
}

TEST_CASE("ply: ascii and big-endian files, extra properties and elements, any order") {
  const auto dir = temp_dir();
  const std::string ascii =
      "ply\nformat ascii 1.0\ncomment made by hand\nelement camera 1\nproperty float fov\n"
      "element vertex 2\nproperty float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\n"
      "property double x\nproperty float y\nproperty float z\nproperty uchar red\n"
      "property float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\nproperty float opacity\n"
      "property float scale_0\nproperty float scale_1\nproperty float scale_2\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0.7\n"
      "1 0 0 0  1.5 2.5 3.5 255  0.1 0.2 0.3  -2  -1 -2 -3\n"
      "0 1 0 0  4 5 6 0  0.4 0.5 0.6  2  -4 -5 -6\n"
      "3 0 1 2\n";
  write_text(dir / "a.ply", ascii);
  const auto a = io::read_ply<double>(dir / "a.ply");
  REQUIRE(a.count == 2);
  CHECK(a.sh_degree == 0);
  CHECK(a.mean[0] == 1.5);
  CHECK(a.mean[5] == 6.0);
  CHECK(a.rotation[5] == 1.0);
  CHECK(a.sh[4] == doctest::Approx(0.5));
  CHECK(a.opacity_logit[1] == 2.0);
  CHECK(a.log_scale[5] == -6.0);

  // Big endian, one vertex.
  std::string be = "ply\nformat binary_big_endian 1.0\nelement vertex 1\n";
  const char* names[] = {"x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"};
  for (const char* n : names) be += std::string("property float ") + n + "\n";
  be += "end_header\n";
  for (int i = 0; i < 14; ++i) {
    const float f = float(i) + 0.5f;
    char b[4];
    std::memcpy(b, &f, 4);
    std::reverse(b, b + 4);
    be.append(b, 4);
  }
  write_text(dir / "be.ply", be);
  const auto b = io::read_ply<float>(dir / "be.ply");
  CHECK(b.mean[1] == 1.5f);
  CHECK(b.rotation[3] == 13.5f);
}

TEST_CASE("ply: clear errors for truncated files, missing properties, wrong counts") {
  const auto dir = temp_dir();
  GaussianCloud<float, 2> c(5);
  io::write_ply(dir / "ok.ply", c);
  std::string bytes;
  {
    std::ifstream in(dir / "ok.ply", std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  write_text(dir / "trunc.ply", bytes.substr(0, bytes.size() - 7));
  CHECK(error_id(dir / "trunc.ply") == "io.truncated");
  write_text(dir / "trunc_header.ply", bytes.substr(0, 40));
  CHECK(error_id(dir / "trunc_header.ply") == "io.truncated");
  std::string missing = bytes;
  missing.replace(missing.find("property float opacity"), 22, "property float opacitz");
  write_text(dir / "missing.ply", missing);
  CHECK(error_id(dir / "missing.ply") == "io.missing_property");
  try {
    (void)io::read_ply<float>(dir / "missing.ply");
  } catch (const io_error& e) {
    CHECK(std::string(e.what()).find("'opacity'") != std::string::npos);
  }
  std::string wrong = bytes;
  wrong.replace(wrong.find("property float f_rest_23"), 24, "property float f_rest_xx");  // 23 f_rest: no degree
  write_text(dir / "wrong.ply", wrong);
  CHECK(error_id(dir / "wrong.ply") == "io.format");
  std::string more = bytes;
  more.replace(more.find("element vertex 5"), 16, "element vertex 6");
  write_text(dir / "count.ply", more);
  CHECK(error_id(dir / "count.ply") == "io.truncated");
  write_text(dir / "notply.ply", "hello\n");
  CHECK(error_id(dir / "notply.ply") == "io.format");
  CHECK(error_id(dir / "absent.ply") == "io.unreadable");
  write_text(dir / "badascii.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n");
  CHECK(error_id(dir / "badascii.ply") == "io.missing_property");
  fs::remove_all(dir);
}

TEST_CASE("ply: write, read, render twice gives identical pixels") {
  const auto dir = temp_dir();
  const auto cloud = synthetic::demo_scene<float>(3, 400, 30);
  const auto cam = synthetic::demo_camera<double>(160, 90, 1, 3).cast<float>();
  io::write_ply(dir / "scene.ply", cloud);
  const auto back = io::read_ply<float>(dir / "scene.ply");
  Rasterizer<float, 16> r;
  RasterContext<float, 3> a, b, c;
  r.forward(cam, cloud.params(), a);
  r.forward(cam, back.params(), b);
  ThreadPool pool(2);
  r.forward(cam, back.params(), c, &pool);
  CHECK(a.image.storage() == b.image.storage());
  CHECK(b.image.storage() == c.image.storage());
  CHECK(a.stats.visible > 100);
  fs::remove_all(dir);
}
