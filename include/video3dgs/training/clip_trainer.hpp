#pragma once
/// @file
/// `ClipTrainer<Model>`: stage 1 of Video-3DGS for one clip (DESIGN.md §2, §4).
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
/// then the hand-chained backward (loss -> merge -> rasterizer -> deformation field), a finiteness
/// check of every gradient (a non-finite loss or gradient skips the step and counts it in
/// `TrainStats::skipped_steps`; it never reaches a parameter), one Adam step (groups: per set mean,
/// log_scale, rotation, opacity, sh (DC at lr_sh_dc, other bands at lr_sh_rest), deformation; one
/// group per alpha map, only the current frame's stepped, as PyTorch skips parameters without a
/// gradient), the log-scale clamp, and densification / pruning / opacity reset on schedule with the
/// optimizer moments following the rows (training/densify.hpp).
///
/// Determinism: every kernel is thread-count independent, so a seed gives the same model for any
/// pool size. A checkpoint holds the model, the optimizer (moments, step counts), the iteration, the
/// RNG state, the epoch permutation and the densification accumulators: resuming continues exactly as
/// an uninterrupted run with the same options would. Buffers are allocated per clip (and when the
/// Gaussian count changes at densification); a steady-state iteration does not allocate.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
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
#include "video3dgs/gaussian/cloud.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/io/binary_stream.hpp"
#include "video3dgs/loss/l1_dssim.hpp"
#include "video3dgs/metrics/psnr.hpp"
#include "video3dgs/model/alpha_merge.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/model/clip_model_io.hpp"
#include "video3dgs/model/render_clip.hpp"
#include "video3dgs/optim/optimizer.hpp"
#include "video3dgs/optim/schedule.hpp"
#include "video3dgs/rasterizer/rasterizer.hpp"
#include "video3dgs/training/densify.hpp"
#include "video3dgs/training/detail_weight.hpp"
#include "video3dgs/training/split_adam.hpp"
#include "video3dgs/training/train_options.hpp"

namespace video3dgs {

inline constexpr const char* kClipCheckpointMagic = "V3DGSCKP";
inline constexpr std::uint32_t kClipCheckpointVersion = 1;

namespace detail {
/// True if no element is NaN or infinite (bit test: vectorises, no floating-point reduction).
template <class Scalar>
[[nodiscard]] bool all_finite(std::span<const Scalar> v) noexcept {
  using Bits = std::conditional_t<sizeof(Scalar) == 4, std::uint32_t, std::uint64_t>;
  constexpr Bits exp_mask = sizeof(Scalar) == 4 ? Bits(0x7f800000u) : Bits(0x7ff0000000000000ull);
  Bits bad = 0;
  for (std::size_t i = 0; i < v.size(); ++i) {
    Bits b;
    std::memcpy(&b, &v[i], sizeof(b));
    bad |= Bits((b & exp_mask) == exp_mask);
  }
  return bad == 0;
}
}  // namespace detail

/// Quality of a clip model over all its frames (merged, Frg-only and Bkg-only renders).
struct ClipEvaluation {
  double psnr = 0, ssim = 0;          ///< merged render, means over frames
  double psnr_frg = 0, psnr_bkg = 0;  ///< single-set renders
  std::vector<double> psnr_per_frame;
};

template <class Model, int TileSize = 16>
class ClipTrainer {
 public:
  using Scalar = typename Model::scalar_type;
  using Field = typename Model::field_type;
  using Cloud = typename Model::Cloud;
  static constexpr int D = Model::sh_degree;
  using Opt = Optimizer<Scalar, SplitLrAdam>;
  /// Called after every iteration; return false to stop `train` early.
  using Callback = std::function<bool(const IterationInfo&)>;

  /// @param frames one image per clip frame, the cameras' size (moved in; the trainer keeps them).
  /// @throws option_error (`option.train`, `option.clip`) on bad options or frames.
  ClipTrainer(Model model, std::vector<Image<Scalar, 3>> frames, const TrainOptions& options = {}, ThreadPool* pool = nullptr)
      : model_(std::move(model)), frames_(std::move(frames)), options_(options), pool_(pool), rng_(options.seed) {
    setup();
  }

  /// Resumes from a checkpoint written by `save_checkpoint` (same template arguments and options).
  /// @throws io_error (`io.*`) on a missing, truncated or mismatched file.
  ClipTrainer(const std::filesystem::path& checkpoint, std::vector<Image<Scalar, 3>> frames, const TrainOptions& options = {},
              ThreadPool* pool = nullptr)
      : frames_(std::move(frames)), options_(options), pool_(pool), rng_(options.seed) {
    const std::string bytes = read_file_bytes(checkpoint);
    io::BinaryReader r(bytes, checkpoint.string(), kClipCheckpointMagic, kClipCheckpointVersion);
    model_ = read_clip_model<Scalar, D, Field>(r);
    setup();
    restore(r);
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
    const auto t_start = clock::now();
    const int k = stats_.iterations;
    IterationInfo& info = info_;
    info = IterationInfo{};
    info.iteration = k;
    const int fi = next_frame();
    info.frame = fi;
    const bool deform = configure(k);
    const Camera<Scalar>& cam = model_.cameras[std::size_t(fi)];
    const bool fg = model_.has_foreground;
    forward(fi, info);
    bool ok = std::isfinite(info.loss) && backward(fi, deform, info);

    // ---- step ----
    auto t = clock::now();
    if (ok) {
      if (fg) {
        if (last_alpha_ != fi) {
          if (last_alpha_ >= 0) opt_.freeze(alpha_names_[std::size_t(last_alpha_)]);
          opt_.unfreeze(alpha_names_[std::size_t(fi)]);
          last_alpha_ = fi;
        }
      }
      for (SetState* s : active_) {
        if (deform != !opt_.frozen(s->field_group)) (deform ? opt_.unfreeze(s->field_group) : opt_.freeze(s->field_group));
      }
      for (const auto& g : opt_.groups()) {
        if (g.frozen()) continue;
        for (const auto& seg : g.segments())
          if (!detail::all_finite<Scalar>(seg.grad)) ok = false;
        if (!ok) break;
      }
    }
    if (ok) {
      // Densification statistics (3DGS: norm of the 2D mean gradient of visible Gaussians).
      if (k < options_.densify_until) {
        for (SetState* s : active_) {
          const Scalar sx = options_.densify_grad_ndc ? Scalar(0.5) * Scalar(cam.width) : Scalar(1);
          const Scalar sy = options_.densify_grad_ndc ? Scalar(0.5) * Scalar(cam.height) : Scalar(1);
          const std::size_t n = s->accum.size();
          for (std::size_t i = 0; i < n; ++i) {
            if (s->ctx.radii[i] <= 0) continue;
            const Scalar gx = s->dmean2d[2 * i] * sx, gy = s->dmean2d[2 * i + 1] * sy;
            s->accum[i] += std::sqrt(gx * gx + gy * gy);
            s->denom[i] += Scalar(1);
          }
        }
      }
      opt_.step(k, pool_);
      clamp_scales();
    } else {
      ++stats_.skipped_steps;
      info.skipped = true;
    }
    info.times.optimizer += secs(t);

    // ---- densify / prune / opacity reset ----
    const int done_iters = k + 1;
    if (done_iters >= options_.densify_from && done_iters <= options_.densify_until && done_iters % options_.densify_interval == 0) {
      t = clock::now();
      densify();
      info.densified = true;
      info.times.densify += secs(t);
    }
    if (done_iters <= options_.densify_until && done_iters % options_.opacity_reset_interval == 0) reset_opacity();

    stats_.iterations = done_iters;
    info.frg_count = model_.frg.size();
    info.bkg_count = model_.bkg.size();
    info.times.total = secs(t_start);
    stats_.times += info.times;
    if (!info.skipped) {
      stats_.last_loss = info.loss;
      stats_.last_psnr = info.psnr;
    }
    return info;
  }

  /// The loss of clip frame `frame` under the current iteration's settings (deformation on once
  /// `iterations() >= deformation_warmup`, active SH degree `iterations / sh_degree_interval`),
  /// forward only: the function whose gradient `gradients_at` computes.
  [[nodiscard]] double loss_at(int frame) {
    check_frame(frame);
    configure(stats_.iterations);
    IterationInfo info;
    forward(frame, info);
    return info.loss;
  }

  /// Forward and backward of clip frame `frame` under the current iteration's settings, without a
  /// step: afterwards every unfrozen optimiser group's gradient buffers (`optimizer().groups()`, and
  /// the gradient of `alpha.<frame>`, which all alpha groups share) hold dL/dparameter of `loss_at`.
  /// Returns the loss, or NaN if the loss or an image gradient was not finite or the rasterizer's
  /// backward refused its input (`step` also checks the parameter gradients before stepping).
  double gradients_at(int frame) {
    check_frame(frame);
    const bool deform = configure(stats_.iterations);
    IterationInfo info;
    forward(frame, info);
    const bool ok = std::isfinite(info.loss) && backward(frame, deform, info);
    return ok ? info.loss : std::numeric_limits<double>::quiet_NaN();
  }

  /// Mean PSNR / SSIM of the merged render over every frame, and PSNR of each set alone.
  [[nodiscard]] ClipEvaluation evaluate() {
    ClipEvaluation e;
    RasterSettings<Scalar, 3> rs = raster_.settings;
    rs.active_sh_degree = std::min(D, std::max(0, stats_.iterations - 1) / options_.sh_degree_interval);
    const int n = model_.frame_count();
    for (int i = 0; i < n; ++i) {
      render_clip_frame(model_, i, eval_, pool_, rs, false);
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
    w.put<std::int32_t>(stats_.iterations);
    std::ostringstream rs;
    rs << rng_;
    w.put_string(rs.str());
    w.put_vector(perm_);
    w.put<std::uint64_t>(perm_pos_);
    for (std::size_t v : {stats_.skipped_steps, stats_.cloned, stats_.split, stats_.pruned, stats_.densify_events, stats_.opacity_resets})
      w.put<std::uint64_t>(v);
    for (SetState* s : active_) {
      w.put_vector(s->accum);
      w.put_vector(s->denom);
    }
    w.put<std::uint64_t>(opt_.groups().size());
    for (const auto& g : opt_.groups()) {
      w.put_string(g.name());
      w.put<std::uint64_t>(g.step_count());
      w.put<std::uint8_t>(g.frozen() ? 1 : 0);
      for (int m = 0; m < Opt::kMoments; ++m) w.put_array(g.moment(m));
    }
    io::write_file_atomic(path, w.bytes());
  }

 private:
  struct SetState {
    GaussianSet which{};
    GaussianCloudGrad<Scalar, D> grad;
    std::vector<Scalar> d_mean, d_log_scale, d_rotation, dmean2d, accum, denom;
    DeformScratch<Scalar, Field> scratch;
    RasterContext<Scalar, 3> ctx;
    GaussianParams<Scalar> params;
    Image<Scalar, 3> d_image;
    std::string prefix, field_group;
  };

  using clock = std::chrono::steady_clock;
  /// Seconds since `a` (the stage timers of IterationInfo::times).
  static double secs(clock::time_point a) { return std::chrono::duration<double>(clock::now() - a).count(); }

  void check_frame(int frame) const {
    if (frame < 0 || frame >= model_.frame_count())
      throw option_error("option.frame", "frame index " + std::to_string(frame), "outside the clip");
  }

  /// Settings of iteration k: deformation on after the warm-up (returned), active SH degree.
  bool configure(int k) {
    const bool deform = k >= options_.deformation_warmup;
    model_.deformation_enabled = deform;
    raster_.settings.active_sh_degree = std::min(D, k / options_.sh_degree_interval);
    return deform;
  }

  /// Forward of clip frame fi: deform and rasterize each set, merge, the three losses (info.loss*,
  /// info.psnr, stage times).
  void forward(int fi, IterationInfo& info) {
    const Camera<Scalar>& cam = model_.cameras[std::size_t(fi)];
    const Image<Scalar, 3>& frame = frames_[std::size_t(fi)];
    for (SetState* s : active_) {
      auto t = clock::now();
      s->params = model_.deformed(s->which, fi, s->scratch, pool_);
      info.times.deformation += secs(t);
      t = clock::now();
      raster_.forward(cam, s->params, s->ctx, pool_);
      info.times.raster_forward += secs(t);
    }
    const auto t = clock::now();
    const ConstImageView<Scalar, 1> weight = detail_weight(fi);
    const Image<Scalar, 3>& Ib = bkg_.ctx.image;
    double Lf = 0, Lb = 0, Lm = 0;
    if (model_.has_foreground) {
      const Image<Scalar, 3>& If = frg_.ctx.image;
      alpha_merge_forward<Scalar, 3>(If, Ib, model_.alpha_logit[std::size_t(fi)], merged_, pool_);
      Lf = loss::l1_dssim_forward<Scalar, 3>(If, frame, loss_frg_, pool_);
      Lb = loss::l1_dssim_forward<Scalar, 3>(Ib, frame, loss_bkg_, pool_);
      Lm = loss::l1_dssim_forward<Scalar, 3>(merged_, frame, loss_merged_, pool_, weight);
      info.psnr = psnr(merged_, frame);
    } else {
      Lb = loss::l1_dssim_forward<Scalar, 3>(Ib, frame, loss_bkg_, pool_);
      Lm = weight.empty() ? Lb : loss::l1_dssim_forward<Scalar, 3>(Ib, frame, loss_merged_, pool_, weight);
      info.psnr = psnr(Ib, frame);
    }
    info.loss_frg = Lf;
    info.loss_bkg = Lb;
    info.loss_merged = Lm;
    info.loss = double(Scalar(options_.weight_frg)) * Lf + double(Scalar(options_.weight_bkg)) * Lb +
                double(Scalar(options_.weight_merged)) * Lm;
    info.times.loss += secs(t);
  }

  [[nodiscard]] ConstImageView<Scalar, 1> detail_weight(int fi) const {
    return options_.detail_weighted_l1 ? ConstImageView<Scalar, 1>(detail_weights_[std::size_t(fi)]) : ConstImageView<Scalar, 1>();
  }

  /// Backward of the last `forward(fi)`, hand-chained: losses -> merge -> rasterizer -> deformation
  /// field, into the optimiser's gradient buffers. False if an image gradient was not finite or the
  /// rasterizer's backward refused its input (the step is then skipped).
  bool backward(int fi, bool deform, IterationInfo& info) {
    auto t = clock::now();
    const Scalar wf = Scalar(options_.weight_frg), wb = Scalar(options_.weight_bkg), wm = Scalar(options_.weight_merged);
    const Image<Scalar, 3>& Ib = bkg_.ctx.image;
    const bool weighted = options_.detail_weighted_l1;
    if (model_.has_foreground) {
      d_merged_.fill(Scalar(0));
      loss::l1_dssim_backward<Scalar, 3>(loss_merged_, wm, d_merged_, pool_);
      alpha_merge_backward<Scalar, 3>(frg_.ctx.image, Ib, model_.alpha_logit[std::size_t(fi)], d_merged_, frg_.d_image, bkg_.d_image,
                                      alpha_grad_, pool_);
      loss::l1_dssim_backward<Scalar, 3>(loss_frg_, wf, frg_.d_image, pool_);
      loss::l1_dssim_backward<Scalar, 3>(loss_bkg_, wb, bkg_.d_image, pool_);
    } else {
      bkg_.d_image.fill(Scalar(0));
      loss::l1_dssim_backward<Scalar, 3>(loss_bkg_, weighted ? wb : wb + wm, bkg_.d_image, pool_);
      if (weighted) loss::l1_dssim_backward<Scalar, 3>(loss_merged_, wm, bkg_.d_image, pool_);
    }
    bool ok = detail::all_finite<Scalar>(frg_.d_image.storage()) && detail::all_finite<Scalar>(bkg_.d_image.storage());
    info.times.loss += secs(t);
    for (SetState* s : active_) {
      if (!ok) break;
      t = clock::now();
      RasterGrads<Scalar, 3> g;
      if (deform) {
        g.gaussians = {s->d_mean, s->d_log_scale, s->d_rotation, s->grad.dL_dopacity_logit, s->grad.dL_dsh};
      } else {
        g.gaussians = s->grad.grads();
      }
      g.dL_dmean2d = s->dmean2d;
      try {
        raster_.backward(s->ctx, s->d_image, {}, {}, g, pool_);
      } catch (const numeric_error&) {
        return false;
      }
      info.times.raster_backward += secs(t);
      if (deform) {
        t = clock::now();
        std::fill(s->grad.dL_dmean.begin(), s->grad.dL_dmean.end(), Scalar(0));
        std::fill(s->grad.dL_dlog_scale.begin(), s->grad.dL_dlog_scale.end(), Scalar(0));
        std::fill(s->grad.dL_drotation.begin(), s->grad.dL_drotation.end(), Scalar(0));
        Field& f = model_.field(s->which);
        f.zero_grad();
        f.backward(s->scratch.ctx, s->d_mean.data(), s->d_log_scale.data(), s->d_rotation.data(),
                   {s->grad.dL_dmean.data(), s->grad.dL_dlog_scale.data(), s->grad.dL_drotation.data()}, pool_);
        info.times.deformation += secs(t);
      }
    }
    return ok;
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
    const int W = model_.width(), H = model_.height();
    raster_.settings.background = {Scalar(0), Scalar(0), Scalar(0)};
    merged_.resize(W, H);
    d_merged_.resize(W, H);
    alpha_grad_.resize(W, H);
    loss_frg_ = loss::L1DssimContext<Scalar, 3>(loss_options());
    loss_bkg_ = loss::L1DssimContext<Scalar, 3>(loss_options());
    loss_merged_ = loss::L1DssimContext<Scalar, 3>(loss_options());
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
    frg_.d_image.resize(W, H);
    bkg_.d_image.resize(W, H);

    using GO = typename Opt::GroupOptions;
    auto hyper = [&] {
      typename SplitLrAdam::Hyper h;
      h.eps = options_.adam_eps;
      return h;
    };
    const double radius = double(model_.scene_radius);
    for (SetState* s : active_) {
      Cloud& c = model_.cloud(s->which);
      resize_set(*s);
      const std::string& p = s->prefix;
      opt_.add_group(GO{p + "mean",
                        LrSchedule::exponential(options_.lr_position_init * radius, options_.lr_position_final * radius,
                                                options_.lr_position_steps),
                        hyper(), 3},
                     c.mean, s->grad.dL_dmean);
      opt_.add_group(GO{p + "log_scale", LrSchedule::constant(options_.lr_scale), hyper(), 3}, c.log_scale, s->grad.dL_dlog_scale);
      opt_.add_group(GO{p + "rotation", LrSchedule::constant(options_.lr_rotation), hyper(), 4}, c.rotation, s->grad.dL_drotation);
      opt_.add_group(GO{p + "opacity", LrSchedule::constant(options_.lr_opacity), hyper(), 1}, c.opacity_logit,
                     s->grad.dL_dopacity_logit);
      auto hs = hyper();
      hs.row_width = std::size_t(3 * sh::coeff_count(D));
      hs.lead = 3;
      hs.tail_scale = options_.lr_sh_dc > 0 ? options_.lr_sh_rest / options_.lr_sh_dc : 1.0;
      hs.base = c.sh.data();
      opt_.add_group(GO{p + "sh", LrSchedule::constant(options_.lr_sh_dc), hs, hs.row_width}, c.sh, s->grad.dL_dsh);
      s->field_group = p + "deformation";
      opt_.add_group(GO{s->field_group,
                        LrSchedule::exponential(options_.lr_deformation_init, options_.lr_deformation_final,
                                                options_.lr_deformation_steps),
                        hyper(), 1},
                     model_.field(s->which).segments());
      opt_.freeze(s->field_group);
    }
    alpha_names_.clear();
    if (model_.has_foreground) {
      for (int i = 0; i < n; ++i) {
        alpha_names_.push_back("alpha." + std::to_string(i));
        auto& a = model_.alpha_logit[std::size_t(i)];
        opt_.add_group(GO{alpha_names_.back(), LrSchedule::constant(options_.lr_alpha), hyper(), 1}, a.storage(), alpha_grad_.storage());
        opt_.freeze(alpha_names_.back());
      }
    }
    last_alpha_ = -1;
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

  [[nodiscard]] loss::L1DssimOptions loss_options() const {
    loss::L1DssimOptions o;
    o.lambda_dssim = options_.lambda_dssim;
    return o;
  }

  /// Sizes a set's per-Gaussian buffers to its cloud (allocates only when the count changed).
  void resize_set(SetState& s) {
    const std::size_t n = model_.cloud(s.which).size();
    s.grad.resize(n);
    s.d_mean.assign(3 * n, Scalar(0));
    s.d_log_scale.assign(3 * n, Scalar(0));
    s.d_rotation.assign(4 * n, Scalar(0));
    s.dmean2d.assign(2 * n, Scalar(0));
    s.accum.assign(n, Scalar(0));
    s.denom.assign(n, Scalar(0));
  }

  void rebind_set(SetState& s) {
    Cloud& c = model_.cloud(s.which);
    const std::string& p = s.prefix;
    opt_.bind(p + "mean", c.mean, s.grad.dL_dmean);
    opt_.bind(p + "log_scale", c.log_scale, s.grad.dL_dlog_scale);
    opt_.bind(p + "rotation", c.rotation, s.grad.dL_drotation);
    opt_.bind(p + "opacity", c.opacity_logit, s.grad.dL_dopacity_logit);
    opt_.bind(p + "sh", c.sh, s.grad.dL_dsh);
    opt_.group(p + "sh").options().hyper.base = c.sh.data();
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
      for (Scalar& v : model_.cloud(s->which).log_scale) v = std::clamp(v, lo, std::max(lo, hi));
  }

  void densify() {
    DensifyOptions d;
    d.grad_threshold = options_.densify_grad_threshold;
    d.dense_scale = options_.percent_dense * double(model_.extent());
    d.children = options_.split_children;
    d.split_scale_divisor = options_.split_scale_divisor;
    d.prune_opacity = options_.prune_opacity;
    d.max_count = options_.max_gaussians;
    for (SetState* s : active_) {
      const std::string& p = s->prefix;
      const auto r = densify_and_prune(model_.cloud(s->which), std::span<const Scalar>(s->accum), std::span<const Scalar>(s->denom), d,
                                       rng_, [&](std::span<const std::size_t> src, std::span<const std::uint8_t> keep) {
                                         for (const char* g : {"mean", "log_scale", "rotation", "opacity", "sh"}) {
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

  void reset_opacity() {
    const Scalar cap = logit(Scalar(options_.opacity_reset_value));
    for (SetState* s : active_) {
      for (Scalar& v : model_.cloud(s->which).opacity_logit) v = std::min(v, cap);
      auto& g = opt_.group(s->prefix + "opacity");
      for (int m = 0; m < Opt::kMoments; ++m) std::fill(g.moment(m).begin(), g.moment(m).end(), Scalar(0));
    }
    ++stats_.opacity_resets;
  }

  void restore(io::BinaryReader& r) {
    stats_.iterations = r.get<std::int32_t>("iteration");
    std::istringstream rs(r.get_string("rng"));
    rs >> rng_;
    if (!rs) throw io_error("io.format", r.file(), "bad RNG state");
    perm_ = r.get_vector<int>("permutation");
    perm_pos_ = r.get<std::uint64_t>("permutation_pos");
    if (perm_pos_ > perm_.size()) throw io_error("io.format", r.file(), "permutation position out of range");
    for (int v : perm_)
      if (v < 0 || v >= model_.frame_count()) throw io_error("io.format", r.file(), "permutation entry out of range");
    for (std::size_t* v : {&stats_.skipped_steps, &stats_.cloned, &stats_.split, &stats_.pruned, &stats_.densify_events,
                           &stats_.opacity_resets})
      *v = r.get<std::uint64_t>("stats");
    for (SetState* s : active_) {
      s->accum = r.get_vector<Scalar>("densify.accum");
      s->denom = r.get_vector<Scalar>("densify.denom");
      if (s->accum.size() != model_.cloud(s->which).size() || s->denom.size() != s->accum.size())
        throw io_error("io.format", r.file(), "densification statistics do not match the Gaussian count");
    }
    const auto ng = r.get<std::uint64_t>("optimizer.groups");
    if (ng != opt_.groups().size()) throw io_error("io.mismatch", r.file(), "optimizer group count differs");
    for (auto& g : opt_.groups()) {
      const std::string name = r.get_string("optimizer.name");
      if (name != g.name()) throw io_error("io.mismatch", r.file(), "optimizer group '" + name + "' where '" + g.name() + "' was expected");
      g.set_step_count(r.get<std::uint64_t>("optimizer.step"));
      const bool frozen = r.get<std::uint8_t>("optimizer.frozen") != 0;
      frozen ? opt_.freeze(name) : opt_.unfreeze(name);
      for (int m = 0; m < Opt::kMoments; ++m) {
        const auto v = r.get_vector<Scalar>("optimizer.moment");
        if (v.size() != g.moment(m).size()) throw io_error("io.mismatch", r.file(), "optimizer moments of '" + name + "' differ in size");
        std::copy(v.begin(), v.end(), g.moment(m).begin());
      }
    }
    last_alpha_ = -1;
    for (std::size_t i = 0; i < alpha_names_.size(); ++i)
      if (!opt_.frozen(alpha_names_[i])) last_alpha_ = int(i);
  }

  Model model_;
  std::vector<Image<Scalar, 3>> frames_;
  TrainOptions options_;
  ThreadPool* pool_ = nullptr;
  std::mt19937_64 rng_;
  std::vector<int> perm_;
  std::size_t perm_pos_ = 0;
  Rasterizer<Scalar, TileSize, 3> raster_;
  Opt opt_;
  SetState frg_, bkg_;
  std::vector<SetState*> active_;
  std::vector<std::string> alpha_names_;
  int last_alpha_ = -1;
  Image<Scalar, 3> merged_, d_merged_;
  Image<Scalar, 1> alpha_grad_;
  std::vector<Image<Scalar, 1>> detail_weights_;
  loss::L1DssimContext<Scalar, 3> loss_frg_, loss_bkg_, loss_merged_;
  ClipRenderBuffers<Scalar, Field> eval_;
  loss::SsimContext<Scalar, 3> eval_ssim_;
  TrainStats stats_;
  IterationInfo info_;
  std::vector<double> psnr_partial_;
};

}  // namespace video3dgs
