// pipeline/trade.hpp: the Pareto frontier (hand-made sets), the grid (product of the axes, presets
// labelling an equal point, keys), one sweep on the synthetic clip (figures plausible and consistent,
// results resumed from their files whatever their names, a changed key trained again), the CSV/JSON
// outputs and the plots.
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>
#include <vector>

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include "../test_data.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/pipeline/trade.hpp"
#include "video3dgs/synthetic/clip.hpp"

using namespace video3dgs;
using namespace video3dgs::pipeline;

TEST_CASE("pareto_frontier: a point is kept unless another is as cheap and as good, one strictly") {
  const std::vector<double> cost{1, 2, 3, 2, 5, 5};
  const std::vector<double> q{10, 12, 11, 12, 15, 14};
  const auto on = pareto_frontier(cost, q);
  CHECK(on == std::vector<bool>{true, true, false, true, true, false});  // 3 is beaten by 2; (5, 14) by (5, 15); equal points both stay
  CHECK(pareto_frontier(std::vector<double>{}, std::vector<double>{}).empty());
  const auto by = dominating_points(cost, q);
  CHECK(by[2] == std::vector<std::size_t>{1, 3});  // (3, 11) is beaten by both (2, 12)
  CHECK(by[5] == std::vector<std::size_t>{4});
  CHECK(by[0].empty());
  CHECK_THROWS_AS((void)pareto_frontier(std::vector<double>{1}, std::vector<double>{}), option_error);
}

TEST_CASE("trade_grid: the product of the axes, a preset equal to a grid point labels it, keys tell settings apart") {
  TradeAxes a;
  a.iterations = {100, 200};
  a.log2_tables = {10, 12};
  a.budgets = {0, 0.5};
  a.presets = {"balanced", "3k"};
  const auto g = trade_grid(a);
  REQUIRE(g.size() == 2 * 2 * 2 + 2);
  std::vector<std::string> keys;
  for (const auto& c : g) keys.push_back(c.key());
  std::sort(keys.begin(), keys.end());
  CHECK(std::unique(keys.begin(), keys.end()) == keys.end());
  CHECK(g.back().label == "3k");
  CHECK(g.back().short_name() == "3k");
  CHECK(g.front().short_name() == "100 it, 2^10 entries");
  // The preset's own point appears once, labelled, when the grid holds it already, also when an axis
  // names its values (3000 iterations, 2^16 entries, 16 levels are the defaults).
  TradeAxes b;
  b.iterations = {3000};
  b.log2_tables = {16};
  b.grid_levels = {16};
  b.presets = {"balanced"};
  const auto h = trade_grid(b);
  REQUIRE(h.size() == 1);
  CHECK(h[0].label == "balanced");
  b.presets = {"no-such-preset"};
  CHECK_THROWS_WITH_AS((void)trade_grid(b), doctest::Contains("[option.train]"), option_error);
  // The training options: the preset scaled to the iterations, the budget and the seed.
  TradeConfig c;
  c.iterations = 300;
  c.budget = 0.25;
  const auto t = c.train_options(9);
  CHECK(t.iterations == 300);
  CHECK(t.gaussians_per_pixel == 0.25);
  CHECK(t.seed == 9);
  CHECK(t.densify_until < TrainOptions::preset("balanced").densify_until);
}

TEST_CASE("trade: results stored before the time cap read as uncapped, under their own keys; the default has another key") {
  TradeConfig c;
  c.preset = "fast", c.label = "fast";
  const std::string today = c.key();
  CHECK(today.find("grid=0:0:0:tframes|") != std::string::npos);
  // A run file of session 21 (no time_cells field, a key without the cap).
  TradeResult r;
  r.config = c;
  r.config.grid.time_cells = 0;
  auto j = nlohmann::json::parse(r.to_json().dump());
  CHECK(j.at("time_cells") == 0);
  const std::string before = j.at("key");
  CHECK(before.find("grid=0:0:0|") != std::string::npos);
  CHECK(before != today);
  j.erase("time_cells");
  const auto back = TradeResult::from_json(j, "old.json");
  CHECK(back.config.grid.time_cells == 0);
  CHECK(back.config.key() == before);
  CHECK(back.config.short_name() == "fast");
  r.config.label.clear();
  CHECK(r.config.short_name() == "time uncapped");
  // A file whose key disagrees with its settings is refused.
  j["key"] = today;
  CHECK(test::error_id([&] { (void)TradeResult::from_json(j, "old.json"); }) == "io.format");
}

TEST_CASE("plot labels: configurations that trained the same model are one point with one label") {
  std::vector<TradeResult> r(4);
  r[0].config.iterations = 2000, r[0].psnr = 31.37, r[0].compact_bytes = 9440613;
  r[1].config.label = "fast", r[1].config.preset = "fast", r[1].psnr = 31.37, r[1].compact_bytes = 9440613;
  r[2].psnr = 32.94, r[2].compact_bytes = 10107173;  // the preset itself
  r[3].config.iterations = 1000, r[3].psnr = 31.37, r[3].compact_bytes = 8036391;  // same PSNR, another model
  const auto none = [](const TradeResult&) { return false; };
  const auto labels = pipeline::detail::plot_labels(r, none);
  CHECK(labels == std::vector<std::string>{"2000 it = fast", "", "balanced", "1000 it"});
  // Beyond kNameAllPoints only labelled or frontier points are named, and a shared point keeps the
  // names that qualify.
  std::vector<TradeResult> many(kNameAllPoints + 1, r[2]);
  for (std::size_t i = 0; i < many.size(); ++i) many[i].psnr = 20.0 + double(i), many[i].config.iterations = int(100 * (i + 1));
  many.back() = r[0];
  many.push_back(r[1]);
  const auto l2 = pipeline::detail::plot_labels(many, none);
  CHECK(l2.front().empty());
  CHECK(l2[kNameAllPoints] == "fast");
  CHECK(l2.back().empty());
}

namespace {
/// The synthetic clip the sweeps below train on: 3 frames of 48x36.
TradeClip small_clip() {
  synthetic::SyntheticClipOptions so;
  so.frames = 3, so.width = 48, so.height = 36;
  so.object_gaussians = 200, so.background_gaussians = 400, so.foreground_points = 80;
  auto clip = synthetic::make_synthetic_clip<float>(so);
  return TradeClip{clip.sfm_result(), clip.frames, clip.masks};
}
}  // namespace

TEST_CASE("run_trade: a sweep on the synthetic clip, resumed from its files; CSV, JSON and plots") {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("video3dgs_trade_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const TradeClip tc = small_clip();
  TradeAxes a;
  a.iterations = {30, 90};
  a.log2_tables = {8};
  a.grid_levels = {4, 16};
  const auto configs = trade_grid(a);
  REQUIRE(configs.size() == 4);
  TradeOptions o;
  o.out = dir;
  o.shell_points = 200;
  std::vector<TradeProgress> seen;
  auto r = run_trade(configs, tc, o, [&](const TradeProgress& p) { seen.push_back(p); });
  REQUIRE(r.size() == 4);
  CHECK(seen.size() == 30 + 30 + 90 + 90);
  CHECK(seen.back().config == 3);
  CHECK(seen.back().iteration == 90);
  int frontier_time = 0, frontier_bytes = 0;
  for (const auto& x : r) {
    INFO(x.config.key());
    CHECK_FALSE(x.reused);
    CHECK(x.psnr > 10);
    CHECK(x.ssim > 0);
    CHECK(x.ssim <= 1);
    CHECK(x.cpu_seconds > 0);
    CHECK(x.wall_seconds > 0);
    CHECK(x.frg + x.bkg > 0);
    CHECK(x.compact_bytes > 0);
    CHECK(x.compact_bytes < x.model_bytes);
    CHECK(std::abs(x.compact_psnr - x.psnr) < 1.0);  // the compact file renders close to the model
    frontier_time += x.frontier_time, frontier_bytes += x.frontier_bytes;
    CHECK(x.frontier_time == x.beaten_on_time_by.empty());  // off the frontier: named who beats it
    CHECK(x.frontier_bytes == x.beaten_on_bytes_by.empty());
  }
  CHECK(frontier_time >= 1);
  CHECK(frontier_bytes >= 1);
  CHECK(r[2].psnr > r[0].psnr);  // 90 iterations beat 30 at the same grid
  CHECK(r[0].model_bytes < r[1].model_bytes);  // 4 levels store fewer entries than 16

  // A second run reuses every file; a changed setting is trained again.
  auto again = run_trade(configs, tc, o);
  for (std::size_t k = 0; k < 4; ++k) {
    CHECK(again[k].reused);
    CHECK(again[k].psnr == r[k].psnr);
    CHECK(again[k].cpu_seconds == r[k].cpu_seconds);
  }
  auto changed = configs;
  changed[0].budget = 0.5;
  changed[0].label = "budgeted";
  const auto c2 = run_trade(changed, tc, o);
  CHECK_FALSE(c2[0].reused);
  CHECK(c2[1].reused);
  // The stored results of both sweeps together: the first sweep's four, then the budget one; an
  // unreadable file is skipped.
  io::write_file_atomic(dir / "runs" / "0000000000000000.json", "{not json");
  const auto all = with_stored_results(again, dir);
  REQUIRE(all.size() == 5);
  CHECK(all[4].config.budget == 0.5);
  CHECK(all[4].config.key() == changed[0].key());
  CHECK(all[4].psnr == c2[0].psnr);
  // Results are found by the key inside the file, not by its name (files named by an older rule are
  // still reused), and a key held by two files is one result.
  const std::string run = trade_run_key(tc, o);
  CHECK(run == "seed=0|shell=200|frames=0-2|48x36|pts=" + std::to_string(tc.sfm.points.size()));
  const fs::path budget_file = dir / "runs" / pipeline::detail::trade_file_name(changed[0].key(), run);
  fs::rename(budget_file, dir / "runs" / "older-name.json");
  fs::copy_file(dir / "runs" / pipeline::detail::trade_file_name(configs[1].key(), run), dir / "runs" / "a-copy.json");
  std::vector<TradeProgress> trained;
  const auto c3 = run_trade(changed, tc, o, [&](const TradeProgress& p) { trained.push_back(p); });
  CHECK(trained.empty());
  CHECK(c3[0].reused);
  CHECK(c3[0].psnr == c2[0].psnr);
  CHECK(with_stored_results(again, dir).size() == 5);
  // A stored result keeps the name it was trained under when a later sweep reaches it unnamed (a grid
  // point equal to an earlier preset run), and takes the later sweep's name when that sweep gives one.
  CHECK(all[4].config.label == "budgeted");
  auto unnamed = changed;
  unnamed[0].label.clear();
  CHECK(run_trade(unnamed, tc, o)[0].config.label == "budgeted");
  auto renamed = changed;
  renamed[0].label = "cheap";
  CHECK(run_trade(renamed, tc, o)[0].config.label == "cheap");
  // Another seed (or shells, or clip) is another run: its results are trained, not taken from the
  // first run's files, and kept beside them; each run's stored results are its own.
  TradeOptions o1 = o;
  o1.seed = 1;
  const auto s1 = run_trade({configs[0]}, tc, o1);
  CHECK_FALSE(s1[0].reused);
  CHECK(s1[0].run == trade_run_key(tc, o1));
  CHECK(s1[0].psnr != r[0].psnr);
  CHECK(run_trade({configs[0]}, tc, o)[0].psnr == r[0].psnr);  // seed 0's file is still there
  CHECK(run_trade({configs[0]}, tc, o1)[0].reused);
  CHECK(with_stored_results(again, dir, run).size() == 5);
  CHECK(with_stored_results({}, dir, trade_run_key(tc, o1)).size() == 1);
  CHECK(with_stored_results({}, dir).size() == 6);  // no run key: every stored result
  // Files from before run keys (no "run") count as the default seed and shells'.
  TradeResult legacy;
  CHECK(same_run(legacy, "seed=0|shell=30000|frames=0-9|854x480|pts=7134"));
  CHECK_FALSE(same_run(legacy, "seed=1|shell=30000|frames=0-9|854x480|pts=7134"));
  CHECK_FALSE(same_run(legacy, run));
  // A result trained under other settings than its configuration gives today (its preset changed
  // since) is stale: left out of the stored results, trained again, its file replaced; so is one from
  // a version that did not record its settings.
  const fs::path first_file = dir / "runs" / pipeline::detail::trade_file_name(configs[0].key(), run);
  auto stale = nlohmann::json::parse(std::ifstream(first_file));
  CHECK(stale.at("training") == configs[0].training_key());
  stale["training"] = TradeConfig{}.training_key();  // balanced's 3000 iterations, not 30
  io::write_file_atomic(first_file, stale.dump());
  CHECK(with_stored_results({}, dir, run).size() == 4);
  std::vector<TradeProgress> retrained;
  const auto fresh = run_trade({configs[0]}, tc, o, [&](const TradeProgress& p) { retrained.push_back(p); });
  CHECK_FALSE(fresh[0].reused);
  CHECK(retrained.size() == 30);
  CHECK(fresh[0].psnr == r[0].psnr);  // the same training, from the same start
  CHECK(with_stored_results({}, dir, run).size() == 5);
  CHECK(run_trade({configs[0]}, tc, o)[0].reused);
  stale = nlohmann::json::parse(std::ifstream(first_file));
  stale.erase("training");
  io::write_file_atomic(first_file, stale.dump());
  CHECK_FALSE(run_trade({configs[0]}, tc, o)[0].reused);

  // Outputs: a CSV row per configuration with the header's columns, the JSON, the plots (with gnuplot).
  const bool plotted = write_trade_outputs(dir, r);
  std::ifstream csv(dir / "trade.csv");
  std::string line;
  std::getline(csv, line);
  const auto columns = std::count(line.begin(), line.end(), ',');
  CHECK(line.rfind("label,preset,iterations", 0) == 0);
  int rows = 0;
  while (std::getline(csv, line)) {
    ++rows;
    CHECK(std::count(line.begin(), line.end(), ',') == columns);
  }
  CHECK(rows == 4);
  const auto j = nlohmann::json::parse(std::ifstream(dir / "trade.json"));
  REQUIRE(j.at("configurations").size() == 4);
  CHECK(j["configurations"][2]["psnr"].get<double>() == r[2].psnr);
  CHECK(j["configurations"][0].contains("frontier_time"));
  if (io::find_executable("gnuplot").empty()) {
    CHECK_FALSE(plotted);
    test::skip("program 'gnuplot' is not installed: plots not drawn");
  } else {
    CHECK(plotted);
    for (const char* png : {"trade_time.png", "trade_bytes.png"}) {
      const auto im = io::read_image<3>(dir / png);
      CHECK(im.width() == 900);
      CHECK(im.height() == 560);
      CHECK(fs::is_regular_file(dir / (std::string(png) + ".dat")));
      CHECK_FALSE(fs::exists(dir / (std::string(png) + ".log")));  // gnuplot succeeded
    }
  }
  CHECK_FALSE(write_trade_outputs(dir, r, dir / "no-gnuplot-here"));
  fs::remove_all(dir);
}

TEST_CASE("run_trade: the model's start (static background, alpha from the masks, background colours) reaches the model and the run key") {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("video3dgs_trade_start_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const TradeClip tc = small_clip();
  TradeAxes a;
  a.iterations = {30};
  a.grid_levels = {4};
  const auto configs = trade_grid(a);
  REQUIRE(configs.size() == 1);
  TradeOptions o;
  o.out = dir;
  o.shell_points = 200;
  const std::string reference = trade_run_key(tc, o);
  CHECK(reference == "seed=0|shell=200|frames=0-2|48x36|pts=" + std::to_string(tc.sfm.points.size()));  // earlier sweeps' keys
  const ClipModelOptions m0 = o.model_options(configs[0]);
  CHECK(m0.departures_key().empty());
  CHECK(m0.frg_grid.levels == 4);
  CHECK(m0.bkg_grid.levels == 4);
  CHECK(m0.background.points_per_shell == 200);

  TradeOptions s = o;
  s.static_background = true;
  s.alpha_mask = 0.9;
  s.background_colour = BackgroundColour::frames;
  const ClipModelOptions m1 = s.model_options(configs[0]);
  CHECK(m1.static_background);
  CHECK(m1.alpha_mask == 0.9);
  CHECK(m1.alpha_outside == 0.1);
  CHECK(m1.background_colour == BackgroundColour::frames);
  CHECK(trade_run_key(tc, s) == reference + "|static_background|alpha_mask=0.90000000000000002,0.10000000000000001|bkg_colour=frames");

  // Each start trains under its own run key: the reference's result is not reused for the other start,
  // and the other start's result differs.
  const auto r0 = run_trade(configs, tc, o);
  const auto r1 = run_trade(configs, tc, s);
  REQUIRE(r0.size() == 1);
  REQUIRE(r1.size() == 1);
  CHECK_FALSE(r1[0].reused);
  CHECK(r1[0].run == trade_run_key(tc, s));
  CHECK(r1[0].psnr > 10);
  CHECK(r1[0].psnr != r0[0].psnr);
  CHECK(run_trade(configs, tc, s)[0].reused);
  fs::remove_all(dir);
}
