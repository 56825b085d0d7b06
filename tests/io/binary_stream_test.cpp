#include "video3dgs/io/binary_stream.hpp"

#include <doctest/doctest.h>

using namespace video3dgs;

TEST_CASE("binary_stream: round trip, truncation, bad magic and newer versions name the file and field") {
  io::BinaryWriter w("V3DGSCKP", 2);
  w.put<std::int32_t>(-7);
  w.put<double>(0.125);
  w.put_vector(std::vector<float>{1.f, 2.f, 3.f});
  w.put_string("clip_000");
  const std::string bytes = w.bytes();

  io::BinaryReader r(bytes, "a.ckpt", "V3DGSCKP", 2);
  CHECK(r.version() == 2);
  CHECK(r.get<std::int32_t>("n") == -7);
  CHECK(r.get<double>("lr") == 0.125);
  CHECK(r.get_vector<float>("xyz") == std::vector<float>{1.f, 2.f, 3.f});
  CHECK(r.get_string("name") == "clip_000");
  CHECK_NOTHROW(r.expect_end());

  for (std::size_t cut : {std::size_t(14), bytes.size() - 3, std::size_t(30)}) {
    io::BinaryReader t(std::string_view(bytes).substr(0, cut), "b.ckpt", "V3DGSCKP", 2);
    try {
      (void)t.get<std::int32_t>("n");
      (void)t.get<double>("lr");
      (void)t.get_vector<float>("xyz");
      (void)t.get_string("name");
      FAIL("expected io.truncated");
    } catch (const io_error& e) {
      CHECK(e.id() == "io.truncated");
      CHECK(std::string(e.what()).find("b.ckpt") != std::string::npos);
    }
  }
  try {
    io::BinaryReader bad(bytes, "c.ckpt", "OTHERMAG", 2);
    FAIL("expected io.format");
  } catch (const io_error& e) {
    CHECK(e.id() == "io.format");
  }
  try {
    io::BinaryReader newer(bytes, "d.ckpt", "V3DGSCKP", 1);
    FAIL("expected io.version");
  } catch (const io_error& e) {
    CHECK(e.id() == "io.version");
  }
  // A corrupt length prefix asking for an absurd count fails cleanly instead of allocating.
  io::BinaryWriter huge("V3DGSCKP", 1);
  huge.put<std::uint64_t>(1ull << 60);
  io::BinaryReader hr(huge.bytes(), "e.ckpt", "V3DGSCKP", 1);
  CHECK_THROWS_AS((void)hr.get_vector<float>("xyz"), io_error);
}
