#pragma once
/// @file
/// Exact, reproducible SIFT matching for COLMAP databases: every pair of images, mutual nearest
/// neighbours by exhaustive search, written as a raw match list for `colmap matches_importer`
/// (write_match_list), and, once COLMAP has verified the pairs, guided matching under each pair's
/// geometry written back to the database (guide_matches).
///
/// Why our own: COLMAP 3.8's CPU matcher searches approximately (randomised kd-trees) with a random
/// generator shared between threads and seeded from the clock, so two runs on the same database give
/// different raw matches for almost every pair (docs/colmap-notes.md), and then different cameras. The
/// search here is exhaustive in exact integer arithmetic and visits candidates in index order, so its
/// output depends only on the descriptors, never on timing or the thread count. COLMAP's geometric
/// verification and mapper then run on one thread each, which made them repeat exactly in our runs,
/// and guided matching is ours as well (ColmapSfmOptions::deterministic).
///
/// The rule is COLMAP's (SiftMatchingOptions): descriptors are unit vectors scaled to 512 and stored as
/// bytes, so the angle between two is acos(<a, b> / 512^2). For descriptor i of A, let j1 and j2 be the
/// candidates of B with the largest and second largest dot product (ties to the lower index) and d1 <= d2
/// their angles: i -> j1 is kept if d1 <= max_distance and d1 < max_ratio x d2 (d2 = pi when B has one
/// descriptor). With cross_check, a pair (i, j) is a match when i -> j and j -> i are both kept.
/// COLMAP's cap on matches per pair (SiftMatching.max_num_matches, 32768) is not applied: a pair of
/// COLMAP's default 8192-feature images cannot exceed 8192 mutual matches.
///
/// Cost: rows(A) x rows(B) dot products of 128 16-bit lanes per pair (8192 x 8192 at most), in
/// blocks of B that stay in cache; pairs are spread over the pool.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <map>
#include <numbers>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "video3dgs/colmap/database.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/io/atomic_file.hpp"

namespace video3dgs::colmap {

/// COLMAP's SiftMatching options that decide raw matches (its defaults).
struct SiftMatchOptions {
  double max_distance = 0.7;  ///< largest angle between matched descriptors, radians
  double max_ratio = 0.8;     ///< Lowe's ratio test on the angles
  bool cross_check = true;    ///< keep only mutual nearest neighbours
};

/// One raw match: descriptor index in the first image, descriptor index in the second.
using SiftMatch = std::array<std::uint32_t, 2>;

namespace detail {

inline constexpr std::size_t kSiftDims = 128;

/// Widened copy of a descriptor block (16-bit lanes: their products sum exactly in 32 bits, at most
/// 128 x 255^2 < 2^31, and compilers vectorise the sums as multiply-adds).
inline std::vector<std::int16_t> widen(const SiftDescriptors& d) {
  return std::vector<std::int16_t>(d.data.begin(), d.data.end());
}

inline std::int32_t dot128(const std::int16_t* a, const std::int16_t* b) noexcept {
  std::int32_t s = 0;
  for (std::size_t k = 0; k < kSiftDims; ++k) s += std::int32_t{a[k]} * std::int32_t{b[k]};
  return s;
}

/// Best and second best dot product of one descriptor, and the best one's index (-1: none yet).
struct Best2 {
  std::int32_t first = -1, second = -1;
  std::int64_t index = -1;
  void offer(std::int32_t s, std::int64_t j) noexcept {
    if (s > first) {
      second = first;
      first = s;
      index = j;
    } else if (s > second) {
      second = s;
    }
  }
};

/// The index a descriptor's best candidate passes the distance and ratio tests with, or -1.
inline std::int64_t accepted(const Best2& b, const SiftMatchOptions& o) noexcept {
  if (b.index < 0) return -1;
  constexpr double kInvNorm = 1.0 / (512.0 * 512.0);
  const double d1 = std::acos(std::min(1.0, double(b.first) * kInvNorm));
  const double d2 = b.second < 0 ? std::numbers::pi : std::acos(std::min(1.0, double(b.second) * kInvNorm));
  return d1 <= o.max_distance && d1 < o.max_ratio * d2 ? b.index : -1;
}

/// Matches between two widened descriptor blocks of na and nb rows; only candidates (i, j) with
/// allowed(i, j) are compared.
template <class Allowed>
std::vector<SiftMatch> match_widened(const std::int16_t* a, std::size_t na, const std::int16_t* b, std::size_t nb,
                                     const SiftMatchOptions& o, Allowed&& allowed) {
  std::vector<Best2> row(na), col(nb);
  constexpr std::size_t kBlock = 128;  // rows of B per sweep over A: 32 KB of B stays in L1/L2
  for (std::size_t j0 = 0; j0 < nb; j0 += kBlock) {
    const std::size_t j1 = std::min(nb, j0 + kBlock);
    for (std::size_t i = 0; i < na; ++i) {
      const std::int16_t* ai = a + i * kSiftDims;
      for (std::size_t j = j0; j < j1; ++j) {
        if (!allowed(i, j)) continue;
        const std::int32_t s = dot128(ai, b + j * kSiftDims);
        row[i].offer(s, static_cast<std::int64_t>(j));
        col[j].offer(s, static_cast<std::int64_t>(i));
      }
    }
  }
  std::vector<SiftMatch> out;
  for (std::size_t i = 0; i < na; ++i) {
    const std::int64_t j = accepted(row[i], o);
    if (j < 0) continue;
    if (o.cross_check && accepted(col[static_cast<std::size_t>(j)], o) != static_cast<std::int64_t>(i)) continue;
    out.push_back({static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(j)});
  }
  return out;
}

inline std::vector<SiftMatch> match_widened(const std::int16_t* a, std::size_t na, const std::int16_t* b, std::size_t nb,
                                            const SiftMatchOptions& o) {
  return match_widened(a, na, b, nb, o, [](std::size_t, std::size_t) { return true; });
}

/// The pieces of the squared Sampson distance under a fundamental matrix F (row-major) that depend on
/// one point only: F x1 (the epipolar line in image 2) and the first two entries of F^T x2.
inline std::array<double, 3> epipolar_line(const std::array<double, 9>& F, const std::array<double, 2>& x1) noexcept {
  return {F[0] * x1[0] + F[1] * x1[1] + F[2], F[3] * x1[0] + F[4] * x1[1] + F[5], F[6] * x1[0] + F[7] * x1[1] + F[8]};
}
inline std::array<double, 2> epipolar_line_t(const std::array<double, 9>& F, const std::array<double, 2>& x2) noexcept {
  return {F[0] * x2[0] + F[3] * x2[1] + F[6], F[1] * x2[0] + F[4] * x2[1] + F[7]};
}
/// (x2^T F x1)^2 / (|F x1|_xy^2 + |F^T x2|_xy^2), pixels^2, from those pieces (infinite when F x1 and
/// F^T x2 both vanish).
inline double sampson_squared(const std::array<double, 3>& f1, const std::array<double, 2>& ft2, const std::array<double, 2>& x2) noexcept {
  const double e = x2[0] * f1[0] + x2[1] * f1[1] + f1[2];
  const double d = f1[0] * f1[0] + f1[1] * f1[1] + ft2[0] * ft2[0] + ft2[1] * ft2[1];
  return d > 0 ? e * e / d : std::numeric_limits<double>::infinity();
}
inline double sampson_squared(const std::array<double, 9>& F, const std::array<double, 2>& x1, const std::array<double, 2>& x2) noexcept {
  return sampson_squared(epipolar_line(F, x1), epipolar_line_t(F, x2), x2);
}

/// H x1 in pixels (H row-major); infinite where x1 maps to infinity.
inline std::array<double, 2> transfer(const std::array<double, 9>& H, const std::array<double, 2>& x1) noexcept {
  const double w = H[6] * x1[0] + H[7] * x1[1] + H[8];
  if (!(std::abs(w) > 0)) return {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
  return {(H[0] * x1[0] + H[1] * x1[1] + H[2]) / w, (H[3] * x1[0] + H[4] * x1[1] + H[5]) / w};
}
/// Squared transfer distance |x2 - H x1|^2, pixels^2.
inline double transfer_squared(const std::array<double, 2>& hx1, const std::array<double, 2>& x2) noexcept {
  const double u = hx1[0] - x2[0], v = hx1[1] - x2[1];
  return u * u + v * v;
}
inline double transfer_squared(const std::array<double, 9>& H, const std::array<double, 2>& x1, const std::array<double, 2>& x2) noexcept {
  return transfer_squared(transfer(H, x1), x2);
}

}  // namespace detail

/// Raw matches between the descriptors of two images (see the file comment for the rule), ordered by
/// the first image's index.
[[nodiscard]] inline std::vector<SiftMatch> match_sift(const SiftDescriptors& a, const SiftDescriptors& b,
                                                       const SiftMatchOptions& o = {}) {
  const auto wa = detail::widen(a), wb = detail::widen(b);
  return detail::match_widened(wa.data(), a.rows, wb.data(), b.rows, o);
}

/// Removes, from every image of `database`, the features whose descriptor COLMAP 3.8 may not have
/// written: VLFeat's vl_sift_calc_keypoint_descriptor returns before touching the output when the
/// keypoint's rounded position in its octave lies in the octave's last row or beyond its last column
/// (its bounds check), and COLMAP leaves that row of its descriptor buffer as it found it, so the
/// bytes differ from run to run (three such rows in 73,000 made two runs of blackswan 40-49 on whole
/// frames register different models; all three within 4.1 px of the bottom edge). Octave o has pixels
/// of 2^o < 0.79 sigma for COLMAP's SIFT (sigma0 1.6, 3 levels, |ds| < 1), so every such keypoint has
/// y >= height - 2.5 x 2^o or x >= width - 1.5 x 2^o; this drops those with y or x at least
/// height or width - 1 - 2 sigma (sigma = sqrt|det A| of the affine shape, or the scale column; 0 for
/// 2-column keypoints). Images with nothing to drop are not rewritten, so running it again changes
/// nothing. Returns the number of features removed.
inline std::size_t drop_border_features(const std::filesystem::path& database) {
  ColmapDatabase db(database, true);
  std::vector<StoredFeatures> changed;
  std::size_t dropped = 0;
  for (auto& f : db.features()) {
    const auto cols = static_cast<std::size_t>(f.keypoint_cols);
    StoredFeatures kept = f;
    kept.rows = 0;
    kept.keypoints.clear();
    kept.descriptors.clear();
    for (std::size_t r = 0; r < f.rows; ++r) {
      const float* k = f.keypoints.data() + r * cols;
      const double sigma = cols == 6   ? std::sqrt(std::abs(double(k[2]) * k[5] - double(k[3]) * k[4]))
                           : cols == 4 ? std::abs(double(k[2]))
                                       : 0.0;
      const double margin = 1.0 + 2.0 * sigma;
      if (double(k[0]) >= f.width - margin || double(k[1]) >= f.height - margin) continue;
      kept.keypoints.insert(kept.keypoints.end(), k, k + cols);
      kept.descriptors.insert(kept.descriptors.end(), f.descriptors.begin() + static_cast<std::ptrdiff_t>(r * 128),
                              f.descriptors.begin() + static_cast<std::ptrdiff_t>((r + 1) * 128));
      ++kept.rows;
    }
    if (kept.rows == f.rows) continue;
    dropped += f.rows - kept.rows;
    changed.push_back(std::move(kept));
  }
  if (!changed.empty()) db.replace_features(changed);
  return dropped;
}

/// What write_match_list did.
struct MatchListStats {
  std::size_t images = 0;
  std::size_t pairs = 0;          ///< pairs matched now (written when they have a match)
  std::size_t pairs_skipped = 0;  ///< pairs that already had matches in the database
  std::size_t matches = 0;
  std::vector<std::uint64_t> pair_ids;  ///< colmap_pair_id of every pair matched now
};

/// COLMAP's guided matching, exact: once a pair is verified, match its descriptors again among the
/// candidates its geometry allows: squared Sampson distance under F (calibrated and uncalibrated
/// pairs) or squared transfer distance under H (planar, panoramic) at most max_error^2, with the
/// same distance, ratio and cross-check rule as match_sift. Pairs of other configurations get none.
struct GuidedMatchOptions {
  SiftMatchOptions match;
  double max_error = 4.0;  ///< pixels (COLMAP's TwoViewGeometry max_error)
};

namespace detail {

/// guided_match_sift on widened descriptor blocks (wa: ka.xy.size() rows, wb: kb.xy.size() rows).
inline std::vector<SiftMatch> guided_widened(const std::int16_t* wa, const SiftKeypoints& ka, const std::int16_t* wb,
                                             const SiftKeypoints& kb, const TwoViewGeometry& g, const GuidedMatchOptions& o) {
  const bool use_f = g.config == TwoViewConfig::calibrated || g.config == TwoViewConfig::uncalibrated;
  const bool use_h = g.config == TwoViewConfig::planar || g.config == TwoViewConfig::panoramic ||
                     g.config == TwoViewConfig::planar_or_panoramic;
  if (!use_f && !use_h) return {};
  const double limit = o.max_error * o.max_error;
  // The per-point parts once per point, not once per candidate pair.
  std::vector<std::array<double, 3>> f1(use_f ? ka.xy.size() : 0);
  std::vector<std::array<double, 2>> ft2(use_f ? kb.xy.size() : 0), hx1(use_h ? ka.xy.size() : 0);
  for (std::size_t i = 0; i < f1.size(); ++i) f1[i] = epipolar_line(g.F, ka.xy[i]);
  for (std::size_t j = 0; j < ft2.size(); ++j) ft2[j] = epipolar_line_t(g.F, kb.xy[j]);
  for (std::size_t i = 0; i < hx1.size(); ++i) hx1[i] = transfer(g.H, ka.xy[i]);
  return match_widened(wa, ka.xy.size(), wb, kb.xy.size(), o.match, [&](std::size_t i, std::size_t j) {
    return (use_f ? sampson_squared(f1[i], ft2[j], kb.xy[j]) : transfer_squared(hx1[i], kb.xy[j])) <= limit;
  });
}

}  // namespace detail

/// Guided matches of one verified pair (a = the image with the smaller id); none when the keypoints
/// and descriptors disagree in count.
[[nodiscard]] inline std::vector<SiftMatch> guided_match_sift(const SiftDescriptors& a, const SiftKeypoints& ka, const SiftDescriptors& b,
                                                              const SiftKeypoints& kb, const TwoViewGeometry& g,
                                                              const GuidedMatchOptions& o = {}) {
  if (ka.xy.size() != a.rows || kb.xy.size() != b.rows) return {};
  const auto wa = detail::widen(a), wb = detail::widen(b);
  return detail::guided_widened(wa.data(), ka, wb.data(), kb, g, o);
}

/// Replaces the inlier matches of the verified pairs among `pair_ids` in `database` by their guided
/// matches (guided_match_sift), in one transaction; pairs that are not verified, or of a configuration
/// without F or H, keep theirs. Returns the number of matches written. The database's bytes do not
/// depend on the pool.
inline std::size_t guide_matches(const std::filesystem::path& database, const std::vector<std::uint64_t>& pair_ids,
                                 const GuidedMatchOptions& o = {}, ThreadPool* pool = nullptr) {
  ColmapDatabase db(database, true);
  // Each image's keypoints and widened descriptors once, from one read of its features.
  std::map<std::uint32_t, std::size_t> at;
  std::vector<SiftKeypoints> keys;
  std::vector<std::vector<std::int16_t>> wide;
  for (auto& f : db.features()) {
    at[f.image_id] = keys.size();
    keys.push_back(keypoints_of(f));
    wide.push_back(detail::widen(descriptors_of(std::move(f))));
  }
  const std::set<std::uint64_t> wanted(pair_ids.begin(), pair_ids.end());
  std::vector<TwoViewGeometry> todo;
  for (const auto& g : db.two_view_geometries()) {
    const auto [id1, id2] = colmap_pair_images(g.pair_id);
    if (wanted.count(g.pair_id) && at.count(id1) && at.count(id2) && g.config != TwoViewConfig::undefined &&
        g.config != TwoViewConfig::degenerate && g.config != TwoViewConfig::watermark && g.config != TwoViewConfig::multiple)
      todo.push_back(g);
  }
  std::vector<std::pair<std::uint64_t, std::vector<SiftMatch>>> found(todo.size());
  parallel_for(pool, todo.size(), [&](std::size_t p) {
    const auto& g = todo[p];
    const auto [id1, id2] = colmap_pair_images(g.pair_id);
    const std::size_t i = at.at(id1), j = at.at(id2);
    found[p] = {g.pair_id, detail::guided_widened(wide[i].data(), keys[i], wide[j].data(), keys[j], g, o)};
  }, 1);
  std::size_t n = 0;
  for (const auto& f : found) n += f.second.size();
  db.replace_inlier_matches(found);
  return n;
}

/// Matches every pair of images of `database` that has no matches yet and writes them to `list` in
/// COLMAP's raw match-list format ("name1 name2", then one "i j" line per match, then an empty line;
/// pairs by increasing image id), atomically. The file's bytes do not depend on the pool.
/// Throws io.* for an unreadable database, and `[io.format]` for an image name with white space (the
/// list's format cannot carry it).
inline MatchListStats write_match_list(const std::filesystem::path& database, const std::filesystem::path& list,
                                       const SiftMatchOptions& o = {}, ThreadPool* pool = nullptr) {
  const ColmapDatabase db(database);
  const auto images = db.descriptors();
  const auto done = db.matched_pairs();
  for (const auto& im : images)
    if (im.name.find_first_of(" \t\r\n") != std::string::npos)
      throw io_error("io.format", database.string(), "image name '" + im.name + "' has white space; the match list cannot name it");
  std::vector<std::vector<std::int16_t>> wide(images.size());
  parallel_for(pool, images.size(), [&](std::size_t i) { wide[i] = detail::widen(images[i]); }, 1);
  std::vector<std::array<std::size_t, 2>> todo;
  MatchListStats stats;
  stats.images = images.size();
  for (std::size_t x = 0; x < images.size(); ++x)
    for (std::size_t y = x + 1; y < images.size(); ++y) {
      const std::uint64_t id = colmap_pair_id(images[x].image_id, images[y].image_id);
      if (done.count(id)) {
        ++stats.pairs_skipped;
      } else {
        todo.push_back({x, y});
        stats.pair_ids.push_back(id);
      }
    }
  std::vector<std::vector<SiftMatch>> found(todo.size());
  parallel_for(pool, todo.size(), [&](std::size_t p) {
    const auto [x, y] = todo[p];
    found[p] = detail::match_widened(wide[x].data(), images[x].rows, wide[y].data(), images[y].rows, o);
  }, 1);
  stats.pairs = todo.size();
  std::ostringstream text;
  for (std::size_t p = 0; p < todo.size(); ++p) {
    if (found[p].empty()) continue;
    text << images[todo[p][0]].name << ' ' << images[todo[p][1]].name << '\n';
    for (const auto& m : found[p]) text << m[0] << ' ' << m[1] << '\n';
    text << '\n';
    stats.matches += found[p].size();
  }
  io::write_file_atomic(list, text.str());
  return stats;
}

}  // namespace video3dgs::colmap
