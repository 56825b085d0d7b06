#include "video3dgs/colmap/model_io.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "video3dgs/colmap/convert.hpp"
#include "video3dgs/colmap/process.hpp"
#include "video3dgs/colmap/undistort.hpp"

using namespace video3dgs;
namespace fs = std::filesystem;

namespace {

double rel(double a, double b) { return std::abs(a - b) / std::max(1.0, std::max(std::abs(a), std::abs(b))); }

/// A small model exercising every camera model's parameter count.
colmap::Model small_model() {
  colmap::Model m;
  for (const auto& info : colmap::kCameraModels) {
    colmap::CameraRecord c;
    c.id = static_cast<std::uint32_t>(info.id + 1);
    c.model_id = info.id;
    c.width = 640;
    c.height = 480;
    for (int i = 0; i < info.num_params; ++i) c.params.push_back(100.0 / 3.0 + i * 0.1);
    m.cameras[c.id] = c;
  }
  colmap::ImageRecord a;
  a.id = 3;
  a.qvec = {0.9, 0.1, -0.3, 0.2};
  a.tvec = {1.0 / 7.0, -2.5, 1e-17};
  a.camera_id = 1;
  a.name = "frame one.jpg";  // a space in the name
  a.points2D = {{10.25, 20.5}, {1.0 / 3.0, 479.99}};
  a.point3D_ids = {7, colmap::kNoPoint3D};
  m.images[a.id] = a;
  colmap::ImageRecord b = a;
  b.id = 9;
  b.name = "b.png";
  b.points2D.clear();  // an image without 2D points (empty POINTS2D line)
  b.point3D_ids.clear();
  m.images[b.id] = b;
  colmap::Point3DRecord p;
  p.id = 7;
  p.xyz = {0.1, -1e300, 3.0};
  p.rgb = {255, 0, 17};
  p.error = 0.625;
  p.track = {{3, 0}};
  m.points[p.id] = p;
  return m;
}

void write_text(const fs::path& p, const std::string& s) {
  std::ofstream o(p, std::ios::binary);
  o << s;
}

template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const error& e) {
    return e.what();
  }
  return "no error";
}

}  // namespace

TEST_CASE("colmap model: camera model table has COLMAP's ids, names and parameter counts") {
  CHECK(colmap::find_camera_model(0)->num_params == 3);
  CHECK(colmap::find_camera_model("PINHOLE")->num_params == 4);
  CHECK(colmap::find_camera_model("SIMPLE_RADIAL")->id == 2);
  CHECK(colmap::find_camera_model("RADIAL")->num_params == 5);
  CHECK(colmap::find_camera_model("OPENCV")->num_params == 8);
  CHECK(colmap::find_camera_model("OPENCV_FISHEYE")->num_params == 8);
  CHECK(colmap::find_camera_model("FULL_OPENCV")->num_params == 12);
  CHECK(colmap::find_camera_model("FOV")->num_params == 5);
  CHECK(colmap::find_camera_model("SIMPLE_RADIAL_FISHEYE")->num_params == 4);
  CHECK(colmap::find_camera_model("RADIAL_FISHEYE")->num_params == 5);
  CHECK(colmap::find_camera_model("THIN_PRISM_FISHEYE")->num_params == 12);
  CHECK(colmap::find_camera_model(11)->num_params == 16);
  CHECK(colmap::find_camera_model(12) == nullptr);
  CHECK(colmap::find_camera_model("pinhole") == nullptr);
}

TEST_CASE("colmap model I/O: write -> read round-trips exactly in binary and text, every camera model") {
  const auto dir = test::fresh_dir("colmap_test_roundtrip");
  const colmap::Model m = small_model();
  colmap::write_model(dir / "bin", m, colmap::Format::binary);
  colmap::write_model(dir / "txt", m, colmap::Format::text);
  CHECK(colmap::detect_format(dir / "bin") == colmap::Format::binary);
  CHECK(colmap::detect_format(dir / "txt") == colmap::Format::text);
  CHECK(colmap::read_model(dir / "bin") == m);
  CHECK(colmap::read_model(dir / "txt") == m);
  fs::remove_all(dir);
}

TEST_CASE("colmap model I/O: truncated and malformed files name the file and the record") {
  const auto dir = test::fresh_dir("colmap_test_bad");
  const colmap::Model m = small_model();
  colmap::write_model(dir, m, colmap::Format::binary);
  // Truncate images.bin inside the first image's 2D points.
  {
    const auto p = dir / "images.bin";
    const auto size = fs::file_size(p);
    fs::resize_file(p, size - 30);
    const std::string e = error_of([&] { (void)colmap::read_images_binary(p); });
    CHECK(e.find("[colmap.truncated]") == 0);
    CHECK(e.find("images.bin") != std::string::npos);
    CHECK(e.find("image #1 (id 9") != std::string::npos);
  }
  // A huge point count is reported as truncation, not attempted as an allocation.
  {
    const auto p = dir / "points3D.bin";
    std::string bytes;
    {
      std::ifstream in(p, std::ios::binary);
      bytes.assign(std::istreambuf_iterator<char>(in), {});
    }
    const std::uint64_t huge = 1ull << 60;
    std::memcpy(bytes.data(), &huge, 8);
    write_text(p, bytes);
    const std::string e = error_of([&] { (void)colmap::read_points3D_binary(p); });
    CHECK(e.find("[colmap.truncated]") == 0);
    CHECK(e.find("point count") != std::string::npos);
  }
  // Unknown camera model id in binary, trailing bytes.
  {
    colmap::Model bad = m;
    colmap::write_cameras_binary(dir / "cameras.bin", bad.cameras);
    std::string bytes;
    {
      std::ifstream in(dir / "cameras.bin", std::ios::binary);
      bytes.assign(std::istreambuf_iterator<char>(in), {});
    }
    write_text(dir / "cameras_extra.bin", bytes + "x");
    CHECK(error_of([&] { (void)colmap::read_cameras_binary(dir / "cameras_extra.bin"); }).find("[colmap.malformed]") == 0);
    const std::int32_t model = 42;
    std::memcpy(bytes.data() + 8 + 4, &model, 4);
    write_text(dir / "cameras_bad.bin", bytes);
    const std::string e = error_of([&] { (void)colmap::read_cameras_binary(dir / "cameras_bad.bin"); });
    CHECK(e.find("[colmap.malformed]") == 0);
    CHECK(e.find("camera #0 (id 1)") != std::string::npos);
    CHECK(e.find("unknown camera model id 42") != std::string::npos);
  }
  // Text: wrong parameter count, bad number, odd track, missing POINTS2D line, bad colour.
  {
    write_text(dir / "c.txt", "# comment\n1 SIMPLE_RADIAL 10 10 1 2 3\n");
    std::string e = error_of([&] { (void)colmap::read_cameras_text(dir / "c.txt"); });
    CHECK(e.find("[colmap.malformed]") == 0);
    CHECK(e.find("c.txt: line 2: camera 1: SIMPLE_RADIAL needs 4 params") != std::string::npos);
    write_text(dir / "c2.txt", "1 FISHEYE 10 10 1 2 3\n");
    CHECK(error_of([&] { (void)colmap::read_cameras_text(dir / "c2.txt"); }).find("unknown camera model 'FISHEYE'") != std::string::npos);
    write_text(dir / "i.txt", "5 1 0 0 0 0 0 zero 1 a.jpg\n\n");
    e = error_of([&] { (void)colmap::read_images_text(dir / "i.txt"); });
    CHECK(e.find("line 1: image 5: cannot parse TVEC from 'zero'") != std::string::npos);
    write_text(dir / "i2.txt", "5 1 0 0 0 0 0 0 1 a.jpg\n");
    e = error_of([&] { (void)colmap::read_images_text(dir / "i2.txt"); });
    CHECK(e.find("[colmap.truncated]") == 0);
    CHECK(e.find("image 5 'a.jpg'") != std::string::npos);
    write_text(dir / "i3.txt", "5 1 0 0 0 0 0 0 1 a.jpg\n1 2 3 4\n");
    CHECK(error_of([&] { (void)colmap::read_images_text(dir / "i3.txt"); }).find("triples") != std::string::npos);
    write_text(dir / "p.txt", "1 0 0 0 1 2 3 0.5 1 2 3\n");
    CHECK(error_of([&] { (void)colmap::read_points3D_text(dir / "p.txt"); }).find("point3D 1: TRACK needs pairs") != std::string::npos);
    write_text(dir / "p2.txt", "1 0 0 0 1 256 3 0.5\n");
    CHECK(error_of([&] { (void)colmap::read_points3D_text(dir / "p2.txt"); }).find("outside 0..255") != std::string::npos);
  }
  // Missing folder / file.
  CHECK(error_of([&] { (void)colmap::read_model(dir / "nowhere"); }).find("[colmap.missing]") == 0);
  // Dangling references.
  {
    colmap::Model bad = m;
    bad.points[7].track.push_back({3, 99});
    colmap::write_model(dir / "dangling", bad, colmap::Format::text);
    const std::string e = error_of([&] { (void)colmap::read_model(dir / "dangling"); });
    CHECK(e.find("[colmap.malformed]") == 0);
    CHECK(e.find("point3D 7: track names point2D 99 of image 3") != std::string::npos);
  }
  fs::remove_all(dir);
}

TEST_CASE("colmap convert: pinhole models convert, distorted ones are rejected, zero distortion is pinhole") {
  colmap::Model m;
  m.cameras[1] = {1, 0, 854, 480, {500.0, 427.0, 240.0}};
  m.cameras[2] = {2, 1, 854, 480, {500.0, 510.0, 420.0, 250.0}};
  m.cameras[3] = {3, 2, 854, 480, {500.0, 427.0, 240.0, -0.1}};
  m.cameras[4] = {4, 4, 854, 480, {500.0, 510.0, 420.0, 250.0, 0.0, 0.0, 0.0, 0.0}};
  colmap::ImageRecord im;
  im.id = 1;
  im.camera_id = 1;
  im.qvec = {std::cos(0.25), 0, std::sin(0.25), 0};  // 0.5 rad about y
  im.tvec = {1, 2, 3};
  const auto c = colmap::to_camera<double>(m, im);
  CHECK(c.fx == 500.0);
  CHECK(c.fy == 500.0);
  CHECK(c.cx == 427.0);
  CHECK(c.cy == 240.0);
  CHECK(c.width == 854);
  CHECK(c.R(0, 2) == doctest::Approx(std::sin(0.5)));
  CHECK(c.t.y() == 2.0);
  // x_c = R x_w + t: the camera centre maps to zero.
  CHECK((c.world_to_camera(c.center())).norm() < 1e-12);
  im.camera_id = 2;
  const auto c2 = colmap::to_camera<float>(m, im);
  CHECK(c2.fy == 510.0f);
  CHECK(c2.cx == 420.0f);
  im.camera_id = 3;
  const std::string e = error_of([&] { (void)colmap::to_camera<double>(m, im); });
  CHECK(e.find("[colmap.distorted_camera] camera 3") == 0);
  CHECK(e.find("image_undistorter") != std::string::npos);
  im.camera_id = 4;
  CHECK(colmap::to_camera<double>(m, im).fy == 510.0);
}

TEST_CASE("colmap model I/O: sceaux_castle binary and text models agree; round-trips; colmap reads ours" *
          doctest::test_suite("shared_data")) {
  const auto root = test::shared_data_or_skip("colmap/sceaux_castle");
  if (root.empty()) return;
  const colmap::Model b = colmap::read_model(root / "sparse/0");
  const colmap::Model t = colmap::read_model(root / "sparse_txt/0");
  REQUIRE(b.cameras.size() == 1);
  CHECK(b.images.size() == 11);
  CHECK(b.points.size() == 7862);
  REQUIRE(t.cameras.size() == b.cameras.size());
  REQUIRE(t.images.size() == b.images.size());
  REQUIRE(t.points.size() == b.points.size());
  // The text files carry 6 significant digits.
  const double tol = 1e-5;
  for (const auto& [id, cb] : b.cameras) {
    const auto& ct = t.cameras.at(id);
    CHECK(ct.model_id == cb.model_id);
    CHECK(colmap::find_camera_model(cb.model_id)->name == std::string("SIMPLE_RADIAL"));
    CHECK(ct.width == cb.width);
    for (std::size_t i = 0; i < cb.params.size(); ++i) CHECK(rel(ct.params[i], cb.params[i]) < tol);
  }
  std::size_t obs = 0;
  for (const auto& [id, ib] : b.images) {
    const auto& it = t.images.at(id);
    CHECK(it.name == ib.name);
    CHECK(it.camera_id == ib.camera_id);
    for (int i = 0; i < 4; ++i) CHECK(std::abs(it.qvec[i] - ib.qvec[i]) < tol);
    for (int i = 0; i < 3; ++i) CHECK(rel(it.tvec[i], ib.tvec[i]) < tol);
    REQUIRE(it.points2D.size() == ib.points2D.size());
    CHECK(it.point3D_ids == ib.point3D_ids);
    for (std::size_t j = 0; j < ib.points2D.size(); ++j)
      if (rel(it.points2D[j][0], ib.points2D[j][0]) > tol || rel(it.points2D[j][1], ib.points2D[j][1]) > tol) FAIL("points2D differ");
    for (auto pid : ib.point3D_ids) obs += pid >= 0;
  }
  std::size_t track = 0;
  for (const auto& [id, pb] : b.points) {
    const auto& pt = t.points.at(id);
    if (pt.rgb != pb.rgb || pt.track != pb.track) FAIL("point " << id << " colour or track differs");
    for (int i = 0; i < 3; ++i)
      if (rel(pt.xyz[i], pb.xyz[i]) > tol) FAIL("point " << id << " xyz differs");
    track += pb.track.size();
  }
  CHECK(track == obs);  // every observation appears in exactly one track

  // Distorted (SIMPLE_RADIAL): conversion refuses instead of pretending it is a pinhole.
  CHECK_THROWS_AS((void)colmap::to_camera<double>(b, b.images.begin()->second), error);

  // Round trips.
  const auto dir = test::fresh_dir("colmap_test_sceaux");
  colmap::write_model(dir / "bin", b, colmap::Format::binary);
  CHECK(colmap::read_model(dir / "bin") == b);
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"})
    CHECK(fs::file_size(dir / "bin" / f) == fs::file_size(root / "sparse/0" / f));
  colmap::write_model(dir / "txt", b, colmap::Format::text);
  CHECK(colmap::read_model(dir / "txt") == b);

  // COLMAP itself reads what we write (binary and text).
  if (colmap::find_executable("colmap").empty()) {
    test::skip("program 'colmap' is not installed");
  } else {
    for (const char* in : {"bin", "txt"}) {
      const auto out = dir / (std::string("conv_") + in);
      fs::create_directories(out);
      const auto pr = colmap::run_process({"colmap", "model_converter", "--input_path", (dir / in).string(), "--output_path",
                                           out.string(), "--output_type", "TXT"},
                                          dir / "convert.log", 120, {"QT_QPA_PLATFORM=offscreen"});
      INFO(colmap::log_tail(dir / "convert.log"));
      REQUIRE(pr.ok());
      const colmap::Model back = colmap::read_model(out);
      CHECK(back.images.size() == b.images.size());
      CHECK(back.points.size() == b.points.size());
      for (const auto& [id, p] : b.points)
        if (back.points.at(id).track != p.track || back.points.at(id).rgb != p.rgb) FAIL("colmap changed point " << id);
      for (const auto& [id, im] : b.images) {
        const auto& o = back.images.at(id);
        CHECK(o.name == im.name);
        for (int i = 0; i < 3; ++i) CHECK(rel(o.tvec[i], im.tvec[i]) < 1e-12);
      }
    }
  }
  fs::remove_all(dir);
}

TEST_CASE("colmap undistort_model: the distorted sceaux_castle model becomes PINHOLE and converts" *
          doctest::test_suite("shared_data")) {
  const auto root = test::shared_data_or_skip("colmap/sceaux_castle");
  if (root.empty()) return;
  if (colmap::find_executable("colmap").empty()) {
    test::skip("program 'colmap' is not installed");
    return;
  }
  const auto dir = test::fresh_dir("colmap_test_undistort");
  colmap::UndistortOptions o;
  o.image_dir = root / "images";
  o.model_dir = root / "sparse/0";
  o.output_dir = dir;
  o.max_image_size = 400;  // small images keep the test fast
  const fs::path sparse = colmap::undistort_model(o);
  const colmap::Model m = colmap::read_model(sparse);
  REQUIRE(m.cameras.size() >= 1);
  CHECK(m.images.size() == 11);
  for (const auto& [id, c] : m.cameras) {
    CHECK(colmap::find_camera_model(c.model_id)->pinhole);
    CHECK(std::max(c.width, c.height) <= 400);
  }
  for (const auto& [id, im] : m.images) {
    const auto cam = colmap::to_camera<double>(m, im);
    CHECK_NOTHROW(cam.validate());
    CHECK(fs::exists(dir / "images" / im.name));
  }
  // Missing input model: a clear error naming the folder.
  o.model_dir = dir / "nowhere";
  CHECK(error_of([&] { (void)colmap::undistort_model(o); }).find("[colmap.missing]") == 0);
  fs::remove_all(dir);
}
