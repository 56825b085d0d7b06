// The main of every test executable: doctest, plus skipping. When a test called test::skip() (what it
// needs, ../shared/data or colmap, is missing; see test_data.hpp) and no test failed, the run exits with
// 77, ctest's SKIP_RETURN_CODE for these executables, so ctest reports it as skipped instead of passed.
#define DOCTEST_CONFIG_IMPLEMENT
#include <doctest/doctest.h>

#include <cstdio>

#include "test_data.hpp"

int main(int argc, char** argv) {
  doctest::Context context(argc, argv);
  const int rc = context.run();
  if (context.shouldExit() || rc != 0) return rc;
  if (const int n = video3dgs::test::skipped_count.load(); n > 0) {
    std::printf("[doctest] %d skip(s): missing shared data or program (see \"skipped:\" above); exit 77 = skipped\n", n);
    return 77;
  }
  return 0;
}
