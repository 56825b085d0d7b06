#pragma once
/// @file
/// A compact file for a finished clip (training checkpoints keep the exact record, clip_model_io.hpp):
/// attributes quantised, the SH rest bands vector-quantised, every part deflated (zlib). Loading gives
/// an ordinary `ClipModel`, which renders, exports PLY (`export_ply`) and saves like any other.
///
///     CompactSizes s = save_compact_clip_model("clip_000.compact", model, {}, &pool);   // s.total bytes
///     auto m = load_compact_clip_model<float>("clip_000.compact");                      // dequantised
///
/// File: `V3DGSCCM` (8 bytes), u32 version (2), then four parts, each `u64 raw size | u64 n | n bytes`
/// of a zlib stream (io/detail/zlib.hpp) | u32 CRC-32 of the raw record` (version 1 had no CRC: zlib's
/// Adler-32 alone let some corrupted streams through), each raw record with its own 8-byte tag:
///
///   ccm.meta   SH degree, the fields' segment sizes, frame range, cameras (f64), scene radius, flags,
///              field boxes (f64) and options, Gaussian counts, warnings: as exact as the full record;
///              part version 2 stores each field's table size and level count, version 3 also its
///              cells cap per axis (versions 1 and 2 are still read)
///   ccm.gaus   per set (frg, bkg), N Gaussians in Morton order of their position codes (part version 3,
///              `detail::compact_order`), each array a plane (all Gaussians, then the next axis):
///              mean        3 x `frg_position_bits` (24, foreground) or `position_bits` (16, background)
///                          uniform codes, per axis over the set's [min, max], each stored as its
///                          zigzagged difference to the previous Gaussian's code mod 2^bits (lossless)
///              log_scale   3 x `scale_bits` (8) uniform codes, per axis over [min, max]
///              rotation    32-bit signed smallest-three code of q/|q| (the sign kept: deformation adds
///                          to it) in 4 byte planes; version-2 parts (file order, positions as codes,
///                          rotations as words) and version-1 parts (sign dropped) are still read
///              opacity     8 bits of sigmoid(opacity_logit)
///              SH DC       3 x `dc_bits` (8) uniform codes, per channel over [min, max], of the DC with
///                          the rest bands' error fed back: DC - mean_f sum_{k>=1} B_k(d_f) (r'_k - r_k) / C0
///                          over the clip's frames f (d_f: camera f's centre to the canonical mean), so
///                          the colour at the clip's own views keeps the rest bands' mean effect
///              SH rest     a codebook of K <= `sh_codebook` vectors of 3 (B - 1) half floats
///                          (B = (D + 1)^2 bands) + an index per Gaussian (1 byte if K <= 256, else 2)
///   ccm.flds   per field: the hash table (segment 0) in blocks of 4096 values, each with a float scale and
///              `field_bits` (8; 2..8 take a byte each, 16 two) symmetric codes; the heads' segments as float32
///   ccm.alph   per frame, A = sigmoid(alpha_logit) area-averaged over `alpha_downscale`^2 pixel blocks,
///              8 bits per stored pixel, rows Sub-filtered. At full size (d = 1) with `alpha_tolerance`
///              tau > 0, the writer renders both sets at each frame and, where the two renders differ
///              little (Delta_p = max_c |I_frg - I_bkg| small), picks the code closest to its left
///              neighbour's among those that move the merged pixel by at most tau: the map is the same
///              kind of map, only cheaper to deflate (the reader does not need to know)
/// Bytes per Gaussian before deflate, defaults, D = 3: 9 + 3 + 4 + 1 + 3 + 2 = 22 (foreground; 19 with the
/// background's 6 position bytes); per field (1 + 4/4096) bytes per table value + 4 per head value; per
/// alpha map ceil(W/d) ceil(H/d) bytes.
///
/// Error bounds of a round trip (maths; model/detail/compact_codec.hpp derives them). With
/// step(b, lo, hi) = (hi - lo) / (2^b - 1), per set and axis/channel:
///   |mean' - mean|            <= step(bits, min, max) / 2 (bits: frg_position_bits or position_bits)
///   |log_scale' - log_scale|  <= step(scale_bits, min, max) / 2
///   rotation: u = q/|q| with its sign; three components within delta = sqrt 2 / 1022 ~ 1.38e-3, the
///             largest within 6 delta (1 + delta) ~ 8.3e-3; the decoded quaternion is unit
///   |sigmoid(opacity') - sigmoid(opacity)| <= 1/510 (+ sigmoid(-30) ~ 1e-13 at 0 and 1)
///   |dc' - dc_fed|            <= step(dc_bits, min, max) / 2 (dc_fed: the DC with the feedback above)
///   SH rest: a set of N <= sh_codebook Gaussians keeps each vector up to half-float rounding
///            (relative 2^-11 per value, 2^-25 absolute below 2^-14); a larger set's vector is replaced by
///            its nearest stored codeword (k-means, model/detail/vector_quantizer.hpp: no a-priori bound)
///   hash table value          <= max |value in its block of 4096| / (2 (2^(field_bits-1) - 1))
///   head values               float32 rounding (relative 2^-24)
///   |A' - A| (alpha_downscale 1, tau = 0) <= 1/510 (+ 1e-13); with tau > 0, |A' - A| Delta_p <= max(tau,
///            Delta_p / 510) at every pixel, so the merged render of the saved model moves by at most
///            max(tau, 1/510 Delta_p) per channel (Delta_p from its own renders); with d > 1 the stored map is the block mean,
///            bilinearly upsampled on load (pixel centres (x + 1/2)/d - 1/2), plus the same 1/510
///   cameras, range, radius, flags, boxes, options, warnings: exact.
/// A loaded set holds the saved set's Gaussians in the stored (Morton) order: Gaussian k is the saved
/// one's `detail::compact_order(set, bits)[k]` (renders do not depend on it: the rasterizer sorts by
/// depth; only Gaussians at exactly equal depths blend in another order). Quantities are computed in
/// double and rounded once to Scalar.
/// Deterministic: the same model and options give the same bytes for any thread count (the k-means
/// blocks depend on N only; zlib runs on each part once).
///
/// Errors: saving: `option.compact` (bad options, naming the field), `numeric.non_finite` (a non-finite
/// parameter, naming it), `io.unwritable`. Loading, naming the file: `io.unreadable`, `io.format` (bad
/// magic or part tag, corrupt zlib stream, a part whose CRC-32 differs, a size that disagrees, a value
/// out of range), `io.version` (newer format), `io.truncated` (the file or a part ends inside a field),
/// `io.mismatch` (written for another SH degree or field layout). No length read from the file is used
/// to allocate before it has been checked against the bytes that hold it.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/gaussian/activations.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/io/binary_stream.hpp"
#include "video3dgs/io/detail/zlib.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/model/clip_model_io.hpp"
#include "video3dgs/model/compact_options.hpp"
#include "video3dgs/model/detail/compact_codec.hpp"
#include "video3dgs/model/detail/compact_parts.hpp"
#include "video3dgs/model/detail/vector_quantizer.hpp"

namespace video3dgs {

/// The compact file's bytes (see the file comment); `sizes` (if not null) receives the parts' sizes.
/// The fields are read through `segments()`, hence the non-const model.
/// @throws option_error `option.compact`, numeric_error `numeric.non_finite`
template <class Scalar, int D, class Field>
[[nodiscard]] std::string write_compact_clip_model(ClipModel<Scalar, D, Field>& m, const CompactOptions& o = {},
                                                   ThreadPool* pool = nullptr, CompactSizes* sizes = nullptr) {
  o.validate();
  std::array<std::string, 4> raw{detail::compact_meta(m), detail::compact_gaussians(m, o, pool), detail::compact_fields(m, o),
                                 detail::compact_alpha(m, o, pool)};
  std::array<std::string, 4> packed;
  static constexpr std::array<const char*, 4> kParts{"meta", "gaussians", "fields", "alpha"};
  const auto deflate_part = [&](std::size_t k) { packed[k] = io::detail::deflate_bytes(raw[k], o.zlib_level, kParts[k]); };
  if (pool) pool->run(4, deflate_part);
  else for (std::size_t k = 0; k < 4; ++k) deflate_part(k);
  io::BinaryWriter w(kCompactModelMagic, kCompactModelVersion);
  std::array<std::size_t, 4> part_bytes{};
  for (std::size_t k = 0; k < 4; ++k) {
    const std::size_t before = w.bytes().size();
    w.put<std::uint64_t>(raw[k].size());
    w.put_string(packed[k]);
    w.put<std::uint32_t>(io::detail::crc32_of(raw[k]));
    part_bytes[k] = w.bytes().size() - before;
  }
  if (sizes) {
    sizes->other = 12 + part_bytes[0];
    sizes->gaussians = part_bytes[1];
    sizes->fields = part_bytes[2];
    sizes->alpha = part_bytes[3];
    sizes->total = w.bytes().size();
  }
  return w.bytes();
}

/// Reads a compact file's bytes (`file` names it in errors) into a model with the given template
/// arguments. @throws io_error (see the file comment)
template <class Scalar, int D = 3, class Field = DefaultDeformationField<Scalar>>
[[nodiscard]] ClipModel<Scalar, D, Field> read_compact_clip_model(std::string_view bytes, const std::string& file) {
  io::BinaryReader r(bytes, file, kCompactModelMagic, kCompactModelVersion);
  std::array<std::string, 4> raw;
  static constexpr std::array<const char*, 4> kParts{"meta", "gaussians", "fields", "alpha"};
  for (std::size_t k = 0; k < 4; ++k) {
    const auto size = r.get<std::uint64_t>(std::string(kParts[k]) + ".size");
    const std::string packed = r.get_string(kParts[k]);
    raw[k] = io::detail::inflate_bytes(packed, size, file, kParts[k]);
    if (r.version() >= 2 && r.get<std::uint32_t>(std::string(kParts[k]) + ".crc32") != io::detail::crc32_of(raw[k]))
      throw io_error("io.format", file, std::string(kParts[k]) + ": CRC-32 of the decoded part differs (corrupt file)");
  }
  r.expect_end();
  ClipModel<Scalar, D, Field> m;
  const auto counts = detail::read_compact_meta(m, raw[0], file);
  detail::read_compact_gaussians(m, raw[1], file, counts);
  detail::read_compact_fields(m, raw[2], file);
  detail::read_compact_alpha(m, raw[3], file);
  return m;
}

/// Writes the compact file of `m` atomically and returns its parts' sizes.
/// @throws option_error `option.compact`, numeric_error `numeric.non_finite`, io_error `io.unwritable`
template <class Scalar, int D, class Field>
CompactSizes save_compact_clip_model(const std::filesystem::path& path, ClipModel<Scalar, D, Field>& m, const CompactOptions& o = {},
                                     ThreadPool* pool = nullptr) {
  CompactSizes sizes;
  const std::string bytes = write_compact_clip_model(m, o, pool, &sizes);
  io::write_file_atomic(path, bytes);
  return sizes;
}

/// Reads a compact file (dequantised; see the file comment for the error bounds).
/// @throws io_error (see the file comment)
template <class Scalar, int D = 3, class Field = DefaultDeformationField<Scalar>>
[[nodiscard]] ClipModel<Scalar, D, Field> load_compact_clip_model(const std::filesystem::path& path) {
  const std::string bytes = read_file_bytes(path);
  return read_compact_clip_model<Scalar, D, Field>(bytes, path.string());
}

}  // namespace video3dgs
