#pragma once
/// @file
/// `ClipTrainer<Model>`: stage 1 of Video-3DGS for one clip (the method's stage 1).
///
///     auto model = make_clip_model<float>(sfm);                       // model/clip_model.hpp
///     ClipTrainer<ClipModel<float>> trainer(std::move(model), frames, TrainOptions::preset("3k"), &pool);
///     trainer.train([](const IterationInfo& it) { return it.psnr < 40; });  // false stops early
///     trainer.save_checkpoint("clip0.ckpt");                          // atomic
///     // later: ClipTrainer<ClipModel<float>> again("clip0.ckpt", frames, options, &pool); again.train();
///
/// One iteration k (frame i from a seeded permutation per epoch, t = t_i):
///
///   P_s     = deform_s(canonical_s, t)           (canonical while k < deformation_warmup)
///   I_s     = rasterize(P_s, camera_i)           s in {frg, bkg}
///   I       = A_i I_frg + (1 - A_i) I_bkg,       A_i = sigmoid(a_i)
///   L       = w_f L(I_frg) + w_b L(I_bkg) + w_m L_w(I),   L = (1 - l) L1 + l (1 - SSIM) against frame i
///
/// at the render size of iteration k (`TrainOptions::resolution_schedule`: frame i area-resampled,
/// camera_i resized, a_i resampled in the graph; full size without a schedule), or, at full size with
/// `TrainOptions::crop`, on a window of frame i (`PixelWindow`, placed by a hash of seed and k);
/// all computed by the clip graph (graph/clip_graph.hpp: forward, then backward on its tape), a finiteness
/// check of every gradient (a non-finite loss or gradient skips the step and counts it in
/// `TrainStats::skipped_steps`; it never reaches a parameter), one Adam step (groups: per set mean,
/// log_scale, rotation, opacity, sh (DC at lr_sh_dc, other bands at lr_sh_rest), deformation; one
/// group per alpha map, only the current frame's stepped, as PyTorch skips parameters without a
/// gradient), the log-scale clamp, and densification / pruning / opacity reset on schedule with the
/// optimizer moments following the rows (training/densify.hpp).
///
/// From k = `TrainOptions::freeze_background_from` on (with a foreground) the background set is a
/// constant: w_b = 0, no gradient, step or clamp for its groups, and I_bkg of each frame is rendered
/// once per render size and SH degree and read after (`ClipGraph::freeze_render`).
///
/// Camera refinement (`TrainOptions::refines_cameras()`): every clip frame but the first (the gauge)
/// gets two groups, `camera_rotation.<i>` (omega, 3) and `camera_translation.<i>` (tau, 3, lr x scene
/// radius), stepped only on the iterations that train frame i, from the graph's camera node
/// (graph/clip_graph.hpp). After each step the correction is folded into the model's camera i
/// (`Camera::world_moved`) and reset to 0, so the model's cameras are always the refined ones and the
/// graph always runs at xi = 0; omega and tau are in world axes about the frame's current camera
/// centre, which is where Adam's moments live from one step to the next.
///
/// Determinism: every kernel is thread-count independent, so a seed gives the same model for any
/// pool size. A checkpoint holds the model, the optimizer (moments, step counts), the iteration, the
/// RNG state, the epoch permutation and the densification accumulators: resuming continues exactly as
/// an uninterrupted run with the same options would. Buffers are allocated per clip (and when the
/// Gaussian count changes at densification); a steady-state iteration does not allocate.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <deque>
#include <filesystem>
#include <functional>
#include <limits>
#include <random>
#include <span>
#include <sstream>
#include <string>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/core/resample.hpp"
#include "video3dgs/core/stopwatch.hpp"
#include "video3dgs/gaussian/cloud.hpp"
#include "video3dgs/graph/clip_graph.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/io/binary_stream.hpp"
#include "video3dgs/loss/ssim.hpp"
#include "video3dgs/metrics/psnr.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/model/clip_model_io.hpp"
#include "video3dgs/model/render_clip.hpp"
#include "video3dgs/optim/optimizer.hpp"
#include "video3dgs/optim/schedule.hpp"
#include "video3dgs/training/densify.hpp"
#include "video3dgs/training/detail_weight.hpp"
#include "video3dgs/training/policy.hpp"
#include "video3dgs/training/split_adam.hpp"
#include "video3dgs/training/train_options.hpp"

namespace video3dgs {

inline constexpr const char* kClipCheckpointMagic = "V3DGSCKP";
/// Version n embeds a version-n model record (clip_model_io.hpp: 3 adds the grids' cells caps);
/// version-1 and -2 checkpoints are still read.
inline constexpr std::uint32_t kClipCheckpointVersion = 3;

/// Quality of a clip model over all its frames (merged, Frg-only and Bkg-only renders).
struct ClipEvaluation {
  double psnr = 0, ssim = 0;          ///< merged render, means over frames
  double psnr_frg = 0, psnr_bkg = 0;  ///< single-set renders
  std::vector<double> psnr_per_frame;
};

namespace detail {
/// The two directions of the checkpoint's ONE field list (`ClipTrainer::transfer`): `Save` appends
/// each field to a BinaryWriter, `Load` reads it back from a BinaryReader, named for error messages.
struct CheckpointSave {
  static constexpr bool loading = false;
  io::BinaryWriter& w;
  template <class T>
  void value(T& v, const char*) { w.put<T>(v); }
  void text(std::string& v, const char*) { w.put_string(v); }
  template <class T>
  void vector(std::vector<T>& v, const char*) { w.put_vector(v); }
  template <class T>
  void array(std::span<T> v, const char*) { w.put_array(std::span<const T>(v)); }
};
struct CheckpointLoad {
  static constexpr bool loading = true;
  io::BinaryReader& r;
  template <class T>
  void value(T& v, const char* name) { v = r.get<T>(name); }
  void text(std::string& v, const char* name) { v = r.get_string(name); }
  template <class T>
  void vector(std::vector<T>& v, const char* name) { v = r.get_vector<T>(name); }
  template <class T>
  void array(std::span<T> v, const char* name) {
    const auto got = r.get_vector<T>(name);
    if (got.size() != v.size()) throw io_error("io.mismatch", r.file(), std::string(name) + " differs in size");
    std::copy(got.begin(), got.end(), v.begin());
  }
};
}  // namespace detail

template <class Model, int TileSize = kTrainingTileSize, class OptimizerPolicy = SplitLrAdam>
class ClipTrainer {
 public:
  using Scalar = typename Model::scalar_type;
  using Field = typename Model::field_type;
  using Cloud = typename Model::Cloud;
  static constexpr int D = Model::sh_degree;
  using Policy = TrainingPolicy<TileSize, OptimizerPolicy>;
  using Opt = Optimizer<Scalar, OptimizerPolicy>;
  using Graph = ClipGraph<Scalar, D, Field, TileSize>;
  /// Called after every iteration; return false to stop `train` early.
  using Callback = std::function<bool(const IterationInfo&)>;

  /// @param frames one image per clip frame, the cameras' size (moved in; the trainer keeps them).
  /// @throws option_error (`option.train`, `option.clip`) on bad options or frames.
  ClipTrainer(Model model, std::vector<Image<Scalar, 3>> frames, const TrainOptions& options = {}, ThreadPool* pool = nullptr)
      : model_(std::move(model)), frames_(std::move(frames)), options_(options), pool_(pool), rng_(options.seed) {
    options_.validate();
    cut_to_budget();
    setup();
  }

  /// Resumes from a checkpoint written by `save_checkpoint` (same template arguments and options).
  /// @throws io_error (`io.*`) on a missing, truncated or mismatched file.
  ClipTrainer(const std::filesystem::path& checkpoint, std::vector<Image<Scalar, 3>> frames, const TrainOptions& options = {},
              ThreadPool* pool = nullptr)
      : frames_(std::move(frames)), options_(options), pool_(pool), rng_(options.seed) {
    const std::string bytes = read_file_bytes(checkpoint);
    io::BinaryReader r(bytes, checkpoint.string(), kClipCheckpointMagic, kClipCheckpointVersion);
    model_ = read_clip_model<Scalar, D, Field>(r, r.version());  // checkpoint version n embeds record version n
    setup();
    detail::CheckpointLoad ar{r};
    transfer(ar);
    r.expect_end();
  }

  ClipTrainer(const ClipTrainer&) = delete;
  ClipTrainer& operator=(const ClipTrainer&) = delete;

  [[nodiscard]] Model& model() noexcept { return model_; }
  [[nodiscard]] const Model& model() const noexcept { return model_; }
  [[nodiscard]] const TrainStats& stats() const noexcept { return stats_; }
  [[nodiscard]] const TrainOptions& options() const noexcept { return options_; }
  [[nodiscard]] const Opt& optimizer() const noexcept { return opt_; }
  [[nodiscard]] const std::vector<Image<Scalar, 3>>& frames() const noexcept { return frames_; }
  [[nodiscard]] bool done() const noexcept { return stats_.iterations >= options_.iterations; }

  /// Lengthens the run to `iterations` (>= `options().iterations`); later `train` calls continue to it.
  /// Nothing in an iteration reads the run's length (every schedule is by iteration index), so a run
  /// lengthened at any point continues exactly as one given the longer length from the start.
  /// @throws option_error `option.train` for a shorter length.
  void extend_to(int iterations) {
    if (iterations < options_.iterations)
      throw option_error("option.train", "iterations", "extend_to(" + std::to_string(iterations) + ") is shorter than the run's " +
                                                           std::to_string(options_.iterations) + " iterations");
    options_.iterations = iterations;
  }

  /// Runs iterations until `options.iterations` (or the callback returns false).
  const TrainStats& train(const Callback& callback = {}) {
    stats_.stopped_early = false;
    while (!done()) {
      const IterationInfo& it = step();
      if (callback && !callback(it)) {
        stats_.stopped_early = true;
        break;
      }
    }
    return stats_;
  }

  /// Runs one iteration (see the file comment) and returns its report.
  const IterationInfo& step() {
    IterationInfo& info = info_;
    info = IterationInfo{};
    {
      ScopedTimer total(info.times.total);
      const int k = stats_.iterations;
      info.iteration = k;
      info.frame = next_frame();
      const bool deform = configure(k);
      bool ok = gradients(info.frame, deform, info);
      {
        ScopedTimer t(info.times.optimizer);
        if (ok) ok = select_groups(info.frame, deform) && gradients_finite();
        if (ok) {
          if (k < options_.densify_until) accumulate_densify_stats(info.frame);
          if (efficiency_pending(k)) accumulate_efficiency_stats();
          opt_.step(k, pool_);
          clamp_scales();
          if (refines_camera(info.frame)) fold_camera(info.frame);
        }
      }
      info.skipped = !ok;
      stats_.skipped_steps += ok ? 0 : 1;
      if (options_.prune_efficiency > 0 && k + 1 == options_.prune_efficiency_at) prune_inefficient();
      maintain(k + 1, info);
      stats_.iterations = k + 1;
      info.frg_count = model_.frg.size();
      info.bkg_count = model_.bkg.size();
    }
    stats_.times += info.times;
    if (!info.skipped) {
      stats_.last_loss = info.loss;
      stats_.last_psnr = info.psnr;
    }
    return info;
  }

  /// The loss of clip frame `frame` under the current iteration's settings (deformation on once
  /// `iterations() >= deformation_warmup`, active SH degree `TrainOptions::active_sh_degree`),
  /// forward only: the function whose gradient `gradients_at` computes.
  [[nodiscard]] double loss_at(int frame) {
    check_frame(frame);
    configure(stats_.iterations);
    const ConstImageView<Scalar, 3> tv(target(frame));
    // A correction that is not zero (a finite-difference probe sets one) renders through the folded
    // camera, the function the camera groups' gradients belong to at active SH degree 0 (above it the
    // groups hold the world move's gradient, see graph/clip_graph.hpp).
    const bool probe = refines_camera(frame) && std::any_of(camera_xi_.begin() + 6 * frame, camera_xi_.begin() + 6 * frame + 6,
                                                            [](Scalar v) { return v != Scalar(0); });
    if (!probe) return graph_.forward(model_, frame, {&tv, 1}, ctx_, {}, detail_weight(frame), pool_, window_).total;
    const Camera<Scalar> kept = model_.cameras[std::size_t(frame)];
    model_.cameras[std::size_t(frame)] = folded_camera(frame);
    double L = 0;
    try {
      L = graph_.forward(model_, frame, {&tv, 1}, ctx_, {}, detail_weight(frame), pool_, window_).total;
    } catch (...) {
      model_.cameras[std::size_t(frame)] = kept;
      throw;
    }
    model_.cameras[std::size_t(frame)] = kept;
    return L;
  }

  /// Forward and backward of clip frame `frame` under the current iteration's settings, without a
  /// step: afterwards every unfrozen optimiser group's gradient buffers (`optimizer().groups()`, and
  /// the gradient of `alpha.<frame>`, which all alpha groups share) hold dL/dparameter of `loss_at`.
  /// The camera groups of `frame` (which share one buffer, zero for frame 0) hold it at active SH
  /// degree 0; above it, the gradient of the world move the fold approximates (graph/clip_graph.hpp).
  /// Returns the loss, or NaN if the loss or an image gradient reaching a rasterizer was not finite
  /// (`step` also checks the parameter gradients before stepping).
  double gradients_at(int frame) {
    check_frame(frame);
    IterationInfo info;
    const bool deform = configure(stats_.iterations);
    select_groups(frame, deform);  // which groups are unfrozen at this iteration
    const bool ok = gradients(frame, deform, info);
    return ok ? info.loss : std::numeric_limits<double>::quiet_NaN();
  }

  /// Mean PSNR / SSIM of the merged render over every frame, and PSNR of each set alone.
  [[nodiscard]] ClipEvaluation evaluate() {
    ClipEvaluation e;
    RasterSettings<Scalar, 3> rs = graph_.settings;
    rs.active_sh_degree = options_.active_sh_degree(stats_.iterations - 1, D);
    const int n = model_.frame_count();
    for (int i = 0; i < n; ++i) {
      render_clip_frame<TileSize>(model_, i, eval_, pool_, rs, false);
      const auto& frame = frames_[std::size_t(i)];
      const double p = metrics::psnr<Scalar, 3>(eval_.merged, frame, pool_);
      e.psnr_per_frame.push_back(p);
      e.psnr += p;
      e.ssim += double(loss::ssim_value<Scalar, 3>(eval_.merged, frame, eval_ssim_, pool_));
      e.psnr_bkg += metrics::psnr<Scalar, 3>(eval_.bkg.image, frame, pool_);
      e.psnr_frg += model_.has_foreground ? metrics::psnr<Scalar, 3>(eval_.frg.image, frame, pool_) : 0.0;
    }
    e.psnr /= n;
    e.ssim /= n;
    e.psnr_frg /= n;
    e.psnr_bkg /= n;
    return e;
  }

  /// Writes model + optimizer + iteration + RNG state + densification statistics, atomically.
  void save_checkpoint(const std::filesystem::path& path) {
    io::BinaryWriter w(kClipCheckpointMagic, kClipCheckpointVersion);
    write_clip_model(w, model_);
    detail::CheckpointSave ar{w};
    transfer(ar);
    io::write_file_atomic(path, w.bytes());
  }

 private:
  /// Clip frames (and detail maps) at one render size of the resolution schedule.
  struct Level {
    int width = 0, height = 0;
    std::vector<Image<Scalar, 3>> frames;
    std::vector<Image<Scalar, 1>> detail;
  };

  struct SetState {
    GaussianSet which{};
    GaussianCloudGrad<Scalar, D> grad;
    std::vector<Scalar> accum, denom;
    std::vector<Scalar> weight;  ///< blend weight sums (full-size pixels) since the last densification, if pruned by weight
    /// Blend weight and evaluation sums (render pixels) since the last densification event, while an
    /// efficiency prune is to come (TrainOptions::prune_efficiency).
    std::vector<Scalar> eff_weight, eff_evals;
    std::string prefix, field_group, sh_group;
    std::array<std::string, 5> gaussian_groups;  ///< prefix + kGaussianGroups
  };
  /// The optimiser groups of a set's Gaussians (names after its prefix), in `add_set_groups`' order.
  static constexpr const char* kGaussianGroups[] = {"mean", "log_scale", "rotation", "opacity", "sh"};
  /// True if set s is a constant this iteration (TrainOptions::freeze_background_from).
  [[nodiscard]] bool frozen_set(const SetState& s) const noexcept { return background_frozen_ && s.which == GaussianSet::background; }

  /// The checkpoint's fields after the model, in order, for both directions (`Ar` is
  /// detail::CheckpointSave or detail::CheckpointLoad); loading validates what it read.
  template <class Ar>
  void transfer(Ar& ar) {
    ar.value(stats_.iterations, "iteration");
    std::string rng_text;
    if constexpr (!Ar::loading) {
      std::ostringstream rs;
      rs << rng_;
      rng_text = rs.str();
    }
    ar.text(rng_text, "rng");
    ar.vector(perm_, "permutation");
    std::uint64_t pos = perm_pos_;
    ar.value(pos, "permutation_pos");
    perm_pos_ = std::size_t(pos);
    for (std::size_t* v : {&stats_.skipped_steps, &stats_.cloned, &stats_.split, &stats_.pruned, &stats_.densify_events,
                           &stats_.opacity_resets}) {
      std::uint64_t x = *v;
      ar.value(x, "stats");
      *v = std::size_t(x);
    }
    for (SetState* s : active_) {
      ar.vector(s->accum, "densify.accum");
      ar.vector(s->denom, "densify.denom");
      if (options_.prune_weight > 0) ar.vector(s->weight, "densify.weight");  // only then: older checkpoints stay valid
      if (efficiency_sums_open(stats_.iterations)) {  // only then (else they are zeros): other checkpoints stay valid
        ar.vector(s->eff_weight, "prune.weight");
        ar.vector(s->eff_evals, "prune.evals");
      }
    }
    std::uint64_t groups = opt_.groups().size();
    ar.value(groups, "optimizer.groups");
    if (groups != opt_.groups().size()) throw_format(ar, "io.mismatch", "optimizer group count differs");
    for (auto& g : opt_.groups()) {
      std::string name = g.name();
      ar.text(name, "optimizer.name");
      if (name != g.name()) throw_format(ar, "io.mismatch", "optimizer group '" + name + "' where '" + g.name() + "' was expected");
      std::uint64_t steps = g.step_count();
      std::uint8_t frozen = g.frozen() ? 1 : 0;
      ar.value(steps, "optimizer.step");
      ar.value(frozen, "optimizer.frozen");
      g.set_step_count(steps);
      frozen ? opt_.freeze(name) : opt_.unfreeze(name);
      for (int m = 0; m < Opt::kMoments; ++m) ar.array(g.moment(m), "optimizer.moment");
    }
    if constexpr (Ar::loading) validate_loaded(ar, rng_text);
  }

  template <class Ar>
  void validate_loaded(Ar& ar, const std::string& rng_text) {
    std::istringstream rs(rng_text);
    rs >> rng_;
    if (!rs) throw_format(ar, "io.format", "bad RNG state");
    if (perm_pos_ > perm_.size()) throw_format(ar, "io.format", "permutation position out of range");
    for (int v : perm_)
      if (v < 0 || v >= model_.frame_count()) throw_format(ar, "io.format", "permutation entry out of range");
    for (SetState* s : active_)
      if (s->accum.size() != model_.cloud(s->which).size() || s->denom.size() != s->accum.size() ||
          (options_.prune_weight > 0 && s->weight.size() != s->accum.size()) ||
          (efficiency_sums_open(stats_.iterations) && (s->eff_weight.size() != s->accum.size() || s->eff_evals.size() != s->accum.size())))
        throw_format(ar, "io.format", "densification statistics do not match the Gaussian count");
    alpha_groups_.restore(opt_);
    camera_groups_.restore(opt_);
  }

  template <class Ar>
  [[noreturn]] static void throw_format(Ar& ar, const char* id, const std::string& why) {
    if constexpr (Ar::loading)
      throw io_error(id, ar.r.file(), why);
    else
      throw io_error(id, "checkpoint", why);
  }

  void check_frame(int frame) const {
    if (frame < 0 || frame >= model_.frame_count())
      throw option_error("option.frame", "frame index " + std::to_string(frame), "outside the clip");
  }

  /// Settings of iteration k: deformation on after the warm-up (returned), active SH degree, render size.
  bool configure(int k) {
    const bool deform = k >= options_.deformation_warmup;
    model_.deformation_enabled = deform;
    fields_constant_ = options_.freeze_deformation_from > 0 && k >= options_.freeze_deformation_from;
    background_frozen_ = model_.has_foreground && options_.freeze_background_from > 0 && k >= options_.freeze_background_from;
    // The backward's blend statistics only while a prune will read them (the weight prune's, in the
    // densification window; the efficiency prune's, before it acts).
    ctx_.blend_weights = (options_.prune_weight > 0 && k < options_.densify_until) || efficiency_pending(k);
    graph_.settings.active_sh_degree = options_.active_sh_degree(k, D);
    graph_.weights.lambda_dssim = options_.lambda_dssim_at(k);
    graph_.weights.bkg = background_frozen_ ? 0.0 : options_.weight_bkg;  // its term's gradient would reach the frozen set alone
    // Bands not active yet have a zero gradient and, never having been active, zero moments: Adam
    // leaves them as they are, so it need not read them (split_adam.hpp, `active`).
    if constexpr (requires(typename OptimizerPolicy::Hyper h) { h.active = std::size_t(0); }) {
      const std::size_t columns = std::size_t(3 * sh::coeff_count(graph_.settings.active_sh_degree));
      for (SetState* s : active_) opt_.group(s->sh_group).options().hyper.active = columns;
    }
    level_ = level_for(options_.resolution_scale(k, model_.width(), model_.height()));
    window_ = level_ ? PixelWindow{} : options_.crop_window(k, model_.width(), model_.height());
    return deform;
  }


  /// The frames (and detail maps) at frame size x `scale`, made on first use; nullptr at full size.
  const Level* level_for(double scale) {
    const int w = std::max(1, static_cast<int>(std::lround(model_.width() * scale)));
    const int h = std::max(1, static_cast<int>(std::lround(model_.height() * scale)));
    if (w == model_.width() && h == model_.height()) return nullptr;
    for (const Level& l : levels_)
      if (l.width == w && l.height == h) return &l;
    Level& l = levels_.emplace_back();
    l.width = w, l.height = h;
    for (const auto& f : frames_) l.frames.push_back(resize_area(f, w, h));
    if (options_.detail_weighted_l1)
      for (const auto& f : l.frames) l.detail.push_back(detail_weight_map<Scalar>(f, options_.detail_gain, pool_));
    return &l;
  }

  /// Target of clip frame fi at this iteration's render size (its window, with a training crop).
  [[nodiscard]] const Image<Scalar, 3>& target(int fi) {
    if (!window_.empty()) return crop_of(frames_[std::size_t(fi)], crop_frame_);
    return level_ ? level_->frames[std::size_t(fi)] : frames_[std::size_t(fi)];
  }

  /// `window_` of `src` into `dst`.
  template <int C>
  const Image<Scalar, C>& crop_of(const Image<Scalar, C>& src, Image<Scalar, C>& dst) const {
    const PixelWindow& w = window_;
    if (dst.width() != w.width || dst.height() != w.height) dst.resize(w.width, w.height);
    const auto v = ConstImageView<Scalar, C>(src).crop(w.x, w.y, w.width, w.height);
    for (int y = 0; y < w.height; ++y) std::copy_n(v.row(y), std::size_t(w.width) * C, dst.pixel(0, y));
    return dst;
  }

  /// Graph forward and backward of clip frame fi into the optimiser's gradient buffers (losses,
  /// PSNR and stage times into `info`). False if the loss or an image gradient was not finite.
  bool gradients(int fi, bool deform, IterationInfo& info) {
    ClipGradients<Scalar, Field> sinks;
    for (SetState* s : active_) {
      if (frozen_set(*s)) continue;  // a constant of the graph: no sink at all
      (s->which == GaussianSet::foreground ? sinks.frg : sinks.bkg) = s->grad.grads();
      const bool field = deform && model_.deforms(s->which);
      // A constant field passes the canonical gradients on and gets none (TrainOptions::freeze_deformation_from);
      // with grid_input_gradient the means' gradient needs its backward: it stays a sink, frozen in the optimiser.
      const bool constant = field && fields_constant_ && !model_.field(s->which).options().grid_input_gradient;
      (s->which == GaussianSet::foreground ? sinks.frg_field : sinks.bkg_field) = field && !constant ? &model_.field(s->which) : nullptr;
      (s->which == GaussianSet::foreground ? sinks.frg_field_constant : sinks.bkg_field_constant) = constant;
    }
    if (model_.has_foreground) sinks.alpha = alpha_grad_.storage();
    if (refines_camera(fi))
      sinks.camera = camera_grad_;
    else
      std::fill(camera_grad_.begin(), camera_grad_.end(), Scalar(0));  // frame 0: no correction, no gradient
    const Image<Scalar, 3>& target_fi = target(fi);
    const ConstImageView<Scalar, 3> tv(target_fi);
    ctx_.times = {};
    keep_frozen_render(tv.width(), tv.height());
    const ClipLosses L = graph_.forward(model_, fi, {&tv, 1}, ctx_, sinks, detail_weight(fi), pool_, window_);
    info.loss = L.total, info.loss_frg = L.frg, info.loss_bkg = L.bkg, info.loss_merged = L.merged;
    info.width = tv.width(), info.height = tv.height();
    info.frg_raster = model_.has_foreground ? ctx_.frg.stats : RasterStats{};
    info.bkg_raster = ctx_.bkg.stats;
    {
      ScopedTimer t(ctx_.times.loss);
      info.psnr = psnr(ctx_.merged, target_fi);
    }
    const bool ok = std::isfinite(info.loss) && graph_.backward(ctx_, pool_);
    info.times.deformation += ctx_.times.deformation;
    info.times.raster_forward += ctx_.times.raster_forward;
    info.times.raster_backward += ctx_.times.raster_backward;
    info.times.loss += ctx_.times.loss;
    return ok;
  }

  /// A frozen background's renders are made once per render size, SH degree and deformation state and read by every
  /// forward after (ClipGraph::freeze_render; the same bits as rendering it); not with camera
  /// refinement (the cameras move) or a training crop (a window). Dropped when the set thaws.
  void keep_frozen_render(int width, int height) {
    const bool keep = background_frozen_ && !options_.refines_cameras() && window_.empty();
    if (!keep) {
      if (!ctx_.bkg_rendered.empty()) Graph::thaw_render(ctx_, GaussianSet::background);
      return;
    }
    if (graph_.has_frozen_render(model_, ctx_, GaussianSet::background, width, height)) return;
    graph_.freeze_render(model_, GaussianSet::background, width, height, ctx_, pool_);
  }

  /// Unfreezes this frame's alpha and camera groups (freezing the previous frame's) and the
  /// deformation groups iff `deform`. Returns true (for chaining).
  bool select_groups(int fi, bool deform) {
    alpha_groups_.select(opt_, fi);
    camera_groups_.select(opt_, fi);
    for (SetState* s : active_) {
      // A static background's field stays frozen, and every field once it is a constant.
      const bool on = deform && model_.deforms(s->which) && !fields_constant_ && !frozen_set(*s);
      if (on != !opt_.frozen(s->field_group)) (on ? opt_.unfreeze(s->field_group) : opt_.freeze(s->field_group));
      // A frozen set's Gaussian groups (TrainOptions::freeze_background_from) take no step.
      for (const std::string& name : s->gaussian_groups)  // also after a checkpoint of another freeze
        if (frozen_set(*s) != opt_.frozen(name)) (frozen_set(*s) ? opt_.freeze(name) : opt_.unfreeze(name));
    }
    return true;
  }

  [[nodiscard]] bool gradients_finite() const {
    for (const auto& g : opt_.groups()) {
      if (g.frozen()) continue;
      for (const auto& seg : g.segments())
        if (!detail::all_finite<Scalar>(seg.grad)) return false;
    }
    return true;
  }

  /// Densification statistics (3DGS: norm of the 2D mean gradient of the Gaussians visible in fi).
  /// The gradients are in pixels of this iteration's render size; NDC units do not depend on it (a
  /// training crop's pixels are full-size pixels: NDC of the whole frame).
  void accumulate_densify_stats(int fi) {
    (void)fi;
    const int tw = level_ ? level_->width : model_.width(), th = level_ ? level_->height : model_.height();
    const Scalar sx = options_.densify_grad_ndc ? Scalar(0.5) * Scalar(tw) : Scalar(1);
    const Scalar sy = options_.densify_grad_ndc ? Scalar(0.5) * Scalar(th) : Scalar(1);
    for (SetState* s : active_) {
      const bool f = s->which == GaussianSet::foreground;
      const RasterContext<Scalar, 3>& rc = f ? ctx_.frg : ctx_.bkg;
      const std::vector<Scalar>& m2d = f ? ctx_.frg_mean2d : ctx_.bkg_mean2d;
      for (std::size_t i = 0; i < s->accum.size(); ++i) {
        if (rc.radii[i] <= 0) continue;
        const Scalar gx = m2d[2 * i] * sx, gy = m2d[2 * i + 1] * sy;
        s->accum[i] += std::sqrt(gx * gx + gy * gy);
        s->denom[i] += Scalar(1);
      }
      if (!s->weight.empty()) {  // blend weights in full-size pixels: x (W H) / (w h)
        const std::vector<Scalar>& bw = f ? ctx_.frg_weight : ctx_.bkg_weight;
        const Scalar to_full = Scalar(double(model_.width()) * model_.height() / (double(tw) * th));
        for (std::size_t i = 0; i < s->weight.size(); ++i) s->weight[i] += bw[i] * to_full;
      }
    }
  }

  /// The first iteration whose blend statistics the efficiency prune reads: the last densification
  /// event before prune_efficiency_at resets them (an event at prune_efficiency_at itself runs after
  /// the prune), 0 without one.
  [[nodiscard]] int efficiency_window_start() const noexcept {
    const int at = options_.prune_efficiency_at, every = options_.densify_interval;
    if (every <= 0) return 0;
    const int e = std::min(options_.densify_until, at - 1) / every * every;
    return e >= options_.densify_from && e > 0 ? e : 0;
  }
  /// True if the periodic efficiency prune (TrainOptions::prune_efficiency_from) acts at the
  /// densification event after `done` iterations.
  [[nodiscard]] bool periodic_efficiency_prune(int done) const noexcept {
    const int first = options_.first_efficiency_event();
    return options_.prune_efficiency > 0 && first >= 0 && done >= first && options_.is_densify_event(done);
  }
  /// True while iteration k's blend statistics feed an efficiency prune still to come: the one-shot
  /// prune's window [efficiency_window_start, prune_efficiency_at), and the periodic prune's, from
  /// the event before its first (or 0) up to the last densification event.
  [[nodiscard]] bool efficiency_pending(int k) const noexcept {
    if (!(options_.prune_efficiency > 0)) return false;
    const int at = options_.prune_efficiency_at;
    if (at > 0 && k >= efficiency_window_start() && k < at) return true;
    const int first = options_.first_efficiency_event();
    if (first < 0) return false;
    const int start = options_.is_densify_event(first - options_.densify_interval) ? first - options_.densify_interval : 0;
    return k >= start && k < options_.last_densify_event();
  }
  /// True if after `done` iterations the efficiency sums hold something (the checkpoint carries them
  /// then only: right after a prune or a densification event they are zeros, so a checkpoint written
  /// there by any run loads).
  [[nodiscard]] bool efficiency_sums_open(int done) const noexcept {
    return done > 0 && efficiency_pending(done - 1) && !options_.is_densify_event(done) &&
           !(options_.prune_efficiency_at > 0 && done == options_.prune_efficiency_at);
  }

  void accumulate_efficiency_stats() {
    for (SetState* s : active_) {
      if (frozen_set(*s)) continue;  // no backward ran for it
      const bool f = s->which == GaussianSet::foreground;
      const std::vector<Scalar>& bw = f ? ctx_.frg_weight : ctx_.bkg_weight;
      const std::vector<Scalar>& be = f ? ctx_.frg_evals : ctx_.bkg_evals;
      if (bw.size() != s->eff_weight.size() || be.size() != s->eff_evals.size()) continue;  // this iteration rendered no such backward
      for (std::size_t i = 0; i < bw.size(); ++i) s->eff_weight[i] += bw[i], s->eff_evals[i] += be[i];
    }
  }

  /// TrainOptions::prune_efficiency: drops, from every set that is not a constant, the Gaussians
  /// with eff_evals > 0 and eff_weight < E x eff_evals (weight per evaluation below the set's
  /// threshold E: prune_efficiency, or prune_efficiency_bkg for the background set when that is set),
  /// keeping at least the set's most efficient one; the optimiser rows and every per-Gaussian
  /// statistic follow the edit.
  void prune_inefficient() {
    for (SetState* s : active_) {
      if (frozen_set(*s)) continue;
      const bool own = s->which == GaussianSet::background && options_.prune_efficiency_bkg > 0;
      const Scalar threshold = Scalar(own ? options_.prune_efficiency_bkg : options_.prune_efficiency);
      const std::size_t n = s->eff_weight.size();
      std::vector<std::uint8_t> keep(n, 1);
      std::size_t kept = n, best = n;
      for (std::size_t i = 0; i < n; ++i) {
        const Scalar e = s->eff_evals[i];
        if (!(e > 0)) continue;
        if (best == n || s->eff_weight[i] * s->eff_evals[best] > s->eff_weight[best] * e) best = i;  // ties: the lower row
        if (s->eff_weight[i] < threshold * e) keep[i] = 0, --kept;
      }
      if (best < n && !keep[best]) keep[best] = 1, ++kept;  // the set's most efficient Gaussian stays
      if (kept == n) {  // nothing to drop: the next window's sums start from zero all the same
        std::fill(s->eff_weight.begin(), s->eff_weight.end(), Scalar(0));
        std::fill(s->eff_evals.begin(), s->eff_evals.end(), Scalar(0));
        continue;
      }
      model_.cloud(s->which).keep_rows(keep);
      for (const auto& g : s->gaussian_groups) opt_.keep_rows(g, keep);
      auto compact = [&](std::vector<Scalar>& v) {  // the densification sums go on over the kept rows
        if (v.size() != n) return;
        std::size_t out = 0;
        for (std::size_t i = 0; i < n; ++i)
          if (keep[i]) v[out++] = v[i];
        v.resize(out);
      };
      compact(s->accum), compact(s->denom), compact(s->weight);
      s->eff_weight.assign(kept, Scalar(0)), s->eff_evals.assign(kept, Scalar(0));
      s->grad.resize(kept);
      rebind_set(*s);
      stats_.pruned += n - kept;
    }
  }

  /// Densification / pruning and opacity reset after `done_iters` iterations, on schedule.
  void maintain(int done_iters, IterationInfo& info) {
    if (options_.is_densify_event(done_iters)) {
      ScopedTimer t(info.times.densify);
      if (periodic_efficiency_prune(done_iters)) prune_inefficient();  // over the sums since the event before
      densify(done_iters);
      info.densified = true;
    }
    if (done_iters <= options_.densify_until && done_iters % options_.opacity_reset_interval == 0) reset_opacity();
  }

  [[nodiscard]] ConstImageView<Scalar, 1> detail_weight(int fi) {
    if (!options_.detail_weighted_l1) return {};
    if (!window_.empty()) return ConstImageView<Scalar, 1>(crop_of(detail_weights_[std::size_t(fi)], crop_detail_));
    return ConstImageView<Scalar, 1>(level_ ? level_->detail[std::size_t(fi)] : detail_weights_[std::size_t(fi)]);
  }

  void setup() {
    options_.validate();
    const int n = model_.frame_count();
    if (n < 1) throw option_error("option.clip", "model", "the clip model has no frames");
    if (frames_.size() != std::size_t(n))
      throw option_error("option.clip", "frames", "got " + std::to_string(frames_.size()) + " frames for a clip of " + std::to_string(n));
    for (std::size_t i = 0; i < frames_.size(); ++i)
      if (frames_[i].width() != model_.width() || frames_[i].height() != model_.height())
        throw option_error("option.clip", "frame " + std::to_string(i), "size differs from the camera's");
    graph_.weights = {options_.weight_frg, options_.weight_bkg, options_.weight_merged, options_.lambda_dssim};
    // The model carries the stop rule it is trained with: every later render of it uses the same.
    model_.min_transmittance = static_cast<Scalar>(options_.min_transmittance);
    model_.blend_at_stop = options_.blend_at_stop;
    alpha_grad_.resize(model_.width(), model_.height());
    if (options_.detail_weighted_l1) {
      detail_weights_.clear();
      for (const auto& f : frames_) detail_weights_.push_back(detail_weight_map<Scalar>(f, options_.detail_gain, pool_));
    }
    frg_.which = GaussianSet::foreground;
    frg_.prefix = "frg.";
    bkg_.which = GaussianSet::background;
    bkg_.prefix = "bkg.";
    active_.clear();
    if (model_.has_foreground) active_.push_back(&frg_);
    active_.push_back(&bkg_);
    for (SetState* s : active_) add_set_groups(*s);
    alpha_groups_.clear(model_.has_foreground ? n : 0);
    for (int i = 0; i < n && model_.has_foreground; ++i) {
      const std::string name = "alpha." + std::to_string(i);
      auto& a = model_.alpha_logit[std::size_t(i)];
      // x lr_alpha_fine from lr_fine_from on (TrainOptions).
      opt_.add_group(GO{name, annealed(LrSchedule::constant(options_.lr_alpha).with_step(options_.lr_fine_from, options_.lr_alpha_fine)), hyper(), 1},
                     a.storage(), alpha_grad_.storage());
      alpha_groups_.add(opt_, i, name);
    }
    camera_groups_.clear(options_.refines_cameras() ? n : 0);
    camera_xi_.assign(options_.refines_cameras() ? std::size_t(6 * n) : 0, Scalar(0));
    camera_grad_.assign(6, Scalar(0));
    if (options_.refines_cameras()) {
      const std::span<Scalar> xi(camera_xi_), g(camera_grad_);
      const double radius = double(model_.scene_radius);
      for (int i = 1; i < n; ++i)  // frame 0 is the gauge: it keeps its camera, no groups
        for (int k = 0; k < 2; ++k) {
          const std::string name = (k == 0 ? "camera_rotation." : "camera_translation.") + std::to_string(i);
          opt_.add_group(GO{name, annealed(LrSchedule::constant(k == 0 ? options_.lr_camera_rotation : options_.lr_camera_translation * radius)),
                            hyper(), 3},
                         xi.subspan(std::size_t(6 * i + 3 * k), 3), g.subspan(std::size_t(3 * k), 3));
          camera_groups_.add(opt_, i, name);
        }
    }
  }

  [[nodiscard]] bool refines_camera(int fi) const noexcept { return options_.refines_cameras() && fi >= 1; }

  /// Camera fi with its correction xi_fi folded in (Camera::world_moved).
  [[nodiscard]] Camera<Scalar> folded_camera(int fi) const {
    const Scalar* x = camera_xi_.data() + 6 * fi;
    using V = typename Camera<Scalar>::Vec3;
    return model_.cameras[std::size_t(fi)].world_moved(V(x[0], x[1], x[2]), V(x[3], x[4], x[5]));
  }

  /// Folds xi_fi into camera fi and sets it back to 0 (see the file comment).
  void fold_camera(int fi) {
    model_.cameras[std::size_t(fi)] = folded_camera(fi);
    std::fill_n(camera_xi_.begin() + 6 * fi, 6, Scalar(0));
  }

  using GO = typename Opt::GroupOptions;
  /// `s` with TrainOptions::lr_anneal_from's descent (unchanged without one).
  [[nodiscard]] LrSchedule annealed(const LrSchedule& s) const {
    return options_.lr_anneal_from > 0 ? s.with_anneal(options_.lr_anneal_from, options_.iterations, options_.lr_anneal_factor) : s;
  }
  [[nodiscard]] typename OptimizerPolicy::Hyper hyper() const { return group_hyper<OptimizerPolicy>(options_.adam_eps); }

  /// The optimiser groups of one set: mean, log_scale, rotation, opacity, sh, deformation (frozen).
  void add_set_groups(SetState& s) {
    Cloud& c = model_.cloud(s.which);
    resize_set(s);
    const std::string& p = s.prefix;
    for (std::size_t k = 0; k < s.gaussian_groups.size(); ++k) s.gaussian_groups[k] = p + kGaussianGroups[k];
    const double radius = double(model_.scene_radius);
    const bool lazy = options_.sparse_adam;
    // The position rate x lr_position_fine from lr_fine_from on (TrainOptions).
    opt_.add_group(GO{p + "mean",
                      annealed(LrSchedule::exponential(options_.lr_position_init * radius, options_.lr_position_final * radius,
                                                       options_.lr_position_steps)
                                   .with_step(options_.lr_fine_from, options_.lr_position_fine)),
                      hyper(), 3, lazy},
                   c.mean, s.grad.dL_dmean);
    opt_.add_group(GO{p + "log_scale", annealed(LrSchedule::constant(options_.lr_scale)), hyper(), 3, lazy}, c.log_scale, s.grad.dL_dlog_scale);
    opt_.add_group(GO{p + "rotation", annealed(LrSchedule::constant(options_.lr_rotation)), hyper(), 4, lazy}, c.rotation, s.grad.dL_drotation);
    opt_.add_group(GO{p + "opacity", annealed(LrSchedule::constant(options_.lr_opacity)), hyper(), 1, lazy}, c.opacity_logit,
                   s.grad.dL_dopacity_logit);
    const auto hs = group_hyper<OptimizerPolicy>(options_.adam_eps, D, options_.lr_sh_dc, options_.lr_sh_rest);
    s.sh_group = p + "sh";
    // Both bands' rates x lr_sh_fine from lr_fine_from on (the group's rate scales the per-band ones).
    opt_.add_group(GO{s.sh_group, annealed(LrSchedule::constant(options_.lr_sh_dc).with_step(options_.lr_fine_from, options_.lr_sh_fine)), hs,
                      std::size_t(3 * sh::coeff_count(D)), lazy},
                   c.sh, s.grad.dL_dsh);
    s.field_group = p + "deformation";
    opt_.add_group(GO{s.field_group,
                      annealed(LrSchedule::exponential(options_.lr_deformation_init, options_.lr_deformation_final, options_.lr_deformation_steps)),
                      hyper(), 1, lazy},
                   model_.field(s.which).segments());
    opt_.freeze(s.field_group);
  }

  /// PSNR (dB, range 1) with a reused per-chunk buffer (metrics::psnr allocates its partial sums).
  double psnr(const Image<Scalar, 3>& a, const Image<Scalar, 3>& b) {
    const std::size_t rows = std::size_t(a.height()), n = std::size_t(a.width()) * 3;
    psnr_partial_.resize(chunk_count(rows, 8));
    parallel_for_chunks(pool_, rows, 8, [&](std::size_t c, std::size_t r0, std::size_t r1) {
      double s = 0;
      for (std::size_t r = r0; r < r1; ++r) {
        const Scalar* x = a.pixel(0, int(r));
        const Scalar* y = b.pixel(0, int(r));
        for (std::size_t i = 0; i < n; ++i) s += double(x[i] - y[i]) * double(x[i] - y[i]);
      }
      psnr_partial_[c] = s;
    });
    double total = 0;
    for (double v : psnr_partial_) total += v;
    const double mse = total / double(rows * n);
    return mse > 0 ? -10.0 * std::log10(mse) : std::numeric_limits<double>::infinity();
  }

  /// Sizes a set's per-Gaussian buffers to its cloud (allocates only when the count changed).
  void resize_set(SetState& s) {
    const std::size_t n = model_.cloud(s.which).size();
    s.grad.resize(n);
    s.accum.assign(n, Scalar(0));
    s.denom.assign(n, Scalar(0));
    s.weight.assign(options_.prune_weight > 0 ? n : 0, Scalar(0));
    s.eff_weight.assign(options_.prune_efficiency > 0 ? n : 0, Scalar(0));
    s.eff_evals.assign(options_.prune_efficiency > 0 ? n : 0, Scalar(0));
  }

  void rebind_set(SetState& s) {
    Cloud& c = model_.cloud(s.which);
    const std::string& p = s.prefix;
    opt_.bind(p + "mean", c.mean, s.grad.dL_dmean);
    opt_.bind(p + "log_scale", c.log_scale, s.grad.dL_dlog_scale);
    opt_.bind(p + "rotation", c.rotation, s.grad.dL_drotation);
    opt_.bind(p + "opacity", c.opacity_logit, s.grad.dL_dopacity_logit);
    opt_.bind(p + "sh", c.sh, s.grad.dL_dsh);
  }

  int next_frame() {
    const int n = model_.frame_count();
    if (perm_pos_ >= perm_.size()) {
      perm_.resize(std::size_t(n));
      for (int i = 0; i < n; ++i) perm_[std::size_t(i)] = i;
      for (int i = n - 1; i > 0; --i) std::swap(perm_[std::size_t(i)], perm_[std::size_t(rng_() % std::uint64_t(i + 1))]);
      perm_pos_ = 0;
    }
    return perm_[perm_pos_++];
  }

  void clamp_scales() {
    const Scalar lo = Scalar(options_.min_log_scale);
    const Scalar hi = Scalar(std::log(options_.max_scale_extent * std::max(double(model_.extent()), 1e-30)));
    for (SetState* s : active_)
      if (!frozen_set(*s))  // a constant stays as it is (its renders are kept)
        for (Scalar& v : model_.cloud(s->which).log_scale) v = std::clamp(v, lo, std::max(lo, hi));
  }

  void densify(int done_iters) {
    DensifyOptions d;
    d.grad_threshold = options_.densify_grad_threshold;
    d.dense_scale = options_.percent_dense * double(model_.extent());
    d.children = options_.split_children;
    d.split_scale_divisor = options_.split_scale_divisor;
    d.prune_opacity = options_.prune_opacity;
    d.prune_weight = done_iters >= options_.prune_weight_from ? options_.prune_weight : 0.0;
    for (SetState* s : active_) {
      d.max_count = budget(s->which);
      const std::string& p = s->prefix;
      // Mean blend weight over the views that saw each Gaussian (in place: the sums are reset below).
      for (std::size_t i = 0; i < s->weight.size(); ++i) s->weight[i] = s->denom[i] > 0 ? s->weight[i] / s->denom[i] : Scalar(0);
      const auto r = densify_and_prune(model_.cloud(s->which), std::span<const Scalar>(s->accum), std::span<const Scalar>(s->denom),
                                       std::span<const Scalar>(s->weight), d, rng_, [&](std::span<const std::size_t> src, std::span<const std::uint8_t> keep) {
                                         for (const char* g : kGaussianGroups) {
                                           opt_.append_rows(p + g, src, RowMoments::zero);
                                           opt_.keep_rows(p + g, keep);
                                         }
                                       });
      stats_.cloned += r.cloned;
      stats_.split += r.split;
      stats_.pruned += r.pruned;
      resize_set(*s);
      rebind_set(*s);
    }
    ++stats_.densify_events;
  }

  [[nodiscard]] std::size_t budget(GaussianSet which) const {
    return options_.gaussian_budget(which == GaussianSet::foreground, model_.width(), model_.height());
  }

  /// A new model's sets above their budgets lose their most transparent rows (densify_and_prune
  /// with no candidate and no opacity threshold only enforces the budget).
  void cut_to_budget() {
    DensifyOptions d;
    d.prune_opacity = 0;
    for (GaussianSet w : {GaussianSet::foreground, GaussianSet::background}) {
      if (w == GaussianSet::foreground && !model_.has_foreground) continue;
      Cloud& c = model_.cloud(w);
      d.max_count = budget(w);
      if (c.size() <= d.max_count) continue;
      const std::vector<Scalar> zero(c.size(), Scalar(0));
      densify_and_prune(c, std::span<const Scalar>(zero), std::span<const Scalar>(zero), d, rng_, [](auto, auto) {});
    }
  }

  void reset_opacity() {
    const Scalar cap = logit(Scalar(options_.opacity_reset_value));
    for (SetState* s : active_) {
      for (Scalar& v : model_.cloud(s->which).opacity_logit) v = std::min(v, cap);
      auto& g = opt_.group(s->prefix + "opacity");
      for (int m = 0; m < Opt::kMoments; ++m) std::fill(g.moment(m).begin(), g.moment(m).end(), Scalar(0));
    }
    ++stats_.opacity_resets;
  }

  Model model_;
  std::vector<Image<Scalar, 3>> frames_;
  TrainOptions options_;
  ThreadPool* pool_ = nullptr;
  std::mt19937_64 rng_;
  std::vector<int> perm_;
  std::size_t perm_pos_ = 0;
  Graph graph_;
  ClipGraphContext<Scalar, Field> ctx_;
  Opt opt_;
  SetState frg_, bkg_;
  std::vector<SetState*> active_;
  /// Optimiser groups that each belong to one clip frame (an alpha map, a camera correction): only
  /// the trained frame's are unfrozen, as PyTorch skips parameters without a gradient.
  struct FrameGroups {
    std::vector<std::vector<std::string>> names;  ///< per frame (none for a frame without groups)
    int current = -1;                             ///< the frame whose groups are unfrozen (-1: none)
    void clear(int frames) { names.assign(std::size_t(frames), {}), current = -1; }
    /// Registers a group of frame i (added to `opt` by the caller), frozen.
    void add(Opt& opt, int i, const std::string& name) {
      names[std::size_t(i)].push_back(name);
      opt.freeze(name);
    }
    void select(Opt& opt, int fi) {
      if (names.empty() || current == fi) return;
      if (current >= 0)
        for (const auto& n : names[std::size_t(current)]) opt.freeze(n);
      for (const auto& n : names[std::size_t(fi)]) opt.unfreeze(n);
      current = fi;
    }
    /// `current` from the groups' frozen flags (after loading a checkpoint).
    void restore(const Opt& opt) {
      current = -1;
      for (std::size_t i = 0; i < names.size(); ++i)
        for (const auto& n : names[i])
          if (!opt.frozen(n)) current = int(i);
    }
  };
  FrameGroups alpha_groups_, camera_groups_;
  std::vector<Scalar> camera_xi_;    ///< 6 per frame: (omega, tau), 0 between steps
  std::vector<Scalar> camera_grad_;  ///< dL/dxi of the frame being trained (shared, like alpha_grad_)
  Image<Scalar, 1> alpha_grad_;
  std::vector<Image<Scalar, 1>> detail_weights_;
  std::deque<Level> levels_;        ///< resolution schedule's sizes (a deque: `level_` stays valid)
  const Level* level_ = nullptr;    ///< this iteration's, nullptr at full size
  bool fields_constant_ = false;    ///< this iteration's: TrainOptions::freeze_deformation_from reached
  bool background_frozen_ = false;  ///< this iteration's: TrainOptions::freeze_background_from reached (with a foreground)
  PixelWindow window_;              ///< this iteration's training crop (empty: the whole frame)
  Image<Scalar, 3> crop_frame_;     ///< the target's window
  Image<Scalar, 1> crop_detail_;    ///< the detail map's window
  ClipRenderBuffers<Scalar, Field> eval_;
  loss::SsimContext<Scalar, 3> eval_ssim_;
  TrainStats stats_;
  IterationInfo info_;
  std::vector<double> psnr_partial_;
};

}  // namespace video3dgs
