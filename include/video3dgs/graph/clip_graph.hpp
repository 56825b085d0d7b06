#pragma once
/// @file
/// `ClipGraph<Scalar, SHDegree, Field, TileSize>`: the whole per-clip computation of Video-3DGS as one
/// forward / backward pair on the autodiff tape (autodiff/tape.hpp). Stage 1 (`ClipTrainer`),
/// stage 2 (`ClipRefiner`) and the renderer (`render_clip_frame`) all run it; they differ only in
/// which parameters receive gradients (`ClipGradients`) and in the targets they pass.
///
/// For clip frame i (time t_i, camera i) and E targets T_0..T_{E-1} (E = 0: render only):
///
///   P_s  = deform_s(canonical_s, t_i)          s in {frg, bkg}; the canonical set if deformation is
///                                              off, the cached geometry if it is frozen (`freeze_geometry`)
///   P_s' = T_xi(P_s)                           only with a camera sink (`ClipGradients::camera`)
///   I_s  = rasterize(P_s', camera_i)            or the set's kept render of frame i if it is a constant
///                                              of the graph (`freeze_render`)
///   I    = A I_frg + (1 - A) I_bkg,            A = sigmoid(a_i)     (I = I_bkg without a foreground)
///   L    = sum_e [ w_f l(I_frg, T_e) + w_b l(I_bkg, T_e) + w_m l_W(I, T_e) ],
///   l    = (1 - lambda) L1 + lambda (1 - SSIM),  l_W: L1 weighted per pixel by W (optional)
///
/// Camera node (pose refinement). T_xi moves the world rigidly about the camera centre c:
///   mu' = c + exp([omega]x) (mu - c) + tau,   q' = q_omega (x) q,   xi = (omega, tau) in R^6,
/// with q_omega the unit quaternion of the rotation vector omega. The graph evaluates it at xi = 0 (the
/// identity: outputs alias the inputs) and its backward passes the gradients through and adds
///   dL/dtau   += sum_i g_i,
///   dL/domega += sum_i (mu_i - c) x g_i + 1/2 sum_i (w_i h_i - h0_i v_i + v_i x h_i),
/// where g_i = dL/dmu_i', (h0_i, h_i) = dL/dq_i' and q_i = (w_i, v_i), over both sets, summed in
/// Gaussian order (one thread: the same sum for any thread count). Rendering P' with camera_i equals
/// rendering P with `camera_i.world_moved(omega, tau)` (core/camera.hpp), which is how a trainer folds
/// a step into the camera, except that SH colours then see the view direction turned by
/// exp(-[omega]x) (exact for SH degree 0; the step follows the world move's gradient).
///
/// Every stage is one array-level tape node and every backward step accumulates (+=) into its
/// inputs' gradients: deformation of a set (outputs: deformed means, log-scales, rotations; backward
/// into the canonical gradients and the field's parameters, or the canonical gradients alone for a
/// field declared constant, `ClipGradients::frg_field_constant`), rasterization of a set (backward through
/// the rasterizer's accumulate mode, also into dL/dmean2d for densification), the alpha merge, one
/// node per loss term, and the weighted sum. A term whose weight is 0 is not recorded. Without a
/// foreground, w_m and w_b share one loss node of weight w_b + w_m unless W is given. When two or
/// more terms compare against each target, the target's SSIM statistics (G*T_e, G*(T_e T_e)) are
/// computed once per forward and read by each of them (`ClipGraph::share_target_statistics`): the
/// same values and gradients, bit for bit.
///
/// Render size. The graph renders at the targets' size: targets of w x h other than the model's
/// W x H (a training resolution schedule) render through camera_i.resized(w, h), and the merge uses
/// the frame's alpha logits resampled to w x h, a_i' = R a_i (`AreaResampler`, exact area weights;
/// its backward adds R^T dL/da_i' into the W x H alpha gradient). Without targets it renders at W x H.
/// A `PixelWindow` instead renders the window [x, x + w) x [y, y + h) of the full-size frame (targets
/// of the window's size; a training crop): camera_i.cropped(x, y, w, h) and the window of a_i, whose
/// backward adds its gradient into that window of the W x H alpha gradient. The rasterizer's
/// Jacobian clamp keeps the whole frame's bounds (RasterSettings::clamp_frame_*), so the window's
/// pixels are the whole render's up to rounding.
///
/// Recording order fixes the order in which contributions to one buffer are summed (reverse of
/// recording): the set losses and the merge are recorded so that the merge's gradient reaches I_frg
/// and I_bkg before the set losses', and targets are summed in increasing e.
///
///     ClipGraph<float, 3, Field> graph;                 // settings: graph.settings (RasterSettings)
///     ClipGraphContext<float, Field> ctx;               // reuse: no steady-state allocation
///     const ClipLosses L = graph.forward(model, i, targets, ctx, sinks, {}, &pool);
///     if (graph.backward(ctx, &pool)) { ... sinks hold dL/dparameters ... }

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <span>
#include <vector>

#include "video3dgs/autodiff/tape.hpp"
#include "video3dgs/core/camera.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/core/resample.hpp"
#include "video3dgs/core/stopwatch.hpp"
#include "video3dgs/gaussian/cloud.hpp"
#include "video3dgs/loss/alpha_merge.hpp"
#include "video3dgs/loss/l1_dssim.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/rasterizer/rasterizer.hpp"

namespace video3dgs {

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

/// Weights of the loss terms (file comment).
struct ClipLossWeights {
  double frg = 1, bkg = 1, merged = 1;
  double lambda_dssim = 0.2;
};

/// Loss values of one forward pass, each summed over the targets; `total` = the weighted sum L.
struct ClipLosses {
  double total = 0, frg = 0, bkg = 0, merged = 0;
};

/// Where gradients go: an empty span (or a null field) makes that parameter a constant of the graph.
/// Spans are sized like the model's clouds (`GaussianGrads`), `alpha` like one alpha map (W x H).
template <class Scalar, class Field>
struct ClipGradients {
  GaussianGrads<Scalar> frg, bkg;
  Field* frg_field = nullptr;  ///< the model's field: its parameters' gradients (`segments()`)
  Field* bkg_field = nullptr;
  /// The set's field is a constant of this graph (no sink above): geometry gradients still reach the
  /// canonical parameters through the deformation (DeformationField::backward_canonical: the same
  /// values as with the field as a sink), and the field's own gradients are not computed.
  bool frg_field_constant = false, bkg_field_constant = false;
  std::span<Scalar> alpha;     ///< dL/d(alpha logits of the frame), W x H
  /// dL/dxi of the frame's camera correction xi = (omega, tau) at xi = 0 (6 values; see the camera
  /// node in the file comment). Empty: the camera is a constant and no camera node is recorded.
  std::span<Scalar> camera;
};

/// Seconds spent in each kind of node (forward and backward), accumulated.
struct ClipGraphTimes {
  double deformation = 0, raster_forward = 0, raster_backward = 0, loss = 0;
};

/// Deformed geometry of every clip frame, computed once when geometry and deformation are frozen
/// (stage 2): per frame N x 3 means, N x 3 log-scales, N x 4 rotations.
template <class Scalar>
struct FrozenGeometry {
  std::vector<std::vector<Scalar>> mean, log_scale, rotation;
  [[nodiscard]] bool empty() const noexcept { return mean.empty(); }
};

/// Renders of a set that is a constant of the graph, one per clip frame at one size and active SH
/// degree (`ClipGraph::freeze_render`).
template <class Scalar>
struct FrozenRenders {
  int width = 0, height = 0, sh_degree = -1;
  bool deformed = false;  ///< the set was deformed when rendered (`ClipModel::deforms`)
  std::vector<Image<Scalar, 3>> image;
  [[nodiscard]] bool empty() const noexcept { return image.empty(); }
};

/// Everything one evaluation of the graph keeps: the renders (`frg.image`, `bkg.image`, `merged`,
/// valid after `forward`), the saved state of every node for `backward`, and scratch. Reuse one per
/// clip (and per thread of use): no allocation once the sizes are stable.
template <class Scalar, class Field = DefaultDeformationField<Scalar>>
struct ClipGraphContext {
  RasterContext<Scalar, 3> frg, bkg;                     ///< per-set raster contexts (image, alpha, radii, ...)
  DeformScratch<Scalar, Field> frg_scratch, bkg_scratch; ///< deformed parameters and the fields' saved state
  Image<Scalar, 3> merged;                               ///< I (= bkg.image without a foreground)
  std::vector<Scalar> frg_mean2d, bkg_mean2d;            ///< dL/dmean2d (pixels) of the last backward
  bool blend_weights = false;                            ///< backward also fills frg_weight / bkg_weight and frg_evals / bkg_evals
  std::vector<Scalar> frg_weight, bkg_weight;            ///< blend weights sum_p alpha T (render pixels) of the last backward
  std::vector<Scalar> frg_evals, bkg_evals;              ///< their evaluations (RasterGrads::blend_evals) in that backward
  FrozenGeometry<Scalar> frg_frozen, bkg_frozen;         ///< see `ClipGraph::freeze_geometry`
  FrozenRenders<Scalar> frg_rendered, bkg_rendered;      ///< see `ClipGraph::freeze_render`
  Image<Scalar, 1> alpha_resampled;                      ///< the frame's alpha logits at the render size or window (if not W x H)
  AreaResampler alpha_resampler;                         ///< W x H -> render size
  ClipGraphTimes times;                                  ///< accumulated; reset it when you like
  ClipLosses losses;                                     ///< of the last forward

  // Saved for backward (internal).
  autodiff::Tape<Scalar> tape{std::size_t(1) << 20};
  std::vector<loss::L1DssimContext<Scalar, 3>> loss_ctx;
  std::vector<loss::SsimTarget<Scalar, 3>> ssim_target;  ///< per target e, filled by each forward that shares them
  autodiff::Var total;
  ClipGradients<Scalar, Field> sinks;
  PixelWindow window;                 ///< of the last forward (empty: the whole frame)
  int frame_width = 0, frame_height = 0;  ///< the model's W x H in the last forward
  bool finite = true;  ///< set false by a raster node whose image gradient was not finite
};

template <class Scalar, int SHDegree = 3, class Field = DefaultDeformationField<Scalar>, int TileSize = 16>
class ClipGraph {
 public:
  using Model = ClipModel<Scalar, SHDegree, Field>;
  using Context = ClipGraphContext<Scalar, Field>;
  using Gradients = ClipGradients<Scalar, Field>;
  using Var = autodiff::Var;
  using Tape = autodiff::Tape<Scalar>;

  /// Background, active SH degree, raster constants; the stop rule (min_transmittance, blend_at_stop)
  /// is each model's own (ClipModel::min_transmittance) and overrides these.
  RasterSettings<Scalar, 3> settings;
  ClipLossWeights weights;
  /// Compute each target's SSIM statistics once per forward for all its terms (false: once per term;
  /// the results are the same bits either way).
  bool share_target_statistics = true;

  ClipGraph() { settings.background = {Scalar(0), Scalar(0), Scalar(0)}; }
  explicit ClipGraph(const RasterSettings<Scalar, 3>& s, const ClipLossWeights& w = {}) : settings(s), weights(w) {}

  /// Computes the deformed geometry of every frame into `ctx.*_frozen` (the deformation is then no
  /// longer evaluated; geometry gradients are not available). Clears it if deformation is off.
  void freeze_geometry(const Model& m, Context& ctx, ThreadPool* pool = nullptr) const {
    for (GaussianSet s : {GaussianSet::foreground, GaussianSet::background}) {
      FrozenGeometry<Scalar>& fz = frozen(ctx, s);
      fz = {};
      if (!m.deforms(s) || m.cloud(s).empty()) continue;
      DeformScratch<Scalar, Field> scratch;
      for (int i = 0; i < m.frame_count(); ++i) {
        const GaussianParams<Scalar> p = m.deformed(s, i, scratch, pool);
        fz.mean.emplace_back(p.mean.begin(), p.mean.end());
        fz.log_scale.emplace_back(p.log_scale.begin(), p.log_scale.end());
        fz.rotation.emplace_back(p.rotation.begin(), p.rotation.end());
      }
    }
  }

  /// Renders set `s` of every clip frame at width x height (the cameras resized as in `forward`) with
  /// the current `settings` into `ctx.*_rendered`. From then on `forward` reads the frame's render
  /// instead of deforming and rasterizing the set whenever it renders at that size, active SH degree
  /// and deformation state (`ClipModel::deforms`), without a window, with no sink for the set (its
  /// Gaussians and its field) and no camera sink: the same image, bit for bit, and no node. The
  /// caller guarantees that nothing else a render of the set reads changes while the renders are
  /// kept (the set, its field, the cameras, the model's stop rule, frozen geometry, the other
  /// `settings`); `thaw_render` drops them. It uses the context's tape: `backward` needs a `forward`
  /// after it.
  /// @throws option_error `option.clip` for a size below 1 x 1
  void freeze_render(const Model& m, GaussianSet s, int width, int height, Context& ctx, ThreadPool* pool = nullptr) const {
    if (width < 1 || height < 1) throw option_error("option.clip", "freeze_render size", "must be at least 1 x 1");
    FrozenRenders<Scalar>& fr = rendered(ctx, s);
    fr = {};
    ctx.sinks = {};
    ctx.window = {};
    ctx.frame_width = m.width(), ctx.frame_height = m.height();
    for (int i = 0; i < m.frame_count(); ++i) {
      const Camera<Scalar>& full = m.cameras[std::size_t(i)];
      const Camera<Scalar> cam = width == m.width() && height == m.height() ? full : full.resized(width, height);
      ctx.tape.clear();
      (void)render_set(m, s, i, cam, ctx, {}, nullptr, pool);
      fr.image.push_back(raster_ctx(ctx, s).image);
    }
    ctx.tape.clear();
    ctx.total = {};
    fr.width = width, fr.height = height, fr.sh_degree = settings.active_sh_degree, fr.deformed = m.deforms(s);
  }
  /// True if `ctx` holds renders of set `s` of `m` (`freeze_render`) at width x height, the current
  /// active SH degree and the model's deformation state: renders `forward` would read.
  [[nodiscard]] bool has_frozen_render(const Model& m, const Context& ctx, GaussianSet s, int width, int height) const noexcept {
    const FrozenRenders<Scalar>& fr = rendered(ctx, s);
    return !fr.empty() && fr.width == width && fr.height == height && fr.sh_degree == settings.active_sh_degree &&
           fr.deformed == m.deforms(s) && fr.image.size() == std::size_t(m.frame_count());
  }
  /// Drops the renders of set `s` kept by `freeze_render`.
  static void thaw_render(Context& ctx, GaussianSet s) { rendered(ctx, s) = {}; }

  /// Records the graph of clip frame `frame` against `targets` (one size, the render size: W x H or
  /// smaller or larger, see the file comment; may be empty: render only, at W x H) and returns the
  /// losses. `grads` names the parameters that will receive gradients (`alpha`: W x H whatever the
  /// render size; `camera`: 6 values or none); `detail` (render size, or empty) weights the L1 of the merged term. Renders are in
  /// `ctx`, at the render size. A non-empty `window` (inside the model's W x H) renders that window of
  /// the full-size frame; targets and detail are then the window's size.
  /// @throws option_error `option.frame` / `option.clip` on a bad frame, targets of different sizes,
  /// a detail map of another size, or a window outside the frame or of another size than the targets
  ClipLosses forward(const Model& m, int frame, std::span<const ConstImageView<Scalar, 3>> targets, Context& ctx,
                     const Gradients& grads = {}, ConstImageView<Scalar, 1> detail = {}, ThreadPool* pool = nullptr,
                     PixelWindow window = {}) const {
    if (frame < 0 || frame >= m.frame_count())
      throw option_error("option.frame", "frame index " + std::to_string(frame), "outside the clip");
    const bool windowed = !window.empty();
    const int W = !targets.empty() ? targets[0].width() : windowed ? window.width : m.width();
    const int H = !targets.empty() ? targets[0].height() : windowed ? window.height : m.height();
    for (const auto& t : targets)
      if (t.width() != W || t.height() != H || W < 1 || H < 1) throw option_error("option.clip", "target", "targets differ in size or are empty");
    if (!detail.empty() && (detail.width() != W || detail.height() != H))
      throw option_error("option.clip", "detail", "size differs from the targets'");
    if (!grads.camera.empty() && grads.camera.size() != 6)
      throw option_error("option.graph", "camera", "the camera sink needs 6 values (omega, tau), got " + std::to_string(grads.camera.size()));
    if (windowed && (window.x < 0 || window.y < 0 || window.x + window.width > m.width() || window.y + window.height > m.height() ||
                     window.width != W || window.height != H))
      throw option_error("option.clip", "window", "outside the frame or of another size than the targets");
    const Camera<Scalar>& full = m.cameras[std::size_t(frame)];
    const Camera<Scalar> cam = windowed                           ? full.cropped(window.x, window.y, W, H)
                               : W == m.width() && H == m.height() ? full
                                                                   : full.resized(W, H);
    Tape& t = ctx.tape;
    t.clear();
    ctx.sinks = grads;
    ctx.window = window;
    ctx.frame_width = m.width(), ctx.frame_height = m.height();
    ctx.finite = true;
    ctx.losses = {};
    ctx.total = {};
    const bool fg = m.has_foreground;
    const Var Ib = render_set(m, GaussianSet::background, frame, cam, ctx, grads.bkg, grads.bkg_field, pool);
    const Var If = fg ? render_set(m, GaussianSet::foreground, frame, cam, ctx, grads.frg, grads.frg_field, pool) : Var{};
    if (ctx.merged.width() != W || ctx.merged.height() != H) ctx.merged.resize(W, H);
    if (!fg) {
      if (ctx.frg.image.width() != W || ctx.frg.image.height() != H) ctx.frg.image.resize(W, H);  // black
      std::copy(ctx.bkg.image.storage().begin(), ctx.bkg.image.storage().end(), ctx.merged.storage().begin());
    }
    if (targets.empty()) {
      if (fg) merge(m, frame, If, Ib, ctx, grads.alpha, pool, window);
      return ctx.losses;
    }

    const Scalar wf = Scalar(weights.frg), wb = Scalar(weights.bkg), wm = Scalar(weights.merged);
    const std::size_t E = targets.size();
    ctx.loss_ctx.resize(std::max(ctx.loss_ctx.size(), 3 * E), loss::L1DssimContext<Scalar, 3>(loss_options()));
    for (auto& lc : ctx.loss_ctx) lc.options = loss_options();  // `weights` may change between passes
    Var terms[3 * 16];
    Scalar term_w[3 * 16];
    double term_v[3 * 16];
    int term_kind[3 * 16];  // 0 frg, 1 bkg, 2 merged, 3 bkg + merged
    if (E > 16) throw option_error("option.clip", "targets", "at most 16 targets (an ensemble of edits) per frame");
    // Terms per target (the recording below); with two or more they share the target's statistics.
    auto positive = [](Scalar w) { return int(w > Scalar(0)); };
    const int uses = fg ? positive(wf) + positive(wb) + positive(wm) : !detail.empty() ? positive(wm) + positive(wb) : positive(wb + wm);
    const bool share = share_target_statistics && uses > 1;
    if (share) {
      ScopedTimer timer(ctx.times.loss);
      if (ctx.ssim_target.size() < E) ctx.ssim_target.resize(E);
      for (std::size_t e = 0; e < E; ++e) loss::fill_ssim_target<Scalar, 3>(targets[e], ctx.ssim_target[e], loss_options().ssim, pool);
    }
    std::size_t n = 0;
    auto add = [&](Var img, std::size_t e, Scalar w, int kind, ConstImageView<Scalar, 1> wmap) {
      if (!(w > Scalar(0))) return;
      terms[n] = loss_node(img, targets[e], share ? &ctx.ssim_target[e] : nullptr, wmap, ctx.loss_ctx[n], ctx, pool);
      term_w[n] = w;
      term_v[n] = double(t.value(terms[n])[0]);
      term_kind[n] = kind;
      ++n;
    };
    if (fg) {
      for (std::size_t e = E; e-- > 0;) add(If, e, wf, 0, {}), add(Ib, e, wb, 1, {});
      const Var I = merge(m, frame, If, Ib, ctx, grads.alpha, pool, window);
      for (std::size_t e = E; e-- > 0;) add(I, e, wm, 2, detail);
    } else if (!detail.empty()) {
      for (std::size_t e = E; e-- > 0;) add(Ib, e, wm, 2, detail);
      for (std::size_t e = E; e-- > 0;) add(Ib, e, wb, 1, {});
    } else {
      for (std::size_t e = E; e-- > 0;) add(Ib, e, wb + wm, 3, {});
    }
    // Values: per kind summed over targets in increasing e, the total as w_f L_f + w_b L_b + w_m L_m.
    ClipLosses& L = ctx.losses;
    for (std::size_t k = n; k-- > 0;) {
      const double v = term_v[k];
      if (term_kind[k] == 0) L.frg += v;
      if (term_kind[k] == 1 || term_kind[k] == 3) L.bkg += v;
      if (term_kind[k] == 2 || term_kind[k] == 3) L.merged += v;
    }
    L.total = double(wf) * L.frg + double(wb) * L.bkg + double(wm) * L.merged;
    ctx.total = weighted_sum(t, std::span<const Var>(terms, n), std::span<const Scalar>(term_w, n), L.total);
    return L;
  }

  /// Back-propagates the last `forward`: zeroes the sinks of `ClipGradients`, then replays the tape,
  /// so that afterwards they hold dL/dparameter (and `ctx.*_mean2d` dL/dmean2d). Returns false if an
  /// image gradient reaching a rasterizer was not finite: the sinks are then incomplete and must not
  /// be used. Requires a forward with at least one target.
  bool backward(Context& ctx, ThreadPool* pool = nullptr) const {
    VIDEO3DGS_ASSERT(ctx.total.valid(), "ClipGraph::backward without a forward with targets");
    const Gradients& g = ctx.sinks;
    for (const GaussianGrads<Scalar>* s : {&g.frg, &g.bkg})
      for (std::span<Scalar> v : {s->dL_dmean, s->dL_dlog_scale, s->dL_drotation, s->dL_dopacity_logit, s->dL_dsh})
        std::fill(v.begin(), v.end(), Scalar(0));
    std::fill(g.alpha.begin(), g.alpha.end(), Scalar(0));
    std::fill(g.camera.begin(), g.camera.end(), Scalar(0));
    for (Field* f : {g.frg_field, g.bkg_field})
      if (f) f->zero_grad();
    (void)pool;
    ctx.tape.backward(ctx.total);
    return ctx.finite;
  }

 private:
  [[nodiscard]] loss::L1DssimOptions loss_options() const {
    loss::L1DssimOptions o;
    o.lambda_dssim = weights.lambda_dssim;
    return o;
  }
  static RasterContext<Scalar, 3>& raster_ctx(Context& c, GaussianSet s) { return s == GaussianSet::foreground ? c.frg : c.bkg; }
  static DeformScratch<Scalar, Field>& scratch(Context& c, GaussianSet s) {
    return s == GaussianSet::foreground ? c.frg_scratch : c.bkg_scratch;
  }
  static FrozenGeometry<Scalar>& frozen(Context& c, GaussianSet s) { return s == GaussianSet::foreground ? c.frg_frozen : c.bkg_frozen; }
  template <class C>  // Context or const Context
  static auto& rendered(C& c, GaussianSet s) { return s == GaussianSet::foreground ? c.frg_rendered : c.bkg_rendered; }
  static std::vector<Scalar>& mean2d(Context& c, GaussianSet s) { return s == GaussianSet::foreground ? c.frg_mean2d : c.bkg_mean2d; }

  static Scalar* grad_or_null(std::span<Scalar> s) { return s.empty() ? nullptr : s.data(); }
  static std::span<Scalar> span_of(Tape& t, Var v) {
    Scalar* g = t.grad(v);
    return g ? std::span<Scalar>(g, t.size(v)) : std::span<Scalar>();
  }

  /// Deformation node (unless off or frozen) and raster node of one set, or its kept render
  /// (`freeze_render`) as a constant when that applies; returns the image node.
  Var render_set(const Model& m, GaussianSet s, int frame, const Camera<Scalar>& cam, Context& ctx, const GaussianGrads<Scalar>& g,
                 Field* field, ThreadPool* pool) const {
    Tape& t = ctx.tape;
    const bool no_sink = field == nullptr && ctx.sinks.camera.empty() && g.dL_dmean.empty() && g.dL_dlog_scale.empty() &&
                         g.dL_drotation.empty() && g.dL_dopacity_logit.empty() && g.dL_dsh.empty();
    if (no_sink && ctx.window.empty() && has_frozen_render(m, ctx, s, cam.width, cam.height)) {
      RasterContext<Scalar, 3>& rc = raster_ctx(ctx, s);
      const Image<Scalar, 3>& kept = rendered(ctx, s).image[std::size_t(frame)];
      if (rc.image.width() != cam.width || rc.image.height() != cam.height) rc.image.resize(cam.width, cam.height);
      std::copy(kept.storage().begin(), kept.storage().end(), rc.image.storage().begin());
      rc.stats = {};  // nothing rasterized
      return t.constant(rc.image.data(), std::size_t(cam.height), std::size_t(cam.width) * 3);
    }
    const auto& cloud = m.cloud(s);
    const std::size_t n = cloud.size();
    GaussianParams<Scalar> p = cloud.params();
    auto leaf = [&](std::span<const Scalar> v, std::span<Scalar> grad, std::size_t cols) {
      return t.leaf(const_cast<Scalar*>(v.data()), grad_or_null(grad), n, cols);
    };
    Var mean = leaf(p.mean, g.dL_dmean, 3), log_scale = leaf(p.log_scale, g.dL_dlog_scale, 3), rotation = leaf(p.rotation, g.dL_drotation, 4);
    const Var opacity = leaf(p.opacity_logit, g.dL_dopacity_logit, 1), sh = leaf(p.sh, g.dL_dsh, p.sh.size() / std::max<std::size_t>(n, 1));
    const FrozenGeometry<Scalar>& fz = frozen(ctx, s);
    if (!fz.empty()) {
      const auto f = std::size_t(frame);
      mean = t.constant(fz.mean[f].data(), n, 3);
      log_scale = t.constant(fz.log_scale[f].data(), n, 3);
      rotation = t.constant(fz.rotation[f].data(), n, 4);
    } else if (m.deforms(s) && n > 0) {
      deform(m, s, frame, ctx, mean, log_scale, rotation, field, pool);
    }
    if (!ctx.sinks.camera.empty() && n > 0) camera_node(cam.center(), ctx, mean, rotation);
    return rasterize(m, cam, s, n, cloud.params().sh_degree, ctx, mean, log_scale, rotation, opacity, sh, pool);
  }

  /// Deformation node: replaces (mean, log_scale, rotation) by the deformed outputs.
  void deform(const Model& m, GaussianSet s, int frame, Context& ctx, Var& mean, Var& log_scale, Var& rotation, Field* field,
              ThreadPool* pool) const {
    Tape& t = ctx.tape;
    DeformScratch<Scalar, Field>& sc = scratch(ctx, s);
    {
      ScopedTimer timer(ctx.times.deformation);
      (void)m.deformed(s, frame, sc, pool);
    }
    const std::size_t n = t.rows(mean);
    const bool geometry = t.requires_grad(mean) || t.requires_grad(log_scale) || t.requires_grad(rotation);
    const bool constant = s == GaussianSet::foreground ? ctx.sinks.frg_field_constant : ctx.sinks.bkg_field_constant;
    // Names built only to throw: a forward allocates nothing once its sizes are stable.
    auto refuse = [s](const char* suffix, const char* why) {
      throw option_error("option.graph", to_string(s) + std::string("_field") + suffix, why);
    };
    if (constant && field != nullptr) refuse("_constant", "a constant field is not a gradient sink");
    // The field's backward gives the canonical gradients and its own together: geometry gradients
    // through a deformation need the field as a sink, or the field declared a constant.
    if (geometry && field == nullptr && !constant) refuse("", "geometry gradients through the deformation need the field as a sink");
    if (constant && t.requires_grad(mean) && m.field(s).options().grid_input_gradient)
      refuse("_constant", "with grid_input_gradient the means' gradient runs through the field: it must be a sink");
    const bool need = field != nullptr || (constant && geometry);
    const Var dm = t.output(sc.mean.data(), n, 3, need), dls = t.output(sc.log_scale.data(), n, 3, need),
              drot = t.output(sc.rotation.data(), n, 4, need);
    if (field != nullptr)
      t.on_backward([&t, &ctx, &sc, field, dm, dls, drot, cm = t.grad(mean), cls = t.grad(log_scale), crot = t.grad(rotation), pool] {
        ScopedTimer timer(ctx.times.deformation);
        field->backward(sc.ctx, t.grad(dm), t.grad(dls), t.grad(drot), {cm, cls, crot}, pool);
      });
    else if (need)
      t.on_backward([&t, &ctx, &sc, f = &m.field(s), dm, dls, drot, cm = t.grad(mean), cls = t.grad(log_scale), crot = t.grad(rotation), pool] {
        ScopedTimer timer(ctx.times.deformation);
        f->backward_canonical(sc.ctx, t.grad(dm), t.grad(dls), t.grad(drot), {cm, cls, crot}, pool);
      });
    mean = dm, log_scale = dls, rotation = drot;
  }

  /// Camera node (see the file comment): identity outputs, backward into the inputs and the camera sink.
  void camera_node(const typename Camera<Scalar>::Vec3& centre, Context& ctx, Var& mean, Var& rotation) const {
    Tape& t = ctx.tape;
    const std::size_t n = t.rows(mean);
    const Var m2 = t.output(t.value(mean), n, 3, true), q2 = t.output(t.value(rotation), n, 4, true);
    t.on_backward([&t, &ctx, mean, rotation, m2, q2, n, c = centre] {
      const Scalar *mu = t.value(mean), *q = t.value(rotation), *gm = t.grad(m2), *gq = t.grad(q2);
      double s[6] = {0, 0, 0, 0, 0, 0};  // omega, tau
      for (std::size_t i = 0; i < n; ++i) {
        const double g[3] = {double(gm[3 * i]), double(gm[3 * i + 1]), double(gm[3 * i + 2])};
        const double r[3] = {double(mu[3 * i]) - double(c.x()), double(mu[3 * i + 1]) - double(c.y()), double(mu[3 * i + 2]) - double(c.z())};
        const double w = double(q[4 * i]), v[3] = {double(q[4 * i + 1]), double(q[4 * i + 2]), double(q[4 * i + 3])};
        const double h0 = double(gq[4 * i]), h[3] = {double(gq[4 * i + 1]), double(gq[4 * i + 2]), double(gq[4 * i + 3])};
        s[0] += r[1] * g[2] - r[2] * g[1] + 0.5 * (w * h[0] - h0 * v[0] + v[1] * h[2] - v[2] * h[1]);
        s[1] += r[2] * g[0] - r[0] * g[2] + 0.5 * (w * h[1] - h0 * v[1] + v[2] * h[0] - v[0] * h[2]);
        s[2] += r[0] * g[1] - r[1] * g[0] + 0.5 * (w * h[2] - h0 * v[2] + v[0] * h[1] - v[1] * h[0]);
        s[3] += g[0], s[4] += g[1], s[5] += g[2];
      }
      for (int k = 0; k < 6; ++k) ctx.sinks.camera[std::size_t(k)] += Scalar(s[k]);
      if (Scalar* d = t.grad(mean))
        for (std::size_t i = 0; i < 3 * n; ++i) d[i] += gm[i];
      if (Scalar* d = t.grad(rotation))
        for (std::size_t i = 0; i < 4 * n; ++i) d[i] += gq[i];
    });
    mean = m2, rotation = q2;
  }

  /// Raster node: image = rasterize(params) with `settings` but the model's stop rule
  /// (ClipModel::min_transmittance, blend_at_stop); backward in the rasterizer's accumulate mode.
  Var rasterize(const Model& m, const Camera<Scalar>& cam, GaussianSet s, std::size_t n, int sh_degree, Context& ctx, Var mean, Var log_scale,
                Var rotation, Var opacity, Var sh, ThreadPool* pool) const {
    Tape& t = ctx.tape;
    RasterContext<Scalar, 3>& rc = raster_ctx(ctx, s);
    GaussianParams<Scalar> p;
    p.count = n;
    p.sh_degree = sh_degree;
    auto cspan = [&](Var v) { return std::span<const Scalar>(t.value(v), t.size(v)); };
    p.mean = cspan(mean), p.log_scale = cspan(log_scale), p.rotation = cspan(rotation), p.opacity_logit = cspan(opacity), p.sh = cspan(sh);
    RasterSettings<Scalar, 3> rs = settings;
    rs.depth = false;  // no node of the graph reads the renders' depth
    rs.min_transmittance = m.min_transmittance, rs.blend_at_stop = m.blend_at_stop;
    if (ctx.window.width > 0) rs.clamp_frame_x = ctx.window.x, rs.clamp_frame_y = ctx.window.y, rs.clamp_frame_width = ctx.frame_width,
                              rs.clamp_frame_height = ctx.frame_height;
    const Rasterizer<Scalar, TileSize, 3> r(rs);
    {
      ScopedTimer timer(ctx.times.raster_forward);
      r.forward(cam, p, rc, pool);
    }
    const bool need = t.requires_grad(mean) || t.requires_grad(log_scale) || t.requires_grad(rotation) || t.requires_grad(opacity) ||
                      t.requires_grad(sh);
    const Var img = t.output(rc.image.data(), std::size_t(cam.height), std::size_t(cam.width) * 3, need);
    if (need) {
      std::vector<Scalar>& m2d = mean2d(ctx, s);
      std::vector<Scalar>& bw = s == GaussianSet::foreground ? ctx.frg_weight : ctx.bkg_weight;
      std::vector<Scalar>& be = s == GaussianSet::foreground ? ctx.frg_evals : ctx.bkg_evals;
      m2d.resize(2 * n);
      bw.resize(ctx.blend_weights ? n : 0);
      be.resize(ctx.blend_weights ? n : 0);
      t.on_backward([&t, &ctx, &rc, &m2d, &bw, &be, r, img, mean, log_scale, rotation, opacity, sh, pool] {
        ScopedTimer timer(ctx.times.raster_backward);
        const Scalar* gi = t.grad(img);
        const ConstImageView<Scalar, 3> dimage(gi, rc.camera.width, rc.camera.height);
        if (!detail::all_finite<Scalar>(std::span<const Scalar>(gi, t.size(img)))) {
          ctx.finite = false;
          return;
        }
        std::fill(m2d.begin(), m2d.end(), Scalar(0));
        std::fill(bw.begin(), bw.end(), Scalar(0));
        std::fill(be.begin(), be.end(), Scalar(0));
        RasterGrads<Scalar, 3> g;
        g.gaussians = {span_of(t, mean), span_of(t, log_scale), span_of(t, rotation), span_of(t, opacity), span_of(t, sh)};
        g.dL_dmean2d = m2d;
        g.blend_weight = bw;
        g.blend_evals = be;
        g.accumulate = true;
        r.backward(rc, dimage, {}, {}, g, pool);
      });
    }
    return img;
  }

  /// Merge node: I = A I_frg + (1 - A) I_bkg into ctx.merged, at the render size W x H (`ctx.merged`'s);
  /// the frame's alpha logits pass through a window node (a non-empty `window`) or a resample node
  /// first when their size differs.
  Var merge(const Model& m, int frame, Var If, Var Ib, Context& ctx, std::span<Scalar> dalpha, ThreadPool* pool,
            PixelWindow window = {}) const {
    Tape& t = ctx.tape;
    const Image<Scalar, 1>& full = m.alpha_logit[std::size_t(frame)];
    const int W = ctx.merged.width(), H = ctx.merged.height();
    Var a = t.leaf(const_cast<Scalar*>(full.data()), grad_or_null(dalpha), std::size_t(full.height()), std::size_t(full.width()));
    const Scalar* logit_data = full.data();
    if (!window.empty()) {
      // a' = the window of a; backward: dL/da (inside the window) += dL/da'.
      if (ctx.alpha_resampled.width() != W || ctx.alpha_resampled.height() != H) ctx.alpha_resampled.resize(W, H);
      const auto in = ConstImageView<Scalar, 1>(full).crop(window.x, window.y, W, H);
      for (int y = 0; y < H; ++y) std::copy_n(in.row(y), std::size_t(W), ctx.alpha_resampled.pixel(0, y));
      const Var low = t.output(ctx.alpha_resampled.data(), std::size_t(H), std::size_t(W), t.requires_grad(a));
      if (t.requires_grad(a))
        t.on_backward([&t, a, low, W, H, window, FW = full.width(), FH = full.height()] {
          const ConstImageView<Scalar, 1> g(t.grad(low), W, H);
          const auto ga = ImageView<Scalar, 1>(t.grad(a), FW, FH).crop(window.x, window.y, W, H);
          for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x) ga(x, y) += g(x, y);
        });
      a = low;
      logit_data = ctx.alpha_resampled.data();
    } else if (W != full.width() || H != full.height()) {
      AreaResampler& rs = ctx.alpha_resampler;
      if (!rs.maps(full.width(), full.height(), W, H)) rs = AreaResampler(full.width(), full.height(), W, H);
      if (ctx.alpha_resampled.width() != W || ctx.alpha_resampled.height() != H) ctx.alpha_resampled.resize(W, H);
      {
        ScopedTimer timer(ctx.times.loss);
        rs.template forward<Scalar, 1>(full, ctx.alpha_resampled);
      }
      const Var low = t.output(ctx.alpha_resampled.data(), std::size_t(H), std::size_t(W), t.requires_grad(a));
      if (t.requires_grad(a))
        t.on_backward([&t, &ctx, &rs, a, low, W, H, FW = full.width(), FH = full.height()] {
          ScopedTimer timer(ctx.times.loss);
          rs.template adjoint_add<Scalar, 1>(ConstImageView<Scalar, 1>(t.grad(low), W, H), ImageView<Scalar, 1>(t.grad(a), FW, FH));
        });
      a = low;
      logit_data = ctx.alpha_resampled.data();
    }
    const ConstImageView<Scalar, 1> logit(logit_data, W, H);
    const ConstImageView<Scalar, 3> f(t.value(If), W, H), b(t.value(Ib), W, H);
    {
      ScopedTimer timer(ctx.times.loss);
      alpha_merge_forward<Scalar, 3>(f, b, logit, ctx.merged, pool);
    }
    const bool need = t.requires_grad(If) || t.requires_grad(Ib) || t.requires_grad(a);
    const Var out = t.output(ctx.merged.data(), std::size_t(H), std::size_t(W) * 3, need);
    if (need)
      t.on_backward([&t, &ctx, f, b, W, H, If, Ib, a, out, pool] {
        ScopedTimer timer(ctx.times.loss);
        auto view3 = [&](Var v) { return t.grad(v) ? ImageView<Scalar, 3>(t.grad(v), W, H) : ImageView<Scalar, 3>(); };
        const ImageView<Scalar, 1> da = t.grad(a) ? ImageView<Scalar, 1>(t.grad(a), W, H) : ImageView<Scalar, 1>();
        alpha_merge_backward<Scalar, 3>(f, b, ConstImageView<Scalar, 1>(t.value(a), W, H), ConstImageView<Scalar, 3>(t.grad(out), W, H),
                                        view3(If), view3(Ib), da, pool, true);
      });
    return out;
  }

  /// Loss node: l(x, y) (1 x 1) with saved state in `lc`; `shared` (or null): y's SSIM statistics.
  Var loss_node(Var x, ConstImageView<Scalar, 3> y, const loss::SsimTarget<Scalar, 3>* shared, ConstImageView<Scalar, 1> wmap,
                loss::L1DssimContext<Scalar, 3>& lc, Context& ctx, ThreadPool* pool) const {
    Tape& t = ctx.tape;
    const int W = y.width(), H = y.height();
    lc.options = loss_options();
    const bool need = t.requires_grad(x);
    ScopedTimer timer(ctx.times.loss);
    return t.custom(
        1, 1, need,
        [&](Scalar* out) {
          const ConstImageView<Scalar, 3> xv(t.value(x), W, H);
          out[0] = shared ? loss::l1_dssim_forward<Scalar, 3>(xv, *shared, lc, pool, wmap) : loss::l1_dssim_forward<Scalar, 3>(xv, y, lc, pool, wmap);
        },
        [&t, &ctx, &lc, x, W, H, pool](const Scalar*, const Scalar* dout) {
          ScopedTimer timer(ctx.times.loss);
          loss::l1_dssim_backward<Scalar, 3>(lc, dout[0], ImageView<Scalar, 3>(t.grad(x), W, H), pool);
        });
  }

  /// L = sum_k w_k l_k (value `total`, computed by the caller in double).
  static Var weighted_sum(Tape& t, std::span<const Var> terms, std::span<const Scalar> w, double total) {
    Var* in = t.template scratch<Var>(terms.size());
    Scalar* wk = t.template scratch<Scalar>(terms.size());
    std::copy(terms.begin(), terms.end(), in);
    std::copy(w.begin(), w.end(), wk);
    const std::size_t n = terms.size();
    return t.custom(
        1, 1, true, [&](Scalar* out) { out[0] = Scalar(total); },
        [&t, in, wk, n](const Scalar*, const Scalar* dout) {
          for (std::size_t k = 0; k < n; ++k)
            if (Scalar* g = t.grad(in[k])) g[0] += wk[k] * dout[0];
        });
  }
};

/// The renders of one clip frame (`frg.image`, `bkg.image`, `merged`): a graph context.
template <class Scalar, class Field = DefaultDeformationField<Scalar>>
using ClipRenderBuffers = ClipGraphContext<Scalar, Field>;

}  // namespace video3dgs
