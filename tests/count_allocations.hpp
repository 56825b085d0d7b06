// Counts every heap allocation of a test program through replaced global operator new / new[], for
// the tests that prove a warm iteration allocates nothing. The replacements are program-wide
// definitions: include this header in exactly one translation unit of a test executable.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdlib>
#include <new>

#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

namespace video3dgs_test {
inline std::atomic<std::size_t> g_allocations{0};
/// operator new / new[] calls so far in this program.
inline std::size_t allocations() noexcept { return g_allocations.load(); }
inline void* counted_malloc(std::size_t n) {
  ++g_allocations;
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
}  // namespace video3dgs_test

void* operator new(std::size_t n) { return video3dgs_test::counted_malloc(n); }
void* operator new[](std::size_t n) { return video3dgs_test::counted_malloc(n); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
