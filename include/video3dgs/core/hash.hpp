#pragma once
/// @file
/// Stable keys for files that outlive a run (resume keys, SfM caches): the 64-bit FNV-1a hash of a
/// canonical text, written as 16 lowercase hex digits. Unlike `std::hash`, the value is fixed by its
/// definition (offset basis 14695981039346656037, prime 1099511628211, one byte at a time), so a key
/// written by one build, standard library or machine is recognised by every other. Also splitmix64
/// (Steele, Lea and Flood 2014), the counter-based generator behind every seeded draw that must not
/// depend on the standard library (hash-grid initialisation, training crops, gradient-check samples).

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

/// splitmix64's output function (a bijective 64-bit mix).
[[nodiscard]] constexpr std::uint64_t splitmix64_mix(std::uint64_t z) noexcept {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}
/// splitmix64's golden-ratio increment.
inline constexpr std::uint64_t kSplitmix64Gamma = 0x9e3779b97f4a7c15ull;
/// The value splitmix64 draws from state x: mix(x + gamma). A generator: `splitmix64(s)`, then s += gamma.
[[nodiscard]] constexpr std::uint64_t splitmix64(std::uint64_t x) noexcept { return splitmix64_mix(x + kSplitmix64Gamma); }

/// `fnv1a64(canonical_text)` as 16 lowercase hex digits.
[[nodiscard]] inline std::string stable_key(std::string_view canonical_text) {
  static constexpr char digits[] = "0123456789abcdef";
  std::uint64_t h = fnv1a64(canonical_text);
  std::string s(16, '0');
  for (int i = 15; i >= 0; --i, h >>= 4) s[static_cast<std::size_t>(i)] = digits[h & 15u];
  return s;
}

}  // namespace video3dgs
