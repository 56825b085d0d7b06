#pragma once
/// @file
/// Stage 2 of Video-3DGS: temporal-consistency refinement of an edited video (the method: docs/method.md).
///
/// The stage-1 model fixes the 3D structure and motion of the source video. Given an edit of the
/// video (any zero-shot editor; its frames flicker), only appearance is re-fitted:
///
///   trained:  SH coefficients (DC at lr_sh_dc, other bands at lr_sh_rest), opacity logits, and
///             optionally the alpha maps;
///   frozen:   means, log-scales, rotations, both deformation fields, cameras (and by default the
///             alpha maps): they are never handed to the optimizer, so they stay bit-identical.
///
/// One iteration on clip c (frame i from a seeded permutation per epoch), for an ensemble of E edits:
///
///   I_s = rasterize(deform_s(canonical_s, t_i), camera_i),   I = A_i I_frg + (1 - A_i) I_bkg
///   L   = sum_e [ w_f L(I_frg, T_e,i) + w_b L(I_bkg, T_e,i) + w_m L(I, T_e,i) ],
///   L(x, y) = (1 - lambda) L1(x, y) + lambda (1 - SSIM(x, y))
///
/// Since geometry and deformation are frozen, the deformed means/scales/rotations of every frame are
/// computed once per clip and reused. A non-finite loss or gradient skips the step.
///
/// Clip overlaps. Clips share frames at their boundaries (MC-COLMAP). Two mechanisms keep the style
/// continuous across a boundary: (1) clips are refined in order, and on a frame that the previous
/// (already refined) clip also holds, the target is (1 - beta) T + beta R_prev, R_prev that clip's
/// render (`overlap_anchor` = beta), so the later clip starts from the style the earlier one ends
/// with; (2) the video is rendered with `VideoModel`'s cross-fade of overlapping clips.
///
/// Ensembles (several edits of the same video, e.g. three guidance scales) sum the loss over the
/// edits (`refine_video` with E target videos). Recursive refinement (`refine_recursive`) alternates
/// N_r editor phases and refinements: phase 0 edits the source, phase p > 0 edits the render of the
/// model refined in phase p - 1, which is refined further.

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/io/binary_stream.hpp"
#include "video3dgs/loss/l1_dssim.hpp"
#include "video3dgs/graph/clip_graph.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/model/clip_model_io.hpp"
#include "video3dgs/model/render_clip.hpp"
#include "video3dgs/model/video_model.hpp"
#include "video3dgs/optim/optimizer.hpp"
#include "video3dgs/optim/schedule.hpp"
#include "video3dgs/training/clip_trainer.hpp"
#include "video3dgs/refine/editor.hpp"
#include "video3dgs/training/policy.hpp"
#include "video3dgs/training/split_adam.hpp"

namespace video3dgs {

/// Options of stage 2 (defaults: the reference values, docs/method.md).
struct RefineOptions {
  int iterations = 1000;        ///< per clip
  bool train_sh = true;         ///< SH coefficients (all bands)
  bool train_opacity = true;    ///< opacity logits
  bool train_alpha = false;     ///< per-frame alpha maps
  double lr_sh_dc = 2.5e-2;
  double lr_sh_rest = 1.25e-3;
  double lr_opacity = 5e-2;
  double lr_alpha = 1e-2;
  double adam_eps = 1e-15;
  double lambda_dssim = 0.2;    ///< L = (1 - lambda) L1 + lambda D-SSIM
  double weight_frg = 1, weight_bkg = 1, weight_merged = 1;
  double overlap_anchor = 0.5;  ///< beta of the file comment (0 = plain edited targets)
  std::uint64_t seed = 0;       ///< frame permutation

  /// @throws option_error `option.refine`
  void validate() const {
    auto bad = [](const char* f, const char* why) { throw option_error("option.refine", f, why); };
    if (iterations < 0) bad("iterations", "must be >= 0");
    if (!train_sh && !train_opacity && !train_alpha) bad("train_*", "at least one group must train");
    for (double v : {lr_sh_dc, lr_sh_rest, lr_opacity, lr_alpha})
      if (!(v >= 0 && std::isfinite(v))) bad("lr_*", "must be finite and >= 0");
    if (!(adam_eps > 0)) bad("adam_eps", "must be > 0");
    if (!(lambda_dssim >= 0 && lambda_dssim <= 1)) bad("lambda_dssim", "must be in [0, 1]");
    if (!(weight_frg >= 0 && weight_bkg >= 0 && weight_merged >= 0) || weight_frg + weight_bkg + weight_merged <= 0)
      bad("weight_*", "must be >= 0, not all 0");
    if (!(overlap_anchor >= 0 && overlap_anchor < 1)) bad("overlap_anchor", "must be in [0, 1)");
  }
};

/// What refining one clip did.
struct ClipRefineStats {
  int iterations = 0;
  std::size_t skipped_steps = 0;
  double first_loss = 0, last_loss = 0;  ///< summed ensemble loss of the first / last iteration
  double seconds = 0;
};

/// What a refinement did.
struct RefineStats {
  std::vector<ClipRefineStats> clips;
  double seconds = 0;
};

/// Deep copy of a clip model (through its binary record: bit-identical, fields included).
template <class Scalar, int D, class Field>
[[nodiscard]] ClipModel<Scalar, D, Field> clone_clip_model(const ClipModel<Scalar, D, Field>& m) {
  io::BinaryWriter w(kClipModelMagic, kClipModelVersion);
  // write_clip_model reads the fields through segments(), which is non-const but does not modify.
  write_clip_model(w, const_cast<ClipModel<Scalar, D, Field>&>(m));
  io::BinaryReader r(w.bytes(), "clone", kClipModelMagic, kClipModelVersion);
  auto out = read_clip_model<Scalar, D, Field>(r);
  out.deformation_enabled = m.deformation_enabled;
  out.static_background = m.static_background;
  return out;
}

/// Deep copy of a video model.
template <class Scalar, int D, class Field>
[[nodiscard]] VideoModel<Scalar, D, Field> clone_video_model(const VideoModel<Scalar, D, Field>& v) {
  VideoModel<Scalar, D, Field> out;
  out.frame_count = v.frame_count;
  out.width = v.width;
  out.height = v.height;
  for (const auto& c : v.clips) out.clips.push_back(clone_clip_model(c));
  return out;
}

/// Stage 2 on one clip: the clip graph (graph/clip_graph.hpp) with frozen geometry (the deformed
/// means / scales / rotations of every frame computed once) against the E edits, and its optimiser
/// over the trained groups. `refine_clip` runs it; `loss_at` / `gradients_at` expose one frame's
/// loss and its gradient (as the optimiser sees it) for checks.
template <class Scalar, int D, class Field, int TileSize = 16, class OptimizerPolicy = SplitLrAdam>
class ClipRefiner {
 public:
  using Model = ClipModel<Scalar, D, Field>;
  using Policy = TrainingPolicy<TileSize, OptimizerPolicy>;
  using Opt = Optimizer<Scalar, OptimizerPolicy>;

  /// Keeps references to `m` (refined in place) and `targets` (`targets[e][i]` = edit e of clip
  /// frame i); both must outlive the refiner.
  /// @throws option_error `option.refine` on bad options or target counts / sizes
  ClipRefiner(Model& m, const std::vector<std::vector<Image<Scalar, 3>>>& targets, const RefineOptions& o = {}, ThreadPool* pool = nullptr)
      : m_(m), targets_(targets), o_(o), pool_(pool) {
    o.validate();
    const int n = m.frame_count();
    const int W = m.width(), H = m.height();
    if (n < 1) throw option_error("option.refine", "model", "the clip has no frames");
    if (targets.empty()) throw option_error("option.refine", "targets", "no edited video given");
    for (std::size_t e = 0; e < targets.size(); ++e) {
      if (targets[e].size() != std::size_t(n))
        throw option_error("option.refine", "edit " + std::to_string(e),
                           std::to_string(targets[e].size()) + " frames for a clip of " + std::to_string(n));
      for (const auto& f : targets[e])
        if (f.width() != W || f.height() != H)
          throw option_error("option.refine", "edit " + std::to_string(e),
                             "frame size differs from the model's " + std::to_string(W) + "x" + std::to_string(H));
    }
    if (targets.size() > 16) throw option_error("option.refine", "targets", "at most 16 edits in an ensemble");
    alpha_on_ = o.train_alpha && m.has_foreground;
    graph_.settings.background = {Scalar(0), Scalar(0), Scalar(0)};
    graph_.settings.active_sh_degree = D;
    graph_.weights = {o.weight_frg, o.weight_bkg, o.weight_merged, o.lambda_dssim};
    graph_.freeze_geometry(m, ctx_, pool);
    add_groups();
    alpha_grad_.resize(W, H);
    if (alpha_on_) {
      for (int i = 0; i < n; ++i) {
        alpha_names_.push_back("alpha." + std::to_string(i));
        opt_.add_group(GO{alpha_names_.back(), LrSchedule::constant(o.lr_alpha), hyper(), 1}, m.alpha_logit[std::size_t(i)].storage(),
                       alpha_grad_.storage());
        opt_.freeze(alpha_names_.back());
      }
    }
  }

  ClipRefiner(const ClipRefiner&) = delete;
  ClipRefiner& operator=(const ClipRefiner&) = delete;

  [[nodiscard]] const Opt& optimizer() const noexcept { return opt_; }

  /// The summed ensemble loss of clip frame `frame` (forward only).
  [[nodiscard]] double loss_at(int frame) { return graph_.forward(m_, frame, targets_of(frame), ctx_, {}, {}, pool_).total; }

  /// Forward and backward of clip frame `frame`: afterwards the trained groups' gradient buffers
  /// (`optimizer().groups()`; the alpha groups share one, filled for `frame`) hold dL/dparameter of
  /// `loss_at`. Returns the loss, or NaN if it or a gradient was not finite.
  double gradients_at(int frame) {
    const double L = graph_.forward(m_, frame, targets_of(frame), ctx_, sinks_, {}, pool_).total;
    const bool ok = std::isfinite(L) && graph_.backward(ctx_, pool_) && gradients_finite();
    return ok ? L : std::numeric_limits<double>::quiet_NaN();
  }

  /// One iteration k on clip frame `frame`: forward, backward, a step of the trained groups (and of
  /// the frame's alpha map) unless the loss or a gradient is not finite. Returns the loss, NaN if
  /// the step was skipped.
  double step(int k, int frame) {
    const double L = gradients_at(frame);
    if (!std::isfinite(L)) return L;
    if (alpha_on_ && last_alpha_ != frame) {
      if (last_alpha_ >= 0) opt_.freeze(alpha_names_[std::size_t(last_alpha_)]);
      opt_.unfreeze(alpha_names_[std::size_t(frame)]);
      last_alpha_ = frame;
    }
    opt_.step(k, pool_);
    return L;
  }

 private:
  using GO = typename Opt::GroupOptions;
  [[nodiscard]] typename OptimizerPolicy::Hyper hyper() const { return group_hyper<OptimizerPolicy>(o_.adam_eps); }

  /// Optimiser groups and gradient sinks of the trained parameters (SH, opacity of each set).
  void add_groups() {
    for (GaussianSet which : {GaussianSet::foreground, GaussianSet::background}) {
      auto& c = m_.cloud(which);
      if (c.empty() || (which == GaussianSet::foreground && !m_.has_foreground)) continue;
      auto& grad = which == GaussianSet::foreground ? frg_grad_ : bkg_grad_;
      GaussianGrads<Scalar>& sink = which == GaussianSet::foreground ? sinks_.frg : sinks_.bkg;
      const std::string p = to_string(which) + std::string(".");
      if (o_.train_sh) {
        grad.d_sh.assign(c.sh.size(), Scalar(0));
        sink.dL_dsh = grad.d_sh;
        const auto hs = group_hyper<OptimizerPolicy>(o_.adam_eps, D, o_.lr_sh_dc, o_.lr_sh_rest);
        opt_.add_group(GO{p + "sh", LrSchedule::constant(o_.lr_sh_dc), hs, std::size_t(3 * sh::coeff_count(D))}, c.sh, grad.d_sh);
      }
      if (o_.train_opacity) {
        grad.d_opacity.assign(c.size(), Scalar(0));
        sink.dL_dopacity_logit = grad.d_opacity;
        opt_.add_group(GO{p + "opacity", LrSchedule::constant(o_.lr_opacity), hyper(), 1}, c.opacity_logit, grad.d_opacity);
      }
    }
  }

  std::span<const ConstImageView<Scalar, 3>> targets_of(int frame) {
    if (frame < 0 || frame >= m_.frame_count())
      throw option_error("option.frame", "frame index " + std::to_string(frame), "outside the clip");
    for (std::size_t e = 0; e < targets_.size(); ++e) views_[e] = ConstImageView<Scalar, 3>(targets_[e][std::size_t(frame)]);
    if (alpha_on_) sinks_.alpha = alpha_grad_.storage();
    return {views_.data(), targets_.size()};
  }

  [[nodiscard]] bool gradients_finite() const {
    for (const auto* g : {&frg_grad_, &bkg_grad_})
      if (!detail::all_finite<Scalar>(g->d_opacity) || !detail::all_finite<Scalar>(g->d_sh)) return false;
    return !alpha_on_ || detail::all_finite<Scalar>(alpha_grad_.storage());
  }

  struct SetGrads {
    std::vector<Scalar> d_opacity, d_sh;
  };

  Model& m_;
  const std::vector<std::vector<Image<Scalar, 3>>>& targets_;
  RefineOptions o_;
  ThreadPool* pool_ = nullptr;
  bool alpha_on_ = false;
  ClipGraph<Scalar, D, Field, TileSize> graph_;
  ClipGraphContext<Scalar, Field> ctx_;
  ClipGradients<Scalar, Field> sinks_;
  std::array<ConstImageView<Scalar, 3>, 16> views_{};
  SetGrads frg_grad_, bkg_grad_;
  Opt opt_;
  Image<Scalar, 1> alpha_grad_;
  std::vector<std::string> alpha_names_;
  int last_alpha_ = -1;
};

/// Refines one clip in place against E target videos (`targets[e][i]` = edit e of clip frame i).
/// @throws option_error `option.refine` on bad options or target counts / sizes
template <class Scalar, int D, class Field>
ClipRefineStats refine_clip(ClipModel<Scalar, D, Field>& m, const std::vector<std::vector<Image<Scalar, 3>>>& targets,
                            const RefineOptions& o = {}, ThreadPool* pool = nullptr) {
  using clock = std::chrono::steady_clock;
  const auto t0 = clock::now();
  ClipRefiner<Scalar, D, Field> refiner(m, targets, o, pool);
  const int n = m.frame_count();
  std::mt19937_64 rng(o.seed);
  std::vector<int> perm;
  std::size_t perm_pos = 0;
  ClipRefineStats st;
  bool stepped = false;
  for (int k = 0; k < o.iterations; ++k) {
    if (perm_pos >= perm.size()) {
      perm.resize(std::size_t(n));
      for (int i = 0; i < n; ++i) perm[std::size_t(i)] = i;
      for (int i = n - 1; i > 0; --i) std::swap(perm[std::size_t(i)], perm[std::size_t(rng() % std::uint64_t(i + 1))]);
      perm_pos = 0;
    }
    const double L = refiner.step(k, perm[perm_pos++]);
    if (std::isfinite(L)) {
      if (!stepped) st.first_loss = L;
      stepped = true;
      st.last_loss = L;
    } else {
      ++st.skipped_steps;
    }
    st.iterations = k + 1;
  }
  st.seconds = std::chrono::duration<double>(clock::now() - t0).count();
  return st;
}

namespace detail {
template <class Scalar>
std::vector<Image<Scalar, 3>> to_scalar(const std::vector<Image<float, 3>>& v) {
  if constexpr (std::is_same_v<Scalar, float>) {
    return v;
  } else {
    std::vector<Image<Scalar, 3>> out;
    for (const auto& f : v) out.push_back(f.template cast<Scalar>());
    return out;
  }
}
}  // namespace detail

/// Renders every frame of a video model (overlaps cross-faded, see model/video_model.hpp), as float.
template <class Scalar, int D, class Field>
[[nodiscard]] std::vector<Image<float, 3>> render_video(const VideoModel<Scalar, D, Field>& v, ThreadPool* pool = nullptr) {
  VideoRenderBuffers<Scalar, Field> buf;
  std::vector<Image<float, 3>> out;
  out.reserve(std::size_t(v.frame_count));
  RasterSettings<Scalar, 3> rs;
  rs.background = {Scalar(0), Scalar(0), Scalar(0)};
  for (int f = 0; f < v.frame_count; ++f) {
    const auto& img = v.render_frame(f, buf, pool, rs);
    if constexpr (std::is_same_v<Scalar, float>)
      out.push_back(img);
    else
      out.push_back(img.template cast<float>());
  }
  return out;
}

/// Stage 2 on a whole video: a copy of `source` with SH / opacity (and optionally alpha maps)
/// re-fitted to the edited videos `edits` (E videos of `source.frame_count` frames each; E > 1 is an
/// ensemble). Clips are refined in order with overlap anchoring (file comment).
/// @throws option_error `option.refine`
template <class Scalar, int D, class Field>
[[nodiscard]] VideoModel<Scalar, D, Field> refine_video(const VideoModel<Scalar, D, Field>& source,
                                                        const std::vector<std::vector<Image<float, 3>>>& edits,
                                                        const RefineOptions& o = {}, ThreadPool* pool = nullptr,
                                                        RefineStats* stats = nullptr) {
  const auto t0 = std::chrono::steady_clock::now();
  o.validate();
  if (edits.empty()) throw option_error("option.refine", "edits", "no edited video given");
  for (std::size_t e = 0; e < edits.size(); ++e) {
    if (edits[e].size() != std::size_t(source.frame_count))
      throw option_error("option.refine", "edit " + std::to_string(e),
                         std::to_string(edits[e].size()) + " frames for a video of " + std::to_string(source.frame_count));
    for (const auto& f : edits[e])
      if (f.width() != source.width || f.height() != source.height)
        throw option_error("option.refine", "edit " + std::to_string(e),
                           "frames are " + std::to_string(f.width()) + "x" + std::to_string(f.height()) + ", the model renders " +
                               std::to_string(source.width) + "x" + std::to_string(source.height));
  }
  VideoModel<Scalar, D, Field> out = clone_video_model(source);
  RefineStats local;
  ClipRenderBuffers<Scalar, Field> buf;
  for (std::size_t c = 0; c < out.clips.size(); ++c) {
    auto& clip = out.clips[c];
    std::vector<std::vector<Image<Scalar, 3>>> targets(edits.size());
    for (int i = 0; i < clip.frame_count(); ++i) {
      const int f = clip.range.first + i;
      const ClipModel<Scalar, D, Field>* prev = nullptr;
      if (c > 0 && o.overlap_anchor > 0 && out.clips[c - 1].range.contains(f)) prev = &out.clips[c - 1];
      if (prev) render_clip_frame(*prev, prev->index_of_frame(f), buf, pool);
      for (std::size_t e = 0; e < edits.size(); ++e) {
        Image<Scalar, 3> t;
        if constexpr (std::is_same_v<Scalar, float>)
          t = edits[e][std::size_t(f)];
        else
          t = edits[e][std::size_t(f)].template cast<Scalar>();
        if (prev) {
          const Scalar b = Scalar(o.overlap_anchor);
          for (std::size_t j = 0; j < t.size(); ++j) t.data()[j] = (Scalar(1) - b) * t.data()[j] + b * buf.merged.data()[j];
        }
        targets[e].push_back(std::move(t));
      }
    }
    RefineOptions oc = o;
    oc.seed = o.seed + c;
    local.clips.push_back(refine_clip(clip, targets, oc, pool));
  }
  local.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (stats) *stats = std::move(local);
  return out;
}

/// Options of `refine_recursive`.
struct RecursiveRefineOptions {
  int phases = 2;          ///< N_r
  RefineOptions refine{};  ///< per phase
};

/// Everything a recursive refinement produced.
template <class Video>
struct RecursiveRefineResult {
  Video model;                                            ///< refined after the last phase
  std::vector<std::vector<Image<float, 3>>> edited;       ///< editor output per phase
  std::vector<std::vector<Image<float, 3>>> refined;      ///< render after each phase
  std::vector<RefineStats> stats;                         ///< per phase
};

/// Recursive refinement: for p = 0..N_r-1, E_p = editor.edit(p == 0 ? source : R_{p-1}, {p, N_r}),
/// M_p = refine_video(M_{p-1}, {E_p}) (M_{-1} = `model`), R_p = render(M_p).
/// @throws option_error `option.refine`; whatever the editor throws
template <class Scalar, int D, class Field, Editor E>
[[nodiscard]] RecursiveRefineResult<VideoModel<Scalar, D, Field>> refine_recursive(const VideoModel<Scalar, D, Field>& model,
                                                                                   const std::vector<Image<float, 3>>& source, E& editor,
                                                                                   const RecursiveRefineOptions& o = {},
                                                                                   ThreadPool* pool = nullptr) {
  if (o.phases < 1) throw option_error("option.refine", "phases", "must be >= 1");
  if (source.size() != std::size_t(model.frame_count))
    throw option_error("option.refine", "source", std::to_string(source.size()) + " frames for a model of " + std::to_string(model.frame_count));
  RecursiveRefineResult<VideoModel<Scalar, D, Field>> r;
  const std::vector<Image<float, 3>>* input = &source;
  for (int p = 0; p < o.phases; ++p) {
    std::vector<Image<float, 3>> edited = editor.edit(*input, EditContext{p, o.phases});
    check_edited(*input, edited, "editor phase " + std::to_string(p));
    RefineStats st;
    RefineOptions ro = o.refine;
    ro.seed = o.refine.seed + 1000003ull * std::uint64_t(p);
    r.model = refine_video(p == 0 ? model : r.model, {edited}, ro, pool, &st);
    r.edited.push_back(std::move(edited));
    r.refined.push_back(render_video(r.model, pool));
    r.stats.push_back(std::move(st));
    input = &r.refined.back();
  }
  return r;
}

}  // namespace video3dgs
