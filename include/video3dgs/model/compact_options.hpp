#pragma once
/// @file
/// Options and part sizes of the compact model format (model/compact_io.hpp describes the format).

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>

#include "video3dgs/core/error.hpp"

namespace video3dgs {

inline constexpr const char* kCompactModelMagic = "V3DGSCCM";
/// Version 2 ends each part with the CRC-32 of its raw record; version-1 files (no CRC) are still read.
inline constexpr std::uint32_t kCompactModelVersion = 2;
/// Version of the ccm.gaus part: 3 = Gaussians in Morton order, positions delta-coded, rotations in
/// byte planes; 2 = rotations keep their sign (9 bits per value); 1 and 2 are still read.
inline constexpr std::uint32_t kCompactGaussiansVersion = 3;
inline constexpr int kMaxAlphaDownscale = 16;

/// How a clip is compacted (see the file comment for what each setting stores).
struct CompactOptions {
  int sh_codebook = 4096;           ///< K: codewords of a set's SH rest bands, 1..65536
  int kmeans_iterations = 8;        ///< Lloyd iterations fitting the codebook, 0..1000
  std::size_t kmeans_sample = 32768;///< Gaussians the codebook is fitted to (at least K), >= 1
  int position_bits = 16;           ///< the background set's: 8, 16 or 24
  /// The foreground set's, 8, 16 or 24: its range spans the few Gaussians that drifted far from the
  /// object, so 16 bits over it were too coarse for the object's own (-0.045 dB on horsejump-high 0-9).
  int frg_position_bits = 24;
  /// 8 or 16 (default 8: a step of (max - min) / 255 per axis; docs/performance.md has what 16 bits buy)
  int scale_bits = 8;
  int dc_bits = 8;                  ///< 8 or 16
  /// 2..8 (one byte per code: fewer bits give fewer distinct codes, which deflate stores in fewer
  /// bits) or 16 (two bytes)
  int field_bits = 8;
  int alpha_downscale = 1;          ///< d: alpha maps stored at ceil(W/d) x ceil(H/d), 1..kMaxAlphaDownscale
  /// tau: with d = 1, an alpha code may move the merged render by up to tau (colour units, 0..1) where
  /// that makes the map smaller to store (compact_io.hpp); 0 stores the nearest code everywhere.
  double alpha_tolerance = 0.5 / 255;
  int zlib_level = 9;               ///< 0 (store) .. 9 (smallest)

  /// Named settings (`preset_names`):
  ///   "default"  the members' defaults: within 0.2 dB of the full model on full-size DAVIS clips
  ///   "small"    hash-table values on 5 bits, 16 SH rest codewords per set, 16-bit foreground
  ///              positions: for clips whose model must be small (the demo's 160x120 clips fit 1 MB;
  ///              docs/performance.md has what each setting costs)
  /// @throws option_error `option.compact` (field preset) naming the presets.
  [[nodiscard]] static CompactOptions preset(const std::string& name) {
    CompactOptions o;
    if (name == "default") return o;
    if (name == "small") {
      o.field_bits = 5;
      o.sh_codebook = 16;
      o.frg_position_bits = 16;
      return o;
    }
    throw option_error("option.compact", "preset", "unknown compact preset '" + name + "' (default, small)");
  }
  [[nodiscard]] static constexpr std::array<const char*, 2> preset_names() noexcept { return {"default", "small"}; }

  /// @throws option_error `option.compact` naming the field.
  void validate() const {
    auto bad = [](const char* field, const char* why) { throw option_error("option.compact", field, why); };
    if (sh_codebook < 1 || sh_codebook > 65536) bad("sh_codebook", "must be in 1..65536");
    if (kmeans_iterations < 0 || kmeans_iterations > 1000) bad("kmeans_iterations", "must be in 0..1000");
    if (kmeans_sample < 1) bad("kmeans_sample", "must be >= 1");
    for (auto [name, bits] : {std::pair{"position_bits", position_bits}, std::pair{"frg_position_bits", frg_position_bits}})
      if (bits != 8 && bits != 16 && bits != 24) bad(name, "must be 8, 16 or 24");
    for (auto [name, bits] : {std::pair{"scale_bits", scale_bits}, std::pair{"dc_bits", dc_bits}})
      if (bits != 8 && bits != 16) bad(name, "must be 8 or 16");
    if (!(field_bits >= 2 && field_bits <= 8) && field_bits != 16) bad("field_bits", "must be in 2..8 or 16");
    if (alpha_downscale < 1 || alpha_downscale > kMaxAlphaDownscale) bad("alpha_downscale", "must be in 1..16");
    if (!(alpha_tolerance >= 0 && alpha_tolerance <= 1)) bad("alpha_tolerance", "must be in 0..1");
    if (zlib_level < 0 || zlib_level > 9) bad("zlib_level", "must be in 0..9");
  }
};

/// Bytes of a compact file by part: `gaussians` (ccm.gaus), `fields` (ccm.flds), `alpha` (ccm.alph),
/// `other` (header + ccm.meta); `total` = their sum = the file size.
struct CompactSizes {
  std::size_t gaussians = 0, fields = 0, alpha = 0, other = 0, total = 0;
};

}  // namespace video3dgs
