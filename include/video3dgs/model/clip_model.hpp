#pragma once
/// @file
/// `ClipModel<Scalar, SHDegree, Field>`: everything stage 1 learns for one clip (docs/method.md):
///
///   frg, bkg            two GaussianClouds (foreground from the clip's SfM points, background on
///                       concentric Fibonacci shells around the foreground)
///   frg_field, bkg_field one DeformationField per set: canonical -> deformed at time t
///   alpha_logit[f]      one W x H logit map per frame; A = sigmoid(a), I = A I_frg + (1 - A) I_bkg
///   cameras[f]          the clip's cameras (COLMAP convention), frame f = range.first + i
///
/// Time of clip frame i (0-based inside the clip): t_i = i / (n - 1), t = 0 for a 1-frame clip.
///
/// Initialisation (`make_clip_model`):
///   frg: mean = point, SH DC = point colour, other bands 0, log-scale = log sqrt(max(d2, 1e-7))
///        (d2 = mean squared distance to the 3 nearest points), identity rotation, opacity 0.1;
///   bkg: `background.points_per_shell` points per shell, radii `radius_factors` x the largest side of
///        the foreground box, random colours (seeded) or, with `background_colour` = frames, the
///        colours the frames show where each point projects (`colours_from_frames`); same
///        scale/rotation/opacity rule;
///        with `background_dense_stride` = s > 0, then one point per s x s pixels of the clip's middle
///        frame at depths read from the SfM points (`frame_surface_points`), with that pixel's colour;
///   with `cull_unseen`, the Gaussians of either set that no clip camera sees (with a guard band of
///        `cull_margin` pixels) are then dropped (`seen_by_any_camera`; the kept ones are as above,
///        their scales from the whole set's points, the fields' boxes those of the whole sets);
///   scene radius = 1.1 x max distance of a camera centre from the mean centre; when all centres
///        coincide (one camera, a tripod), the floor `min_radius_fraction` x (distance from the mean
///        centre to the centre of the points' box) is used instead, so learning rates never vanish;
///   each field's normalisation box is the bounding box of its set's initial means (+ margin), kept
///        fixed (`box_min/box_max` are stored so that a reloaded field is bit-identical);
///   alpha: A = alpha_init everywhere, or, with `alpha_mask` > 0 and masks, A = alpha_outside +
///        (alpha_mask - alpha_outside) m from each frame's mask m.
/// A clip with no usable foreground (no points, or masks given and all empty) gets an empty frg set,
/// alpha logits of -30 (A ~ 0: the merge is the background) and a warning in `warnings`.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <memory>
#include <optional>
#include <random>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "video3dgs/core/camera.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/core/resample.hpp"
#include "video3dgs/deformation/deformation_field.hpp"
#include "video3dgs/gaussian/activations.hpp"
#include "video3dgs/gaussian/cloud.hpp"
#include "video3dgs/hash_grid/hash_grid.hpp"
#include "video3dgs/model/point_init.hpp"
#include "video3dgs/rasterizer/project.hpp"
#include "video3dgs/rasterizer/settings.hpp"
#include "video3dgs/scheduling/sfm_result.hpp"
#include "video3dgs/sh/basis.hpp"

namespace video3dgs {

/// log2 of the deformation hash table used by default. The reference uses 2^19; a
/// 4D table of 2^19 x 16 levels x 2 features is ~60 MB per field plus 2x for Adam moments, and its
/// optimizer step dominates small clips. 2^16 keeps the dense low levels and stays in L2/L3; pick
/// another size through the `Field` template parameter and measure (benchmarks/bench_train_clip).
inline constexpr int kDefaultDeformationLog2Table = 16;

template <class Scalar>
using DefaultDeformationField = DeformationField<Scalar, HashGrid4D<Scalar, kDefaultDeformationLog2Table>>;

/// Which Gaussian set of a clip.
enum class GaussianSet { foreground, background };

[[nodiscard]] inline const char* to_string(GaussianSet s) noexcept {
  return s == GaussianSet::foreground ? "frg" : "bkg";
}

/// Size of one set's deformation hash grid (each 0: as ClipModelOptions::deformation.grid says; the
/// default time_cells, kTimeCellsPerFrame, replaces deformation.grid.max_cells of the time axis).
/// L' = `levels` levels (of the grid type's L) run geometrically from the base resolution b to
/// `finest` (default: the full grid's finest, b s^(L-1)): the per-level scale becomes
/// (finest / b)^(1 / (L' - 1)). So fewer levels span the same resolutions, and a smaller `finest`
/// drops the cells finer than the images can supervise. L' = 1 keeps the coarsest level alone.
struct GridSize {
  int log2_table_size = 0;  ///< HashGridOptions::log2_table_size: 2^this entries per hashed level
  int levels = 0;           ///< HashGridOptions::levels
  double finest = 0;        ///< cells per axis of the finest level in use (>= the base resolution)
  static constexpr int kTimeCellsPerFrame = -1;
  /// Cap on every level's cells along time (HashGridOptions::max_cells of axis 3): 0 = none, M > 0,
  /// or kTimeCellsPerFrame (the default): the clip's n frames - 1 (at least 1), which puts frame i
  /// (t = i / (n - 1)) on vertex i of every level, one time slice per frame, instead of two slices of
  /// its own per frame on the levels finer than n cells (measured in docs/performance.md). A clip of
  /// fewer frames never gets more entries.
  int time_cells = kTimeCellsPerFrame;
  friend bool operator==(const GridSize&, const GridSize&) = default;

  /// Whether the table size, level count or finest level is set (the time cap aside).
  [[nodiscard]] bool resized() const noexcept { return log2_table_size != 0 || levels != 0 || finest != 0; }
  /// `time_cells` as text: "frames" for kTimeCellsPerFrame, else the number ("0": no cap).
  [[nodiscard]] std::string time_cells_text() const {
    return time_cells == kTimeCellsPerFrame ? std::string("frames") : std::to_string(time_cells);
  }
  /// A time cap from text: `frames` (kTimeCellsPerFrame), `none` (0) or a positive count.
  /// @throws option_error `option.deformation` naming `time_cells` otherwise.
  [[nodiscard]] static int parse_time_cells(const std::string& v) {
    if (v == "frames") return kTimeCellsPerFrame;
    if (v == "none") return 0;
    std::size_t used = 0;
    int n = 0;
    try {
      n = std::stoi(v, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != v.size() || n < 1)
      throw option_error("option.deformation", "time_cells", "must be a positive integer, `frames` or `none`, got '" + v + "'");
    return n;
  }
};

/// `base` with `size` applied for a grid of `Levels` levels (see GridSize) over a clip of `frames` frames
/// (read only by GridSize::kTimeCellsPerFrame).
/// @throws option_error `option.deformation` if `finest` is below the base resolution or not finite, or
/// `time_cells` is below kTimeCellsPerFrame (or is it without frames).
[[nodiscard]] inline DeformationOptions sized_deformation(DeformationOptions base, GridSize size, int Levels, int frames = 0) {
  if (size.log2_table_size != 0) base.grid.log2_table_size = size.log2_table_size;
  if (size.time_cells == GridSize::kTimeCellsPerFrame) {
    if (frames < 1) throw option_error("option.deformation", "time_cells", "one cell per frame needs the clip's frame count");
    size.time_cells = std::max(frames - 1, 1);
  }
  if (size.time_cells < 0) throw option_error("option.deformation", "time_cells", "must be >= 0 or kTimeCellsPerFrame (-1)");
  if (size.time_cells != 0) base.grid.max_cells[3] = std::uint32_t(size.time_cells);
  const int L = size.levels != 0 ? size.levels : (base.grid.levels != 0 ? base.grid.levels : Levels);
  if (size.levels == 0 && size.finest == 0) return base;
  const double b = base.grid.base_resolution;
  double finest = b * std::pow(base.grid.per_level_scale, double(Levels - 1));
  if (size.finest != 0) {
    if (!(size.finest >= b) || !std::isfinite(size.finest))
      throw option_error("option.deformation", "finest", "must be finite and >= the base resolution " + std::to_string(b));
    finest = size.finest;
  }
  if (L > 1 && !(L == Levels && size.finest == 0)) base.grid.per_level_scale = std::pow(finest / b, 1.0 / double(L - 1));
  base.grid.levels = L;
  return base;
}

/// Where the background set's first colours come from.
enum class BackgroundColour {
  random,  ///< uniform in [0, 1)^3, drawn with `ClipModelOptions::seed` (the reference)
  frames,  ///< `colours_from_frames`: what the clip's frames show where each point projects (no draw)
};

[[nodiscard]] inline const char* to_string(BackgroundColour c) noexcept { return c == BackgroundColour::frames ? "frames" : "random"; }

/// Options of `make_clip_model` (defaults: the reference values, docs/method.md).
struct ClipModelOptions {
  double init_opacity = 0.1;            ///< opacity of every initial Gaussian
  int knn = 3;                          ///< neighbours for the initial scale
  double min_sq_distance = 1e-7;        ///< floor of the mean squared kNN distance before sqrt
  BackgroundShellOptions background{};  ///< shells: points per shell, radius factors (x largest fg side)
  std::uint64_t seed = 0;               ///< background colours (with BackgroundColour::random)
  BackgroundColour background_colour = BackgroundColour::random;  ///< `frames` needs the frames
  double alpha_init = 0.5;              ///< initial alpha A (stored as a logit)
  /// > 0 (with masks): alpha starts from the masks instead, A = alpha_outside + (alpha_mask -
  /// alpha_outside) m per pixel, m the mask value in [0, 1] (masks of another size than the frames
  /// area-resampled to theirs); 0: A = alpha_init everywhere (the reference).
  double alpha_mask = 0.0;
  double alpha_outside = 0.1;           ///< A outside the masks when alpha_mask > 0
  DeformationOptions deformation{};     ///< both fields (box margin, grid options, mode)
  double min_radius_fraction = 0.2;     ///< scene-radius floor, x viewing distance (see file comment)
  double min_mask_fraction = 0.0;       ///< masks whose mean foreground fraction is <= this are "empty"
  bool static_background = false;       ///< `ClipModel::static_background` (false: the reference, both sets deformed)
  GridSize frg_grid{};                  ///< the foreground field's table size, levels and time cells (0: deformation.grid's)
  GridSize bkg_grid{};                  ///< the background field's (no size with static_background: 4 entries, 1 level)
  /// > 0: the background set also starts with the surfaces the clip's middle frame shows, one
  /// Gaussian per `background_dense_stride` x `background_dense_stride` pixels (`frame_surface_points`:
  /// the pixel's colour, at a depth read from the SfM points near it in the image); needs the frames.
  /// 0: the shells alone (the reference).
  int background_dense_stride = 0;
  /// true: after both sets are made, drop every initial Gaussian that the rasterizer (default
  /// `RasterSettings`) culls in every clip camera widened by `cull_margin` pixels on each side
  /// (`seen_by_any_camera`). Such a Gaussian has a zero gradient, so no step, densification or prune
  /// changes it while it stays out of view: it only costs deformation and optimiser work (most of the
  /// outer background shell lies behind or beside the cameras). The margin keeps the Gaussians just
  /// outside the frame, which a coarse render's low-pass (0.3 render pixels², up to 4.8 full-size
  /// pixels² at a quarter of the size: 0.3 x 4²) or a small move of the field can bring into view. The fields'
  /// boxes are those of the uncut sets, so while no culled row would have come into view and no
  /// Gaussian budget binds (budgets count rows), the kept rows follow the uncut model's maths; sums
  /// then skip zero terms, so they round differently (the runs drift apart as any two orders of the
  /// same sums do). A set none of whose Gaussians any camera sees is kept whole (with a warning).
  /// false: every point is kept (the reference).
  bool cull_unseen = false;
  int cull_margin = 16;  ///< pixels of `cull_unseen`'s guard band around each clip frame, in [0, 2^20]

  /// The initialisation choices that depart from the reference, as resume-key text: "|static_background",
  /// "|alpha_mask=A,B" (alpha_mask, alpha_outside), "|bkg_colour=frames", "|bkg_dense=S", "|cull_unseen=M" (cull_margin), in that order, each only when
  /// set, so the reference gives "" and keys written before an option existed stay valid. Numbers are
  /// written to round-trip. (Part of `reconstruct`'s clip key and the end of `trade`'s run key.)
  [[nodiscard]] std::string departures_key() const {
    std::string t;
    char num[64];
    if (static_background) t += "|static_background";
    if (alpha_mask > 0) {
      std::snprintf(num, sizeof(num), "|alpha_mask=%.17g,%.17g", alpha_mask, alpha_outside);
      t += num;
    }
    if (background_colour != BackgroundColour::random) t += std::string("|bkg_colour=") + to_string(background_colour);
    if (background_dense_stride > 0) t += "|bkg_dense=" + std::to_string(background_dense_stride);
    if (cull_unseen) t += "|cull_unseen=" + std::to_string(cull_margin);
    return t;
  }
};

/// The start `reconstruct` and the command-line tool use unless told otherwise: the reference's
/// options (`ClipModelOptions{}`) with two departures: the background set's first colours read from
/// the frames (BackgroundColour::frames) instead of drawn, so no draw is left in a clip's start (why:
/// docs/performance.md, "The frames' background start becomes the default"), and `cull_unseen` (the
/// initial Gaussians no clip camera sees are dropped). The single-algorithm option structs
/// (ClipModelOptions, pipeline::TradeOptions) keep the reference.
[[nodiscard]] inline ClipModelOptions recommended_model_options() {
  ClipModelOptions o;
  o.background_colour = BackgroundColour::frames;
  o.cull_unseen = true;
  return o;
}

/// Per-call buffers of `ClipModel::deformed`: reuse one per set to avoid allocation.
template <class Scalar, class Field>
struct DeformScratch {
  std::vector<Scalar> mean, log_scale, rotation;
  typename Field::Context ctx;
};

template <class Scalar, int SHDegree = 3, class Field = DefaultDeformationField<Scalar>>
class ClipModel {
  static_assert(std::is_floating_point_v<Scalar>, "video3dgs: ClipModel<Scalar, ...> needs Scalar = float or double");
  static_assert(std::is_same_v<typename Field::scalar_type, Scalar>, "video3dgs: ClipModel's Field must use the same Scalar");

 public:
  using scalar_type = Scalar;
  using field_type = Field;
  using Cloud = GaussianCloud<Scalar, SHDegree>;
  static constexpr int sh_degree = SHDegree;
  using Vec3 = Eigen::Matrix<Scalar, 3, 1>;

  FrameRange range;                          ///< video frames of the clip
  std::vector<Camera<Scalar>> cameras;       ///< one per clip frame
  Cloud frg, bkg;                            ///< canonical Gaussians
  std::unique_ptr<Field> frg_field, bkg_field;
  std::array<Scalar, 3> frg_box_min{}, frg_box_max{}, bkg_box_min{}, bkg_box_max{};  ///< field boxes (before margin)
  std::vector<Image<Scalar, 1>> alpha_logit; ///< one per clip frame, W x H
  Scalar scene_radius = 1;                   ///< 3DGS's camera-extent radius (lr scale; extent = 4 radius)
  bool has_foreground = true;                ///< false: Bkg-only clip
  bool deformation_enabled = false;          ///< render deformed (set by the trainer after warm-up)
  /// The background set is static in the world: its field is neither evaluated nor trained, and every
  /// frame renders its canonical Gaussians (the cameras carry the motion). Set at initialisation
  /// (`ClipModelOptions::static_background`); the foreground set is always deformed.
  bool static_background = false;
  /// How renders of this model stop a pixel (RasterSettings::min_transmittance, blend_at_stop): the
  /// rule it was trained with (ClipTrainer sets it from TrainOptions). Every render through the clip
  /// graph (training, evaluation, outputs, stage 2) uses it, so a model composites as it was trained.
  /// Default: the method's (1e-4, the crossing Gaussian not blended).
  Scalar min_transmittance = kReferenceStop;
  bool blend_at_stop = false;
  static constexpr Scalar kReferenceStop = RasterSettings<Scalar, 3>::kReferenceMinTransmittance;  ///< the method's stop
  /// Whether the stop rule is the method's (model records store the rule only otherwise).
  [[nodiscard]] bool reference_stop() const noexcept { return min_transmittance == kReferenceStop && !blend_at_stop; }
  std::vector<std::string> warnings;         ///< initialisation notes for a person

  ClipModel() = default;
  ClipModel(ClipModel&&) noexcept = default;
  ClipModel& operator=(ClipModel&&) noexcept = default;

  [[nodiscard]] int frame_count() const noexcept { return static_cast<int>(cameras.size()); }
  [[nodiscard]] int width() const noexcept { return cameras.empty() ? 0 : cameras.front().width; }
  [[nodiscard]] int height() const noexcept { return cameras.empty() ? 0 : cameras.front().height; }
  /// t of clip frame i: i / (n - 1), 0 for a 1-frame clip.
  [[nodiscard]] Scalar time_of(int i) const noexcept {
    const int n = frame_count();
    return n > 1 ? Scalar(i) / Scalar(n - 1) : Scalar(0);
  }
  /// Index inside the clip of a video frame (throws `option.frame` if outside the clip).
  [[nodiscard]] int index_of_frame(int video_frame) const {
    if (!range.contains(video_frame) || video_frame - range.first >= frame_count())
      throw option_error("option.frame", "frame " + std::to_string(video_frame), "is not a frame of this clip");
    return video_frame - range.first;
  }
  /// Extent used by densification: 4 x scene radius (as in 3DGS).
  [[nodiscard]] Scalar extent() const noexcept { return Scalar(4) * scene_radius; }

  /// Whether set `s` is rendered deformed at frames other than its canonical one right now.
  [[nodiscard]] bool deforms(GaussianSet s) const noexcept {
    return deformation_enabled && !(s == GaussianSet::background && static_background);
  }

  [[nodiscard]] Cloud& cloud(GaussianSet s) noexcept { return s == GaussianSet::foreground ? frg : bkg; }
  [[nodiscard]] const Cloud& cloud(GaussianSet s) const noexcept { return s == GaussianSet::foreground ? frg : bkg; }
  [[nodiscard]] Field& field(GaussianSet s) noexcept { return s == GaussianSet::foreground ? *frg_field : *bkg_field; }
  [[nodiscard]] const Field& field(GaussianSet s) const noexcept { return s == GaussianSet::foreground ? *frg_field : *bkg_field; }

  /// Builds the field of a set from its stored box corners and `options` (bit-identical on reload).
  void build_field(GaussianSet s, const DeformationOptions& options) {
    const auto& lo = s == GaussianSet::foreground ? frg_box_min : bkg_box_min;
    const auto& hi = s == GaussianSet::foreground ? frg_box_max : bkg_box_max;
    const std::array<Scalar, 6> corners{lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]};
    (s == GaussianSet::foreground ? frg_field : bkg_field) = std::make_unique<Field>(std::span<const Scalar>(corners), options);
  }

  using DeformScratch = video3dgs::DeformScratch<Scalar, Field>;

  /// The set's parameters at clip frame i: deformed (if `deforms(s)`) into `scratch`, else the
  /// canonical cloud. Valid until the cloud or scratch changes.
  [[nodiscard]] GaussianParams<Scalar> deformed(GaussianSet s, int i, DeformScratch& scratch, ThreadPool* pool = nullptr) const {
    const Cloud& c = cloud(s);
    if (!deforms(s) || c.empty()) return c.params();
    const std::size_t n = c.size();
    scratch.mean.resize(3 * n);
    scratch.log_scale.resize(3 * n);
    scratch.rotation.resize(4 * n);
    typename Field::Inputs in{c.mean.data(), c.log_scale.data(), c.rotation.data(), n, time_of(i)};
    typename Field::Outputs out{scratch.mean.data(), scratch.log_scale.data(), scratch.rotation.data()};
    field(s).forward(in, out, scratch.ctx, pool);
    GaussianParams<Scalar> p = c.params();
    p.mean = scratch.mean;
    p.log_scale = scratch.log_scale;
    p.rotation = scratch.rotation;
    return p;
  }

  /// A copy of the set deformed to clip frame i (for PLY export).
  [[nodiscard]] Cloud deformed_cloud(GaussianSet s, int i, ThreadPool* pool = nullptr) const {
    DeformScratch scratch;
    const GaussianParams<Scalar> p = deformed(s, i, scratch, pool);
    Cloud out = cloud(s);
    std::copy(p.mean.begin(), p.mean.end(), out.mean.begin());
    std::copy(p.log_scale.begin(), p.log_scale.end(), out.log_scale.begin());
    std::copy(p.rotation.begin(), p.rotation.end(), out.rotation.begin());
    return out;
  }
};

namespace detail {

template <class Scalar>
void bounding_box(std::span<const Scalar> means, std::array<Scalar, 3>& lo, std::array<Scalar, 3>& hi) {
  lo = {Scalar(-1), Scalar(-1), Scalar(-1)};
  hi = {Scalar(1), Scalar(1), Scalar(1)};
  bool any = false;
  for (std::size_t i = 0; i + 2 < means.size(); i += 3) {
    if (!(std::isfinite(means[i]) && std::isfinite(means[i + 1]) && std::isfinite(means[i + 2]))) continue;
    for (int d = 0; d < 3; ++d) {
      lo[d] = any ? std::min(lo[d], means[i + d]) : means[i + d];
      hi[d] = any ? std::max(hi[d], means[i + d]) : means[i + d];
    }
    any = true;
  }
}

/// Appends Gaussians at `pts` with colours `rgb` (0..1) to `cloud`: kNN scale, identity rotation.
template <class Scalar, int D>
void append_init_gaussians(GaussianCloud<Scalar, D>& cloud, const std::vector<Eigen::Matrix<Scalar, 3, 1>>& pts,
                           const std::vector<std::array<Scalar, 3>>& rgb, const ClipModelOptions& o, ThreadPool* pool) {
  const auto d2 = knn_mean_sq_distance<Scalar>(pts, o.knn, pool);
  Gaussian<Scalar, D> g;
  const Scalar op = logit(Scalar(o.init_opacity));
  cloud.reserve(cloud.size() + pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i) {
    for (int k = 0; k < 3; ++k) g.mean[k] = pts[i][k];
    const Scalar ls = Scalar(0.5 * std::log(std::max(double(d2[i]), o.min_sq_distance)));
    g.log_scale = {ls, ls, ls};
    g.rotation = {Scalar(1), Scalar(0), Scalar(0), Scalar(0)};
    g.opacity_logit = op;
    g.sh.fill(Scalar(0));
    g.set_rgb(rgb[i][0], rgb[i][1], rgb[i][2]);
    cloud.push_back(g);
  }
}

/// A mask value as a foreground fraction in [0, 1]; NaN (an unreadable value) counts as background, 0.
[[nodiscard]] inline double foreground_fraction(double v) noexcept { return v == v ? std::clamp(v, 0.0, 1.0) : 0.0; }

/// `cull_margin` / `seen_by_any_camera`'s margin: pixels in [0, 2^20] (so width + 2 margin stays an int).
inline void check_cull_margin(int margin) {
  if (margin < 0 || margin > (1 << 20)) throw option_error("option.clip", "cull_margin", "must be in [0, 2^20], got " + std::to_string(margin));
}
}  // namespace detail

/// Per row of `cloud`: 1 if at least one of `cameras`, widened by `margin` pixels on each side (width
/// and height + 2 margin, principal point + margin), sees it, i.e. `project_gaussian` with `settings`
/// does not cull it (its footprint reaches the image, it lies between the planes, its opacity reaches
/// alpha_min), else 0. The widened image is a window of `margin` pixels around the camera's
/// (`clamp_frame_*` moved by -margin), so each Gaussian's projection, Jacobian clamp included, is the
/// one a render of the camera itself gives; only the image's bounds grow. Non-finite SH coefficients
/// are not looked at (the SH colour of a finite cloud is finite).
/// @throws option_error `option.clip` for a margin outside [0, 2^20]
template <class Scalar, int D>
[[nodiscard]] std::vector<std::uint8_t> seen_by_any_camera(const GaussianCloud<Scalar, D>& cloud, std::span<const Camera<Scalar>> cameras,
                                                           const RasterSettings<Scalar, 3>& settings = {}, ThreadPool* pool = nullptr,
                                                           int margin = 0) {
  detail::check_cull_margin(margin);
  std::vector<Camera<Scalar>> wide(cameras.begin(), cameras.end());
  std::vector<RasterSettings<Scalar, 3>> framed(cameras.size(), settings);
  for (std::size_t k = 0; k < wide.size(); ++k) {
    Camera<Scalar>& c = wide[k];
    RasterSettings<Scalar, 3>& s = framed[k];
    if (!(s.clamp_frame_width > 0 && s.clamp_frame_height > 0)) s.clamp_frame_width = c.width, s.clamp_frame_height = c.height;
    s.clamp_frame_x -= margin, s.clamp_frame_y -= margin;
    c.width += 2 * margin, c.height += 2 * margin, c.cx += Scalar(margin), c.cy += Scalar(margin);
  }
  std::vector<std::uint8_t> seen(cloud.size(), 0);
  parallel_for(pool, cloud.size(), [&](std::size_t i) {
    ProjectedGaussian<Scalar> pg;
    for (std::size_t k = 0; k < wide.size(); ++k)
      if (project_gaussian(wide[k], framed[k], &cloud.mean[3 * i], &cloud.log_scale[3 * i], &cloud.rotation[4 * i], cloud.opacity_logit[i], pg)) {
        seen[i] = 1;
        return;
      }
  }, 1024);
  return seen;
}

/// Fraction of the pixels of `masks` that are foreground (> 0.5), in [0, 1]; 0 for no pixels.
template <class Scalar>
[[nodiscard]] double mask_coverage(std::span<const Image<Scalar, 1>> masks) {
  double area = 0, total = 0;
  for (const auto& mk : masks) {
    for (std::size_t k = 0; k < mk.size(); ++k) area += mk.data()[k] > Scalar(0.5) ? 1.0 : 0.0;
    total += double(mk.size());
  }
  return total > 0 ? area / total : 0.0;
}

/// Mean merge weight sigmoid(alpha logit) of clip model `m` inside ([0]: mask >= 1/2) and outside ([1])
/// its masks (one per frame, any size: area-resampled to the model's). Empty without a foreground, with
/// a mask count other than the frames', or for a side with no pixel.
template <class Model, class Scalar>
[[nodiscard]] std::array<std::optional<double>, 2> alpha_inside_outside(const Model& m, std::span<const Image<Scalar, 1>> masks) {
  std::array<std::optional<double>, 2> out;
  if (!m.has_foreground || masks.size() != m.alpha_logit.size()) return out;
  double sum[2] = {0, 0};
  std::size_t count[2] = {0, 0};
  for (std::size_t f = 0; f < masks.size(); ++f) {
    const Image<Scalar, 1> mask = resize_area(masks[f], m.width(), m.height());  // a copy when the sizes match
    const auto& a = m.alpha_logit[f];
    for (int y = 0; y < m.height(); ++y)
      for (int x = 0; x < m.width(); ++x) {
        const int side = mask(x, y) >= Scalar(0.5) ? 0 : 1;
        sum[side] += sigmoid(double(a(x, y)));
        ++count[side];
      }
  }
  for (int side = 0; side < 2; ++side)
    if (count[side] > 0) out[std::size_t(side)] = sum[side] / double(count[side]);
  return out;
}

/// The colour the frames show at each world point: c(x) = sum_f w_f I_f(p_f(x)) / sum_f w_f over the
/// frames f whose camera has x in front (z > 0) and inside the image, p_f(x) the pixel holding the
/// projection (pixel i covers [i, i + 1)) and w_f = 1 - m_f(p_f(x)) the mask's background weight there
/// (1 without masks; masks of another size are area-resampled to the frames'). A point no frame shows
/// outside the masks (sum w_f < 1e-6) gets the same weighting's mean over every pixel of every frame,
/// and (0.5, 0.5, 0.5) if there is none. Thread-count independent; no random draw.
/// @throws option_error `option.clip` unless there is one frame of the cameras' size per camera and
/// masks are absent or one per frame.
template <class Scalar>
[[nodiscard]] std::vector<std::array<Scalar, 3>> colours_from_frames(const std::vector<Eigen::Matrix<Scalar, 3, 1>>& points,
                                                                     std::span<const Camera<Scalar>> cameras,
                                                                     std::span<const Image<Scalar, 3>> frames,
                                                                     std::span<const Image<Scalar, 1>> masks = {},
                                                                     ThreadPool* pool = nullptr) {
  if (frames.size() != cameras.size() || frames.empty())
    throw option_error("option.clip", "frames", "need one frame per camera (" + std::to_string(cameras.size()) + "), got " + std::to_string(frames.size()));
  if (!masks.empty() && masks.size() != frames.size())
    throw option_error("option.clip", "masks", "need one mask per frame (" + std::to_string(frames.size()) + "), got " + std::to_string(masks.size()));
  for (std::size_t f = 0; f < frames.size(); ++f)
    if (frames[f].width() != cameras[f].width || frames[f].height() != cameras[f].height)
      throw option_error("option.clip", "frame " + std::to_string(f),
                         "is " + std::to_string(frames[f].width()) + "x" + std::to_string(frames[f].height()) + ", its camera " +
                             std::to_string(cameras[f].width) + "x" + std::to_string(cameras[f].height));
  // Background weights 1 - m per frame pixel (NaN mask values count as background); none without masks.
  std::vector<Image<Scalar, 1>> w(masks.size());
  auto weight = [&](std::size_t f, int x, int y) { return masks.empty() ? 1.0 : double(w[f](x, y)); };
  double fallback[3] = {0, 0, 0}, fallback_w = 0;
  for (std::size_t f = 0; f < frames.size(); ++f) {
    const int W = frames[f].width(), H = frames[f].height();
    if (!masks.empty()) {
      w[f] = resize_area(masks[f], W, H);
      for (std::size_t k = 0; k < w[f].size(); ++k) {
        w[f].data()[k] = Scalar(1.0 - detail::foreground_fraction(double(w[f].data()[k])));
      }
    }
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const double wk = weight(f, x, y);
        for (int c = 0; c < 3; ++c) fallback[c] += wk * double(frames[f](x, y, c));
        fallback_w += wk;
      }
  }
  std::array<Scalar, 3> mean_colour{Scalar(0.5), Scalar(0.5), Scalar(0.5)};
  if (fallback_w > 1e-6)
    for (int c = 0; c < 3; ++c) mean_colour[std::size_t(c)] = Scalar(fallback[c] / fallback_w);
  std::vector<std::array<Scalar, 3>> out(points.size());
  parallel_for(pool, points.size(), [&](std::size_t i) {
    double sum[3] = {0, 0, 0}, sw = 0;
    for (std::size_t f = 0; f < frames.size(); ++f) {
      const auto xc = cameras[f].world_to_camera(points[i]);
      if (!(xc.z() > Scalar(0))) continue;
      const auto uv = cameras[f].camera_to_pixel(xc);
      const double u = std::floor(double(uv.x())), v = std::floor(double(uv.y()));
      if (!(u >= 0 && v >= 0 && u < frames[f].width() && v < frames[f].height())) continue;
      const int x = int(u), y = int(v);
      const double wk = weight(f, x, y);
      for (int c = 0; c < 3; ++c) sum[c] += wk * double(frames[f](x, y, c));
      sw += wk;
    }
    if (sw < 1e-6) {
      out[i] = mean_colour;
      return;
    }
    for (int c = 0; c < 3; ++c) out[i][std::size_t(c)] = Scalar(sum[c] / sw);
  });
  return out;
}

/// Points on the surfaces one frame shows, with their colours: for the pixels (i, j) = (s/2 + s a,
/// s/2 + s b) of `frame` (s = `stride`; every pixel of the s x s block starting at (s a, s b) is
/// represented by the one nearest its middle), the world point on the ray through the pixel's centre
/// (i + 0.5, j + 0.5) at camera depth z(i, j) = the median camera depth of the `k` points of `points`
/// whose projections lie nearest to that centre (among the points in front of the camera that project
/// inside the image; the lower median for even counts, fewer than k when fewer project), and the
/// frame's colour at (i, j). So each point projects back onto its pixel's centre in this frame at a
/// depth the SfM points around it agree on. The depths are those of whatever points are given (from
/// masked SfM, foreground points only: background pixels then take the foreground's depths). No
/// point projects into the image: no points. Thread-count independent (one result per pixel, each
/// from every point). @throws option_error `option.clip` on a frame of another size than the camera,
/// stride < 1 or k < 1.
template <class Scalar>
[[nodiscard]] std::pair<std::vector<Eigen::Matrix<Scalar, 3, 1>>, std::vector<std::array<Scalar, 3>>> frame_surface_points(
    const Camera<Scalar>& camera, const Image<Scalar, 3>& frame, const std::vector<Eigen::Matrix<Scalar, 3, 1>>& points, int stride,
    int k = 8, ThreadPool* pool = nullptr) {
  using V3 = Eigen::Matrix<Scalar, 3, 1>;
  if (frame.width() != camera.width || frame.height() != camera.height)
    throw option_error("option.clip", "frame", "is " + std::to_string(frame.width()) + "x" + std::to_string(frame.height()) + ", its camera " +
                                                   std::to_string(camera.width) + "x" + std::to_string(camera.height));
  if (stride < 1) throw option_error("option.clip", "background_dense_stride", "must be >= 1 (0 = off), got " + std::to_string(stride));
  if (k < 1) throw option_error("option.clip", "k", "must be >= 1");
  // The points seen inside the image: pixel position and camera depth.
  struct Seen {
    double u, v, z;
  };
  std::vector<Seen> seen;
  for (const V3& p : points) {
    if (!p.allFinite()) continue;
    const V3 xc = camera.world_to_camera(p);
    if (!(xc.z() > Scalar(0))) continue;
    const auto uv = camera.camera_to_pixel(xc);
    if (!(uv.x() >= 0 && uv.y() >= 0 && uv.x() < Scalar(frame.width()) && uv.y() < Scalar(frame.height()))) continue;
    seen.push_back({double(uv.x()), double(uv.y()), double(xc.z())});
  }
  std::pair<std::vector<V3>, std::vector<std::array<Scalar, 3>>> out;
  if (seen.empty()) return out;
  const int W = frame.width(), H = frame.height(), half = stride / 2;
  const int nx = (W - half + stride - 1) / stride, ny = (H - half + stride - 1) / stride;  // i = half + s a < W
  const std::size_t n = std::size_t(nx) * std::size_t(ny), kk = std::min<std::size_t>(std::size_t(k), seen.size());
  out.first.resize(n);
  out.second.resize(n);
  parallel_for(pool, n, [&](std::size_t q) {
    const int i = half + stride * int(q % std::size_t(nx)), j = half + stride * int(q / std::size_t(nx));
    const double cu = i + 0.5, cv = j + 0.5;
    // The kk nearest by squared distance (ties: the earlier point), then the lower median of their depths.
    std::vector<std::pair<double, std::size_t>> best;  // (distance^2, index), a max-heap of size kk
    best.reserve(kk + 1);
    for (std::size_t s = 0; s < seen.size(); ++s) {
      const double d2 = (seen[s].u - cu) * (seen[s].u - cu) + (seen[s].v - cv) * (seen[s].v - cv);
      if (best.size() < kk) {
        best.emplace_back(d2, s);
        std::push_heap(best.begin(), best.end());
      } else if (std::pair<double, std::size_t>(d2, s) < best.front()) {
        std::pop_heap(best.begin(), best.end());
        best.back() = {d2, s};
        std::push_heap(best.begin(), best.end());
      }
    }
    std::vector<double> z;
    z.reserve(best.size());
    for (const auto& b : best) z.push_back(seen[b.second].z);
    std::sort(z.begin(), z.end());
    const double depth = z[(z.size() - 1) / 2];
    out.first[q] = camera.pixel_to_world({Scalar(cu), Scalar(cv)}, Scalar(depth));
    for (int c = 0; c < 3; ++c) out.second[q][std::size_t(c)] = frame(i, j, c);
  }, 64);
  return out;
}

/// Builds a clip's initial model from its cameras (one per clip frame, in order) and foreground
/// points (world, with colours). `masks` (optional, one per frame) decide whether the clip has a
/// usable foreground and, with `alpha_mask` > 0, the initial alpha maps. `frames` (one per camera, at
/// the cameras' size) are read only with `background_colour` = frames or `background_dense_stride` > 0. @throws option_error
/// `option.clip` on no cameras, unequal image sizes, bad options or frames missing when needed;
/// cameras are validated (`option.camera`).
template <class Scalar, int SHDegree = 3, class Field = DefaultDeformationField<Scalar>, class PointScalar = double>
[[nodiscard]] ClipModel<Scalar, SHDegree, Field> make_clip_model(FrameRange range, std::span<const Camera<Scalar>> cameras,
                                                                 std::span<const SfmPoint<PointScalar>> points,
                                                                 const ClipModelOptions& o = {},
                                                                 std::span<const Image<Scalar, 1>> masks = {},
                                                                 ThreadPool* pool = nullptr,
                                                                 std::span<const Image<Scalar, 3>> frames = {}) {
  using Model = ClipModel<Scalar, SHDegree, Field>;
  using V3 = typename Model::Vec3;
  if (cameras.empty()) throw option_error("option.clip", "cameras", "a clip needs at least one camera");
  if (range.size() != static_cast<int>(cameras.size()))
    throw option_error("option.clip", "range", "frame range has " + std::to_string(range.size()) + " frames but " +
                                                   std::to_string(cameras.size()) + " cameras were given");
  if (!(o.init_opacity > 0 && o.init_opacity < 1)) throw option_error("option.clip", "init_opacity", "must be in (0, 1)");
  if (!(o.alpha_init > 0 && o.alpha_init < 1)) throw option_error("option.clip", "alpha_init", "must be in (0, 1)");
  if (!(o.alpha_mask == 0 || (o.alpha_mask > 0 && o.alpha_mask < 1)))
    throw option_error("option.clip", "alpha_mask", "must be 0 (off) or in (0, 1)");
  if (o.alpha_mask > 0 && !(o.alpha_outside > 0 && o.alpha_outside < 1))
    throw option_error("option.clip", "alpha_outside", "must be in (0, 1)");
  if (o.knn < 1) throw option_error("option.clip", "knn", "must be >= 1");
  if (o.background_dense_stride < 0)
    throw option_error("option.clip", "background_dense_stride", "must be >= 1 (0 = off), got " + std::to_string(o.background_dense_stride));
  if (o.background_dense_stride > 0 && frames.size() != cameras.size())
    throw option_error("option.clip", "background_dense_stride", "needs the clip's frames, one per camera (make_clip_model's frames argument)");
  detail::check_cull_margin(o.cull_margin);  // before the sets are made
  if (o.background.points_per_shell < 1 || o.background.radius_factors.empty())
    throw option_error("option.clip", "background", "needs at least one shell with at least one point");
  for (std::size_t i = 0; i < cameras.size(); ++i) {
    cameras[i].validate(("camera " + std::to_string(i)).c_str());
    if (cameras[i].width != cameras[0].width || cameras[i].height != cameras[0].height)
      throw option_error("option.clip", "camera " + std::to_string(i), "all frames of a clip must have the same size");
  }
  if (!masks.empty() && masks.size() != cameras.size())
    throw option_error("option.clip", "masks", "give one mask per frame or none");

  Model m;
  m.range = range;
  m.cameras.assign(cameras.begin(), cameras.end());

  // Usable foreground points.
  std::vector<V3> pts;
  std::vector<std::array<Scalar, 3>> rgb;
  for (const auto& p : points) {
    const V3 x = p.xyz.template cast<Scalar>();
    if (!x.allFinite()) continue;
    pts.push_back(x);
    rgb.push_back({Scalar(p.rgb[0] / 255.0), Scalar(p.rgb[1] / 255.0), Scalar(p.rgb[2] / 255.0)});
  }
  const bool masks_empty = !masks.empty() && mask_coverage<Scalar>(masks) <= o.min_mask_fraction;
  m.has_foreground = !pts.empty() && !masks_empty;
  if (!m.has_foreground)
    m.warnings.push_back(pts.empty() ? "clip has no foreground points: training the background set only"
                                     : "clip masks are empty: training the background set only");

  // Scene radius.
  V3 mean_centre = V3::Zero();
  for (const auto& c : cameras) mean_centre += c.center();
  mean_centre /= Scalar(cameras.size());
  double max_d = 0;
  for (const auto& c : cameras) max_d = std::max(max_d, double((c.center() - mean_centre).norm()));
  V3 box_centre = mean_centre + cameras[0].R.row(2).transpose();  // 1 unit ahead when there are no points
  if (!pts.empty()) {
    V3 lo = pts[0], hi = pts[0];
    for (const auto& p : pts) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
    box_centre = Scalar(0.5) * (lo + hi);
  }
  const double view_distance = std::max(double((box_centre - mean_centre).norm()), 1e-6);
  m.scene_radius = Scalar(std::max(1.1 * max_d, o.min_radius_fraction * view_distance));
  if (1.1 * max_d < o.min_radius_fraction * view_distance)
    m.warnings.push_back("camera centres (almost) coincide: scene radius floored at " +
                         std::to_string(double(m.scene_radius)));

  // Foreground set.
  if (m.has_foreground) detail::append_init_gaussians(m.frg, pts, rgb, o, pool);

  // Background shells around the foreground box (or around a point ahead of the cameras).
  BackgroundShellOptions bo = o.background;
  std::vector<V3> shell_src = pts;
  if (shell_src.empty()) {
    // No points: shells of radius factor x scene radius around the point 1 view distance ahead.
    const Scalar half = m.scene_radius;
    shell_src = {box_centre - V3::Constant(half), box_centre + V3::Constant(half)};
  }
  auto bpts = background_shell_points<Scalar>(shell_src, bo, box_centre);
  std::vector<std::array<Scalar, 3>> brgb;
  if (o.background_colour == BackgroundColour::frames) {
    if (frames.empty())
      throw option_error("option.clip", "background_colour", "'frames' needs the clip's frames (make_clip_model's frames argument)");
    brgb = colours_from_frames<Scalar>(bpts, cameras, frames, masks, pool);
  } else {
    brgb.resize(bpts.size());
    std::mt19937_64 rng(o.seed ^ 0xb4c4'0000'0000'0001ull);
    for (auto& c : brgb)
      for (auto& v : c) v = Scalar(double(rng() >> 11) * 0x1.0p-53);
  }
  // The middle frame's surfaces after the shells (their scales from the same k nearest neighbours).
  if (o.background_dense_stride > 0) {
    const std::size_t mid = (cameras.size() - 1) / 2;
    auto [dpts, drgb] = frame_surface_points<Scalar>(cameras[mid], frames[mid], pts, o.background_dense_stride, 8, pool);
    if (dpts.empty())
      m.warnings.push_back("no SfM point projects into the clip's middle frame (or the stride exceeds it): the background starts from its shells alone");
    bpts.insert(bpts.end(), dpts.begin(), dpts.end());
    brgb.insert(brgb.end(), drgb.begin(), drgb.end());
  }
  detail::append_init_gaussians(m.bkg, bpts, brgb, o, pool);
  // Fields' boxes from every initial mean (before culling: a culled Gaussian would have added nothing
  // to any gradient, so the kept ones train exactly as in the uncut model).
  detail::bounding_box<Scalar>(m.frg.mean, m.frg_box_min, m.frg_box_max);
  detail::bounding_box<Scalar>(m.bkg.mean, m.bkg_box_min, m.bkg_box_max);
  if (o.cull_unseen) {
    for (GaussianSet s : {GaussianSet::foreground, GaussianSet::background}) {
      auto& cloud = m.cloud(s);
      if (cloud.empty()) continue;
      const std::vector<std::uint8_t> seen = seen_by_any_camera<Scalar, SHDegree>(cloud, m.cameras, {}, pool, o.cull_margin);
      if (std::find(seen.begin(), seen.end(), std::uint8_t(1)) == seen.end()) {
        m.warnings.push_back(std::string("no clip camera sees any initial Gaussian of set ") + to_string(s) + ": the set is kept whole");
        continue;
      }
      cloud.keep_rows(seen);
    }
  }

  // Fields and alpha maps.
  constexpr int kLevels = Field::grid_type::kLevels;
  const int frame_count = static_cast<int>(cameras.size());
  m.build_field(GaussianSet::foreground, sized_deformation(o.deformation, o.frg_grid, kLevels, frame_count));
  // A static background never reads its field: the smallest grid, so it costs no bytes nor optimiser steps.
  const GridSize bkg = o.static_background && !o.bkg_grid.resized() ? GridSize{2, 1, 0, 0} : o.bkg_grid;
  m.build_field(GaussianSet::background, sized_deformation(o.deformation, bkg, kLevels, frame_count));
  const Scalar a0 = m.has_foreground ? logit(Scalar(o.alpha_init)) : Scalar(-30);
  m.alpha_logit.assign(cameras.size(), Image<Scalar, 1>(m.width(), m.height(), a0));
  if (m.has_foreground && o.alpha_mask > 0 && !masks.empty()) {
    for (std::size_t f = 0; f < masks.size(); ++f) {
      // Masks come at the source size when the clip trains at another (reconstruct --scale): area-resampled.
      const Image<Scalar, 1> mk = resize_area(masks[f], m.width(), m.height());
      Scalar* a = m.alpha_logit[f].data();
      for (std::size_t k = 0; k < mk.size(); ++k) {
        a[k] = logit(Scalar(o.alpha_outside + (o.alpha_mask - o.alpha_outside) * detail::foreground_fraction(double(mk.data()[k]))));
      }
    }
  }
  m.static_background = o.static_background;
  return m;
}

/// Builds a clip model from an SfM result (cameras of `sfm.frames`, which must be the contiguous
/// range `sfm.range`, and its points). @throws option_error `option.clip` if a frame is not registered.
template <class Scalar, int SHDegree = 3, class Field = DefaultDeformationField<Scalar>, class SfmScalar = double>
[[nodiscard]] ClipModel<Scalar, SHDegree, Field> make_clip_model(const SfmResult<SfmScalar>& sfm, const ClipModelOptions& o = {},
                                                                 std::span<const Image<Scalar, 1>> masks = {},
                                                                 ThreadPool* pool = nullptr,
                                                                 std::span<const Image<Scalar, 3>> frames = {}) {
  std::vector<Camera<Scalar>> cams;
  for (int f = sfm.range.first; f <= sfm.range.last; ++f) {
    const int i = sfm.index_of(f);
    if (i < 0) throw option_error("option.clip", "frame " + std::to_string(f), "is not registered in the SfM result");
    cams.push_back(sfm.cameras[std::size_t(i)].template cast<Scalar>());
  }
  return make_clip_model<Scalar, SHDegree, Field, SfmScalar>(sfm.range, cams, sfm.points, o, masks, pool, frames);
}

}  // namespace video3dgs
