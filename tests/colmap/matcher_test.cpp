#include "video3dgs/colmap/matcher.hpp"

#include <array>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <sqlite3.h>

#include <doctest/doctest.h>

#include "../test_data.hpp"

using namespace video3dgs;
using namespace video3dgs::colmap;
namespace fs = std::filesystem;

namespace {

/// A descriptor with `value` at the given dimensions and 0 elsewhere (four dimensions of 255 have the
/// norm of COLMAP's descriptors, about 512).
std::array<std::uint8_t, 128> pattern(std::initializer_list<int> dims, std::uint8_t value = 255) {
  std::array<std::uint8_t, 128> d{};
  for (int k : dims) d[static_cast<std::size_t>(k)] = value;
  return d;
}

SiftDescriptors descriptors(std::uint32_t id, const std::vector<std::array<std::uint8_t, 128>>& rows) {
  SiftDescriptors d;
  d.image_id = id;
  d.name = "im" + std::to_string(id) + ".png";
  d.rows = rows.size();
  for (const auto& r : rows) d.data.insert(d.data.end(), r.begin(), r.end());
  return d;
}

SiftKeypoints keypoints(std::uint32_t id, const std::vector<std::array<double, 2>>& xy) {
  SiftKeypoints k;
  k.image_id = id;
  k.xy = xy;
  return k;
}

/// The tables of a COLMAP database this adapter reads (the columns it uses, COLMAP's names).
class TestDatabase {
 public:
  explicit TestDatabase(const fs::path& path) {
    REQUIRE(sqlite3_open(path.c_str(), &db_) == SQLITE_OK);
    exec("CREATE TABLE cameras (camera_id INTEGER PRIMARY KEY NOT NULL, model INTEGER NOT NULL, width INTEGER NOT NULL, height INTEGER "
         "NOT NULL, params BLOB, prior_focal_length INTEGER NOT NULL);"
         "INSERT INTO cameras VALUES (1, 0, 100, 80, NULL, 0);"
         "CREATE TABLE images (image_id INTEGER PRIMARY KEY NOT NULL, name TEXT NOT NULL UNIQUE, camera_id INTEGER NOT NULL);"
         "CREATE TABLE keypoints (image_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, data BLOB);"
         "CREATE TABLE descriptors (image_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, data BLOB);"
         "CREATE TABLE matches (pair_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, data BLOB);"
         "CREATE TABLE two_view_geometries (pair_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, "
         "data BLOB, config INTEGER NOT NULL, F BLOB, E BLOB, H BLOB, qvec BLOB, tvec BLOB);");
  }
  TestDatabase(const TestDatabase&) = delete;
  TestDatabase& operator=(const TestDatabase&) = delete;
  ~TestDatabase() { sqlite3_close(db_); }

  /// Image `d` (camera 1: 100 x 80 pixels) with keypoints `k` (6 floats per row, x, y and the affine
  /// shape sigma I, as COLMAP writes them; sigma 1 unless `sigmas` says); `blob_rows` overrides the
  /// descriptor blob's row count (a corrupt row).
  void add_image(const SiftDescriptors& d, const SiftKeypoints& k, long long blob_rows = -1, const std::vector<float>& sigmas = {}) {
    exec("INSERT INTO images VALUES (" + std::to_string(d.image_id) + ", '" + d.name + "', 1)");
    std::vector<float> kp;
    for (std::size_t i = 0; i < k.xy.size(); ++i) {
      const float s = i < sigmas.size() ? sigmas[i] : 1.0f;
      kp.insert(kp.end(), {float(k.xy[i][0]), float(k.xy[i][1]), s, 0, 0, s});
    }
    insert_blob("keypoints", d.image_id, static_cast<long long>(k.xy.size()), 6, kp.data(), kp.size() * sizeof(float));
    insert_blob("descriptors", d.image_id, blob_rows < 0 ? static_cast<long long>(d.rows) : blob_rows, 128, d.data.data(), d.data.size());
  }
  /// A verified pair with configuration `config` and homography / fundamental matrix (row-major).
  void add_geometry(std::uint64_t pair_id, TwoViewConfig config, const std::array<double, 9>& F, const std::array<double, 9>& H) {
    sqlite3_stmt* st = nullptr;
    REQUIRE(sqlite3_prepare_v2(db_, "INSERT INTO two_view_geometries VALUES (?, 0, 2, NULL, ?, ?, NULL, ?, NULL, NULL)", -1, &st, nullptr) == SQLITE_OK);
    sqlite3_bind_int64(st, 1, static_cast<sqlite3_int64>(pair_id));
    sqlite3_bind_int(st, 2, static_cast<int>(config));
    sqlite3_bind_blob(st, 3, F.data(), sizeof(F), SQLITE_TRANSIENT);
    sqlite3_bind_blob(st, 4, H.data(), sizeof(H), SQLITE_TRANSIENT);
    REQUIRE(sqlite3_step(st) == SQLITE_DONE);
    sqlite3_finalize(st);
  }
  void exec(const std::string& sql) { REQUIRE(sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, nullptr) == SQLITE_OK); }

 private:
  void insert_blob(const char* table, std::uint32_t id, long long rows, int cols, const void* data, std::size_t bytes) {
    sqlite3_stmt* st = nullptr;
    REQUIRE(sqlite3_prepare_v2(db_, (std::string("INSERT INTO ") + table + " VALUES (?, ?, ?, ?)").c_str(), -1, &st, nullptr) == SQLITE_OK);
    sqlite3_bind_int64(st, 1, id);
    sqlite3_bind_int64(st, 2, rows);
    sqlite3_bind_int(st, 3, cols);
    sqlite3_bind_blob(st, 4, data, static_cast<int>(bytes), SQLITE_TRANSIENT);
    REQUIRE(sqlite3_step(st) == SQLITE_DONE);
    sqlite3_finalize(st);
  }
  sqlite3* db_ = nullptr;
};

std::string read_text(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// A: p0, p1, p2, p5, p5; B: p1, p6, p0, p5, p1. Expected: A0-B2 (clean), A1 ambiguous (B0 and B4 tie),
/// A2 has no neighbour within max_distance, A3 and A4 both pick B3, which cannot choose between them.
const std::vector<std::array<std::uint8_t, 128>> kA = {pattern({0, 1, 2, 3}), pattern({10, 11, 12, 13}), pattern({20, 21, 22, 23}),
                                                       pattern({50, 51, 52, 53}), pattern({50, 51, 52, 53})};
const std::vector<std::array<std::uint8_t, 128>> kB = {pattern({10, 11, 12, 13}), pattern({60, 61, 62, 63}), pattern({0, 1, 2, 3}),
                                                       pattern({50, 51, 52, 53}), pattern({10, 11, 12, 13})};

}  // namespace

TEST_CASE("match_sift: mutual nearest neighbours under COLMAP's distance and ratio tests") {
  const auto a = descriptors(1, kA), b = descriptors(2, kB);
  CHECK(match_sift(a, b) == std::vector<SiftMatch>{{0, 2}});
  SiftMatchOptions one_way;
  one_way.cross_check = false;
  // Without the cross check, A3 and A4 each keep B3 (their own test passes; B3's does not).
  CHECK(match_sift(a, b, one_way) == std::vector<SiftMatch>{{0, 2}, {3, 3}, {4, 3}});
  // A looser distance still leaves the ambiguous A1 out (its two candidates are equally near).
  SiftMatchOptions loose = one_way;
  loose.max_distance = 2.0;
  const auto m = match_sift(a, b, loose);
  CHECK(std::find(m.begin(), m.end(), SiftMatch{1, 0}) == m.end());
  CHECK(std::find(m.begin(), m.end(), SiftMatch{1, 4}) == m.end());
  // A near but not identical candidate: angle acos(3 x 255^2 / 512^2) = 0.73 rad > 0.7 is refused,
  // accepted once max_distance allows it.
  const auto c = descriptors(3, {pattern({0, 1, 2, 63})});
  CHECK(match_sift(descriptors(1, {pattern({0, 1, 2, 3})}), c).empty());
  SiftMatchOptions wide;
  wide.max_distance = 0.75;
  CHECK(match_sift(descriptors(1, {pattern({0, 1, 2, 3})}), c, wide) == std::vector<SiftMatch>{{0, 0}});
  // Empty images match nothing.
  CHECK(match_sift(descriptors(1, {}), b).empty());
  CHECK(match_sift(a, descriptors(2, {})).empty());
}

TEST_CASE("guided_match_sift: only candidates the pair's geometry allows compete") {
  // A0 = p0 at (10, 10). B0 = p0 at (100, 100) (identical descriptor, wrong place); B1 = p0 with one
  // dimension at 254 at (12.5, 10) (where the homography x + 2 sends A0, within 4 px).
  const auto a = descriptors(1, {pattern({0, 1, 2, 3})});
  auto near = pattern({0, 1, 2, 3});
  near[3] = 254;
  const auto b = descriptors(2, {pattern({0, 1, 2, 3}), near});
  const auto ka = keypoints(1, {{10, 10}}), kb = keypoints(2, {{100, 100}, {12.5, 10}});
  // Unguided, the two candidates are too alike for the ratio test.
  CHECK(match_sift(a, b).empty());
  TwoViewGeometry g;
  g.pair_id = colmap_pair_id(1, 2);
  g.config = TwoViewConfig::planar;
  g.H = {1, 0, 2, 0, 1, 0, 0, 0, 1};
  CHECK(guided_match_sift(a, ka, b, kb, g) == std::vector<SiftMatch>{{0, 1}});
  // The same through F: x2 on the epipolar line y2 = y1 (a sideways camera move).
  g.config = TwoViewConfig::uncalibrated;
  g.F = {0, 0, 0, 0, 0, -1, 0, 1, 0};
  CHECK(guided_match_sift(a, ka, b, kb, g) == std::vector<SiftMatch>{{0, 1}});
  // Degenerate pairs and keypoint counts that disagree with the descriptors give nothing.
  g.config = TwoViewConfig::degenerate;
  CHECK(guided_match_sift(a, ka, b, kb, g).empty());
  g.config = TwoViewConfig::planar;
  CHECK(guided_match_sift(a, ka, b, keypoints(2, {{1, 1}}), g).empty());
}

TEST_CASE("Sampson and transfer distances against hand values") {
  const std::array<double, 9> F = {0, 0, 0, 0, 0, -1, 0, 1, 0};  // epipolar lines y2 = y1
  // x2^T F x1 = y1 - y2 = -4; |F x1|_xy^2 = |F^T x2|_xy^2 = 1: 16 / 2.
  CHECK(colmap::detail::sampson_squared(F, {5, 3}, {50, 7}) == doctest::Approx(8.0));
  CHECK(colmap::detail::sampson_squared(F, {5, 3}, {-20, 3}) == doctest::Approx(0.0));
  const std::array<double, 9> H = {2, 0, 1, 0, 2, -1, 0, 0, 1};
  CHECK(colmap::detail::transfer_squared(H, {1, 1}, {3, 1}) == doctest::Approx(0.0));
  CHECK(colmap::detail::transfer_squared(H, {1, 1}, {6, 5}) == doctest::Approx(9.0 + 16.0));
  const std::array<double, 9> at_infinity = {1, 0, 0, 0, 1, 0, 1, 0, -1};  // w = x - 1 = 0 at x = 1
  CHECK(std::isinf(colmap::detail::transfer_squared(at_infinity, {1, 5}, {0, 0})));
}

TEST_CASE("write_match_list and guide_matches on a database: COLMAP's format, already matched pairs skipped, same bytes on any pool") {
  const fs::path dir = test::fresh_dir("matcher_test_list");
  const fs::path db_path = dir / "database.db";
  {
    TestDatabase db(db_path);
    db.add_image(descriptors(1, kA), keypoints(1, {{1, 1}, {2, 2}, {3, 3}, {4, 4}, {5, 5}}));
    db.add_image(descriptors(2, kB), keypoints(2, {{1, 1}, {2, 2}, {3, 3}, {4, 4}, {5, 5}}));
    db.add_image(descriptors(3, {pattern({0, 1, 2, 3}), pattern({60, 61, 62, 63})}), keypoints(3, {{1, 1}, {9, 9}}));
    // Pair (2, 3) was matched before (a grown clip's database).
    db.exec("INSERT INTO matches VALUES (" + std::to_string(colmap_pair_id(2, 3)) + ", 0, 2, NULL)");
    // Both new pairs verified as planar with the identity homography (what matches_importer adds).
    const std::array<double, 9> I = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    db.add_geometry(colmap_pair_id(1, 2), TwoViewConfig::planar, {}, I);
    db.add_geometry(colmap_pair_id(1, 3), TwoViewConfig::planar, {}, I);
  }
  const auto s1 = write_match_list(db_path, dir / "one.txt");
  ThreadPool pool(3);
  const auto s3 = write_match_list(db_path, dir / "three.txt", {}, &pool);
  CHECK(s1.images == 3);
  CHECK(s1.pairs == 2);
  CHECK(s1.pairs_skipped == 1);
  CHECK(s1.matches == 2);
  CHECK(s1.pair_ids == std::vector<std::uint64_t>{colmap_pair_id(1, 2), colmap_pair_id(1, 3)});
  CHECK(colmap_pair_id(3, 1) == colmap_pair_id(1, 3));
  CHECK(colmap_pair_images(colmap_pair_id(7, 3)) == std::pair<std::uint32_t, std::uint32_t>{3, 7});
  CHECK(read_text(dir / "one.txt") == "im1.png im2.png\n0 2\n\nim1.png im3.png\n0 0\n\n");
  CHECK(read_text(dir / "three.txt") == read_text(dir / "one.txt"));
  CHECK(s3.pair_ids == s1.pair_ids);

  // guide_matches rewrites the verified pairs it is given, and only those. Keypoints i of A and j of B
  // sit at (i+1, i+1) and (j+1, j+1), so under the identity only |i - j| <= 2 (2.8 px) compete: A0-B2
  // stays, and A1-B0 is no longer ambiguous (its twin B4 is 4.2 px away).
  CHECK(guide_matches(db_path, {colmap_pair_id(1, 2)}, {}, &pool) == 2);
  const ColmapDatabase db(db_path);
  const auto g = db.two_view_geometries();
  REQUIRE(g.size() == 2);
  CHECK(g[0].pair_id == colmap_pair_id(1, 2));
  CHECK(g[0].config == TwoViewConfig::planar);
  CHECK(g[0].H[0] == 1.0);
  CHECK(g[0].inliers == 2);
  CHECK(g[1].inliers == 0);  // not in the list: untouched
  fs::remove_all(dir);
}

TEST_CASE("drop_border_features: features whose descriptor COLMAP may leave unwritten go, keypoints and descriptors together") {
  const fs::path dir = test::fresh_dir("matcher_test_border");
  const fs::path db_path = dir / "database.db";
  // Camera 100 x 80. Kept: (50, 40) and (50, 74) with sigma 2 (margin 1 + 2 sigma = 5: 74 < 75).
  // Dropped: (50, 79.5) and (97, 10) with sigma 1 (margin 3), (50, 76) with sigma 2.
  const std::vector<std::array<std::uint8_t, 128>> rows = {pattern({0}), pattern({1}), pattern({2}), pattern({3}), pattern({4})};
  {
    TestDatabase db(db_path);
    db.add_image(descriptors(1, rows), keypoints(1, {{50, 40}, {50, 79.5}, {97, 10}, {50, 76}, {50, 74}}), -1, {1, 1, 1, 2, 2});
    db.add_image(descriptors(2, {pattern({9})}), keypoints(2, {{10, 10}}));
  }
  CHECK(drop_border_features(db_path) == 3);
  CHECK(drop_border_features(db_path) == 0);  // nothing left to drop
  const ColmapDatabase db(db_path);
  const auto f = db.features();
  REQUIRE(f.size() == 2);
  CHECK(f[0].width == 100);
  CHECK(f[0].height == 80);
  REQUIRE(f[0].rows == 2);
  CHECK(f[0].keypoint_cols == 6);
  CHECK(f[0].keypoints[1] == 40.0f);
  CHECK(f[0].keypoints[6 + 1] == 74.0f);
  CHECK(f[0].keypoints[6 + 2] == 2.0f);
  CHECK(f[0].descriptors[0] == 255);        // pattern({0})'s row
  CHECK(f[0].descriptors[128 + 4] == 255);  // pattern({4})'s row
  CHECK(f[1].rows == 1);
  const auto d = db.descriptors();
  CHECK(d[0].rows == 2);
  CHECK(db.keypoints()[0].xy.size() == 2);
  fs::remove_all(dir);
}

TEST_CASE("ColmapDatabase: unreadable and malformed databases are refused with ids") {
  const fs::path dir = test::fresh_dir("matcher_test_bad");
  CHECK(test::error_id([&] { (void)ColmapDatabase(dir / "missing.db").descriptors(); }) == "io.unreadable");
  {
    std::ofstream(dir / "text.db") << "not a database at all, just some text that is long enough to be a page of sqlite";
  }
  CHECK(test::error_id([&] { (void)ColmapDatabase(dir / "text.db").descriptors(); }) == "io.format");
  {
    TestDatabase db(dir / "short.db");
    db.add_image(descriptors(1, kA), keypoints(1, {{1, 1}, {2, 2}, {3, 3}, {4, 4}, {5, 5}}), 6);  // 6 rows claimed, 5 stored
  }
  CHECK(test::error_id([&] { (void)write_match_list(dir / "short.db", dir / "list.txt"); }) == "io.format");
  CHECK_FALSE(fs::exists(dir / "list.txt"));
  fs::remove_all(dir);
}
