#pragma once
/// @file
/// Stable keys for files that outlive a run (resume keys, SfM caches): the 64-bit FNV-1a hash of a
/// canonical text, written as 16 lowercase hex digits. Unlike `std::hash`, the value is fixed by its
/// definition (offset basis 14695981039346656037, prime 1099511628211, one byte at a time), so a key
/// written by one build, standard library or machine is recognised by every other.

#include <cstdint>
#include <string>
#include <string_view>

namespace video3dgs {

/// FNV-1a, 64 bit, over the bytes of `text`.
[[nodiscard]] constexpr std::uint64_t fnv1a64(std::string_view text) noexcept {
  std::uint64_t h = 14695981039346656037ull;
  for (const char c : text) {
    h ^= static_cast<unsigned char>(c);
    h *= 1099511628211ull;
  }
  return h;
}

/// `fnv1a64(canonical_text)` as 16 lowercase hex digits.
[[nodiscard]] inline std::string stable_key(std::string_view canonical_text) {
  static constexpr char digits[] = "0123456789abcdef";
  std::uint64_t h = fnv1a64(canonical_text);
  std::string s(16, '0');
  for (int i = 15; i >= 0; --i, h >>= 4) s[static_cast<std::size_t>(i)] = digits[h & 15u];
  return s;
}

}  // namespace video3dgs
