#pragma once
/// @file
/// The scalar codes of the compact model format (model/compact_io.hpp), each with its error bound:
///
///   uniform b-bit code over [lo, hi]    step = (hi - lo) / (2^b - 1),  q = round((x - lo) / step),
///                                        x' = lo + q step,              |x - x'| <= step / 2
///   symmetric block code (b bits)       s = max|x| / (2^(b-1) - 1),    q = round(x / s) (zigzag-stored),
///                                        x' = q s,                      |x - x'| <= s / 2
///   unit value on [0, 1] (8 bits)       q = round(255 v),  v' = q / 255 (0 and 255 decode to logits -+30),
///                                        |v - v'| <= 1/510
///   half float (IEEE binary16, round to nearest even, saturated at +-65504)
///                                        |x - x'| <= 2^-11 |x| for |x| >= 2^-14, <= 2^-25 below
///   signed smallest-three unit quaternion (32 bits, format version 2): u = q/|q| KEEPS its sign. u and
///     -u are one rotation, but not once deformed: the field adds its output to u (q' ~ u + drot,
///     deformation/deformation_field.hpp), so the sign is stored. Code: bits 0-1 the index m of the
///     largest |u_m|, bit 2 set iff u_m < 0, bits 3-29 the other three v_i = sign(u_m) u_i on 9 bits each
///     over [-1/sqrt 2, 1/sqrt 2] (step sqrt 2 / 511), so |v_i - v_i'| <= delta = sqrt 2 / 1022 ~ 1.38e-3;
///     |u_m|' = sqrt(1 - sum v_i'^2). With s = sum v_i^2 <= 3/4, sum |v_i| <= 3/2 and |u_m| >= 1/2:
///       |s - s'| <= sum delta (2|v_i| + delta) <= 3 delta (1 + delta),
///       ||u_m| - |u_m|'| = |s - s'| / (|u_m| + |u_m|') <= 2 |s - s'| <= 6 delta (1 + delta) ~ 8.3e-3
///     (Version 1 stored sign(u_m) u with 10 bits per value and no sign bit; `decode_rotation_v1` reads it.)
///
/// Code planes: codes of b = 16 or 24 bits are stored as b/8 byte planes (all low bytes, then the next
/// bytes), which deflate compresses better than interleaved bytes; alpha rows are stored as
/// differences to their left neighbour (mod 256, PNG's "Sub" filter). Positions (part version 3) are
/// stored in Morton order of their codes as zigzagged differences to the previous point's code, mod
/// 2^b (`morton_order`, `delta_codes`): lossless, the codes' error bounds are unchanged.

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace video3dgs::detail {

/// float -> IEEE binary16 bits (round to nearest even; |x| >= 65504 saturates; NaN -> 0).
[[nodiscard]] inline std::uint16_t float_to_half(float f) noexcept {
  const std::uint32_t x = std::bit_cast<std::uint32_t>(f);
  const auto sign = static_cast<std::uint16_t>((x >> 16) & 0x8000u);
  const float a = std::fabs(f);
  if (!(a == a)) return 0;
  if (a >= 65504.0f) return static_cast<std::uint16_t>(sign | 0x7bffu);
  if (a < 0x1.0p-14f) return static_cast<std::uint16_t>(sign | static_cast<std::uint16_t>(std::nearbyint(a * 0x1.0p24f)));
  const std::uint32_t ax = x & 0x7fffffffu;
  const std::uint32_t e = (ax >> 23) - 127 + 15, m = ax & 0x7fffffu;
  std::uint32_t h = (e << 10) | (m >> 13);
  const std::uint32_t rem = m & 0x1fffu;
  if (rem > 0x1000u || (rem == 0x1000u && (h & 1u))) ++h;  // a carry into the exponent is the right result
  return static_cast<std::uint16_t>(sign | h);
}

/// IEEE binary16 bits -> float (exact).
[[nodiscard]] inline float half_to_float(std::uint16_t h) noexcept {
  const float s = (h & 0x8000u) ? -1.0f : 1.0f;
  const int e = (h >> 10) & 0x1f, m = h & 0x3ff;
  if (e == 0) return s * std::ldexp(float(m), -24);
  if (e == 31) return m ? 0.0f : s * 65504.0f;  // never written (saturated); read as the largest finite
  return s * std::ldexp(float(1024 + m), e - 25);
}

/// Uniform code over [lo, lo + (2^bits - 1) step] (see the file comment).
struct UniformCode {
  double lo = 0, step = 0;
  int bits = 8;

  /// The code of [mn, mx] on `bits` bits (step 0 when mn == mx).
  [[nodiscard]] static UniformCode fit(double mn, double mx, int bits) noexcept {
    return {mn, mx > mn ? (mx - mn) / double((std::uint32_t(1) << bits) - 1) : 0.0, bits};
  }
  [[nodiscard]] std::uint32_t max_code() const noexcept { return (std::uint32_t(1) << bits) - 1; }
  [[nodiscard]] std::uint32_t encode(double x) const noexcept {
    if (!(step > 0)) return 0;
    const double t = std::round((x - lo) / step);
    return t <= 0 ? 0u : t >= double(max_code()) ? max_code() : static_cast<std::uint32_t>(t);
  }
  [[nodiscard]] double decode(std::uint32_t q) const noexcept { return lo + double(q) * step; }
};

/// Signed smallest-three code of a quaternion (w, x, y, z), any nonzero norm (zero: the identity).
[[nodiscard]] inline std::uint32_t encode_rotation(std::array<double, 4> q) noexcept {
  double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!(n > 0) || !std::isfinite(n)) q = {1, 0, 0, 0}, n = 1;
  int m = 0;
  for (int c = 1; c < 4; ++c)
    if (std::fabs(q[c]) > std::fabs(q[m])) m = c;
  const bool negative = q[m] < 0;
  const double sign = negative ? -1.0 : 1.0;
  const UniformCode code{-std::sqrt(0.5), std::sqrt(2.0) / 511.0, 9};
  std::uint32_t out = std::uint32_t(m) | (negative ? 4u : 0u);
  int shift = 3;
  for (int c = 0; c < 4; ++c) {
    if (c == m) continue;
    out |= code.encode(sign * q[c] / n) << shift;
    shift += 9;
  }
  return out;
}

namespace rotation_detail {
/// The unit quaternion whose component m is positive from three stored codes of `bits` bits at `shift`.
[[nodiscard]] inline std::array<double, 4> decode_three(std::uint32_t v, int m, int shift, int bits) noexcept {
  const UniformCode code{-std::sqrt(0.5), std::sqrt(2.0) / double((1u << bits) - 1), bits};
  std::array<double, 4> q{};
  double s = 0;
  for (int c = 0; c < 4; ++c) {
    if (c == m) continue;
    q[c] = code.decode((v >> shift) & code.max_code());
    s += q[c] * q[c];
    shift += bits;
  }
  q[m] = std::sqrt(std::max(0.0, 1.0 - s));
  const double n = std::sqrt(s + q[m] * q[m]);  // 1 unless the three stored values are not from a unit vector
  for (double& c : q) c /= n;
  return q;
}
}  // namespace rotation_detail

/// The unit quaternion of a signed smallest-three code (any 32 bits decode to a unit quaternion).
[[nodiscard]] inline std::array<double, 4> decode_rotation(std::uint32_t v) noexcept {
  auto q = rotation_detail::decode_three(v, int(v & 3u), 3, 9);
  if (v & 4u)
    for (double& c : q) c = -c;
  return q;
}

/// The unit quaternion of a format-version-1 code (10 bits per value, the sign not kept: u_m > 0).
[[nodiscard]] inline std::array<double, 4> decode_rotation_v1(std::uint32_t v) noexcept {
  return rotation_detail::decode_three(v, int(v & 3u), 2, 10);
}

/// Codes of 1 to 3 bytes as byte planes (see the file comment).
[[nodiscard]] inline std::vector<std::uint8_t> to_planes(std::span<const std::uint32_t> q, int bytes) {
  std::vector<std::uint8_t> out(q.size() * std::size_t(bytes));
  for (int b = 0; b < bytes; ++b)
    for (std::size_t i = 0; i < q.size(); ++i) out[std::size_t(b) * q.size() + i] = std::uint8_t(q[i] >> (8 * b));
  return out;
}

/// Code i of `n` codes stored by `to_planes` (the caller checked planes.size() == n * bytes).
[[nodiscard]] inline std::uint32_t from_planes(std::span<const std::uint8_t> planes, std::size_t n, std::size_t i, int bytes) noexcept {
  std::uint32_t v = 0;
  for (int b = 0; b < bytes; ++b) v |= std::uint32_t(planes[std::size_t(b) * n + i]) << (8 * b);
  return v;
}

/// Morton (Z-order) permutation of n points given by three planes of position codes of `bits` bits
/// (axis j of point i at codes[j n + i]): order[k] is the point stored k-th. The key interleaves the
/// top min(bits, 21) bits of the three codes (x lowest); ties keep their index order, so the order
/// depends on the codes alone. Neighbours in this order are neighbours in space: their code
/// differences are small, and so are the differences of everything that varies smoothly in space.
[[nodiscard]] inline std::vector<std::uint32_t> morton_order(std::span<const std::uint32_t> codes, std::size_t n, int bits) {
  const int drop = std::max(0, bits - 21), kept = bits - drop;
  std::vector<std::uint64_t> key(n, 0);
  for (std::size_t i = 0; i < n; ++i)
    for (int j = 0; j < 3; ++j) {
      const std::uint64_t q = codes[std::size_t(j) * n + i] >> drop;
      for (int b = 0; b < kept; ++b) key[i] |= ((q >> b) & 1u) << (3 * b + j);
    }
  std::vector<std::uint32_t> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = std::uint32_t(i);
  std::stable_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return key[a] < key[b]; });
  return order;
}

/// Delta code of a sequence of `bits`-bit codes: d_i = (q_i - q_{i-1}) mod 2^bits (q_{-1} = 0) read as
/// a signed number in [-2^(bits-1), 2^(bits-1)) and zigzagged, so it fits `bits` bits again and small
/// steps give small codes; `undelta_codes` inverts it exactly.
inline void delta_codes(std::span<std::uint32_t> q, int bits) noexcept {
  const std::uint32_t mask = bits >= 32 ? ~0u : (std::uint32_t(1) << bits) - 1, half = std::uint32_t(1) << (bits - 1);
  std::uint32_t prev = 0;
  for (auto& v : q) {
    const std::uint32_t d = (v - prev) & mask, cur = v;
    const std::int64_t s = d >= half ? std::int64_t(d) - std::int64_t(mask) - 1 : std::int64_t(d);
    v = s >= 0 ? std::uint32_t(2 * s) : std::uint32_t(-2 * s - 1);
    prev = cur;
  }
}
inline void undelta_codes(std::span<std::uint32_t> q, int bits) noexcept {
  const std::uint32_t mask = bits >= 32 ? ~0u : (std::uint32_t(1) << bits) - 1;
  std::uint32_t prev = 0;
  for (auto& v : q) {
    const std::int64_t s = (v & 1u) ? -std::int64_t(v >> 1) - 1 : std::int64_t(v >> 1);
    prev = std::uint32_t((std::int64_t(prev) + s) & std::int64_t(mask));
    v = prev;
  }
}

/// Signed code <-> zigzag (0, -1, 1, -2, ... -> 0, 1, 2, 3, ...): small magnitudes give small bytes.
[[nodiscard]] constexpr std::uint32_t zigzag(std::int32_t v) noexcept {
  return (std::uint32_t(v) << 1) ^ std::uint32_t(v >> 31);
}
[[nodiscard]] constexpr std::int32_t unzigzag(std::uint32_t z) noexcept {
  return std::int32_t(z >> 1) ^ -std::int32_t(z & 1u);
}

/// Unit value v in [0, 1] -> 8 bits.
[[nodiscard]] inline std::uint8_t encode_unit(double v) noexcept {
  return std::uint8_t(std::clamp(std::round(v * 255.0), 0.0, 255.0));
}
/// The logit of v in [0, 1], clamped to [-30, 30] (sigmoid(-30) ~ 1e-13): 0 and 1 stay finite.
[[nodiscard]] inline double unit_logit(double v) noexcept {
  if (!(v > 0)) return -30.0;
  if (!(v < 1)) return 30.0;
  return std::clamp(std::log(v / (1.0 - v)), -30.0, 30.0);
}

/// PNG's Sub filter on rows of width w (in place) and its inverse.
inline void sub_filter(std::span<std::uint8_t> rows, std::size_t w) noexcept {
  if (w == 0) return;
  for (std::size_t r = 0; r + w <= rows.size(); r += w)
    for (std::size_t x = w - 1; x > 0; --x) rows[r + x] = std::uint8_t(rows[r + x] - rows[r + x - 1]);
}
inline void sub_unfilter(std::span<std::uint8_t> rows, std::size_t w) noexcept {
  if (w == 0) return;
  for (std::size_t r = 0; r + w <= rows.size(); r += w)
    for (std::size_t x = 1; x < w; ++x) rows[r + x] = std::uint8_t(rows[r + x] + rows[r + x - 1]);
}

}  // namespace video3dgs::detail
