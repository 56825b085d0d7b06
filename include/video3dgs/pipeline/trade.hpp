#pragma once
/// @file
/// The speed/accuracy/size trade of stage 1 on one clip (`video3dgs trade`): a grid of training
/// configurations, each trained from the same cameras and frames, measured (PSNR and SSIM of the merged
/// render over the clip's frames, wall and CPU seconds of training, Gaussians, bytes of the full record
/// and of the compact file, the compact file's PSNR), and the Pareto frontiers of PSNR against CPU
/// seconds and against compact bytes.
///
///     auto configs = pipeline::trade_grid(axes);                       // the product of the axes, + presets
///     auto results = pipeline::run_trade(configs, clip, {.out = "trade/"}, hooks, &pool);
///     pipeline::write_trade_outputs("trade/", results, "gnuplot");     // trade.csv, trade.json, two plots
///
/// Resumable: configuration c's result is written to OUT/runs/<hash of its key>.json (atomic) and reused
/// by any later sweep whose configuration has the same key (looked up by the key stored in the files,
/// whatever their names), so an interrupted sweep loses at most the configuration it was training.
///
/// Frontier (maths): with cost c (CPU seconds, or bytes) and quality q (PSNR), configuration i is on the
/// frontier iff no j has c_j <= c_i and q_j >= q_i with one of them strict. A preset is "on the
/// frontier" in that sense: no measured configuration is both cheaper and better.

#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <optional>
#include <set>
#include <span>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/hash.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/metrics/psnr.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/model/clip_model_io.hpp"
#include "video3dgs/model/compact_io.hpp"
#include "video3dgs/model/render_clip.hpp"
#include "video3dgs/pipeline/outputs.hpp"
#include "video3dgs/scheduling/sfm_result.hpp"
#include "video3dgs/training/clip_trainer.hpp"
#include "video3dgs/training/train_options.hpp"

namespace video3dgs::pipeline {

/// One training configuration of a sweep.
struct TradeConfig {
  std::string preset = "balanced";  ///< TrainOptions::preset name
  int iterations = 0;               ///< 0: the preset's; else TrainOptions::with_iterations
  /// In the preset's iterations (scaled with `iterations`); nullopt: the preset's schedule. {0:1}: none.
  std::optional<std::vector<TrainOptions::ResolutionStep>> resolution;
  double budget = 0;                ///< TrainOptions::gaussians_per_pixel (0: none)
  GridSize grid{};                  ///< both deformation fields
  int alpha_downscale = 1;          ///< CompactOptions::alpha_downscale of the compact file
  std::string label;                ///< a name shown in the plots (the presets' names); may be empty

  /// Every setting as text: equal keys train the same model (the resume key; the label is not part).
  [[nodiscard]] std::string key() const {
    std::ostringstream t;
    char num[32];
    auto exact = [&](double v) {
      std::snprintf(num, sizeof(num), "%.17g", v);
      return std::string(num);
    };
    t << "trade1|preset=" << preset << "|it=" << iterations << "|res=";
    if (resolution)
      for (const auto& r : *resolution) t << r.from_iteration << ":" << exact(r.scale) << ";";
    else
      t << "preset";
    t << "|budget=" << exact(budget) << "|grid=" << grid.log2_table_size << ":" << grid.levels << ":" << exact(grid.finest);
    // Sweeps before the time cap (none) keep their keys.
    if (grid.time_cells != 0) t << ":t" << grid.time_cells_text();
    t << "|alpha_d=" << alpha_downscale;
    return t.str();
  }
  /// A short name for plots: the label, else the settings that differ from the preset's
  /// ("1000 it, 2^14 entries, 8 levels"; the preset's name when none does).
  [[nodiscard]] std::string short_name() const {
    if (!label.empty()) return label;
    std::string n;
    auto add = [&](const std::string& part) { n += (n.empty() ? "" : ", ") + part; };
    char num[32];
    if (iterations > 0) add(std::to_string(iterations) + " it");
    if (resolution) {
      std::string r = "res";
      for (const auto& s : *resolution) {
        std::snprintf(num, sizeof(num), " %d:%g", s.from_iteration, s.scale);
        r += num;
      }
      add(r);
    }
    if (budget > 0) {
      std::snprintf(num, sizeof(num), "budget %g", budget);
      add(num);
    }
    if (grid.log2_table_size > 0) add("2^" + std::to_string(grid.log2_table_size) + " entries");
    if (grid.levels > 0) add(std::to_string(grid.levels) + " levels");
    if (grid.time_cells > 0) add(std::to_string(grid.time_cells) + " time cells");
    if (grid.time_cells == 0) add("time uncapped");
    if (alpha_downscale > 1) add("alpha/" + std::to_string(alpha_downscale));
    return n.empty() ? preset : n;
  }
  /// stable_key of TrainOptions::settings_text of this configuration under today's presets (the seed
  /// is the run key's): a stored result whose key differs was trained under other presets.
  /// @throws option_error
  [[nodiscard]] std::string training_key() const { return stable_key(train_options(0).settings_text()); }
  /// The training options (seed included). @throws option_error
  [[nodiscard]] TrainOptions train_options(std::uint64_t seed) const {
    TrainOptions t = TrainOptions::preset(preset);
    if (resolution) t = t.with_resolution_schedule(*resolution);
    if (iterations > 0) t = t.with_iterations(iterations);
    t.gaussians_per_pixel = budget;
    t.seed = seed;
    t.validate();
    return t;
  }
};

/// The axes of a sweep: every combination of one value per axis (an empty axis: the preset's value),
/// then one configuration per entry of `presets` (that preset as is, labelled with its name).
struct TradeAxes {
  std::string preset = "balanced";
  std::vector<int> iterations;
  std::vector<std::vector<TrainOptions::ResolutionStep>> resolutions;
  std::vector<double> budgets;
  std::vector<int> log2_tables;
  std::vector<int> grid_levels;
  std::vector<int> alpha_downscales;
  std::vector<std::string> presets;
};

/// The configurations of `axes`, without repeats (a preset equal to a grid point labels that point).
/// Values equal to the defaults are written as the default (the preset's iterations, the default
/// table size, all levels: 0), so an axis that names them does not train the same model twice.
[[nodiscard]] inline std::vector<TradeConfig> trade_grid(const TradeAxes& axes) {
  std::vector<TradeConfig> out;
  auto add = [&](TradeConfig c) {
    if (c.iterations == TrainOptions::preset(c.preset).iterations) c.iterations = 0;
    if (c.grid.log2_table_size == kDefaultDeformationLog2Table) c.grid.log2_table_size = 0;
    if (c.grid.levels == DefaultDeformationField<float>::grid_type::kLevels) c.grid.levels = 0;
    for (auto& o : out)
      if (o.key() == c.key()) {
        if (!c.label.empty()) o.label = o.label.empty() ? c.label : o.label + "=" + c.label;
        return;
      }
    out.push_back(c);
  };
  auto or_default = []<class T>(const std::vector<T>& v, T d) { return v.empty() ? std::vector<T>{d} : v; };
  using Res = std::optional<std::vector<TrainOptions::ResolutionStep>>;
  std::vector<Res> res;
  for (const auto& r : axes.resolutions) res.push_back(r);
  if (res.empty()) res.push_back(std::nullopt);
  for (int it : or_default(axes.iterations, 0))
    for (const Res& r : res)
      for (double b : or_default(axes.budgets, 0.0))
        for (int t : or_default(axes.log2_tables, 0))
          for (int l : or_default(axes.grid_levels, 0))
            for (int d : or_default(axes.alpha_downscales, 1)) {
              TradeConfig c;
              c.preset = axes.preset, c.iterations = it, c.resolution = r, c.budget = b, c.grid = {t, l, 0.0}, c.alpha_downscale = d;
              add(c);
            }
  for (const auto& p : axes.presets) {
    TradeConfig c;
    c.preset = p, c.label = p;
    (void)TrainOptions::preset(p);  // throws option.train for an unknown name
    add(c);
  }
  return out;
}

/// What one configuration measured.
struct TradeResult {
  TradeConfig config;
  double psnr = 0, ssim = 0;          ///< merged render against the frames, means over the clip
  double wall_seconds = 0;            ///< training (model built to last step)
  double cpu_seconds = 0;             ///< user + system CPU time of the process over the same span
  std::size_t frg = 0, bkg = 0;       ///< Gaussians at the end
  std::size_t model_bytes = 0;        ///< the full record (clip_model_io.hpp)
  std::size_t compact_bytes = 0;      ///< the compact file (compact_io.hpp, default options but alpha_downscale)
  double compact_psnr = 0;            ///< the reloaded compact model's merged render against the frames
  bool frontier_time = false;         ///< on the PSNR / CPU-seconds frontier
  bool frontier_bytes = false;        ///< on the compact-PSNR / compact-bytes frontier
  /// The configurations (TradeConfig::short_name) that are at most as costly and at least as good,
  /// one strictly: empty exactly when on that frontier.
  std::vector<std::string> beaten_on_time_by, beaten_on_bytes_by;
  bool reused = false;                ///< read from an earlier run's file
  /// The sweep's settings besides the configuration that the result depends on (`trade_run_key`:
  /// seed, background shells, the clip's frames, size and SfM points); empty in files written before
  /// it was recorded (see `same_run`).
  std::string run;
  /// The configuration's training settings when it was trained (TradeConfig::training_key); empty in
  /// files written before it was recorded, which are therefore never reused (`current`).
  std::string training;

  /// Whether the stored result was trained with the settings its configuration names today (a preset
  /// changed since, or a file that did not record them: false).
  [[nodiscard]] bool current() const { return !training.empty() && training == config.training_key(); }

  /// The result a run file (to_json without the frontier fields) holds; its key must be the settings'.
  /// @throws nlohmann::json::exception on a missing or mistyped field, io_error `io.format` when the
  /// stored key disagrees with the settings stored beside it
  [[nodiscard]] static TradeResult from_json(const nlohmann::json& j, const std::string& file) {
    TradeResult r;
    TradeConfig& c = r.config;
    c.preset = j.at("preset"), c.iterations = j.at("iterations"), c.budget = j.at("budget");
    c.label = j.at("label");
    if (!j.at("resolution_schedule").is_null()) {
      c.resolution.emplace();
      for (const auto& s : j["resolution_schedule"]) c.resolution->push_back({s.at(0).get<int>(), s.at(1).get<double>()});
    }
    // Files written before the time cap trained without one.
    c.grid = {j.at("log2_table").get<int>(), j.at("grid_levels").get<int>(), 0.0, j.value("time_cells", 0)};
    c.alpha_downscale = j.at("alpha_downscale");
    if (j.at("key").get<std::string>() != c.key()) throw io_error("io.format", file, "the stored key disagrees with the stored settings");
    r.psnr = j.at("psnr"), r.ssim = j.at("ssim"), r.wall_seconds = j.at("wall_seconds"), r.cpu_seconds = j.at("cpu_seconds");
    r.frg = j.at("frg"), r.bkg = j.at("bkg"), r.model_bytes = j.at("model_bytes"), r.compact_bytes = j.at("compact_bytes");
    r.compact_psnr = j.at("compact_psnr");
    r.run = j.value("run", std::string());
    r.training = j.value("training", std::string());
    r.reused = true;
    return r;
  }

  [[nodiscard]] nlohmann::ordered_json to_json() const {
    nlohmann::ordered_json res = nullptr;
    if (config.resolution) {
      res = nlohmann::ordered_json::array();
      for (const auto& r : *config.resolution) res.push_back({r.from_iteration, r.scale});
    }
    return {{"key", config.key()}, {"label", config.label}, {"preset", config.preset}, {"iterations", config.iterations},
            {"resolution_schedule", res}, {"budget", config.budget}, {"log2_table", config.grid.log2_table_size},
            {"grid_levels", config.grid.levels}, {"time_cells", config.grid.time_cells}, {"alpha_downscale", config.alpha_downscale}, {"psnr", psnr}, {"ssim", ssim},
            {"wall_seconds", wall_seconds}, {"cpu_seconds", cpu_seconds}, {"frg", frg}, {"bkg", bkg}, {"model_bytes", model_bytes},
            {"compact_bytes", compact_bytes}, {"compact_psnr", compact_psnr}, {"run", run}, {"training", training}, {"frontier_time", frontier_time},
            {"frontier_bytes", frontier_bytes}, {"beaten_on_time_by", beaten_on_time_by}, {"beaten_on_bytes_by", beaten_on_bytes_by}};
  }
};

/// For each point of (cost, quality), the points that dominate it: at most as costly and at least as
/// good, one of the two strictly (see the file comment).
[[nodiscard]] inline std::vector<std::vector<std::size_t>> dominating_points(std::span<const double> cost, std::span<const double> quality) {
  if (cost.size() != quality.size()) throw option_error("option.size", "pareto_frontier", "cost and quality differ in length");
  std::vector<std::vector<std::size_t>> by(cost.size());
  for (std::size_t i = 0; i < cost.size(); ++i)
    for (std::size_t j = 0; j < cost.size(); ++j)
      if (cost[j] <= cost[i] && quality[j] >= quality[i] && (cost[j] < cost[i] || quality[j] > quality[i])) by[i].push_back(j);
  return by;
}

/// Pareto frontier of (cost, quality): true where no point dominates (dominating_points). Equal points
/// are all on it.
[[nodiscard]] inline std::vector<bool> pareto_frontier(std::span<const double> cost, std::span<const double> quality) {
  const auto by = dominating_points(cost, quality);
  std::vector<bool> on(by.size());
  for (std::size_t i = 0; i < by.size(); ++i) on[i] = by[i].empty();
  return on;
}

/// Marks frontier_time / frontier_bytes and the beaten_on_*_by lists on `results`.
inline void mark_frontiers(std::vector<TradeResult>& results) {
  std::vector<double> cpu, bytes, q, qc;
  for (const auto& r : results) {
    cpu.push_back(r.cpu_seconds), bytes.push_back(double(r.compact_bytes)), q.push_back(r.psnr), qc.push_back(r.compact_psnr);
  }
  const auto bt = dominating_points(cpu, q), bb = dominating_points(bytes, qc);
  for (std::size_t i = 0; i < results.size(); ++i) {
    auto& r = results[i];
    r.beaten_on_time_by.clear(), r.beaten_on_bytes_by.clear();
    for (std::size_t j : bt[i]) r.beaten_on_time_by.push_back(results[j].config.short_name());
    for (std::size_t j : bb[i]) r.beaten_on_bytes_by.push_back(results[j].config.short_name());
    r.frontier_time = bt[i].empty(), r.frontier_bytes = bb[i].empty();
  }
}

/// The clip a sweep trains on: SfM result (cameras at the frames' size), frames, masks (may be empty).
struct TradeClip {
  SfmResult<double> sfm;
  std::vector<Image<float, 3>> frames;
  std::vector<Image<float, 1>> masks;
};

struct TradeOptions {
  std::filesystem::path out;                  ///< OUT/runs/ holds one file per configuration
  std::uint64_t seed = 0;
  std::size_t shell_points = 30000;           ///< ClipModelOptions::background.points_per_shell
  bool resume = true;                         ///< reuse OUT/runs/ files whose key and run key (trade_run_key) match
  /// How every configuration's model starts, as `reconstruct --static-background / --alpha-mask /
  /// --bkg-colour / --keep-unseen` set it: ClipModelOptions' fields of the same names (the defaults: the reference's).
  bool static_background = false;
  double alpha_mask = 0;
  double alpha_outside = 0.1;
  BackgroundColour background_colour = BackgroundColour::random;
  bool cull_unseen = false;  ///< ClipModelOptions::cull_unseen (`reconstruct --keep-unseen` clears it)

  /// The model options of configuration `c` under these settings.
  [[nodiscard]] ClipModelOptions model_options(const TradeConfig& c) const {
    ClipModelOptions mo;
    mo.seed = seed;
    mo.background.points_per_shell = shell_points;
    mo.frg_grid = mo.bkg_grid = c.grid;
    mo.static_background = static_background;
    mo.alpha_mask = alpha_mask;
    mo.alpha_outside = alpha_outside;
    mo.background_colour = background_colour;
    mo.cull_unseen = cull_unseen;
    return mo;
  }
};

namespace detail {
/// The run key's leading "seed=S|shell=N|".
[[nodiscard]] inline std::string run_key_prefix(const TradeOptions& o) {
  return "seed=" + std::to_string(o.seed) + "|shell=" + std::to_string(o.shell_points) + "|";
}
}  // namespace detail

/// The settings of a sweep besides its configurations that decide what a configuration trains to:
/// "seed=S|shell=N|frames=A-B|WxH|pts=P" (the seed, background points per shell, the clip's frame
/// range and size, its SfM point count), then the model's departures from the reference start
/// (`ClipModelOptions::departures_key`: none by default, so earlier sweeps' keys stay valid). A stored
/// result is reused only under the same run key.
[[nodiscard]] inline std::string trade_run_key(const TradeClip& clip, const TradeOptions& o) {
  std::ostringstream t;
  const int w = clip.frames.empty() ? 0 : clip.frames.front().width(), h = clip.frames.empty() ? 0 : clip.frames.front().height();
  t << detail::run_key_prefix(o) << "frames=" << clip.sfm.range.first << "-" << clip.sfm.range.last << "|" << w << "x" << h
    << "|pts=" << clip.sfm.points.size() << o.model_options(TradeConfig{}).departures_key();
  return t.str();
}

/// Whether `stored` was trained under the run key `run`. Files written before run keys were recorded
/// hold none; they count as trained with the default seed and shells (the only settings the tool
/// then had besides the clip, which they cannot tell).
[[nodiscard]] inline bool same_run(const TradeResult& stored, const std::string& run) {
  if (!stored.run.empty()) return stored.run == run;
  return run.rfind(detail::run_key_prefix(TradeOptions{}), 0) == 0;
}

struct TradeProgress {
  std::size_t config = 0, configs = 0;  ///< index of the configuration being trained, of how many
  int iteration = 0, iterations = 0;
  double psnr = 0;
};

namespace detail {
[[nodiscard]] inline double process_cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

/// A result's file name: a hash of its key and run key (files are found by the keys they hold, so
/// files named by the key alone, before run keys existed, are still read).
[[nodiscard]] inline std::string trade_file_name(const std::string& key, const std::string& run = {}) {
  return stable_key(run.empty() ? key : key + "||" + run) + ".json";
}

/// Every readable result in `runs` (OUT/runs/) trained under the run key `run` (`same_run`; empty:
/// every result), one per key and run (of files holding the same, the first by file name), found by the
/// key stored inside, not by the file's name: a sweep still reuses results written under an earlier
/// naming of the files. Unreadable files are skipped, and so are results not `current` (trained under
/// presets that have changed since, or by a version that did not record its settings).
[[nodiscard]] inline std::vector<TradeResult> stored_results(const std::filesystem::path& runs, const std::string& run = {}) {
  namespace fs = std::filesystem;
  std::vector<fs::path> files;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(runs, ec))
    if (e.path().extension() == ".json") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  std::vector<TradeResult> out;
  std::set<std::string> keys;
  for (const auto& f : files) {
    try {
      TradeResult r = TradeResult::from_json(nlohmann::json::parse(read_file_bytes(f)), f.string());
      if (!run.empty() && !same_run(r, run)) continue;
      if (!r.current()) continue;  // trained under other presets (or unknown ones): stale
      if (keys.insert(r.config.key() + "||" + r.run).second) out.push_back(std::move(r));
    } catch (const nlohmann::json::exception&) {
    } catch (const io_error&) {
    } catch (const option_error&) {  // a preset this version does not know
    }
  }
  return out;
}

/// Mean PSNR of the merged renders of `m` against `frames`.
template <class Model>
[[nodiscard]] double mean_psnr(const Model& m, const std::vector<Image<float, 3>>& frames, ThreadPool* pool) {
  ClipRenderBuffers<float, typename Model::field_type> b;
  double s = 0;
  for (int i = 0; i < m.frame_count(); ++i) {
    render_clip_frame(m, i, b, pool);
    s += metrics::psnr<float, 3>(b.merged, frames[std::size_t(i)], pool);
  }
  return s / std::max(1, m.frame_count());
}
}  // namespace detail

/// Trains and measures one configuration on `clip`. @throws option_error on bad settings
[[nodiscard]] inline TradeResult run_trade_config(const TradeConfig& c, const TradeClip& clip, const TradeOptions& o,
                                                  const std::function<void(int, double)>& on_iteration = {}, ThreadPool* pool = nullptr) {
  const TrainOptions topt0 = c.train_options(o.seed);
  const ClipModelOptions mo = o.model_options(c);
  TradeResult r;
  r.config = c;
  r.run = trade_run_key(clip, o);
  r.training = c.training_key();
  const auto t0 = std::chrono::steady_clock::now();
  const double cpu0 = detail::process_cpu_seconds();
  auto model = make_clip_model<float>(clip.sfm, mo, std::span<const Image<float, 1>>(clip.masks), pool,
                                      std::span<const Image<float, 3>>(clip.frames));
  TrainOptions topt = topt0;
  if (!clip.masks.empty()) topt.foreground_share = std::max(1e-3, mask_coverage<float>(std::span<const Image<float, 1>>(clip.masks)));
  ClipTrainer<ClipModel<float>> trainer(std::move(model), clip.frames, topt, pool);
  trainer.train([&](const IterationInfo& it) {
    if (on_iteration) on_iteration(it.iteration + 1, it.psnr);
    return true;
  });
  r.wall_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.cpu_seconds = detail::process_cpu_seconds() - cpu0;
  const ClipEvaluation e = trainer.evaluate();
  r.psnr = e.psnr, r.ssim = e.ssim;
  auto& m = trainer.model();
  r.frg = m.frg.size(), r.bkg = m.bkg.size();
  io::BinaryWriter w(kClipModelMagic, kClipModelVersion);
  write_clip_model(w, m);
  r.model_bytes = w.bytes().size();
  CompactOptions co;
  co.alpha_downscale = c.alpha_downscale;
  const std::string packed = write_compact_clip_model(m, co, pool);
  r.compact_bytes = packed.size();
  r.compact_psnr = detail::mean_psnr(read_compact_clip_model<float>(packed, "compact"), clip.frames, pool);
  return r;
}

/// Runs every configuration (reusing OUT/runs/ files when `o.resume`), then marks the frontiers.
/// @throws io_error `io.unwritable`; option_error on bad settings (before any training)
[[nodiscard]] inline std::vector<TradeResult> run_trade(const std::vector<TradeConfig>& configs, const TradeClip& clip, const TradeOptions& o,
                                                        const std::function<void(const TradeProgress&)>& progress = {},
                                                        ThreadPool* pool = nullptr) {
  namespace fs = std::filesystem;
  for (const auto& c : configs) (void)c.train_options(o.seed);  // every setting checked before hours of work
  const fs::path runs = o.out / "runs";
  std::error_code ec;
  fs::create_directories(runs, ec);
  if (ec) throw io_error("io.unwritable", runs.string(), "cannot create folder: " + ec.message());
  // An unreadable result is trained again (and its file overwritten).
  const std::string run = trade_run_key(clip, o);
  const std::vector<TradeResult> stored = o.resume ? detail::stored_results(runs, run) : std::vector<TradeResult>{};
  std::vector<TradeResult> out;
  for (std::size_t k = 0; k < configs.size(); ++k) {
    const TradeConfig& c = configs[k];
    const fs::path file = runs / detail::trade_file_name(c.key(), run);
    const auto hit = std::find_if(stored.begin(), stored.end(), [&](const TradeResult& r) { return r.config.key() == c.key(); });
    if (hit != stored.end()) {
      out.push_back(*hit);
      // This sweep's name for it; unnamed here (a grid point), the name it was trained under.
      if (!c.label.empty()) out.back().config.label = c.label;
      continue;
    }
    TradeProgress p;
    p.config = k, p.configs = configs.size(), p.iterations = c.train_options(o.seed).iterations;
    auto r = run_trade_config(c, clip, o, [&](int it, double psnr) {
      p.iteration = it, p.psnr = psnr;
      if (progress) progress(p);
    }, pool);
    auto j = r.to_json();  // the frontiers belong to the whole sweep, not to this file
    for (const char* k : {"frontier_time", "frontier_bytes", "beaten_on_time_by", "beaten_on_bytes_by"}) j.erase(k);
    io::write_file_atomic(file, j.dump(1) + "\n");
    out.push_back(r);
  }
  mark_frontiers(out);
  return out;
}

/// `results` followed by every result stored in OUT/runs/ by earlier sweeps under the run key `run`
/// (`same_run`; empty: under any) that `results` does not hold (a sweep grown in steps: each step's
/// grid trains what is new, the tables show everything), ordered by key; the frontiers are marked again
/// over the whole set. Unreadable files are skipped.
[[nodiscard]] inline std::vector<TradeResult> with_stored_results(std::vector<TradeResult> results, const std::filesystem::path& out,
                                                                  const std::string& run = {}) {
  std::vector<TradeResult> stored;
  for (auto& r : detail::stored_results(out / "runs", run)) {
    bool known = false;
    for (const auto& x : results) known = known || x.config.key() == r.config.key();
    if (!known) stored.push_back(std::move(r));
  }
  std::sort(stored.begin(), stored.end(), [](const TradeResult& a, const TradeResult& b) { return a.config.key() < b.config.key(); });
  for (auto& r : stored) results.push_back(std::move(r));
  mark_frontiers(results);
  return results;
}

/// Sweeps of at most this many configurations have every point named in the plots.
inline constexpr std::size_t kNameAllPoints = 12;

namespace detail {
/// The plots' point labels: TradeConfig::short_name of the named points (all of them up to
/// kNameAllPoints results, else those with a label or `on_frontier`). Results that trained the same
/// model (equal PSNR and compact bytes, for example a preset and the grid point it equals) are one
/// point: the first carries every name, joined by " = ", the others none, so labels never overprint.
template <class OnFrontier>
[[nodiscard]] std::vector<std::string> plot_labels(const std::vector<TradeResult>& results, OnFrontier on_frontier) {
  const auto same = [&](std::size_t a, std::size_t b) {
    return results[a].psnr == results[b].psnr && results[a].compact_bytes == results[b].compact_bytes;
  };
  std::vector<std::string> labels(results.size());
  for (std::size_t i = 0; i < results.size(); ++i) {
    bool shown = false;
    for (std::size_t j = 0; j < i && !shown; ++j) shown = same(i, j);
    if (shown) continue;
    for (std::size_t k = i; k < results.size(); ++k) {
      const TradeResult& r = results[k];
      if (!same(i, k) || !(results.size() <= kNameAllPoints || on_frontier(r) || !r.config.label.empty())) continue;
      labels[i] += (labels[i].empty() ? "" : " = ") + r.config.short_name();
    }
  }
  return labels;
}
}  // namespace detail

/// Writes OUT/trade.csv, OUT/trade.json and, with gnuplot (`program`), OUT/trade_time.png (PSNR against
/// CPU seconds) and OUT/trade_bytes.png (the compact file's PSNR against its megabytes): every
/// configuration a point, the frontier a line through its points; points named by
/// TradeConfig::short_name (all of them up to kNameAllPoints configurations, else the frontier's and
/// the labelled ones; configurations that trained the same model share one label, detail::plot_labels);
/// the cost axis is logarithmic when it spans more than 20x. The plotted points
/// stay beside each plot (OUT/<plot>.dat).
/// @returns whether both plots were drawn (false without gnuplot).
inline bool write_trade_outputs(const std::filesystem::path& out, const std::vector<TradeResult>& results,
                                const std::filesystem::path& program = "gnuplot") {
  namespace fs = std::filesystem;
  std::ostringstream csv;
  csv << "label,preset,iterations,resolution_schedule,budget,log2_table,grid_levels,alpha_downscale,psnr,ssim,wall_seconds,"
         "cpu_seconds,frg,bkg,model_bytes,compact_bytes,compact_psnr,frontier_time,frontier_bytes,time_cells\n";
  nlohmann::ordered_json all = nlohmann::ordered_json::array();
  for (const auto& r : results) {
    const auto j = r.to_json();
    std::string res = "preset";
    if (r.config.resolution) {
      res.clear();
      for (const auto& s : *r.config.resolution) res += (res.empty() ? "" : " ") + std::to_string(s.from_iteration) + ":" + nlohmann::json(s.scale).dump();
    }
    csv << (r.config.label.empty() ? "-" : r.config.label) << "," << r.config.preset << "," << r.config.iterations << "," << res << ","
        << j["budget"].dump() << "," << r.config.grid.log2_table_size << "," << r.config.grid.levels << "," << r.config.alpha_downscale << ","
        << j["psnr"].dump() << "," << j["ssim"].dump() << "," << j["wall_seconds"].dump() << "," << j["cpu_seconds"].dump() << "," << r.frg
        << "," << r.bkg << "," << r.model_bytes << "," << r.compact_bytes << "," << j["compact_psnr"].dump() << "," << int(r.frontier_time)
        << "," << int(r.frontier_bytes) << ","
        << r.config.grid.time_cells_text() << "\n";
    all.push_back(j);
  }
  io::write_file_atomic(out / "trade.csv", csv.str());
  io::write_file_atomic(out / "trade.json", nlohmann::ordered_json{{"configurations", all}}.dump(1) + "\n");
  // Plot data: x y label, one file of all points and one of the frontier sorted by cost.
  auto plot = [&](const char* png, const char* title, const char* xlabel, const char* ylabel, auto x_of, auto y_of, auto on_of) {
    const fs::path dat = out / (std::string(png) + ".dat");
    std::ostringstream d;
    d << "# x y label\n";
    double lo = 0, hi = 0;
    const std::vector<std::string> labels = detail::plot_labels(results, on_of);
    for (std::size_t i = 0; i < results.size(); ++i) {
      const TradeResult& r = results[i];
      d << x_of(r) << " " << y_of(r) << " \"" << labels[i] << "\"\n";
      lo = lo == 0 ? x_of(r) : std::min(lo, x_of(r));
      hi = std::max(hi, x_of(r));
    }
    d << "\n\n";
    std::vector<const TradeResult*> f;
    for (const auto& r : results)
      if (on_of(r)) f.push_back(&r);
    std::sort(f.begin(), f.end(), [&](const TradeResult* a, const TradeResult* b) { return x_of(*a) < x_of(*b); });
    for (const auto* r : f) d << x_of(*r) << " " << y_of(*r) << " \"\"\n";
    io::write_file_atomic(dat, d.str());
    const fs::path target = out / png;
    std::string gp =
        "set terminal pngcairo size 900,560 font ',10'\n"
        "set output " + detail::gnuplot_quote(target.string() + ".part.png") + "\n"
        "set title " + detail::gnuplot_quote(title) + "\n"
        "set xlabel " + detail::gnuplot_quote(xlabel) + "\nset ylabel " + detail::gnuplot_quote(ylabel) + "\n"
        "set grid\nset key bottom right box opaque\nset offsets graph 0.05, graph 0.12, graph 0.08, graph 0.08\n" +
        std::string(lo > 0 && hi > 20 * lo ? "set logscale x\n" : "") +
        "plot " + detail::gnuplot_quote(dat) + " index 0 using 1:2 with points pointtype 7 pointsize 1.1 linecolor rgb '#7f7f7f' title 'configuration', \\\n"
        "  '' index 1 using 1:2 with linespoints pointtype 7 pointsize 1.3 linewidth 2 linecolor rgb '#d82a1a' title 'Pareto frontier', \\\n"
        "  '' index 0 using 1:2:3 with labels offset char 0.8,0.8 left font ',10' noenhanced notitle\n";
    return detail::run_gnuplot(gp, target, program);
  };
  const bool a = plot("trade_time.png", "Speed against accuracy: training one clip", "CPU time of training (s)", "PSNR over the clip's frames (dB)",
                      [](const TradeResult& r) { return r.cpu_seconds; }, [](const TradeResult& r) { return r.psnr; },
                      [](const TradeResult& r) { return r.frontier_time; });
  const bool b = plot("trade_bytes.png", "Size against accuracy: the compact file of one clip", "compact file (MB)",
                      "PSNR of the compact model over the clip's frames (dB)", [](const TradeResult& r) { return double(r.compact_bytes) / 1e6; },
                      [](const TradeResult& r) { return r.compact_psnr; }, [](const TradeResult& r) { return r.frontier_bytes; });
  return a && b;
}

}  // namespace video3dgs::pipeline
