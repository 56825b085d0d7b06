#pragma once
/// @file
/// `DeformationField<Scalar, Grid, Hidden, HiddenLayers, Activation>`: the time-dependent deformation
/// of a Gaussian cloud (docs/method.md). For Gaussian i at time t:
///
///     x_i = clamp((mu_i - lo) / (hi - lo), 0, 1)          box [lo, hi] fixed at construction (+ margin)
///     h_i = [Grid(x_i, t), x_i, t]                        (Grid::kOutputs + 4 features)
///     (dxyz, drot, dscale) = (Head_xyz(h_i), Head_rot(h_i), Head_scale(h_i))
///
/// and the deformed parameters, in the default (stable) mode:
///
///     mu'  = mu + dxyz
///     s'   = s + dscale                       (log-scale: the scale exp(s') stays positive)
///     q'   = v / |v|,  v = q/|q| + drot       (a unit quaternion; |v| is floored at 1e-12)
///
/// and in the reference mode (`DeformationMode::reference`, the public implementation):
///
///     mu' = mu + dxyz,   exp(s') = exp(s) + dscale (floored at min_scale),   q' = q/|q| + drot,
///     with the box recomputed from the current means on every call (treated as a constant).
///
/// Backward (g' = dL/d(deformed parameter)):
///
///     dL/dmu += g'_mu,  dL/ddxyz = g'_mu
///     stable:    dL/ds += g'_s,  dL/ddscale = g'_s
///                dL/dv = (g'_q - q'(q'.g'_q)) / |v|,  dL/ddrot = dL/dv,  dL/dq += (dL/dv - u(u.dL/dv)) / |q|
///     reference: a = exp(s) + dscale: dL/da = g'_s / a (0 if floored), dL/ds += dL/da exp(s), dL/ddscale = dL/da
///                dL/ddrot = g'_q,  dL/dq += (g'_q - u(u.g'_q)) / |q|
///     heads: Linear/Mlp adjoints give dL/dparams and dL/dh; the grid: dL/dtable (scatter-add).
///     Optionally (`grid_input_gradient`) dL/dmu += (dL/dx from the grid and the raw-input columns) / (hi - lo).
///     A field held constant (`backward_canonical`): the dL/dmu, dL/ds, dL/dq lines alone.
///
/// Buffers are per Gaussian, row-major: means and log-scales N x 3, quaternions (w, x, y, z) N x 4.
/// The field owns its parameters and their gradient accumulators (`segments()`, for the optimizer).

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "video3dgs/autodiff/param_segment.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/hash_grid/hash_grid.hpp"
#include "video3dgs/heads/mlp.hpp"

namespace video3dgs {

enum class DeformationMode { stable, reference };

struct DeformationOptions {
  HashGridOptions grid{};
  /// Hidden layers of the heads (if any) use `hidden_init`; their output layers use `head_init`.
  HeadInitOptions hidden_init{HeadInit::uniform_fan_in, 1e-3, 11};
  HeadInitOptions head_init{HeadInit::small, 1e-3, 13};
  DeformationMode mode = DeformationMode::stable;
  double box_margin = 0.1;          ///< fraction of the box extent added on every side
  bool grid_input_gradient = false; ///< propagate dL/dx through the normalised inputs into the means
  double min_scale = 1e-7;          ///< reference mode: floor of exp(s) + dscale
};

template <class Scalar, class Grid = HashGrid4D<Scalar, 19>, int Hidden = 64, int HiddenLayers = 0, class Activation = Relu>
class DeformationField {
  static_assert(Grid::kDims == 4, "video3dgs: DeformationField needs a 4D grid over (x, y, z, t)");
  static_assert(std::is_same_v<typename Grid::scalar_type, Scalar>, "video3dgs: DeformationField's Grid must use the same Scalar");

 public:
  using scalar_type = Scalar;
  using grid_type = Grid;
  static constexpr int kFeatures = Grid::kOutputs + 4;
  using HeadXyz = Mlp<Scalar, kFeatures, 3, Hidden, HiddenLayers, Activation>;
  using HeadRot = Mlp<Scalar, kFeatures, 4, Hidden, HiddenLayers, Activation>;
  using HeadScale = Mlp<Scalar, kFeatures, 3, Hidden, HiddenLayers, Activation>;
  using Matrix = BatchMatrix<Scalar>;

  struct Inputs {
    const Scalar* mean = nullptr;       ///< N x 3
    const Scalar* log_scale = nullptr;  ///< N x 3
    const Scalar* rotation = nullptr;   ///< N x 4, (w, x, y, z), any nonzero norm
    std::size_t count = 0;
    Scalar time = 0;                    ///< t in [0, 1] (clamped)
  };
  struct Outputs {
    Scalar* mean = nullptr;       ///< N x 3
    Scalar* log_scale = nullptr;  ///< N x 3
    Scalar* rotation = nullptr;   ///< N x 4
  };
  /// Gradients w.r.t. the canonical parameters (accumulated; any may be null).
  struct Gradients {
    Scalar* dL_dmean = nullptr;
    Scalar* dL_dlog_scale = nullptr;
    Scalar* dL_drotation = nullptr;
  };
  /// Saved forward state; reuse one per cloud so buffers are allocated once. The input buffers must
  /// stay alive and unchanged until `backward`.
  struct Context {
    Inputs in;
    std::array<Scalar, 3> lo{}, extent{};
    std::vector<Scalar> x;                 ///< N x 4 normalised inputs (row-major)
    Matrix h;                              ///< N x kFeatures head input (grid features first)
    Matrix dxyz, drot, dscale;             ///< head outputs
    typename HeadXyz::Context cxyz;
    typename HeadRot::Context crot;
    typename HeadScale::Context cscale;
    std::vector<Scalar> unit, qnorm, vnorm;  ///< u = q/|q| (N x 4), |q|, |v| (stable)
    Matrix g_xyz, g_rot, g_scale, dh;      ///< backward scratch
    std::vector<Scalar> dx;                ///< N x 4 grid input gradient scratch
  };

  /// @param canonical_means N x 3, the means the box is fitted to (with `box_margin`).
  /// @throws numeric_error `numeric.non_finite` if a mean is not finite; option_error on bad options.
  DeformationField(std::span<const Scalar> canonical_means, const DeformationOptions& options = {})
      : options_(options), grid_(options.grid), xyz_(options.hidden_init, options.head_init),
        rot_(with_seed(options.hidden_init, 100), with_seed(options.head_init, 100)),
        scale_(with_seed(options.hidden_init, 200), with_seed(options.head_init, 200)) {
    if (!(options.box_margin >= 0) || !std::isfinite(options.box_margin))
      throw option_error("option.deformation", "box_margin", "must be finite and >= 0");
    if (!(options.min_scale > 0)) throw option_error("option.deformation", "min_scale", "must be > 0");
    if (canonical_means.size() % 3 != 0)
      throw option_error("option.deformation", "canonical_means", "size must be a multiple of 3");
    fit_box(canonical_means.data(), canonical_means.size() / 3, box_lo_, box_extent_, true);
    grid_grad_.assign(grid_.param_count(), Scalar(0));
    for (std::size_t i = 0; i < HeadXyz::segment_count(); ++i) xyz_grad_[i].assign(xyz_.segment_size(i), Scalar(0));
    for (std::size_t i = 0; i < HeadRot::segment_count(); ++i) rot_grad_[i].assign(rot_.segment_size(i), Scalar(0));
    for (std::size_t i = 0; i < HeadScale::segment_count(); ++i) scale_grad_[i].assign(scale_.segment_size(i), Scalar(0));
  }

  [[nodiscard]] const DeformationOptions& options() const noexcept { return options_; }
  [[nodiscard]] Grid& grid() noexcept { return grid_; }
  [[nodiscard]] const Grid& grid() const noexcept { return grid_; }
  [[nodiscard]] HeadXyz& head_xyz() noexcept { return xyz_; }
  [[nodiscard]] HeadRot& head_rotation() noexcept { return rot_; }
  [[nodiscard]] HeadScale& head_scale() noexcept { return scale_; }
  /// The normalisation box: lo and extent (hi - lo) per axis.
  [[nodiscard]] std::array<Scalar, 3> box_lo() const noexcept { return box_lo_; }
  [[nodiscard]] std::array<Scalar, 3> box_extent() const noexcept { return box_extent_; }

  /// Every parameter buffer with its gradient: the grid table, then the heads' layers (xyz, rot, scale).
  [[nodiscard]] std::vector<ParamSegment<Scalar>> segments() {
    std::vector<ParamSegment<Scalar>> s;
    s.push_back({grid_.params(), grid_grad_});
    for (std::size_t i = 0; i < HeadXyz::segment_count(); ++i) s.push_back({xyz_.segment(i), xyz_grad_[i]});
    for (std::size_t i = 0; i < HeadRot::segment_count(); ++i) s.push_back({rot_.segment(i), rot_grad_[i]});
    for (std::size_t i = 0; i < HeadScale::segment_count(); ++i) s.push_back({scale_.segment(i), scale_grad_[i]});
    return s;
  }
  [[nodiscard]] std::span<Scalar> grid_grad() noexcept { return grid_grad_; }
  void zero_grad() {
    std::fill(grid_grad_.begin(), grid_grad_.end(), Scalar(0));
    for (auto& g : xyz_grad_) std::fill(g.begin(), g.end(), Scalar(0));
    for (auto& g : rot_grad_) std::fill(g.begin(), g.end(), Scalar(0));
    for (auto& g : scale_grad_) std::fill(g.begin(), g.end(), Scalar(0));
  }

  /// Deforms N Gaussians to time `in.time`; writes the deformed parameters to `out`.
  void forward(const Inputs& in, const Outputs& out, Context& ctx, ThreadPool* pool = nullptr) const {
    const std::size_t n = in.count;
    const auto N = Eigen::Index(n);
    ctx.in = in;
    if (options_.mode == DeformationMode::reference) {
      fit_box(in.mean, n, ctx.lo, ctx.extent, false);
    } else {
      ctx.lo = box_lo_;
      ctx.extent = box_extent_;
    }
    const Scalar t = std::clamp(in.time, Scalar(0), Scalar(1));
    ctx.x.resize(n * 4);
    ctx.h.resize(N, kFeatures);
    for (std::size_t i = 0; i < n; ++i) {
      for (int d = 0; d < 3; ++d) {
        const Scalar v = (in.mean[i * 3 + d] - ctx.lo[d]) / ctx.extent[d];
        ctx.x[i * 4 + d] = v;  // unclamped here: the grid clamps, and backward needs to know where
        ctx.h(Eigen::Index(i), Grid::kOutputs + d) = std::clamp(v, Scalar(0), Scalar(1));
      }
      ctx.x[i * 4 + 3] = t;
      ctx.h(Eigen::Index(i), Grid::kOutputs + 3) = t;
    }
    // The grid writes feature-major output: exactly the first kOutputs columns of h.
    grid_.forward(ctx.x.data(), n, ctx.h.data(), pool);
    if constexpr (kFusedHeads) {
      // The three layers block by block (Linear::forward_block): each block of h is read from memory
      // once for all three; every output is the bits of the layer's own forward.
      ctx.dxyz.resize(N, 3);
      ctx.drot.resize(N, 4);
      ctx.dscale.resize(N, 3);
      parallel_for_chunks(pool, n, HeadXyz::First::kRowBlock, [&](std::size_t, std::size_t b, std::size_t e) {
        const auto r0 = Eigen::Index(b), len = Eigen::Index(e - b);
        xyz_.first().forward_block(ctx.h, ctx.dxyz, r0, len);
        rot_.first().forward_block(ctx.h, ctx.drot, r0, len);
        scale_.first().forward_block(ctx.h, ctx.dscale, r0, len);
      });
    } else {
      xyz_.forward(ctx.h, ctx.dxyz, ctx.cxyz, pool);
      rot_.forward(ctx.h, ctx.drot, ctx.crot, pool);
      scale_.forward(ctx.h, ctx.dscale, ctx.cscale, pool);
    }

    const bool stable = options_.mode == DeformationMode::stable;
    ctx.unit.resize(n * 4);
    ctx.qnorm.resize(n);
    ctx.vnorm.resize(n);
    const Scalar min_log = Scalar(std::log(options_.min_scale));
    parallel_for(pool, n, [&](std::size_t i) {
      const auto r = Eigen::Index(i);
      for (int d = 0; d < 3; ++d) out.mean[i * 3 + d] = in.mean[i * 3 + d] + ctx.dxyz(r, d);
      for (int d = 0; d < 3; ++d) {
        const Scalar s = in.log_scale[i * 3 + d];
        if (stable) {
          out.log_scale[i * 3 + d] = s + ctx.dscale(r, d);
        } else {
          const Scalar a = std::exp(s) + ctx.dscale(r, d);
          out.log_scale[i * 3 + d] = a > Scalar(options_.min_scale) ? std::log(a) : min_log;
        }
      }
      const Scalar* q = in.rotation + i * 4;
      const Scalar qn = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
      const Scalar iq = Scalar(1) / std::max(qn, kNormFloor);
      ctx.qnorm[i] = qn;
      std::array<Scalar, 4> v;
      for (int c = 0; c < 4; ++c) {
        ctx.unit[i * 4 + c] = q[c] * iq;
        v[c] = ctx.unit[i * 4 + c] + ctx.drot(r, c);
      }
      if (stable) {
        const Scalar vn = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2] + v[3] * v[3]);
        ctx.vnorm[i] = vn;
        const Scalar iv = Scalar(1) / std::max(vn, kNormFloor);
        for (int c = 0; c < 4; ++c) out.rotation[i * 4 + c] = v[c] * iv;
      } else {
        for (int c = 0; c < 4; ++c) out.rotation[i * 4 + c] = v[c];
      }
    }, 1024);
  }

  /// Given dL/d(deformed parameters) (N x 3, N x 3, N x 4; any may be null = zero), accumulates the
  /// gradients of the field's parameters (see `segments()`) and of the canonical parameters.
  void backward(Context& ctx, const Scalar* dL_dmean_out, const Scalar* dL_dlog_scale_out, const Scalar* dL_drotation_out,
                const Gradients& canonical, ThreadPool* pool = nullptr) {
    const std::size_t n = ctx.in.count;
    const auto N = Eigen::Index(n);
    pointwise_backward<true>(ctx, dL_dmean_out, dL_dlog_scale_out, dL_drotation_out, canonical, pool);

    // Heads: parameter gradients and dL/dh.
    ctx.dh.setZero(N, kFeatures);
    if constexpr (kFusedHeads) {
      // The three layers' backwards part by part and block by block (Linear::backward_block): the
      // same parts, the same per-part sums and, per element of dL/dh, the same additions in the same
      // order (xyz's, then rot's, then scale's) as the three backwards in turn: the same bits.
      using Lx = typename HeadXyz::First;
      using Lr = typename HeadRot::First;
      using Ls = typename HeadScale::First;
      typename Lx::Partials px;
      typename Lr::Partials pr;
      typename Ls::Partials ps;
      parallel_for(pool, Lx::kBackwardParts, [&](std::size_t k) {
        Lx::clear(px[k]);
        Lr::clear(pr[k]);
        Ls::clear(ps[k]);
        Lx::for_part_blocks(n, k, [&](Eigen::Index r0, Eigen::Index len) {
          xyz_.first().backward_block(ctx.h, ctx.g_xyz, px[k], r0, len, &ctx.dh);
          rot_.first().backward_block(ctx.h, ctx.g_rot, pr[k], r0, len, &ctx.dh);
          scale_.first().backward_block(ctx.h, ctx.g_scale, ps[k], r0, len, &ctx.dh);
        });
      }, 1);
      Lx::add_partials(px, xyz_grad_[0]);
      Lr::add_partials(pr, rot_grad_[0]);
      Ls::add_partials(ps, scale_grad_[0]);
    } else {
      std::array<std::span<Scalar>, HeadXyz::segment_count()> gx;
      std::array<std::span<Scalar>, HeadRot::segment_count()> gr;
      std::array<std::span<Scalar>, HeadScale::segment_count()> gs;
      for (std::size_t i = 0; i < gx.size(); ++i) gx[i] = xyz_grad_[i];
      for (std::size_t i = 0; i < gr.size(); ++i) gr[i] = rot_grad_[i];
      for (std::size_t i = 0; i < gs.size(); ++i) gs[i] = scale_grad_[i];
      xyz_.backward(ctx.h, ctx.g_xyz, ctx.cxyz, std::span<const std::span<Scalar>>(gx), &ctx.dh, pool);
      rot_.backward(ctx.h, ctx.g_rot, ctx.crot, std::span<const std::span<Scalar>>(gr), &ctx.dh, pool);
      scale_.backward(ctx.h, ctx.g_scale, ctx.cscale, std::span<const std::span<Scalar>>(gs), &ctx.dh, pool);
    }

    // Grid: dL/dtable from the first kOutputs columns of dL/dh (feature-major), optionally dL/dx.
    const bool to_means = options_.grid_input_gradient && canonical.dL_dmean != nullptr;
    if (to_means) ctx.dx.assign(n * 4, Scalar(0));
    grid_.backward(ctx.x.data(), n, ctx.dh.data(), grid_grad_.data(), to_means ? ctx.dx.data() : nullptr, pool);
    if (to_means) {
      for (std::size_t i = 0; i < n; ++i)
        for (int d = 0; d < 3; ++d) {
          const Scalar v = ctx.x[i * 4 + d];
          if (v < Scalar(0) || v > Scalar(1)) continue;  // clamped: no gradient
          const Scalar g = ctx.dx[i * 4 + d] + ctx.dh(Eigen::Index(i), Grid::kOutputs + d);
          canonical.dL_dmean[i * 3 + d] += g / ctx.extent[d];
        }
    }
  }

  /// The field held constant: accumulates the canonical parameters' gradients alone, the same values
  /// `backward` accumulates into `canonical` (the first lines of the file comment's backward; the
  /// heads and the grid are not visited, the field's own gradients are left as they are).
  /// @throws option_error `option.deformation` (`grid_input_gradient`) when that option is on and
  /// `canonical.dL_dmean` is given: dL/dmu then runs through the heads and the grid.
  void backward_canonical(Context& ctx, const Scalar* dL_dmean_out, const Scalar* dL_dlog_scale_out, const Scalar* dL_drotation_out,
                          const Gradients& canonical, ThreadPool* pool = nullptr) const {
    if (options_.grid_input_gradient && canonical.dL_dmean != nullptr)
      throw option_error("option.deformation", "grid_input_gradient", "the means' gradient runs through the grid: the field cannot be held constant");
    pointwise_backward<false>(ctx, dL_dmean_out, dL_dlog_scale_out, dL_drotation_out, canonical, pool);
  }

 private:
  static constexpr Scalar kNormFloor = Scalar(1e-12);
  /// Single-layer heads with few outputs (the default, HiddenLayers = 0) run forward and backward
  /// together over the blocks of h; deeper heads run one after the other.
  static constexpr bool kFusedHeads = HiddenLayers == 0 && HeadRot::kOut <= HeadRot::First::kSmallOut;

  /// The per-Gaussian part of the backward: canonical gradients (accumulated) and, if `Heads`, the
  /// heads' output gradients g_xyz, g_scale, g_rot into `ctx`.
  template <bool Heads>
  void pointwise_backward(Context& ctx, const Scalar* dL_dmean_out, const Scalar* dL_dlog_scale_out, const Scalar* dL_drotation_out,
                          const Gradients& canonical, ThreadPool* pool) const {
    const Inputs& in = ctx.in;
    const std::size_t n = in.count;
    const auto N = Eigen::Index(n);
    const bool stable = options_.mode == DeformationMode::stable;
    if constexpr (Heads) {
      ctx.g_xyz.setZero(N, 3);
      ctx.g_rot.setZero(N, 4);
      ctx.g_scale.setZero(N, 3);
    }
    parallel_for(pool, n, [&](std::size_t i) {
      const auto r = Eigen::Index(i);
      if (dL_dmean_out) {
        for (int d = 0; d < 3; ++d) {
          const Scalar g = dL_dmean_out[i * 3 + d];
          if constexpr (Heads) ctx.g_xyz(r, d) = g;
          if (canonical.dL_dmean) canonical.dL_dmean[i * 3 + d] += g;
        }
      }
      if (dL_dlog_scale_out) {
        for (int d = 0; d < 3; ++d) {
          const Scalar g = dL_dlog_scale_out[i * 3 + d];
          if (stable) {
            if constexpr (Heads) ctx.g_scale(r, d) = g;
            if (canonical.dL_dlog_scale) canonical.dL_dlog_scale[i * 3 + d] += g;
          } else {
            const Scalar es = std::exp(in.log_scale[i * 3 + d]);
            const Scalar a = es + ctx.dscale(r, d);
            const Scalar ga = a > Scalar(options_.min_scale) ? g / a : Scalar(0);
            if constexpr (Heads) ctx.g_scale(r, d) = ga;
            if (canonical.dL_dlog_scale) canonical.dL_dlog_scale[i * 3 + d] += ga * es;
          }
        }
      }
      if (dL_drotation_out) {
        const Scalar* go = dL_drotation_out + i * 4;
        const Scalar* u = ctx.unit.data() + i * 4;
        std::array<Scalar, 4> gv;
        if (stable) {
          const Scalar vn = ctx.vnorm[i];
          const Scalar iv = Scalar(1) / std::max(vn, kNormFloor);
          std::array<Scalar, 4> qo;
          for (int c = 0; c < 4; ++c) qo[c] = (u[c] + ctx.drot(r, c)) * iv;
          Scalar dot = 0;
          for (int c = 0; c < 4; ++c) dot += qo[c] * go[c];
          for (int c = 0; c < 4; ++c) gv[c] = vn > kNormFloor ? (go[c] - qo[c] * dot) * iv : go[c] * iv;
        } else {
          for (int c = 0; c < 4; ++c) gv[c] = go[c];
        }
        if constexpr (Heads)
          for (int c = 0; c < 4; ++c) ctx.g_rot(r, c) = gv[c];
        if (canonical.dL_drotation) {
          const Scalar qn = ctx.qnorm[i];
          const Scalar iq = Scalar(1) / std::max(qn, kNormFloor);
          Scalar dot = 0;
          for (int c = 0; c < 4; ++c) dot += u[c] * gv[c];
          for (int c = 0; c < 4; ++c)
            canonical.dL_drotation[i * 4 + c] += qn > kNormFloor ? (gv[c] - u[c] * dot) * iq : gv[c] * iq;
        }
      }
    }, 1024);
  }

  static HeadInitOptions with_seed(HeadInitOptions o, std::uint64_t add) {
    o.seed += add;
    return o;
  }

  void fit_box(const Scalar* means, std::size_t n, std::array<Scalar, 3>& lo, std::array<Scalar, 3>& extent,
               bool validate) const {
    std::array<double, 3> mn{1e300, 1e300, 1e300}, mx{-1e300, -1e300, -1e300};
    for (std::size_t i = 0; i < n; ++i)
      for (int d = 0; d < 3; ++d) {
        const double v = double(means[i * 3 + d]);
        if (!std::isfinite(v)) {
          if (validate)
            throw numeric_error("numeric.non_finite", "canonical_means[" + std::to_string(i) + "]",
                                "a Gaussian mean is not finite");
          continue;
        }
        mn[d] = std::min(mn[d], v);
        mx[d] = std::max(mx[d], v);
      }
    for (int d = 0; d < 3; ++d) {
      if (mn[d] > mx[d]) { mn[d] = -1; mx[d] = 1; }  // no points: the unit cube around 0
      double e = std::max(mx[d] - mn[d], 1e-6 * std::max(1.0, std::abs(mn[d])));
      const double m = options_.box_margin * e;
      lo[d] = Scalar(mn[d] - m);
      extent[d] = Scalar(e + 2 * m);
    }
  }

  DeformationOptions options_;
  Grid grid_;
  HeadXyz xyz_;
  HeadRot rot_;
  HeadScale scale_;
  std::array<Scalar, 3> box_lo_{}, box_extent_{};
  std::vector<Scalar> grid_grad_;
  std::array<std::vector<Scalar>, HeadXyz::segment_count()> xyz_grad_;
  std::array<std::vector<Scalar>, HeadRot::segment_count()> rot_grad_;
  std::array<std::vector<Scalar>, HeadScale::segment_count()> scale_grad_;
};

}  // namespace video3dgs
