#pragma once
/// @file
/// Debug invariants. `VIDEO3DGS_ASSERT(cond, msg)` checks an internal invariant (a programming error,
/// never bad user input: that raises a `video3dgs::error`). It is active unless `NDEBUG` is defined, or
/// always when `VIDEO3DGS_ENABLE_ASSERTS` is defined. Define `VIDEO3DGS_ASSERT` yourself before
/// including any video3dgs header to route failures elsewhere (e.g. to throw in tests).

#include <cstdio>
#include <cstdlib>

namespace video3dgs::detail {
[[noreturn]] inline void assert_fail(const char* expr, const char* msg, const char* file, int line) noexcept {
  std::fprintf(stderr, "video3dgs assertion failed: %s (%s) at %s:%d\n", expr, msg, file, line);
  std::abort();
}
}  // namespace video3dgs::detail

#ifndef VIDEO3DGS_ASSERT
#if !defined(NDEBUG) || defined(VIDEO3DGS_ENABLE_ASSERTS)
#define VIDEO3DGS_ASSERT(cond, msg) \
  ((cond) ? static_cast<void>(0) : ::video3dgs::detail::assert_fail(#cond, msg, __FILE__, __LINE__))
#else
#define VIDEO3DGS_ASSERT(cond, msg) static_cast<void>(0)
#endif
#endif
