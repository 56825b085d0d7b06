#pragma once
/// @file
/// `TrainOptions` (stage 1, one clip), its presets, and what the trainer reports: `IterationInfo`
/// (per iteration, to a callback) and `TrainStats` (accumulated). Every schedule of the method (docs/method.md) is
/// an option; the defaults are the reference values (3k preset).
///
/// Schedules, with k the 0-based iteration:
///   position lr   exponential lr_position_init -> lr_position_final over lr_position_steps, x scene radius
///   deformation   exponential lr_deformation_init -> lr_deformation_final over lr_deformation_steps,
///                 fields off (canonical render, frozen) while k < deformation_warmup; constants
///                 (evaluated, not trained) while k >= freeze_deformation_from > 0
///   SH degree     active degree = min(SHDegree, max_sh_degree, k / sh_degree_interval)
///   densify       after the iteration counts k+1 that are multiples of densify_interval in
///                 [densify_from, densify_until]
///   opacity reset after iteration k+1 multiple of opacity_reset_interval (<= densify_until)
///   resolution    render and target size of iteration k: the frame size x resolution_scale(k)

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/hash.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/rasterizer/settings.hpp"
#include "video3dgs/rasterizer/stats.hpp"

namespace video3dgs {

struct TrainOptions {
  int iterations = 3000;
  std::uint64_t seed = 0;  ///< frame permutation and split sampling

  // Learning rates (Adam, eps below).
  double lr_position_init = 1.6e-4;  ///< x scene radius
  double lr_position_final = 1.6e-6; ///< x scene radius
  int lr_position_steps = 30000;
  double lr_sh_dc = 2.5e-3;
  double lr_sh_rest = 1.25e-4;
  double lr_opacity = 0.05;
  double lr_scale = 5e-3;
  double lr_rotation = 1e-3;
  /// Alpha maps are stored as logits (model/alpha_merge.hpp); 4e-2 on the logit moves A by the
  /// reference's 1e-2 per unit step at A = 0.5 (dA/da = 1/4).
  double lr_alpha = 4e-2;
  double lr_deformation_init = 8e-4;
  double lr_deformation_final = 1.6e-6;
  int lr_deformation_steps = 30000;
  /// The fine phase's position rate: from iteration lr_fine_from on, the Gaussians' position rate
  /// (its decay goes on) is multiplied by lr_position_fine (`LrSchedule::with_step`); the other rates
  /// are unchanged. 1: the reference's rate throughout.
  double lr_position_fine = 1;
  int lr_fine_from = 0;
  /// The fine phase's alpha rate: from iteration lr_fine_from on, the alpha maps' rate is multiplied
  /// by lr_alpha_fine. The maps are stored at full size; a coarse phase's gradient reaches a map only
  /// through the area resampling to the render's size (block means), so its detail is learnt in the
  /// full-size iterations alone, and a map is stepped only when its frame is drawn. 1: the
  /// reference's rate throughout (the paper's presets).
  double lr_alpha_fine = 1;
  /// The fine phase's colour rate: from iteration lr_fine_from on, the SH coefficients' rates (the
  /// DC band's lr_sh_dc and the other bands' lr_sh_rest alike) are multiplied by lr_sh_fine. 1: the
  /// reference's rates throughout (the paper's presets).
  double lr_sh_fine = 1;
  /// The run's last stretch at falling rates: from iteration lr_anneal_from on (0: never), every
  /// trained rate (the Gaussians', the alpha maps', the deformation fields' and the cameras', after
  /// their own schedules and steps) is multiplied by lr_anneal_factor^((k - lr_anneal_from) /
  /// (iterations - lr_anneal_from)): a log-linear descent from 1 to lr_anneal_factor at the run's end
  /// (`LrSchedule::with_anneal`). An extension past `iterations` (training/extend.hpp) goes on at
  /// lr_anneal_factor. The paper's rates are a 30,000-iteration schedule cut at 3,000, and `balanced`'s
  /// fine phase steps the colours' and the alpha maps' rates up, so without it a run ends at full rates.
  int lr_anneal_from = 0;
  double lr_anneal_factor = 1;
  /// Where an anneal starts when nothing says otherwise: half way through the fine phase
  /// (lr_fine_from to the run's end; the whole run's second half without a fine phase).
  [[nodiscard]] int default_lr_anneal_from() const noexcept {
    return std::clamp((std::max(lr_fine_from, 0) + iterations) / 2, 1, std::max(1, iterations - 1));
  }
  double adam_eps = 1e-15;
  /// Lazy Adam steps (optim/optimizer.hpp, `GroupOptions::lazy`) for the Gaussian groups and the
  /// deformation fields: a Gaussian this iteration's render did not touch, or a hash-table entry no
  /// point reached, keeps its values and moments instead of drifting along its momentum (the sparse
  /// Adam of Taming 3DGS). false: the reference's dense steps.
  bool sparse_adam = false;
  /// Camera refinement (training/clip_trainer.hpp): each clip frame but the first gets a rigid
  /// correction of its camera, stepped by Adam from the clip graph's camera node: the rotation vector
  /// at lr_camera_rotation (radians), the translation at lr_camera_translation x scene radius. Both 0:
  /// the SfM cameras are used as they are (the reference).
  double lr_camera_rotation = 0;
  double lr_camera_translation = 0;
  [[nodiscard]] bool refines_cameras() const noexcept { return lr_camera_rotation > 0 || lr_camera_translation > 0; }

  /// One step of the resolution schedule: from iteration `from_iteration` on, render and compare at
  /// the frame size x `scale` (0 < scale <= 1; sizes rounded to the nearest pixel, at least 1).
  struct ResolutionStep {
    int from_iteration = 0;
    double scale = 1;
  };
  /// Coarse to fine (DashGaussian, CVPR 2025): targets are the frames area-resampled
  /// (`resize_area`), cameras `Camera::resized`, the alpha logits resampled in the graph
  /// (graph/clip_graph.hpp). Before the first step and when empty: full size. Evaluation, checkpoints
  /// and the model stay at full size.
  std::vector<ResolutionStep> resolution_schedule;
  /// "K:S,K:S,..." (from iteration K, scale S; "" = none) as resolution steps, unvalidated.
  /// @throws option_error `option.train` (field resolution_schedule) on a malformed text.
  [[nodiscard]] static std::vector<ResolutionStep> parse_resolution_schedule(const std::string& text) {
    std::vector<ResolutionStep> steps;
    if (!text.empty() && text.back() == ',')
      throw option_error("option.train", "resolution_schedule", "expected K:S,K:S,... (iteration:scale), got a trailing ','");
    for (std::size_t pos = 0; pos < text.size();) {
      const std::size_t comma = std::min(text.find(',', pos), text.size());
      const std::string item = text.substr(pos, comma - pos);
      const std::size_t colon = item.find(':');
      ResolutionStep r;
      bool ok = false;
      try {
        std::size_t used_k = 0, used_s = 0;
        if (colon != std::string::npos && colon > 0 && colon + 1 < item.size()) {
          r.from_iteration = std::stoi(item.substr(0, colon), &used_k);
          r.scale = std::stod(item.substr(colon + 1), &used_s);
          ok = used_k == colon && used_s == item.size() - colon - 1;
        }
      } catch (const std::exception&) {
        ok = false;
      }
      if (!ok)
        throw option_error("option.train", "resolution_schedule", "expected K:S,K:S,... (iteration:scale), got '" + item + "'");
      steps.push_back(r);
      pos = comma + 1;
    }
    return steps;
  }
  /// The scale of iteration k (`resolution_schedule`).
  [[nodiscard]] double resolution_scale(int k) const {
    double s = 1;
    for (const ResolutionStep& r : resolution_schedule)
      if (r.from_iteration <= k) s = r.scale;
    return s;
  }
  /// The first iteration rendered at full size under `resolution_schedule`: 0 when the schedule is
  /// empty or iteration 0 is at scale 1, `iterations` when no step reaches scale 1.
  [[nodiscard]] int first_full_size_iteration() const {
    int k = resolution_scale(0) >= 1 ? 0 : iterations;
    for (const ResolutionStep& r : resolution_schedule)
      if (r.from_iteration < k && resolution_scale(r.from_iteration) >= 1) k = r.from_iteration;
    return k;
  }
  /// The coarse-to-fine presets' alpha factor for a fine phase from iteration `from` on: iterations /
  /// full-size iterations (the alpha maps' full-size steps x rate as in an all-full-size schedule);
  /// 1 when the fine phase is the whole run or empty.
  [[nodiscard]] double alpha_fine_rule(int from) const noexcept {
    return from <= 0 || from >= iterations ? 1.0 : double(iterations) / double(iterations - from);
  }
  /// These options with `schedule` as the resolution schedule. When the fine phase starts at the old
  /// schedule's first full-size iteration (a coarse-to-fine preset's: lr_fine_from =
  /// first_full_size_iteration(), the schedule not empty), it moves with the schedule: lr_fine_from
  /// becomes the new first full-size iteration and lr_alpha_fine keeps its ratio to
  /// `alpha_fine_rule` (balanced's x 3 becomes x 2 for "0:0.5,1500:1"). Otherwise (the paper's
  /// presets, or a fine phase set by hand) only the schedule changes.
  [[nodiscard]] TrainOptions with_resolution_schedule(std::vector<ResolutionStep> schedule) const {
    TrainOptions t = *this;
    t.resolution_schedule = std::move(schedule);
    if (!resolution_schedule.empty() && lr_fine_from == first_full_size_iteration()) {
      t.lr_fine_from = t.first_full_size_iteration();
      t.lr_alpha_fine = lr_alpha_fine / alpha_fine_rule(lr_fine_from) * t.alpha_fine_rule(t.lr_fine_from);
    }
    return t;
  }
  /// Smallest longer side, in pixels, of a scheduled render size: a step's scale is raised to
  /// min(1, resolution_min_size / max(width, height)), so that small frames are not trained at a
  /// few dozen pixels (a 160x120 video trains at full size throughout). 0: no floor.
  int resolution_min_size = 0;
  /// The scale of iteration k for frames of width x height (`resolution_scale(k)`, floored by
  /// `resolution_min_size`).
  [[nodiscard]] double resolution_scale(int k, int width, int height) const {
    const double s = resolution_scale(k);
    if (resolution_min_size <= 0) return s;
    const double longer = double(std::max({width, height, 1}));
    return std::max(s, std::min(1.0, double(resolution_min_size) / longer));
  }

  /// Training crops: an iteration at full size renders and compares one cell of its frame instead of
  /// the whole frame: the frame is cut into n x n cells, n = ceil(1 / crop), at boundaries jittered
  /// at random (a hash of the seed and the iteration, so resuming and thread counts do not change it),
  /// and one cell is drawn uniformly. Every pixel is then trained with the same probability 1 / n^2 per
  /// iteration, and no cell is a sliver (see `crop_window`). 0 or 1: whole frames. Evaluation and
  /// rendering always use whole frames.
  double crop = 0;
  /// The training crop of iteration k for frames of width x height (empty without `crop`). Per axis of
  /// length L: n cells with inner boundaries b_j = round(j L / n + u_j L / (2 n)), u_j uniform in
  /// [-1/2, 1/2) (j = 1 .. n - 1), so a cell is between L / (2n) and 3 L / (2n) long (up to rounding);
  /// then a column and a row drawn uniformly. Each pixel lies in exactly one cell, hence the 1 / n^2.
  /// (Windows of a fixed size at a uniform origin, clipped at the border, covered pixels equally but
  /// were often slivers of a few pixels, each taking a full optimiser step.)
  [[nodiscard]] PixelWindow crop_window(int k, int width, int height) const {
    const double c = crop;
    if (!(c > 0 && c < 1) || width < 2 || height < 2) return {};
    const int n = static_cast<int>(std::ceil(1 / c - 1e-9));
    if (n < 2) return {};
    // splitmix64 (core/hash.hpp) from a state seeded by (seed, k).
    std::uint64_t z = splitmix64_mix(seed ^ splitmix64(std::uint64_t(k)));
    auto next = [&z] {
      z += kSplitmix64Gamma;
      return splitmix64_mix(z);
    };
    // [lo, hi) of the cell drawn on an axis of length L (cells of at least one pixel).
    auto axis = [&](int L, int& lo, int& hi) {
      const int m = std::min(n, L);
      const int cell = static_cast<int>(next() % std::uint64_t(m));
      lo = 0, hi = L;
      for (int j = 1; j < m; ++j) {  // every inner boundary is drawn, in order; the cell keeps its two
        const double u = double(next() >> 11) * 0x1.0p-53;  // [0, 1)
        const int b = static_cast<int>(std::lround(double(j) * L / m + (u - 0.5) * L / (2.0 * m)));
        if (j == cell) lo = b;
        if (j == cell + 1) hi = b;
      }
      hi = std::max(hi, lo + 1);
    };
    int x0 = 0, x1 = 0, y0 = 0, y1 = 0;
    axis(width, x0, x1);
    axis(height, y0, y1);
    return {x0, y0, x1 - x0, y1 - y0};
  }

  int deformation_warmup = 1000;  ///< iterations rendered without deformation
  /// From iteration k = freeze_deformation_from on (0: never) the deformation fields are constants:
  /// still evaluated, so the canonical parameters keep their gradients through them, but the fields
  /// get no gradient and no optimiser step (the same run as their rates set to 0 from there, without
  /// the fields' backward and Adam).
  int freeze_deformation_from = 0;
  /// From iteration k = freeze_background_from on (0: never; at or after densify_until) the
  /// background set of a clip with a foreground is a constant: its Gaussians, field and colours get
  /// no gradient and no step, its loss term is dropped (its gradient would reach only the set), and
  /// the merged render reads its render as it stands. The foreground set and the alpha maps train on.
  /// A clip without a foreground ignores it (its background is the only set).
  int freeze_background_from = 0;
  int sh_degree_interval = 1000;  ///< SH degree +1 every this many iterations
  /// Highest SH degree ever active, 0..3 (capacity.hpp's plan; 3: the schedule's alone). The bands
  /// above it keep their initial zeros, so the model renders the same with every band.
  int max_sh_degree = 3;
  /// The active SH degree of iteration k for a model of degree D.
  [[nodiscard]] int active_sh_degree(int k, int D) const noexcept {
    return std::min({D, max_sh_degree, std::max(k, 0) / sh_degree_interval});
  }

  // Densification (3DGS).
  int densify_from = 500;
  int densify_until = 2000;
  int densify_interval = 100;
  double densify_grad_threshold = 2e-4;  ///< on the mean |dL/dmean2d| (NDC units if densify_grad_ndc)
  /// Convert the rasterizer's pixel-unit 2D gradient to NDC units (x W/2, x H/2) as the reference's
  /// threshold assumes; false thresholds the pixel-unit gradient directly.
  bool densify_grad_ndc = true;
  double percent_dense = 0.01;      ///< clone if max scale <= percent_dense x extent, else split
  int split_children = 2;
  double split_scale_divisor = 1.6; ///< 0.8 x children (reference)
  double prune_opacity = 0.005;
  int opacity_reset_interval = 3000;
  double opacity_reset_value = 0.01;
  std::size_t max_gaussians = 3'000'000;  ///< per set: densification never grows a set beyond this
  /// Gaussian budget that follows the image (Taming 3DGS): > 0 caps each set at
  /// ceil(gaussians_per_pixel x frame pixels x the set's share), the background's share being 1 and
  /// the foreground's `foreground_share` (the fraction of the clip's pixels its masks cover, which the
  /// caller measures), clamped to [1, max_gaussians]; 0: max_gaussians alone. Densification fills
  /// a set up to its budget by decreasing gradient (training/densify.hpp); a set initialised above it
  /// is cut to it before the first iteration.
  double gaussians_per_pixel = 0;
  double foreground_share = 1;
  /// > 0: each densification also prunes the Gaussians whose mean blend weight sum_p alpha T over
  /// the views that saw them since the last one (in full-size pixels) is below this, and does not
  /// densify them (training/densify.hpp). 0: the reference's opacity prune alone.
  double prune_weight = 0;
  /// The weight prune acts only at the densification events that come after at least
  /// prune_weight_from iterations (the events before it prune by opacity alone); 0: at every event.
  /// Set to `last_densify_event()` it is one prune at the end of densification, when the sets are as
  /// large as they get and before the most expensive iterations. With prune_weight > 0 and at least
  /// one densification event, some event must qualify (`validate`).
  int prune_weight_from = 0;
  /// > 0: one prune after iteration prune_efficiency_at (>= 1, < iterations; it may come after the
  /// densification window; 0 for none with prune_efficiency_from), of the Gaussians whose blend weight per evaluation since the last
  /// densification event (or the run's start), sum_views W_i / sum_views E_i
  /// (`RasterGrads::blend_evals`), is below this: the pairs that cost compositing work and buy
  /// nearly no colour (faint wide footprints, Gaussians behind opaque surfaces). Gaussians without an
  /// evaluation since then and a set held constant (freeze_background_from) are not judged; a set
  /// keeps at least its most efficient Gaussian. 0: never.
  double prune_efficiency = 0;
  /// > 0 (with prune_efficiency > 0): the background set's own threshold in that prune (both the
  /// one-shot and the periodic one); the foreground set keeps prune_efficiency. A set's threshold is
  /// a blend weight per evaluation in its own render, while the merged render weighs the background
  /// by 1 - alpha: where the foreground set covers most of the frame, the background's evaluations buy
  /// less of the image than their own render says. 0: prune_efficiency for both sets.
  double prune_efficiency_bkg = 0;
  int prune_efficiency_at = 0;
  /// > 0 (with prune_efficiency > 0): the same prune also at every densification event from the
  /// first at or after iteration prune_efficiency_from on (`first_efficiency_event`), just before the
  /// event densifies, over the blend statistics since the event before it (or the run's start): the
  /// sets stop carrying the Gaussians that cost work for nearly no colour while they grow, not only
  /// once they have grown. Some event must come at or after it (`validate`); prune_efficiency_at
  /// may then be 0 (no one-shot prune). 0: the one-shot prune alone.
  int prune_efficiency_from = 0;
  /// True if a densification event runs after `done` iterations: a multiple of densify_interval in
  /// [densify_from, densify_until].
  [[nodiscard]] bool is_densify_event(int done) const noexcept {
    return densify_interval > 0 && done >= densify_from && done <= densify_until && done % densify_interval == 0;
  }
  /// The first densification event (an iteration count, as last_densify_event) at or after
  /// prune_efficiency_from, or -1 if there is none or the periodic efficiency prune is off.
  [[nodiscard]] int first_efficiency_event() const noexcept {
    if (prune_efficiency_from <= 0 || densify_interval <= 0) return -1;
    const int from = std::max({prune_efficiency_from, densify_from, 1});
    const int e = (from + densify_interval - 1) / densify_interval * densify_interval;
    return e <= densify_until ? e : -1;
  }
  /// The iteration count after which the last densification event runs (the largest multiple of
  /// densify_interval in [densify_from, densify_until]), or -1 if there is none.
  [[nodiscard]] int last_densify_event() const noexcept {
    if (densify_interval <= 0) return -1;
    const int e = densify_until / densify_interval * densify_interval;
    return e >= densify_from && e > 0 ? e : -1;
  }
  /// Where a one-shot efficiency prune goes when nothing says otherwise: 50 iterations after the
  /// last densification event (its statistics are those of the first 50 iterations without
  /// densification), kept inside the run.
  [[nodiscard]] int default_prune_efficiency_at() const noexcept {
    return std::clamp(std::max(last_densify_event(), 0) + 50, 1, std::max(1, iterations - 1));
  }

  /// The rasterizer's transmittance stop while training and evaluating
  /// (`RasterSettings::min_transmittance`): a pixel stops when its transmittance would fall below it.
  /// Under the method's rule (blend_at_stop false) the Gaussian that crosses it is not blended, so a
  /// stop s drops up to s alpha_max / (1 - alpha_max) of a pixel's colour (99 s with alpha_max = 0.99;
  /// the reference's 1e-4: 1 %), and at or above 1 - alpha_max a fully opaque Gaussian in front is
  /// dropped, so `validate` refuses such stops. 1e-4: the reference's. A larger stop skips the pairs
  /// behind nearly opaque surfaces (measured in docs/performance.md).
  double min_transmittance = kReferenceMinTransmittance;
  static constexpr double kReferenceMinTransmittance = 1e-4;  ///< the method's (and RasterSettings') stop
  /// `RasterSettings::blend_at_stop`: the crossing Gaussian is blended before the pixel stops, so a
  /// stop s drops less than s of a pixel's colour and stops up to 0.5 are allowed. false: the method's.
  bool blend_at_stop = false;

  // Loss.
  double lambda_dssim = 0.2;   ///< L = (1 - lambda) L1 + lambda D-SSIM
  /// The fine phase's D-SSIM weight: from iteration lr_fine_from on, the loss uses this lambda
  /// instead of lambda_dssim (`lambda_dssim_at`). Unset: lambda_dssim throughout (the paper's).
  std::optional<double> lambda_dssim_fine;
  /// The loss's D-SSIM weight at iteration k.
  [[nodiscard]] double lambda_dssim_at(int k) const noexcept {
    return lambda_dssim_fine && k >= lr_fine_from ? *lambda_dssim_fine : lambda_dssim;
  }
  double weight_frg = 1, weight_bkg = 1, weight_merged = 1;
  bool detail_weighted_l1 = false;  ///< merged L1 weighted by 1 + detail_gain W (W: normalised |I - bilateral(I)|)
  double detail_gain = 2;

  // Stability.
  double min_log_scale = -18;  ///< canonical log-scales are clamped after each step...
  double max_scale_extent = 10; ///< ... to <= log(max_scale_extent x extent)

  /// 3k / 5k / 10k presets: iterations, densification until 2/3 of the run (2000 for 3k).
  [[nodiscard]] static TrainOptions preset(int iterations) {
    if (iterations != 3000 && iterations != 5000 && iterations != 10000)
      throw option_error("option.train", "preset", "presets are 3000, 5000 and 10000 iterations");
    TrainOptions o;
    o.iterations = iterations;
    o.densify_until = iterations == 3000 ? 2000 : (iterations * 2 / 3) / 100 * 100;
    return o;
  }
  /// Preset by name (`preset_names`):
  ///   "3k", "5k", "10k"  the paper's (`preset(int)`); "reference" is "3k";
  ///   "balanced"         3k, coarse to fine (resolution_schedule 0:0.25, 1000:0.5, 2000:1; never
  ///                      below 200 pixels on the longer side: resolution_min_size): the same
  ///                      iterations and densification as 3k, far fewer pixels while the model is
  ///                      coarse; the alpha maps' rate x 3 from the first full-size iteration
  ///                      (lr_alpha_fine, lr_fine_from), the loss's D-SSIM weight 0.4 there
  ///                      (lambda_dssim_fine) and the SH coefficients' rates x 8 there (lr_sh_fine).
  ///                      One prune by blend weight per evaluation (prune_efficiency 0.01 after
  ///                      prune_efficiency_at 2050: 50 iterations after the last densification
  ///                      event, 50 into the full-size phase) removes the Gaussians that cost
  ///                      evaluations and carry little of the image. Pruning by blend weight
  ///                      (prune_weight) is an option, in no preset.
  ///   "fast"             balanced over 2000 iterations (`with_iterations(2000)`: every schedule
  ///                      scaled by 2/3, so 667 iterations at full size).
  ///   "best"             the paper's 5k with balanced's departures: resolution_schedule 0:0.25,
  ///                      1500:0.5, 3000:1 (2000 iterations at full size) and the same size floor.
  /// fast / balanced / best are the tool's points on the speed/accuracy trade (measured with
  /// `video3dgs trade` in docs/performance.md); 3k / 5k / 10k reproduce the paper.
  [[nodiscard]] static TrainOptions preset(const std::string& name) {
    if (name == "3k" || name == "reference") return preset(3000);
    if (name == "5k") return preset(5000);
    if (name == "10k") return preset(10000);
    // balanced's departures from a paper schedule: coarse to fine, with a size floor.
    const auto departures = [](TrainOptions o, std::vector<ResolutionStep> schedule) {
      o.resolution_schedule = std::move(schedule);
      o.resolution_min_size = 200;
      o.lr_fine_from = o.first_full_size_iteration();
      // The alpha maps' full-size steps x rate as the paper's schedule gives them (every iteration
      // at full size): iterations / full-size iterations (balanced and fast 3, best 2.5).
      o.lr_alpha_fine = o.alpha_fine_rule(o.lr_fine_from);
      // The full-size phase learns the detail only full-size pixels carry; D-SSIM's gradient is the
      // loss's detail term (docs/performance.md, "The D-SSIM weight at full size").
      o.lambda_dssim_fine = 0.4;
      // The colours get a third (best: two fifths) of the paper's full-size iterations, at 8 times
      // its rates (docs/performance.md, "The fine phase's other rates").
      o.lr_sh_fine = 8;
      return o;
    };
    if (name == "balanced") {
      TrainOptions o = departures(preset(3000), {{0, 0.25}, {1000, 0.5}, {2000, 1.0}});
      // One prune by blend weight per evaluation 50 iterations after the last densification event,
      // which is also the first full-size iteration (the statistics of iterations 2001-2050). It stays
      // there under another resolution schedule: a prune before the last event is regrown
      // (docs/performance.md, "The one prune becomes balanced's").
      o.prune_efficiency = 0.01;
      o.prune_efficiency_at = o.default_prune_efficiency_at();
      return o;
    }
    if (name == "fast") return preset("balanced").with_iterations(2000);
    if (name == "best") return departures(preset(5000), {{0, 0.25}, {1500, 0.5}, {3000, 1.0}});
    std::string names;
    for (const char* n : preset_names()) names += std::string(names.empty() ? "" : ", ") + n;
    throw option_error("option.train", "preset", "unknown preset '" + name + "' (" + names + ")");
  }
  /// These options over `n` iterations with the same proportions: densification window, warm-up, SH
  /// and opacity-reset steps, the resolution schedule and lr_fine_from scaled by n / iterations; the densification
  /// interval shrinks at most to 50 (each event can double a set: a scaled interval of 10 over a short
  /// run multiplies the Gaussians ~50-fold for no gain). n = iterations returns the options unchanged.
  [[nodiscard]] TrainOptions with_iterations(int n) const {
    TrainOptions t = *this;
    if (n == iterations || iterations <= 0) {
      t.iterations = n;
      return t;
    }
    const double f = double(n) / double(iterations);
    t.iterations = n;
    t.densify_from = std::max(1, static_cast<int>(std::lround(densify_from * f)));
    t.densify_until = std::max(t.densify_from, static_cast<int>(std::lround(densify_until * f)));
    t.densify_interval = std::min(densify_interval, std::max(50, static_cast<int>(std::lround(densify_interval * f))));
    t.deformation_warmup = static_cast<int>(std::lround(deformation_warmup * f));
    if (freeze_deformation_from > 0) t.freeze_deformation_from = std::max(1, static_cast<int>(std::lround(freeze_deformation_from * f)));
    if (freeze_background_from > 0)
      t.freeze_background_from = std::max(t.densify_until, static_cast<int>(std::lround(freeze_background_from * f)));
    if (prune_efficiency_at > 0) t.prune_efficiency_at = std::clamp(static_cast<int>(std::lround(prune_efficiency_at * f)), 1, std::max(1, n - 1));
    // The periodic efficiency prune's start: scaled, at most to the scaled run's last event (so a
    // start that had an event keeps one).
    if (prune_efficiency_from > 0) {
      const int scaled = std::max(1, static_cast<int>(std::lround(prune_efficiency_from * f)));
      const int t_last = t.last_densify_event();
      t.prune_efficiency_from = first_efficiency_event() >= 0 && t_last > 0 ? std::min(scaled, t_last) : scaled;
    }
    t.sh_degree_interval = std::max(1, static_cast<int>(std::lround(sh_degree_interval * f)));
    t.opacity_reset_interval = std::max(1, static_cast<int>(std::lround(opacity_reset_interval * f)));
    for (auto& r : t.resolution_schedule) r.from_iteration = static_cast<int>(std::lround(r.from_iteration * f));
    t.lr_fine_from = static_cast<int>(std::lround(lr_fine_from * f));
    if (lr_anneal_from > 0) t.lr_anneal_from = std::clamp(static_cast<int>(std::lround(lr_anneal_from * f)), 1, std::max(1, n - 1));
    // The weight prune's first event, in events: a value past the last event stays past it (so
    // `validate` refuses it at any iteration count); a prune at the last event alone stays at the
    // scaled run's last event (densify_interval scales down only, to 50 at least, so the scaled value
    // need not be an event); any other start is scaled, at most to the last event.
    if (prune_weight_from > 0) {
      const int last = last_densify_event(), t_last = t.last_densify_event();
      const int scaled = static_cast<int>(std::lround(prune_weight_from * f));
      if (last >= 0 && prune_weight_from > last) t.prune_weight_from = std::max(scaled, t_last + 1);
      else if (t_last > 0 && last >= 0 && prune_weight_from > last - densify_interval) t.prune_weight_from = t_last;
      else t.prune_weight_from = t_last > 0 ? std::min(scaled, t_last) : scaled;
    }
    return t;
  }

  /// The names `preset(name)` accepts.
  [[nodiscard]] static constexpr std::array<const char*, 7> preset_names() noexcept {
    return {"balanced", "fast", "best", "reference", "3k", "5k", "10k"};
  }

  /// The Gaussian budget of a set for frames of width x height (see gaussians_per_pixel).
  [[nodiscard]] std::size_t gaussian_budget(bool foreground, int width, int height) const {
    if (!(gaussians_per_pixel > 0)) return max_gaussians;
    const double b = std::ceil(gaussians_per_pixel * double(width) * double(height) * (foreground ? foreground_share : 1.0));
    return std::clamp<std::size_t>(b < 1e18 ? static_cast<std::size_t>(b) : max_gaussians, 1, std::max<std::size_t>(max_gaussians, 1));
  }

  /// @throws option_error `option.train` naming the field.
  void validate() const {
    auto bad = [](const char* f, const char* why) { throw option_error("option.train", f, why); };
    if (iterations < 0) bad("iterations", "must be >= 0");
    for (double lr : {lr_position_init, lr_position_final, lr_sh_dc, lr_sh_rest, lr_opacity, lr_scale, lr_rotation, lr_alpha,
                      lr_deformation_init, lr_deformation_final, lr_camera_rotation, lr_camera_translation})
      if (!(lr >= 0) || !(lr < 1e30)) bad("lr_*", "learning rates must be finite and >= 0");
    if (lr_position_steps <= 0 || lr_deformation_steps <= 0) bad("lr_*_steps", "must be > 0");
    for (const auto& [field, f] : {std::pair{"lr_position_fine", lr_position_fine}, std::pair{"lr_alpha_fine", lr_alpha_fine},
                                   std::pair{"lr_sh_fine", lr_sh_fine}})
      if (!(f >= 0) || !(f < 1e30)) bad(field, "must be finite and >= 0");
    if (lr_fine_from < 0) bad("lr_fine_from", "must be >= 0");
    if (lr_anneal_from != 0 && !(lr_anneal_from >= 1 && lr_anneal_from < iterations))
      bad("lr_anneal_from", "must be 0 (never) or in [1, iterations): the rates fall from there to the run's end");
    if (!(lr_anneal_factor > 0 && lr_anneal_factor < 1e30)) bad("lr_anneal_factor", "must be finite and > 0");
    if (!(adam_eps > 0)) bad("adam_eps", "must be > 0");
    if (sh_degree_interval <= 0) bad("sh_degree_interval", "must be > 0");
    if (max_sh_degree < 0 || max_sh_degree > 3) bad("max_sh_degree", "must be in 0..3");
    if (densify_interval <= 0) bad("densify_interval", "must be > 0");
    if (!(densify_grad_threshold > 0)) bad("densify_grad_threshold", "must be > 0");
    if (split_children < 1) bad("split_children", "must be >= 1");
    if (!(split_scale_divisor > 0)) bad("split_scale_divisor", "must be > 0");
    if (!(prune_opacity >= 0 && prune_opacity < 1)) bad("prune_opacity", "must be in [0, 1)");
    if (opacity_reset_interval <= 0) bad("opacity_reset_interval", "must be > 0");
    if (!(opacity_reset_value > 0 && opacity_reset_value < 1)) bad("opacity_reset_value", "must be in (0, 1)");
    if (!(lambda_dssim >= 0 && lambda_dssim <= 1)) bad("lambda_dssim", "must be in [0, 1]");
    if (lambda_dssim_fine && !(*lambda_dssim_fine >= 0 && *lambda_dssim_fine <= 1)) bad("lambda_dssim_fine", "must be in [0, 1]");
    if (!(weight_frg >= 0 && weight_bkg >= 0 && weight_merged >= 0)) bad("weight_*", "must be >= 0");
    if (!(weight_frg + weight_bkg + weight_merged > 0)) bad("weight_*", "at least one loss term needs a weight > 0");
    if (!(detail_gain >= 0)) bad("detail_gain", "must be >= 0");
    if (!(max_scale_extent > 0)) bad("max_scale_extent", "must be > 0");
    if (max_gaussians < 1) bad("max_gaussians", "must be >= 1");
    if (!(gaussians_per_pixel >= 0 && gaussians_per_pixel <= 1e6)) bad("gaussians_per_pixel", "must be in [0, 1e6]");
    if (!(foreground_share > 0 && foreground_share <= 1)) bad("foreground_share", "must be in (0, 1]");
    if (!(prune_weight >= 0 && prune_weight < 1e12)) bad("prune_weight", "must be finite and >= 0");
    if (prune_weight_from < 0) bad("prune_weight_from", "must be >= 0");
    if (!(prune_efficiency >= 0 && prune_efficiency <= 1)) bad("prune_efficiency", "must be in [0, 1] (a blend weight per evaluation)");
    if (!(prune_efficiency_bkg >= 0 && prune_efficiency_bkg <= 1)) bad("prune_efficiency_bkg", "must be in [0, 1] (0: prune_efficiency)");
    if (prune_efficiency_bkg > 0 && !(prune_efficiency > 0)) bad("prune_efficiency_bkg", "needs prune_efficiency > 0 (it is the background's threshold in that prune)");
    if (prune_efficiency_from < 0) bad("prune_efficiency_from", "must be >= 0 (0: the one-shot prune alone)");
    if (prune_efficiency > 0 && !(prune_efficiency_at >= 1 && prune_efficiency_at < iterations) &&
        !(prune_efficiency_from > 0 && prune_efficiency_at == 0))
      bad("prune_efficiency_at", prune_efficiency_from > 0 ? "must be 0 (none) or in [1, iterations): the prune acts after that iteration"
                                                           : "must be in [1, iterations): the prune acts after that iteration");
    if (prune_efficiency > 0 && prune_efficiency_from > 0 && first_efficiency_event() < 0)
      bad("prune_efficiency_from", ("no densification event comes at or after it (the last is after iteration " +
                                    std::to_string(last_densify_event()) + "): the periodic efficiency prune would never act").c_str());
    if (freeze_deformation_from < 0) bad("freeze_deformation_from", "must be >= 0 (0: never)");
    if (freeze_background_from != 0 && freeze_background_from < std::max(densify_until, 1))
      bad("freeze_background_from", "must be 0 (never) or at least densify_until: a frozen set is not densified");
    if (freeze_background_from != 0 && !(weight_frg + weight_merged > 0))
      bad("freeze_background_from", "the foreground or merged term needs a weight > 0 once the background is frozen");
    if (blend_at_stop ? !(min_transmittance > 0 && min_transmittance <= 0.5)
                      : !(min_transmittance > 0 && min_transmittance < 1 - double(RasterSettings<float, 3>{}.alpha_max)))
      bad("min_transmittance", blend_at_stop ? "must be in (0, 0.5] (blend_at_stop)"
                                             : "must be in (0, 1 - alpha_max = 0.01) unless blend_at_stop: from there on a fully opaque Gaussian in front is not blended");
    // Without any densification event nothing is pruned, as nothing is densified: not an error.
    if (const int last = last_densify_event(); prune_weight > 0 && last >= 0 && prune_weight_from > last)
      bad("prune_weight_from", ("no densification event comes after it (the last is after iteration " + std::to_string(last) +
                                "): the weight prune would never act").c_str());
    if (resolution_min_size < 0) bad("resolution_min_size", "must be >= 0");
    if (!(crop >= 0 && crop <= 1)) bad("crop", "must be in [0, 1]");
    for (std::size_t i = 0; i < resolution_schedule.size(); ++i) {
      const ResolutionStep& r = resolution_schedule[i];
      if (!(r.scale > 0 && r.scale <= 1)) bad("resolution_schedule", "scales must be in (0, 1]");
      if (r.from_iteration < 0 || (i > 0 && r.from_iteration <= resolution_schedule[i - 1].from_iteration))
        bad("resolution_schedule", "from_iteration must be >= 0 and increasing");
    }
  }

  /// Every field but `seed` as `name=value|` text, reals exact (%.17g): two options with equal texts train
  /// the same model from the same start and seed. A result stored with this text is stale when the
  /// text of the options it names (a preset, say) has changed since. A field added to TrainOptions
  /// belongs here (tests/training/clip_trainer_test.cpp checks the struct's size against this list's on x86-64).
  [[nodiscard]] std::string settings_text() const {
    std::string t;
    char num[40];
    const auto real = [&](const char* name, double v) {
      std::snprintf(num, sizeof(num), "%.17g", v);
      t.append(name).append("=").append(num).append("|");
    };
    const auto integer = [&](const char* name, long long v) { t.append(name).append("=").append(std::to_string(v)).append("|"); };
    integer("iterations", iterations);
    real("lr_position_init", lr_position_init), real("lr_position_final", lr_position_final), integer("lr_position_steps", lr_position_steps);
    real("lr_sh_dc", lr_sh_dc), real("lr_sh_rest", lr_sh_rest), real("lr_opacity", lr_opacity), real("lr_scale", lr_scale);
    real("lr_rotation", lr_rotation), real("lr_alpha", lr_alpha);
    real("lr_deformation_init", lr_deformation_init), real("lr_deformation_final", lr_deformation_final);
    integer("lr_deformation_steps", lr_deformation_steps);
    real("lr_position_fine", lr_position_fine), integer("lr_fine_from", lr_fine_from), real("lr_alpha_fine", lr_alpha_fine);
    real("lr_sh_fine", lr_sh_fine), real("adam_eps", adam_eps), integer("sparse_adam", sparse_adam);
    real("lr_camera_rotation", lr_camera_rotation), real("lr_camera_translation", lr_camera_translation);
    t.append("resolution_schedule=");
    for (const auto& r : resolution_schedule) {
      std::snprintf(num, sizeof(num), "%d:%.17g,", r.from_iteration, r.scale);
      t.append(num);
    }
    t.append("|");
    integer("resolution_min_size", resolution_min_size), real("crop", crop);
    integer("deformation_warmup", deformation_warmup), integer("sh_degree_interval", sh_degree_interval);
    integer("max_sh_degree", max_sh_degree);
    integer("densify_from", densify_from), integer("densify_until", densify_until), integer("densify_interval", densify_interval);
    real("densify_grad_threshold", densify_grad_threshold), integer("densify_grad_ndc", densify_grad_ndc);
    real("percent_dense", percent_dense), integer("split_children", split_children), real("split_scale_divisor", split_scale_divisor);
    real("prune_opacity", prune_opacity), integer("opacity_reset_interval", opacity_reset_interval);
    real("opacity_reset_value", opacity_reset_value), integer("max_gaussians", static_cast<long long>(max_gaussians));
    real("gaussians_per_pixel", gaussians_per_pixel), real("foreground_share", foreground_share), real("prune_weight", prune_weight);
    if (prune_weight_from != 0) integer("prune_weight_from", prune_weight_from);  // absent at 0: earlier texts stay valid
    if (min_transmittance != kReferenceMinTransmittance) real("min_transmittance", min_transmittance);  // absent at the reference's: likewise
    if (blend_at_stop) integer("blend_at_stop", 1);  // absent under the method's rule: likewise
    if (freeze_deformation_from != 0) integer("freeze_deformation_from", freeze_deformation_from);  // absent at 0: likewise
    if (freeze_background_from != 0) integer("freeze_background_from", freeze_background_from);  // absent at 0: likewise
    if (prune_efficiency != 0) real("prune_efficiency", prune_efficiency), integer("prune_efficiency_at", prune_efficiency_at);  // likewise
    if (prune_efficiency_from != 0) integer("prune_efficiency_from", prune_efficiency_from);  // likewise
    if (prune_efficiency_bkg != 0) real("prune_efficiency_bkg", prune_efficiency_bkg);  // likewise
    if (lr_anneal_from != 0) integer("lr_anneal_from", lr_anneal_from), real("lr_anneal_factor", lr_anneal_factor);  // likewise
    real("lambda_dssim", lambda_dssim);
    if (lambda_dssim_fine) real("lambda_dssim_fine", *lambda_dssim_fine);
    else t.append("lambda_dssim_fine=none|");
    real("weight_frg", weight_frg), real("weight_bkg", weight_bkg), real("weight_merged", weight_merged);
    integer("detail_weighted_l1", detail_weighted_l1), real("detail_gain", detail_gain);
    real("min_log_scale", min_log_scale), real("max_scale_extent", max_scale_extent);
    return t;
  }
};

/// Wall-clock seconds per stage.
struct StageTimes {
  double deformation = 0;  ///< field forward + backward
  double raster_forward = 0;
  double raster_backward = 0;
  double loss = 0;         ///< merge + losses forward and backward
  double optimizer = 0;    ///< finiteness check + Adam + clamps
  double densify = 0;
  double total = 0;
  StageTimes& operator+=(const StageTimes& o) {
    deformation += o.deformation; raster_forward += o.raster_forward; raster_backward += o.raster_backward;
    loss += o.loss; optimizer += o.optimizer; densify += o.densify; total += o.total;
    return *this;
  }
};

/// What one iteration reports to the callback.
struct IterationInfo {
  int iteration = 0;        ///< 0-based index of the iteration just run
  int frame = 0;            ///< clip frame index it used
  double loss = 0;          ///< weighted total
  double loss_frg = 0, loss_bkg = 0, loss_merged = 0;
  double psnr = 0;          ///< merged render vs frame (dB), at the render size
  int width = 0, height = 0; ///< render size (`TrainOptions::resolution_schedule`)
  std::size_t frg_count = 0, bkg_count = 0;
  bool skipped = false;     ///< non-finite loss or gradient: no step taken
  bool densified = false;
  StageTimes times;
  /// The rasterizer's work counters of this iteration's two renders (zero for a set not rendered).
  RasterStats frg_raster, bkg_raster;
};

/// Accumulated over `ClipTrainer::train` calls (saved in checkpoints).
struct TrainStats {
  int iterations = 0;            ///< iterations run so far (the next one's index)
  std::size_t skipped_steps = 0; ///< iterations whose step was skipped (non-finite loss / gradient)
  std::size_t cloned = 0, split = 0, pruned = 0;
  std::size_t densify_events = 0, opacity_resets = 0;
  bool stopped_early = false;    ///< the callback returned false
  double last_loss = 0, last_psnr = 0;
  StageTimes times;
};

}  // namespace video3dgs
