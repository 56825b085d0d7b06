#include "video3dgs/io/atomic_file.hpp"

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include <doctest/doctest.h>

#include "png_writer.hpp"

using namespace video3dgs;
namespace fs = std::filesystem;

namespace {
std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
std::size_t entries(const fs::path& dir) {
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++n;
  return n;
}
}  // namespace

TEST_CASE("atomic_file: write_file_atomic creates and replaces, leaving no temporary file") {
  const auto dir = test::fresh_temp_dir("atomic_write");
  const auto target = dir / "out.bin";
  io::write_file_atomic(target, std::string("first\0with nul", 14));
  CHECK(slurp(target) == std::string("first\0with nul", 14));
  io::write_file_atomic(target, "second");
  CHECK(slurp(target) == "second");
  CHECK(entries(dir) == 1);
  fs::remove_all(dir);
}

TEST_CASE("atomic_file: without commit the target is untouched and the temporary file removed") {
  const auto dir = test::fresh_temp_dir("atomic_abort");
  const auto target = dir / "model.ply";
  io::write_file_atomic(target, "old");
  {
    io::AtomicFile f;
    f.open(target) << "new content that is never committed";
    CHECK(f.is_open());
    CHECK(fs::exists(f.temp_path()));
    CHECK(f.temp_path().parent_path() == target.parent_path());
    CHECK(slurp(target) == "old");
  }
  CHECK(slurp(target) == "old");
  CHECK(entries(dir) == 1);

  io::AtomicFile g(target);
  g.stream() << "committed";
  g.commit();
  CHECK_FALSE(g.is_open());
  CHECK(slurp(target) == "committed");
  CHECK(entries(dir) == 1);
  fs::remove_all(dir);
}

TEST_CASE("atomic_file: errors are io.unwritable and name the target") {
  const auto dir = test::fresh_temp_dir("atomic_errors");
  const auto target = dir / "no_such_dir" / "x.bin";
  try {
    io::write_file_atomic(target, "x");
    FAIL("expected io.unwritable");
  } catch (const io_error& e) {
    CHECK(e.id() == "io.unwritable");
    CHECK(e.where() == target.string());
    CHECK(std::string(e.what()).find("does not exist") != std::string::npos);
  }
  io::AtomicFile f;
  CHECK_THROWS_AS(f.commit(), io_error);
  fs::remove_all(dir);
}
