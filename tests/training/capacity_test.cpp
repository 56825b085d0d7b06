// Capacity plans (training/capacity.hpp): the two measured anchors, monotone in pixels, frames and view
// spread on synthetic clips of many sizes, the view spread of known camera paths, bad rules refused;
// the SH cap of TrainOptions keeps the bands above it at their initial zeros in training.
#include <cmath>
#include <numbers>
#include <vector>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "../tiny_clip.hpp"
#include "video3dgs/synthetic/clip.hpp"
#include "video3dgs/training/capacity.hpp"
#include "video3dgs/training/clip_trainer.hpp"

using namespace video3dgs;

namespace {

constexpr double kDegree = std::numbers::pi / 180;

/// The shape of a synthetic clip (its cameras on an arc of `arc` degrees around the object at the
/// origin, `npoints` SfM points near it).
ClipShape synthetic_shape(int width, int height, int frames, double arc, std::size_t npoints = 186) {
  synthetic::SyntheticClipOptions o;
  o.width = width, o.height = height, o.frames = frames, o.arc_degrees = arc;
  std::vector<Camera<double>> cams;
  for (int i = 0; i < frames; ++i) cams.push_back(synthetic::synthetic_clip_camera<double>(o, i));
  std::vector<SfmPoint<double>> points(npoints);
  for (std::size_t i = 0; i < points.size(); ++i) points[i].xyz = Eigen::Vector3d(0.01 * double(i % 7), -0.01 * double(i % 5), 0.02 * double(i % 3));
  return clip_shape(width, height, std::span<const Camera<double>>(cams), std::span<const SfmPoint<double>>(points));
}

/// What a plan spends, comparably: hash-table entries per level, levels, finest cells (the default grid
/// is 2^16 entries, 16 levels, 2006 cells), Gaussians allowed per set (no cap: +inf), SH degree.
struct Spend {
  double entries, levels, finest, gaussians;
  int sh;
};
Spend spend(const CapacityPlan& p, const ClipShape& s) {
  const bool dflt = !p.frg_grid.resized();
  return {std::ldexp(1.0, dflt ? 16 : p.frg_grid.log2_table_size), dflt ? 16.0 : double(p.frg_grid.levels), dflt ? 2006.0 : p.frg_grid.finest,
          p.gaussians_per_pixel > 0 ? std::ceil(p.gaussians_per_pixel * s.width * s.height) : INFINITY, p.max_sh_degree};
}
bool no_more(const Spend& a, const Spend& b) {
  return a.entries <= b.entries && a.levels <= b.levels && a.finest <= b.finest && a.gaussians <= b.gaussians && a.sh <= b.sh;
}

}  // namespace

TEST_CASE("capacity: the measured anchors, the demo's clips and full-size DAVIS clips") {
  // scripts/demo.sh's clips: 160x120, 10 frames, a camera on an arc, ~186 SfM points.
  const ClipShape demo = synthetic_shape(160, 120, 10, 20);
  CHECK(demo.frames == 10);
  CHECK(demo.points == 186);
  CHECK(demo.view_spread > 10 * kDegree);
  const CapacityPlan p = plan_capacity(demo);
  CHECK(p.log2_table == 14);
  CHECK(p.frg_grid.log2_table_size == 14);
  CHECK(p.frg_grid.levels == 8);
  CHECK(p.frg_grid.finest == 128);
  CHECK(p.frg_grid.time_cells == GridSize::kTimeCellsPerFrame);
  CHECK(p.bkg_grid == p.frg_grid);
  // 165 Gaussians per SfM point and set: 30,690 for the demo's 186 points (1.6 per pixel).
  TrainOptions topt;
  topt.gaussians_per_pixel = p.gaussians_per_pixel;
  CHECK(topt.gaussian_budget(false, 160, 120) == 30690);  // the count exactly
  // A textured clip of the same size (7,134 points, blackswan's): the default grid, no budget.
  const CapacityPlan textured = plan_capacity(synthetic_shape(160, 120, 10, 20, 7134));
  CHECK(textured.log2_table == 16);
  CHECK(!textured.frg_grid.resized());
  CHECK(textured.gaussians_per_pixel == 0);
  // Between: 400 points ask for 25,600 entries, more than the pixels' 16,000: 2^15.
  CHECK(plan_capacity(synthetic_shape(160, 120, 10, 20, 400)).log2_table == 15);
  // No points: the budget of one point, never "no cap".
  topt.gaussians_per_pixel = plan_capacity({160, 120, 10, 0.2, 0}).gaussians_per_pixel;
  CHECK(topt.gaussian_budget(false, 160, 120) == 165);
  CHECK(p.max_sh_degree == 3);
  // A full-size DAVIS clip (854x480, 10 frames, ~2 degrees of spread): the default grid, no budget, SH 3.
  const CapacityPlan f = plan_capacity({854, 480, 10, 2 * kDegree});
  CHECK(f.log2_table == 16);
  CHECK(!f.frg_grid.resized());
  CHECK(!f.bkg_grid.resized());
  CHECK(f.gaussians_per_pixel == 0);
  CHECK(f.max_sh_degree == 3);
  // The smallest table, and the base resolution as the finest level.
  const CapacityPlan t = plan_capacity({16, 12, 2, 0.1});
  CHECK(t.log2_table == 12);
  CHECK(t.frg_grid.finest == 16);
  CHECK(t.frg_grid.levels == 1);
}

TEST_CASE("capacity: a smaller or simpler clip never gets a larger model (synthetic clips of many sizes)") {
  struct Case {
    ClipShape shape;
    CapacityPlan plan;
  };
  std::vector<Case> cases;
  for (int w : {16, 32, 64, 96, 128, 160, 240, 320, 427, 640, 854, 1280, 1920})
    for (int frames : {2, 5, 10, 20, 40})
      for (double arc : {0.0, 0.2, 20.0})
        for (std::size_t npoints : {0, 186, 7134}) {
          const ClipShape s = synthetic_shape(w, w * 9 / 16 + 1, frames, arc, npoints);
          cases.push_back({s, plan_capacity(s)});
        }
  std::size_t pairs = 0, larger = 0, larger_budget = 0;
  for (const auto& a : cases)
    for (const auto& b : cases) {
      const bool smaller = a.shape.width <= b.shape.width && a.shape.height <= b.shape.height && a.shape.frames <= b.shape.frames &&
                           a.shape.view_spread <= b.shape.view_spread && a.shape.points <= b.shape.points;
      if (!smaller) continue;
      ++pairs;
      const Spend sa = spend(a.plan, a.shape), sb = spend(b.plan, b.shape);
      CAPTURE(a.shape.width);
      CAPTURE(a.shape.frames);
      CAPTURE(b.shape.width);
      CAPTURE(b.shape.frames);
      CHECK(no_more(sa, sb));
      larger += sa.entries < sb.entries;
      larger_budget += sa.gaussians < sb.gaussians;
    }
  CHECK(pairs > 10000);
  CHECK(larger > 1000);  // the sizes do differ
  CHECK(larger_budget > 1000);
  // Every table size in between occurs: the rule is not two points.
  std::vector<int> tables;
  for (const auto& c : cases) tables.push_back(c.plan.log2_table);
  for (int T = 12; T <= 16; ++T) CHECK(std::count(tables.begin(), tables.end(), T) > 0);
  // The levels grow by about level_growth from 16 cells to the finest.
  for (const auto& c : cases)
    if (c.plan.frg_grid.resized() && c.plan.frg_grid.levels > 1) {
      const double growth = std::pow(c.plan.frg_grid.finest / 16, 1.0 / (c.plan.frg_grid.levels - 1));
      CHECK(growth == doctest::Approx(1.35).epsilon(0.12));
    }
}

TEST_CASE("capacity: view spread of known camera paths; a still or turning camera gets SH degree 0") {
  const Eigen::Vector3d centre(0, 0, 0);
  auto camera_at = [](const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
    auto c = Camera<double>::from_fov(64, 48, 1.0);
    c.look_at(eye, target);
    return c;
  };
  // Two cameras 30 degrees apart around the centre, at different distances.
  std::vector<Camera<double>> cams = {camera_at({0, 0, -4}, centre), camera_at({2 * std::sin(30 * kDegree), 0, -2 * std::cos(30 * kDegree)}, centre)};
  CHECK(view_spread(std::span<const Camera<double>>(cams), centre) == doctest::Approx(30 * kDegree).epsilon(1e-9));
  // A camera that stays in place and turns: no spread, and the plan drops the SH bands.
  std::vector<Camera<double>> turning = {camera_at({0, 0, -4}, centre), camera_at({0, 0, -4}, {1, 0, 0}), camera_at({0, 0, -4}, {0, 1, 0})};
  const double spread = view_spread(std::span<const Camera<double>>(turning), centre);
  CHECK(spread == doctest::Approx(0).epsilon(1e-12));
  CHECK(plan_capacity({160, 120, 3, spread}).max_sh_degree == 0);
  // One camera, or none: 0.
  CHECK(view_spread(std::span<const Camera<double>>(cams.data(), 1), centre) == 0);
  // Just above the threshold: SH on.
  CHECK(plan_capacity({160, 120, 3, 0.6 * kDegree}).max_sh_degree == 3);
  // The scene centre is the per-axis median of the points.
  std::vector<SfmPoint<double>> pts(5);
  const double xs[] = {0, 1, 2, 3, 100};
  for (int i = 0; i < 5; ++i) pts[std::size_t(i)].xyz = Eigen::Vector3d(xs[i], -xs[i], 2 * xs[i]);
  const Eigen::Vector3d c = scene_centre(std::span<const SfmPoint<double>>(pts));
  CHECK(c.x() == 2);
  CHECK(c.y() == -2);
  CHECK(c.z() == 4);
}

TEST_CASE("capacity: bad rules and empty clips are refused with option.capacity") {
  auto id_of = [](auto f) { return test::error_id(f); };
  CapacityRules r;
  r.pixels_per_entry = 0;
  CHECK(id_of([&] { (void)plan_capacity({16, 16, 2, 0}, r); }) == "option.capacity");
  r = {};
  r.min_log2_table = 17;
  CHECK(id_of([&] { (void)plan_capacity({16, 16, 2, 0}, r); }) == "option.capacity");
  r = {};
  r.level_growth = 1;
  CHECK(id_of([&] { (void)plan_capacity({16, 16, 2, 0}, r); }) == "option.capacity");
  r = {};
  r.entries_per_point = -1;
  CHECK(id_of([&] { (void)plan_capacity({16, 16, 2, 0}, r); }) == "option.capacity");
  r = {};
  r.gaussians_per_point = 0;
  CHECK(id_of([&] { (void)plan_capacity({16, 16, 2, 0}, r); }) == "option.capacity");
  r = {};
  r.min_view_spread = std::nan("");
  CHECK(id_of([&] { (void)plan_capacity({16, 16, 2, 0}, r); }) == "option.capacity");
  CHECK(id_of([&] { (void)plan_capacity({0, 16, 2, 0}); }) == "option.capacity");
  CHECK(id_of([&] { (void)plan_capacity({16, 16, 0, 0}); }) == "option.capacity");
}

TEST_CASE("TrainOptions::max_sh_degree caps the active degree; the bands above it stay zero in training") {
  TrainOptions o;
  o.sh_degree_interval = 10;
  CHECK(o.active_sh_degree(35, 3) == 3);
  CHECK(o.active_sh_degree(25, 3) == 2);
  CHECK(o.active_sh_degree(-1, 3) == 0);
  CHECK(o.active_sh_degree(35, 1) == 1);
  o.max_sh_degree = 1;
  CHECK(o.active_sh_degree(35, 3) == 1);
  o.max_sh_degree = 4;
  CHECK(test::error_id([&] { o.validate(); }) == "option.train");
  o.max_sh_degree = -1;
  CHECK(test::error_id([&] { o.validate(); }) == "option.train");

  // A tiny clip trained 30 iterations with a new degree every 5: with the cap at 1 the bands 2 and 3
  // (coefficients 4..15) stay at their initial zeros, band 1 moved; without the cap they all move.
  for (int cap : {1, 3}) {
    CAPTURE(cap);
    auto clip = test::make_tiny_clip(true, false, 3);
    TrainOptions t = TrainOptions::preset(3000).with_iterations(30);
    t.sh_degree_interval = 5;
    t.deformation_warmup = 0;
    t.densify_from = t.densify_until = t.opacity_reset_interval = 1000;  // no densification: the sets keep their rows
    t.max_sh_degree = cap;
    ClipTrainer<test::TinyModel> trainer(std::move(clip.model), std::move(clip.frames), t);
    trainer.train();
    const auto& m = trainer.model();
    double band1 = 0, above = 0;
    for (const auto* c : {&m.frg, &m.bkg})
      for (std::size_t i = 0; i < c->size(); ++i)
        for (std::size_t k = 1; k < 16; ++k)
          for (std::size_t ch = 0; ch < 3; ++ch) (k < 4 ? band1 : above) += std::abs(c->sh[48 * i + 3 * k + ch]);
    CHECK(band1 > 0);
    if (cap == 1) CHECK(above == 0);
    else CHECK(above > 0);
  }
}
