#pragma once
/// @file
/// Access to the parts of a COLMAP database (SQLite, COLMAP 3.x schema) that video3dgs matches
/// itself (colmap/matcher.hpp): each image's name, keypoints and SIFT descriptors, which image pairs
/// already hold raw matches, the verified pairs' geometry, and replacing a verified pair's inlier
/// matches (guided matching). COLMAP's `matches_importer` writes the raw matches and verifies them.
///
/// Schema facts used (COLMAP's database.cc): `images(image_id, name, ...)`; `keypoints(image_id,
/// rows, cols, data)`, rows x cols float32 with x, y first; `descriptors(image_id, rows, cols, data)`,
/// rows x 128 uint8; `matches(pair_id, ...)` with pair_id = 2147483647 x min(id) + max(id);
/// `two_view_geometries(pair_id, rows, cols, data, config, F, E, H, ...)`, data = rows x 2 uint32
/// (index in the smaller id's image first), F/E/H 3x3 float64 row-major.
///
/// Errors: `[io.unreadable]` (the file cannot be opened as a database), `[io.format]` (a table or
/// column is missing, or a blob's size disagrees with its rows x cols), `[io.unwritable]` (a write
/// failed; nothing of it stays), each naming the file.

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <memory>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <sqlite3.h>

#include "video3dgs/core/error.hpp"

namespace video3dgs::colmap {

/// One image's SIFT descriptors as COLMAP stores them: `rows` x 128 bytes, row-major.
struct SiftDescriptors {
  std::uint32_t image_id = 0;
  std::string name;  ///< the image's file name relative to COLMAP's image folder
  std::size_t rows = 0;
  std::vector<std::uint8_t> data;
};

/// COLMAP's largest image id, the base of its pair ids (2^31 - 1).
inline constexpr std::uint64_t kColmapMaxImageId = 2147483647;

/// COLMAP's pair id of two image ids (order-free).
[[nodiscard]] constexpr std::uint64_t colmap_pair_id(std::uint32_t a, std::uint32_t b) noexcept {
  if (a > b) std::swap(a, b);
  return kColmapMaxImageId * a + b;
}

/// One image's keypoint positions (x, y in pixels, COLMAP's convention: the first pixel's centre is
/// (0.5, 0.5)), in the order of its descriptors.
struct SiftKeypoints {
  std::uint32_t image_id = 0;
  std::vector<std::array<double, 2>> xy;
};

/// COLMAP's TwoViewGeometry::ConfigurationType (the `config` column).
enum class TwoViewConfig : int {
  undefined = 0,
  degenerate = 1,
  calibrated = 2,
  uncalibrated = 3,
  planar = 4,
  panoramic = 5,
  planar_or_panoramic = 6,
  watermark = 7,
  multiple = 8
};

/// A verified image pair: its configuration, fundamental matrix and homography (row-major, from the
/// first image, the one with the smaller id, to the second; zero when COLMAP stored none) and how many
/// inlier matches it holds.
struct TwoViewGeometry {
  std::uint64_t pair_id = 0;
  TwoViewConfig config = TwoViewConfig::undefined;
  std::array<double, 9> F{}, H{};
  std::size_t inliers = 0;
};

/// One image's features as stored: keypoint rows of `keypoint_cols` floats (x, y first; 6 = x, y and
/// the affine shape a11, a12, a21, a22; 4 = x, y, scale, orientation), descriptor rows of 128 bytes,
/// and the size of the image's camera.
struct StoredFeatures {
  std::uint32_t image_id = 0;
  std::string name;  ///< the image's file name relative to COLMAP's image folder
  int width = 0, height = 0;
  std::size_t rows = 0;
  int keypoint_cols = 0;
  std::vector<float> keypoints;
  std::vector<std::uint8_t> descriptors;
};

/// An image's descriptors out of its stored features (which give them up).
[[nodiscard]] inline SiftDescriptors descriptors_of(StoredFeatures&& f) {
  SiftDescriptors d;
  d.image_id = f.image_id;
  d.name = std::move(f.name);
  d.rows = f.rows;
  d.data = std::move(f.descriptors);
  return d;
}

/// An image's keypoint positions out of its stored features.
[[nodiscard]] inline SiftKeypoints keypoints_of(const StoredFeatures& f) {
  SiftKeypoints k;
  k.image_id = f.image_id;
  k.xy.resize(f.rows);
  const auto cols = static_cast<std::size_t>(f.keypoint_cols);
  for (std::size_t r = 0; r < f.rows; ++r) k.xy[r] = {double(f.keypoints[r * cols]), double(f.keypoints[r * cols + 1])};
  return k;
}

/// The two image ids of a pair id (smaller first).
[[nodiscard]] constexpr std::pair<std::uint32_t, std::uint32_t> colmap_pair_images(std::uint64_t pair_id) noexcept {
  return {static_cast<std::uint32_t>(pair_id / kColmapMaxImageId), static_cast<std::uint32_t>(pair_id % kColmapMaxImageId)};
}

/// A COLMAP database, opened read-only unless `writable`.
class ColmapDatabase {
 public:
  explicit ColmapDatabase(std::filesystem::path path, bool writable = false) : path_(std::move(path)) {
    sqlite3* db = nullptr;
    const int rc = sqlite3_open_v2(path_.c_str(), &db, writable ? SQLITE_OPEN_READWRITE : SQLITE_OPEN_READONLY, nullptr);
    db_.reset(db);
    if (rc != SQLITE_OK || !std::filesystem::is_regular_file(path_))
      throw io_error("io.unreadable", path_.string(), std::string("cannot open the COLMAP database: ") + (db ? sqlite3_errmsg(db) : "out of memory"));
  }

  /// The descriptors of every image with features (as features() lists them), by image id.
  [[nodiscard]] std::vector<SiftDescriptors> descriptors() const {
    std::vector<SiftDescriptors> out;
    for (auto& f : features()) out.push_back(descriptors_of(std::move(f)));
    return out;
  }

  /// The features of every image with keypoints and descriptors, by image id.
  [[nodiscard]] std::vector<StoredFeatures> features() const {
    std::vector<StoredFeatures> out;
    Statement st(*this,
                 "SELECT images.image_id, cameras.width, cameras.height, keypoints.rows, keypoints.cols, keypoints.data, descriptors.rows, "
                 "descriptors.cols, descriptors.data, images.name FROM images JOIN cameras ON images.camera_id = cameras.camera_id "
                 "JOIN keypoints ON images.image_id = keypoints.image_id JOIN descriptors ON images.image_id = descriptors.image_id "
                 "ORDER BY images.image_id");
    while (st.step()) {
      StoredFeatures f;
      f.image_id = static_cast<std::uint32_t>(sqlite3_column_int64(st.get(), 0));
      const auto* name = sqlite3_column_text(st.get(), 9);
      f.name = name ? reinterpret_cast<const char*>(name) : "";
      f.width = sqlite3_column_int(st.get(), 1);
      f.height = sqlite3_column_int(st.get(), 2);
      const auto rows = sqlite3_column_int64(st.get(), 3);
      f.keypoint_cols = sqlite3_column_int(st.get(), 4);
      const auto kbytes = static_cast<std::size_t>(sqlite3_column_bytes(st.get(), 5));
      const auto* kblob = static_cast<const unsigned char*>(sqlite3_column_blob(st.get(), 5));
      const auto drows = sqlite3_column_int64(st.get(), 6);
      const auto dcols = sqlite3_column_int64(st.get(), 7);
      const auto dbytes = static_cast<std::size_t>(sqlite3_column_bytes(st.get(), 8));
      const auto* dblob = static_cast<const std::uint8_t*>(sqlite3_column_blob(st.get(), 8));
      const bool ok_cols = f.keypoint_cols == 2 || f.keypoint_cols == 4 || f.keypoint_cols == 6;
      if (rows < 0 || rows != drows || (rows > 0 && (!ok_cols || dcols != 128)) ||
          kbytes != static_cast<std::size_t>(rows) * static_cast<std::size_t>(std::max(f.keypoint_cols, 0)) * sizeof(float) ||
          dbytes != static_cast<std::size_t>(rows) * 128 || (kbytes > 0 && !kblob) || (dbytes > 0 && !dblob))
        throw io_error("io.format", path_.string(),
                       "features of image " + std::to_string(f.image_id) + " (" + f.name + "): " + std::to_string(rows) + " keypoints of " +
                           std::to_string(f.keypoint_cols) + " floats in " + std::to_string(kbytes) + " bytes, " + std::to_string(drows) +
                           " descriptors of " + std::to_string(dcols) + " bytes in " + std::to_string(dbytes));
      f.rows = static_cast<std::size_t>(rows);
      f.keypoints.resize(kbytes / sizeof(float));
      if (kbytes > 0) std::memcpy(f.keypoints.data(), kblob, kbytes);
      f.descriptors.assign(dblob, dblob + dbytes);
      out.push_back(std::move(f));
    }
    return out;
  }

  /// Replaces the keypoints and descriptors of each listed image (rows, keypoint_cols, keypoints,
  /// descriptors) in one transaction: all or none. For images without matches yet: match rows index them.
  void replace_features(const std::vector<StoredFeatures>& images) {
    in_transaction([&] {
      Statement k(*this, "UPDATE keypoints SET rows = ?, cols = ?, data = ? WHERE image_id = ?");
      Statement d(*this, "UPDATE descriptors SET rows = ?, cols = 128, data = ? WHERE image_id = ?");
      for (const auto& f : images) {
        sqlite3_reset(k.get());
        sqlite3_bind_int64(k.get(), 1, static_cast<sqlite3_int64>(f.rows));
        sqlite3_bind_int(k.get(), 2, f.keypoint_cols);
        sqlite3_bind_blob(k.get(), 3, f.keypoints.data(), static_cast<int>(f.keypoints.size() * sizeof(float)), SQLITE_TRANSIENT);
        sqlite3_bind_int64(k.get(), 4, f.image_id);
        while (k.step()) {
        }
        sqlite3_reset(d.get());
        sqlite3_bind_int64(d.get(), 1, static_cast<sqlite3_int64>(f.rows));
        sqlite3_bind_blob(d.get(), 2, f.descriptors.data(), static_cast<int>(f.descriptors.size()), SQLITE_TRANSIENT);
        sqlite3_bind_int64(d.get(), 3, f.image_id);
        while (d.step()) {
        }
      }
    });
  }

  /// Pair ids (colmap_pair_id) that already have a row in `matches`.
  [[nodiscard]] std::set<std::uint64_t> matched_pairs() const {
    std::set<std::uint64_t> out;
    Statement st(*this, "SELECT pair_id FROM matches");
    while (st.step()) out.insert(static_cast<std::uint64_t>(sqlite3_column_int64(st.get(), 0)));
    return out;
  }

  /// Keypoint positions of every image with features (as features() lists them), by image id.
  [[nodiscard]] std::vector<SiftKeypoints> keypoints() const {
    std::vector<SiftKeypoints> out;
    for (const auto& f : features()) out.push_back(keypoints_of(f));
    return out;
  }

  /// Every verified pair (table two_view_geometries), by pair id.
  [[nodiscard]] std::vector<TwoViewGeometry> two_view_geometries() const {
    std::vector<TwoViewGeometry> out;
    Statement st(*this, "SELECT pair_id, rows, config, F, H FROM two_view_geometries ORDER BY pair_id");
    while (st.step()) {
      TwoViewGeometry g;
      g.pair_id = static_cast<std::uint64_t>(sqlite3_column_int64(st.get(), 0));
      g.inliers = static_cast<std::size_t>(std::max<std::int64_t>(0, sqlite3_column_int64(st.get(), 1)));
      g.config = static_cast<TwoViewConfig>(sqlite3_column_int(st.get(), 2));
      read_matrix(st, 3, g.F, g.pair_id);
      read_matrix(st, 4, g.H, g.pair_id);
      out.push_back(g);
    }
    return out;
  }

  /// Replaces the inlier matches of each listed pair (pair id, then (index in the smaller id's image,
  /// index in the other) pairs) in one transaction: all or none.
  void replace_inlier_matches(const std::vector<std::pair<std::uint64_t, std::vector<std::array<std::uint32_t, 2>>>>& pairs) {
    in_transaction([&] {
      Statement st(*this, "UPDATE two_view_geometries SET rows = ?, cols = 2, data = ? WHERE pair_id = ?");
      for (const auto& [pair_id, matches] : pairs) {
        std::vector<std::uint32_t> flat;
        flat.reserve(2 * matches.size());
        for (const auto& m : matches) flat.insert(flat.end(), {m[0], m[1]});
        sqlite3_reset(st.get());
        sqlite3_bind_int64(st.get(), 1, static_cast<sqlite3_int64>(matches.size()));
        sqlite3_bind_blob(st.get(), 2, flat.data(), static_cast<int>(flat.size() * sizeof(std::uint32_t)), SQLITE_TRANSIENT);
        sqlite3_bind_int64(st.get(), 3, static_cast<sqlite3_int64>(pair_id));
        while (st.step()) {
        }
      }
    });
  }

  [[nodiscard]] const std::filesystem::path& path() const noexcept { return path_; }

 private:
  struct Closer {
    void operator()(sqlite3* db) const noexcept { sqlite3_close(db); }
  };
  /// A prepared statement; step() is true while it yields a row and throws on an error.
  class Statement {
   public:
    Statement(const ColmapDatabase& db, const char* sql) : db_(db) {
      if (sqlite3_prepare_v2(db.db_.get(), sql, -1, &st_, nullptr) != SQLITE_OK) fail();
    }
    Statement(const Statement&) = delete;
    Statement& operator=(const Statement&) = delete;
    ~Statement() { sqlite3_finalize(st_); }
    bool step() {
      const int rc = sqlite3_step(st_);
      if (rc == SQLITE_ROW) return true;
      if (rc != SQLITE_DONE) fail();
      return false;
    }
    [[nodiscard]] sqlite3_stmt* get() const noexcept { return st_; }

   private:
    [[noreturn]] void fail() const {
      throw io_error("io.format", db_.path_.string(), std::string("not a COLMAP database this version can read: ") + sqlite3_errmsg(db_.db_.get()));
    }
    const ColmapDatabase& db_;
    sqlite3_stmt* st_ = nullptr;
  };

  /// Runs f() inside one transaction: all of its writes, or none of them when it throws.
  template <class F>
  void in_transaction(F&& f) {
    exec("BEGIN");
    try {
      f();
      exec("COMMIT");
    } catch (...) {
      sqlite3_exec(db_.get(), "ROLLBACK", nullptr, nullptr, nullptr);
      throw;
    }
  }
  void exec(const char* sql) {
    if (sqlite3_exec(db_.get(), sql, nullptr, nullptr, nullptr) != SQLITE_OK)
      throw io_error("io.unwritable", path_.string(), std::string(sql) + ": " + sqlite3_errmsg(db_.get()));
  }
  /// A 3x3 float64 blob (row-major) into m; a NULL or empty blob leaves zeros.
  void read_matrix(const Statement& st, int column, std::array<double, 9>& m, std::uint64_t pair_id) const {
    const auto bytes = static_cast<std::size_t>(sqlite3_column_bytes(st.get(), column));
    if (bytes == 0) return;
    const void* blob = sqlite3_column_blob(st.get(), column);
    if (bytes != sizeof(m) || !blob)
      throw io_error("io.format", path_.string(), "two-view geometry of pair " + std::to_string(pair_id) + ": a matrix of " +
                                                      std::to_string(bytes) + " bytes; expected 9 doubles");
    std::memcpy(m.data(), blob, sizeof(m));
  }

  std::filesystem::path path_;
  std::unique_ptr<sqlite3, Closer> db_;
};

}  // namespace video3dgs::colmap
