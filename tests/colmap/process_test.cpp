#include "video3dgs/colmap/process.hpp"

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <doctest/doctest.h>

using namespace video3dgs;
namespace fs = std::filesystem;

namespace {
std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}
}  // namespace

TEST_CASE("run_process: arguments reach the program verbatim (no shell), output goes to the log") {
  const fs::path dir = fs::temp_directory_path() / ("video3dgs process test " + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path log = dir / "out put.log";
  const auto r = colmap::run_process({"echo", "a b; rm -rf x", "$HOME", "`id`"}, log, 10, {"VIDEO3DGS_TEST_VAR=42"});
  CHECK(r.ok());
  CHECK(r.exit_code == 0);
  CHECK(slurp(log).find("a b; rm -rf x $HOME `id`\n") != std::string::npos);
  const auto env = colmap::run_process({"sh", "-c", "echo var=$VIDEO3DGS_TEST_VAR"}, log, 10, {"VIDEO3DGS_TEST_VAR=42"});
  CHECK(env.ok());
  CHECK(slurp(log).find("var=42") != std::string::npos);
  CHECK(colmap::log_tail(log, 7) == "var=42\n");

  const auto f = colmap::run_process({"false"}, log);
  CHECK_FALSE(f.ok());
  CHECK(f.exit_code == 1);
  fs::remove_all(dir);
}

TEST_CASE("run_process: a timeout kills the program (and its children)") {
  const fs::path log = fs::temp_directory_path() / ("video3dgs_process_timeout_" + std::to_string(::getpid()) + ".log");
  const auto r = colmap::run_process({"sh", "-c", "sleep 30 & sleep 30"}, log, 0.3);
  CHECK(r.timed_out);
  CHECK_FALSE(r.ok());
  CHECK(r.seconds < 10);
  fs::remove(log);
}

TEST_CASE("run_process: a missing program is a clear error") {
  const fs::path log = fs::temp_directory_path() / ("video3dgs_process_missing_" + std::to_string(::getpid()) + ".log");
  try {
    (void)colmap::run_process({"/nonexistent/video3dgs-no-such-program"}, log);
    FAIL("expected an error");
  } catch (const external_error& e) {
    CHECK(e.id() == "external.missing");
  }
  CHECK(colmap::find_executable("sh").filename() == "sh");
  CHECK(colmap::find_executable("video3dgs-no-such-program-anywhere").empty());
  fs::remove(log);
}
