#include "video3dgs/model/point_init.hpp"

#include <algorithm>
#include <random>

#include <doctest/doctest.h>

#include "../test_data.hpp"

using namespace video3dgs;

TEST_CASE("fibonacci_sphere: points lie on the sphere and are spread evenly") {
  const Eigen::Vector3d c(1, -2, 3);
  const auto pts = fibonacci_sphere<double>(1000, c, 2.5);
  REQUIRE(pts.size() == 1000);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : pts) {
    CHECK((p - c).norm() == doctest::Approx(2.5).epsilon(1e-12));
    mean += p / 1000.0;
  }
  CHECK((mean - c).norm() < 0.01);  // balanced around the centre
  // No two points closer than a fraction of the mean spacing (sqrt(4 pi r^2 / n)).
  const double spacing = std::sqrt(4 * 3.14159265 * 2.5 * 2.5 / 1000);
  double min_d = 1e9;
  for (std::size_t i = 0; i < pts.size(); ++i)
    for (std::size_t j = i + 1; j < pts.size(); ++j) min_d = std::min(min_d, (pts[i] - pts[j]).norm());
  CHECK(min_d > 0.5 * spacing);
}

TEST_CASE("background_shell_points: radii follow the foreground box; no foreground falls back") {
  std::vector<Eigen::Vector3f> fg = {{0, 0, 0}, {2, 1, 0.5f}, {1, 0.5f, 0.25f}};
  BackgroundShellOptions opt;
  opt.points_per_shell = 100;
  const auto bg = background_shell_points(fg, opt);
  REQUIRE(bg.size() == 200);
  const Eigen::Vector3f centre(1, 0.5f, 0.25f);
  CHECK((bg[0] - centre).norm() == doctest::Approx(2.0f).epsilon(1e-5));    // 1 x largest side (2)
  CHECK((bg[150] - centre).norm() == doctest::Approx(6.0f).epsilon(1e-5));  // 3 x
  const auto none = background_shell_points(std::vector<Eigen::Vector3f>{}, opt);
  REQUIRE(none.size() == 200);
  for (const auto& p : none) CHECK(p.allFinite());
  const auto single = background_shell_points(std::vector<Eigen::Vector3f>{{5, 5, 5}}, opt);
  for (const auto& p : single) CHECK((p - Eigen::Vector3f(5, 5, 5)).norm() > 0);
}

TEST_CASE("knn_mean_sq_distance: exact against brute force, with clusters and outliers") {
  const std::uint64_t seed = 1234;
  INFO("seed " << seed);
  auto rng = test::seeded_rng(seed);
  std::normal_distribution<double> nd(0, 1);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < 1500; ++i) pts.emplace_back(nd(rng), 0.1 * nd(rng), 0.01 * nd(rng));  // a flat cluster
  pts.emplace_back(100, 100, 100);                                                          // outliers
  pts.emplace_back(-50, 3, 7);
  pts.push_back(pts[3]);  // an exact duplicate
  ThreadPool pool(2);
  const auto d = knn_mean_sq_distance(pts, 3, &pool);
  for (std::size_t i = 0; i < pts.size(); i += 7) {
    std::vector<double> all;
    for (std::size_t j = 0; j < pts.size(); ++j)
      if (j != i) all.push_back((pts[i] - pts[j]).squaredNorm());
    std::partial_sort(all.begin(), all.begin() + 3, all.end());
    CHECK(d[i] == doctest::Approx((all[0] + all[1] + all[2]) / 3).epsilon(1e-12));
  }
  CHECK(d[pts.size() - 1] < d[4] + 1e9);
  CHECK(d == knn_mean_sq_distance(pts, 3, nullptr));  // thread-count independent
  CHECK(knn_mean_sq_distance(std::vector<Eigen::Vector3d>{{1, 2, 3}}).at(0) == 0);
  const auto two = knn_mean_sq_distance(std::vector<Eigen::Vector3d>{{0, 0, 0}, {0, 0, 2}});
  CHECK(two[0] == doctest::Approx(4));
}
