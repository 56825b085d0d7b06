#pragma once
/// @file
/// Stage 2 of Video-3DGS: temporal-consistency refinement of an edited video (DESIGN.md §4).
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
#include "video3dgs/model/alpha_merge.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/model/clip_model_io.hpp"
#include "video3dgs/model/render_clip.hpp"
#include "video3dgs/model/video_model.hpp"
#include "video3dgs/optim/optimizer.hpp"
#include "video3dgs/optim/schedule.hpp"
#include "video3dgs/rasterizer/rasterizer.hpp"
#include "video3dgs/training/clip_trainer.hpp"
#include "video3dgs/training/editor.hpp"
#include "video3dgs/training/split_adam.hpp"

namespace video3dgs {

/// Options of stage 2 (defaults: DESIGN.md §4).
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

/// Stage 2 on one clip: the frozen-geometry graph of the file comment (rasterize both sets at the
/// precomputed deformed geometry, merge, the summed ensemble losses) and its optimiser over the
/// trained groups. `refine_clip` runs it; `loss_at` / `gradients_at` expose one frame's loss and its
/// gradient (as the optimiser sees it) for checks.
template <class Scalar, int D, class Field>
class ClipRefiner {
 public:
  using Model = ClipModel<Scalar, D, Field>;
  using Opt = Optimizer<Scalar, SplitLrAdam>;

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
    fg_ = m.has_foreground;
    alpha_on_ = o.train_alpha && fg_;

    // Frozen geometry: deformed means / scales / rotations of every frame, once.
    sets_.resize(fg_ ? 2 : 1);
    sets_.front().which = fg_ ? GaussianSet::foreground : GaussianSet::background;
    sets_.back().which = GaussianSet::background;
    for (Set& s : sets_) {
      const auto& c = m.cloud(s.which);
      if (m.deformation_enabled && !c.empty()) {
        DeformScratch<Scalar, Field> scratch;
        for (int i = 0; i < n; ++i) {
          const GaussianParams<Scalar> p = m.deformed(s.which, i, scratch, pool);
          s.mean.emplace_back(p.mean.begin(), p.mean.end());
          s.log_scale.emplace_back(p.log_scale.begin(), p.log_scale.end());
          s.rotation.emplace_back(p.rotation.begin(), p.rotation.end());
        }
      }
      s.d_opacity.assign(c.size(), Scalar(0));
      s.d_sh.assign(c.sh.size(), Scalar(0));
      s.d_image.resize(W, H);
    }

    // Optimizer over the trained groups only.
    using GO = typename Opt::GroupOptions;
    auto hyper = [&] {
      typename SplitLrAdam::Hyper h;
      h.eps = o.adam_eps;
      return h;
    };
    for (Set& s : sets_) {
      auto& c = m.cloud(s.which);
      const std::string p = to_string(s.which) + std::string(".");
      if (o.train_sh && !c.empty()) {
        auto hs = hyper();
        hs.row_width = std::size_t(3 * sh::coeff_count(D));
        hs.lead = 3;
        hs.tail_scale = o.lr_sh_dc > 0 ? o.lr_sh_rest / o.lr_sh_dc : 1.0;
        hs.base = c.sh.data();
        opt_.add_group(GO{p + "sh", LrSchedule::constant(o.lr_sh_dc), hs, hs.row_width}, c.sh, s.d_sh);
      }
      if (o.train_opacity && !c.empty())
        opt_.add_group(GO{p + "opacity", LrSchedule::constant(o.lr_opacity), hyper(), 1}, c.opacity_logit, s.d_opacity);
    }
    alpha_grad_.resize(W, H);
    if (alpha_on_) {
      for (int i = 0; i < n; ++i) {
        alpha_names_.push_back("alpha." + std::to_string(i));
        opt_.add_group(GO{alpha_names_.back(), LrSchedule::constant(o.lr_alpha), hyper(), 1}, m.alpha_logit[std::size_t(i)].storage(),
                       alpha_grad_.storage());
        opt_.freeze(alpha_names_.back());
      }
    }

    RasterSettings<Scalar, 3> rs;
    rs.background = {Scalar(0), Scalar(0), Scalar(0)};
    rs.active_sh_degree = D;
    raster_ = Rasterizer<Scalar, 16, 3>(rs);
    loss::L1DssimOptions lo;
    lo.lambda_dssim = o.lambda_dssim;
    lctx_ = loss::L1DssimContext<Scalar, 3>(lo);
    merged_.resize(W, H);
    d_merged_.resize(W, H);
  }

  ClipRefiner(const ClipRefiner&) = delete;
  ClipRefiner& operator=(const ClipRefiner&) = delete;

  [[nodiscard]] const Opt& optimizer() const noexcept { return opt_; }

  /// The summed ensemble loss of clip frame `frame` (forward only).
  [[nodiscard]] double loss_at(int frame) {
    check_frame(frame);
    return graph(frame, false);
  }

  /// Forward and backward of clip frame `frame`: afterwards the trained groups' gradient buffers
  /// (`optimizer().groups()`; the alpha groups share one, filled for `frame`) hold dL/dparameter of
  /// `loss_at`. Returns the loss, or NaN if it or a gradient was not finite.
  double gradients_at(int frame) {
    check_frame(frame);
    const double L = graph(frame, true);
    return std::isfinite(L) && gradients_finite() ? L : std::numeric_limits<double>::quiet_NaN();
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
  struct Set {
    GaussianSet which{};
    std::vector<std::vector<Scalar>> mean, log_scale, rotation;  // per frame (empty: canonical)
    std::vector<Scalar> d_opacity, d_sh;
    RasterContext<Scalar, 3> ctx;
    Image<Scalar, 3> d_image;
  };

  void check_frame(int frame) const {
    if (frame < 0 || frame >= m_.frame_count())
      throw option_error("option.frame", "frame index " + std::to_string(frame), "outside the clip");
  }

  GaussianParams<Scalar> params_of(Set& s, int i) const {
    GaussianParams<Scalar> p = m_.cloud(s.which).params();
    if (!s.mean.empty()) {
      p.mean = s.mean[std::size_t(i)];
      p.log_scale = s.log_scale[std::size_t(i)];
      p.rotation = s.rotation[std::size_t(i)];
    }
    return p;
  }

  /// The loss of frame fi, and with `backward` its gradient into the trained groups' buffers (the
  /// rasterizer and the merge overwrite them; the image gradients are summed over the ensemble).
  /// NaN if the rasterizer's backward refused its input.
  double graph(int fi, bool backward) {
    const Camera<Scalar>& cam = m_.cameras[std::size_t(fi)];
    for (Set& s : sets_) raster_.forward(cam, params_of(s, fi), s.ctx, pool_);
    Set& bk = sets_.back();
    const Scalar wf = Scalar(o_.weight_frg), wb = Scalar(o_.weight_bkg), wm = Scalar(o_.weight_merged);
    double L = 0;
    if (fg_) {
      Set& fr = sets_.front();
      alpha_merge_forward<Scalar, 3>(fr.ctx.image, bk.ctx.image, m_.alpha_logit[std::size_t(fi)], merged_, pool_);
      if (backward) d_merged_.fill(Scalar(0));
      for (const auto& tv : targets_) {
        L += double(wm) * loss::l1_dssim_forward<Scalar, 3>(merged_, tv[std::size_t(fi)], lctx_, pool_);
        if (backward) loss::l1_dssim_backward<Scalar, 3>(lctx_, wm, d_merged_, pool_);
      }
      if (backward)
        alpha_merge_backward<Scalar, 3>(fr.ctx.image, bk.ctx.image, m_.alpha_logit[std::size_t(fi)], d_merged_, fr.d_image, bk.d_image,
                                        alpha_on_ ? ImageView<Scalar, 1>(alpha_grad_) : ImageView<Scalar, 1>(), pool_);
      for (const auto& tv : targets_) {
        if (wf > 0) {
          L += double(wf) * loss::l1_dssim_forward<Scalar, 3>(fr.ctx.image, tv[std::size_t(fi)], lctx_, pool_);
          if (backward) loss::l1_dssim_backward<Scalar, 3>(lctx_, wf, fr.d_image, pool_);
        }
        if (wb > 0) {
          L += double(wb) * loss::l1_dssim_forward<Scalar, 3>(bk.ctx.image, tv[std::size_t(fi)], lctx_, pool_);
          if (backward) loss::l1_dssim_backward<Scalar, 3>(lctx_, wb, bk.d_image, pool_);
        }
      }
    } else {
      if (backward) bk.d_image.fill(Scalar(0));
      for (const auto& tv : targets_) {
        L += double(wb + wm) * loss::l1_dssim_forward<Scalar, 3>(bk.ctx.image, tv[std::size_t(fi)], lctx_, pool_);
        if (backward) loss::l1_dssim_backward<Scalar, 3>(lctx_, wb + wm, bk.d_image, pool_);
      }
    }
    if (!backward || !std::isfinite(L)) return L;
    for (Set& s : sets_) {
      if (!detail::all_finite<Scalar>(s.d_image.storage())) return std::numeric_limits<double>::quiet_NaN();
      RasterGrads<Scalar, 3> g;
      g.gaussians.dL_dopacity_logit = s.d_opacity;
      g.gaussians.dL_dsh = s.d_sh;
      try {
        raster_.backward(s.ctx, s.d_image, {}, {}, g, pool_);
      } catch (const numeric_error&) {
        return std::numeric_limits<double>::quiet_NaN();
      }
    }
    return L;
  }

  [[nodiscard]] bool gradients_finite() const {
    for (const Set& s : sets_)
      if (!detail::all_finite<Scalar>(s.d_opacity) || !detail::all_finite<Scalar>(s.d_sh)) return false;
    return !alpha_on_ || detail::all_finite<Scalar>(alpha_grad_.storage());
  }

  Model& m_;
  const std::vector<std::vector<Image<Scalar, 3>>>& targets_;
  RefineOptions o_;
  ThreadPool* pool_ = nullptr;
  bool fg_ = false, alpha_on_ = false;
  std::vector<Set> sets_;
  Opt opt_;
  Image<Scalar, 1> alpha_grad_;
  std::vector<std::string> alpha_names_;
  int last_alpha_ = -1;
  Rasterizer<Scalar, 16, 3> raster_;
  loss::L1DssimContext<Scalar, 3> lctx_;
  Image<Scalar, 3> merged_, d_merged_;
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
