// Stage-1 training of one clip (ClipTrainer) on the synthetic clip (synthetic/clip.hpp): prints JSON
// lines — one "progress" line every --every iterations, then one "stages" line with the median
// per-iteration time of each stage (deformation, rasterize forward/backward, loss, optimizer,
// densify; medians over the iterations of each phase: before/after the deformation warm-up), one
// "stages_by_size" line per render size of the resolution schedule (the same medians, the summed
// seconds, and the medians of the rasterizer's work counters of each set: visible Gaussians,
// tile-Gaussian pairs, pixel-Gaussian evaluations), and one
// "result" line with the Gaussian counts, the final PSNR/SSIM over the clip's frames (merged, Frg-only,
// Bkg-only; the merged render's PSNR of each frame), the model size in bytes and the wall time.
// --evaluate-at K,K,... adds a "checkpoint" line after each listed iteration: the same evaluation
// over the clip's frames at that point of one run, and the training seconds so far (evaluations
// excluded), so one run gives PSNR against iterations (ClipTrainer::evaluate leaves the training
// state as it was: the run's later iterations and result are those of a run without it).
// --save-state FILE [--save-state-at K] writes the training state (ClipTrainer::save_checkpoint: model,
// optimiser moments, iteration, RNG, densification statistics) after iteration K (default: the last);
// --resume FILE continues such a state with the options given now, so variants of a run's later
// phase start from one shared state instead of each re-training the phases before it (with the same
// options, the resumed run ends with the uninterrupted run's model).
//
// Usage: kUsage below (`bench_train_clip --help` prints it).
// With --images/--sparse the frames are the folder's images in natural order (frame i = i-th image);
// --first/--last pick the clip (default: every frame), and the COLMAP model (for example the
// OUT/sfm/frames_<first>_<last>/model folder of a `video3dgs reconstruct` run, so SfM is not re-run)
// must register every frame of it, its images named by frame number (000000.jpg, as ColmapSfm names
// them) or by the frame files' names. --masks gives the foreground masks (as `reconstruct --masks`:
// the model's points are split into Frg/Bkg by them). --scale F resamples frames area-weighted to
// round(F x size) (default 1 for real clips); --downscale K box-downscales by K instead. --preset
// takes the reconstruction preset's schedule (3k: what `video3dgs reconstruct` trains) instead of this
// program's short synthetic schedule; later flags still override it. Needs the COLMAP adapter.
#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "video3dgs/core/parallel.hpp"
#include "video3dgs/io/frame_folder.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/model/clip_model_io.hpp"
#include "video3dgs/pipeline/outputs.hpp"
#include "video3dgs/synthetic/clip.hpp"
#include "video3dgs/training/clip_trainer.hpp"

#include "bench_common.hpp"

#if __has_include("video3dgs/colmap/clip_input.hpp")
#include "video3dgs/colmap/clip_input.hpp"
#define BENCH_HAVE_COLMAP 1
#endif

using namespace video3dgs;

namespace {

constexpr const char* kUsage = R"(Usage: bench_train_clip [--iterations N] [--frames N] [--width W] [--height H] [--threads T]
         [--seed S] [--model-seed S] (ClipModelOptions::seed: the background's colours; `reconstruct`
         gives clip c seed + c) [--shell-points N] [--warmup N] [--densify-from N] [--densify-until N]
         [--densify-grad G] (TrainOptions::densify_grad_threshold: the mean view-space gradient that
         clones or splits a Gaussian; 2e-4)
         [--sh-interval N] [--every N] [--object N] [--background N] [--log2-table N] [--levels L]
         [--frg-log2-table N] [--bkg-log2-table N] [--frg-levels L] [--bkg-levels L] (ClipModelOptions::
         frg_grid / bkg_grid: 2^N entries per hashed level, L of the 16 levels over the same resolutions)
         [--finest R] (GridSize::finest of both: the finest level's cells per axis)
         [--time-cells M] (GridSize::time_cells of both: every level's cells along time capped at M; 0 = none,
         -1 = the default, the clip's frames - 1)
         [--sparse-adam 0|1] [--max-gaussians N] [--static-background 0|1] (TrainOptions::sparse_adam,
         max_gaussians per set; ClipModelOptions::static_background) [--alpha-mask A] [--alpha-outside B]
         (ClipModelOptions::alpha_mask / alpha_outside: alpha maps start at A inside the masks, B outside)
         [--bkg-colour random|frames] (ClipModelOptions::background_colour: the background set's first
         colours drawn with the model seed, or read from the frames where each point projects)
         [--bkg-dense S] (ClipModelOptions::background_dense_stride: the background set also starts with one
         Gaussian per S x S pixels of the clip's middle frame, at depths read from the SfM points; 0 = off)
         [--cull-unseen 0|1] (ClipModelOptions::cull_unseen: drop the initial Gaussians no clip camera sees)
         [--cull-margin M] (its guard band around each frame, pixels; default 16)
         [--resolution K:S,K:S,...]
         (TrainOptions::resolution_schedule: from iteration K on, scale S; "0:0.25,500:0.5,1500:1"; a
         coarse-to-fine preset's fine phase moves with it: TrainOptions::with_resolution_schedule)
         [--budget G] [--frg-share S] (TrainOptions::gaussians_per_pixel, foreground_share; the
         share defaults to the masks' coverage) [--prune-weight P] [--prune-weight-from K] (TrainOptions::prune_weight, prune_weight_from: the weight prune at
         the densification events from iteration K on) [--min-transmittance T] (TrainOptions::min_transmittance,
         the rasterizer's transmittance stop; 1e-4) [--blend-at-stop 0|1] (TrainOptions::blend_at_stop: the
         crossing Gaussian blended before the pixel stops; 0, the method's) [--crop C]
         (TrainOptions::crop: full-size iterations on one random cell of a jittered ceil(1/C)^2 cut)
         [--lr-camera-rotation R] [--lr-camera-translation T] (TrainOptions: camera refinement, 0 = off)
         [--lr-deformation R] [--lr-position-steps N] [--lr-deformation-steps N] (TrainOptions::
         lr_deformation_init; the lengths of the position and deformation rates' exponential decays)
         [--freeze-deformation-from K] (TrainOptions::freeze_deformation_from: the fields constants
         from iteration K on, 0 = never) [--freeze-background-from K] (TrainOptions::freeze_background_from:
         the background set a constant from iteration K on, K >= the densification's end; 0 = never)
         [--prune-efficiency E --prune-efficiency-at K] (TrainOptions::prune_efficiency, prune_efficiency_at:
         after iteration K, one prune of the Gaussians whose blend weight per evaluation since the last
         densification event is below E; 0 = never) [--prune-efficiency-from F] (TrainOptions::
         prune_efficiency_from: the same prune also just before every densification event from the first at
         or after F on; --prune-efficiency-at may then be 0; 0 = the one-shot prune alone)
         [--prune-efficiency-bkg E] (TrainOptions::prune_efficiency_bkg: the background set's own threshold
         in those prunes; 0 = --prune-efficiency's)
         [--lr-position R] [--lr-sh-dc R] [--lr-sh-rest R] [--lr-opacity R] [--lr-scale R] [--lr-rotation R]
         (TrainOptions::lr_position_init (x scene radius), lr_sh_dc, lr_sh_rest, lr_opacity, lr_scale,
         lr_rotation: the Gaussians' rates; the result line's "lr" gives every rate in use)
         [--lambda-dssim L] [--lambda-dssim-fine L] [--weight-frg W] [--weight-bkg W] [--detail 0|1]
         (TrainOptions::lambda_dssim: the loss (1 - L) L1 + L D-SSIM; lambda_dssim_fine: L from lr_fine_from
         on; weight_frg / weight_bkg: the sets' own terms against the merged render's; detail_weighted_l1;
         the result line's "loss" gives them)
         [--lr-position-fine F] [--lr-alpha-fine A] [--lr-sh-fine S] [--lr-fine-from K] (TrainOptions::
         lr_position_fine, lr_alpha_fine, lr_sh_fine, lr_fine_from: the position rate x F, the alpha maps'
         rate x A and the SH coefficients' rates x S from iteration K on)
         [--lr-anneal-from K] [--lr-anneal-factor A] (TrainOptions::lr_anneal_from, lr_anneal_factor: every
         rate falls log-linearly from iteration K on to A times itself at the run's end)
         [--images DIR --sparse DIR [--masks DIR] [--first N --last N] [--scale F | --downscale K]
          [--preset balanced|fast|best|reference|3k|5k|10k] [--shell-points N]]   (a real clip: frame folder + COLMAP model)
         [--tile 8|16|32] (the rasterizer's tile size, default kTrainingTileSize = 32: the same images, the
         gradients summed per tile, so another rounding, and another speed)
         [--scaled-iterations N] (TrainOptions::with_iterations: the schedules so far scaled to N iterations,
         as `video3dgs reconstruct --iterations N` does with its preset)
         [--save FILE] (the trained clip model, clip_model_io.hpp's format, for `video3dgs compact`)
         [--evaluate-at K,K,...] (a "checkpoint" line after each iteration K: PSNR/SSIM over the clip's
         frames at that point and the training seconds so far, evaluations excluded)
         [--save-state FILE [--save-state-at K]] (the training state after iteration K, default the last:
         ClipTrainer::save_checkpoint) [--resume FILE] (continue a saved state: same clip and frames,
         the options given now; the model options and --model-seed are the state's, so the result line
         gives them as null, and frg_init / bkg_init, the seconds and the stage medians count from the
         resumed state)
Numbers are read whole: "12x" or "1.5" for a count is an error; a count may be written as 1e9.
)";

using bench::median;

struct Input {
  SfmResult<double> sfm;
  std::vector<Image<float, 3>> frames;
  std::vector<Image<float, 1>> masks;
  std::string source;
};

/// The schedule as [[from_iteration, scale], ...].
nlohmann::json resolution_json(const TrainOptions& to) {
  nlohmann::json a = nlohmann::json::array();
  for (const auto& r : to.resolution_schedule) a.push_back({r.from_iteration, r.scale});
  return a;
}

/// Box-downscales by an integer factor (floor size); intrinsics follow (pixel centres preserved).
Image<float, 3> downscale(const Image<float, 3>& in, int k) {
  const int w = in.width() / k, h = in.height() / k;
  Image<float, 3> out(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) {
        double s = 0;
        for (int dy = 0; dy < k; ++dy)
          for (int dx = 0; dx < k; ++dx) s += in(k * x + dx, k * y + dy, c);
        out(x, y, c) = float(s / (k * k));
      }
  return out;
}

/// Where the training state is saved and read (--save-state, --save-state-at, --resume).
struct StateFiles {
  std::string save, resume;
  int save_at = 0;  ///< after this iteration; 0: after the last
};

template <int Tile>
int run(Input& in, const TrainOptions& to_in, const ClipModelOptions& mo, unsigned threads, int every, const std::string& save,
        const std::vector<int>& evaluate_at, const StateFiles& state) {
  using Field = DefaultDeformationField<float>;
  using Model = ClipModel<float, 3, Field>;
  ThreadPool pool(threads);
  ThreadPool* p = threads > 1 ? &pool : nullptr;
  TrainOptions to = to_in;
  if (!in.masks.empty() && to.foreground_share == 0) to.foreground_share = std::max(1e-3, mask_coverage<float>(in.masks));
  if (to.foreground_share == 0) to.foreground_share = 1;
  const auto make_trainer = [&] {
    if (!state.resume.empty()) return std::make_unique<ClipTrainer<Model, Tile>>(state.resume, std::move(in.frames), to, p);
    auto model = make_clip_model<float, 3, Field>(in.sfm, mo, std::span<const Image<float, 1>>(in.masks), p,
                                                  std::span<const Image<float, 3>>(in.frames));
    return std::make_unique<ClipTrainer<Model, Tile>>(std::move(model), std::move(in.frames), to, p);
  };
  const std::unique_ptr<ClipTrainer<Model, Tile>> owner = make_trainer();
  ClipTrainer<Model, Tile>& trainer = *owner;
  const std::size_t frg0 = trainer.model().frg.size(), bkg0 = trainer.model().bkg.size();  // at the start (or the resumed state)
  const int W = trainer.model().width(), H = trainer.model().height(), F = trainer.model().frame_count();
  const int resumed_at = trainer.stats().iterations;
  const int save_at = state.save_at > 0 ? state.save_at : to.iterations;
  if (!state.save.empty() && (save_at <= resumed_at || save_at > to.iterations))
    throw option_error("option.range", "--save-state-at", "iteration " + std::to_string(save_at) + " is not in this run (" +
                                                              std::to_string(resumed_at + 1) + " to " + std::to_string(to.iterations) + ")");
  std::vector<double> st[2][7];  // [phase][stage] ms
  // Per render size: the same stage times, the rasterizer's work counters of both renders, and the
  // summed seconds (where the run's time went, size by size).
  struct BySize {
    int width = 0, height = 0;
    std::vector<double> ms[7];
    std::vector<double> work[2][3];  // [frg, bkg][visible, tile_pairs, evaluations]
    double total_s = 0;
  };
  std::vector<BySize> by_size;
  const auto t0 = std::chrono::steady_clock::now();
  double evaluate_s = 0;  // spent in the checkpoints' evaluations and in saving the state
  trainer.train([&](const IterationInfo& it) {
    const int ph = it.iteration < to.deformation_warmup ? 0 : 1;
    const auto& t = it.times;
    const double v[7] = {t.deformation, t.raster_forward, t.raster_backward, t.loss, t.optimizer, t.densify, t.total};
    for (int k = 0; k < 7; ++k)
      if (k != 5 || it.densified) st[ph][k].push_back(1e3 * v[k]);
    auto size_it = std::find_if(by_size.begin(), by_size.end(), [&](const BySize& b) { return b.width == it.width && b.height == it.height; });
    if (size_it == by_size.end()) size_it = by_size.insert(by_size.end(), BySize{it.width, it.height, {}, {}, 0});
    for (int k = 0; k < 7; ++k)
      if (k != 5 || it.densified) size_it->ms[k].push_back(1e3 * v[k]);
    size_it->total_s += t.total;
    for (int set = 0; set < 2; ++set) {
      const RasterStats& r = set == 0 ? it.frg_raster : it.bkg_raster;
      size_it->work[set][0].push_back(double(r.visible));
      size_it->work[set][1].push_back(double(r.tile_pairs));
      size_it->work[set][2].push_back(double(r.evaluations));
    }
    if ((it.iteration + 1) % every == 0)
      bench::emit({{"bench", "train_clip"}, {"kind", "progress"}, {"iteration", it.iteration + 1}, {"loss", bench::round_to(it.loss, 5)},
                   {"psnr", bench::round_to(it.psnr, 3)}, {"width", it.width}, {"frg", it.frg_count}, {"bkg", it.bkg_count}});
    if (std::find(evaluate_at.begin(), evaluate_at.end(), it.iteration + 1) != evaluate_at.end()) {
      const auto e0 = std::chrono::steady_clock::now();
      const double train_s = std::chrono::duration<double>(e0 - t0).count() - evaluate_s;
      const auto e = trainer.evaluate();
      evaluate_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - e0).count();
      bench::emit({{"bench", "train_clip"}, {"kind", "checkpoint"}, {"iteration", it.iteration + 1}, {"psnr", bench::round_to(e.psnr, 3)},
                   {"ssim", bench::round_to(e.ssim, 4)}, {"psnr_frg", bench::round_to(e.psnr_frg, 3)},
                   {"psnr_bkg", bench::round_to(e.psnr_bkg, 3)}, {"frg", it.frg_count}, {"bkg", it.bkg_count},
                   {"train_s", bench::round_to(train_s, 2)}});
    }
    if (!state.save.empty() && it.iteration + 1 == save_at) {  // left out of the seconds, like the evaluations
      const auto s0 = std::chrono::steady_clock::now();
      trainer.save_checkpoint(state.save);
      evaluate_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - s0).count();
    }
    return true;
  });
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const char* names[2] = {"warmup", "deformed"};
  for (int ph = 0; ph < 2; ++ph) {
    if (st[ph][6].empty()) continue;
    auto ms = [&](int k) { return bench::round_to(median(st[ph][k]), 3); };
    bench::emit({{"bench", "train_clip"}, {"kind", "stages"}, {"source", in.source}, {"phase", names[ph]}, {"iterations", st[ph][6].size()},
                 {"threads", threads},
                 {"median_ms", {{"deformation", ms(0)}, {"raster_forward", ms(1)}, {"raster_backward", ms(2)}, {"loss", ms(3)},
                                {"optimizer", ms(4)}, {"densify_per_event", ms(5)}, {"total", ms(6)}}}});
  }
  for (const BySize& b : by_size) {
    auto ms = [&](int k) { return bench::round_to(median(b.ms[k]), 3); };
    auto work = [&](int set) {
      return nlohmann::ordered_json{{"visible", median(b.work[set][0])}, {"tile_pairs", median(b.work[set][1])},
                                    {"evaluations", median(b.work[set][2])}};
    };
    bench::emit({{"bench", "train_clip"}, {"kind", "stages_by_size"}, {"source", in.source}, {"width", b.width}, {"height", b.height},
                 {"iterations", b.ms[6].size()}, {"threads", threads}, {"sum_s", bench::round_to(b.total_s, 2)},
                 {"median_ms", {{"deformation", ms(0)}, {"raster_forward", ms(1)}, {"raster_backward", ms(2)}, {"loss", ms(3)},
                                {"optimizer", ms(4)}, {"densify_per_event", ms(5)}, {"total", ms(6)}}},
                 {"median_work", {{"frg", work(0)}, {"bkg", work(1)}}}});
  }
  const auto e = trainer.evaluate();
  io::BinaryWriter w(kClipModelMagic, kClipModelVersion);
  write_clip_model(w, trainer.model());
  if (!save.empty()) io::write_file_atomic(save, w.bytes());  // = save_clip_model's file
  const auto& s = trainer.stats();
  using bench::round_to;
  // Mean merge weight inside / outside the masks, as report.json's alpha_inside / alpha_outside.
  const auto alpha = alpha_inside_outside(trainer.model(), std::span<const Image<float, 1>>(in.masks));
  auto alpha_mean = [&](int side) {
    const auto& a = alpha[std::size_t(side)];
    return a ? nlohmann::ordered_json(round_to(*a, 3)) : nlohmann::ordered_json();
  };
  nlohmann::ordered_json per_frame = nlohmann::ordered_json::array();  // the merged render's, clip frame 0 first
  for (double p : e.psnr_per_frame) per_frame.push_back(round_to(p, 3));
  auto log2_of = [](std::size_t t) { return int(std::countr_zero(t)); };
  // The model's start options: those of the flags, or unknown (null) for a resumed state, which holds
  // the model but not the options that made it.
  auto start = [&](const auto& v) { return resumed_at > 0 ? nlohmann::ordered_json() : nlohmann::ordered_json(v); };
  const auto& fg = trainer.model().frg_field->grid();
  const auto& bg = trainer.model().bkg_field->grid();
  bench::emit({{"bench", "train_clip"}, {"kind", "result"}, {"source", in.source}, {"frames", F}, {"width", W}, {"height", H},
               {"iterations", s.iterations}, {"resumed_at", resumed_at}, {"threads", threads}, {"tile", Tile}, {"log2_table", log2_of(fg.table_size())}, {"levels", fg.active_levels()},
               {"bkg_log2_table", log2_of(bg.table_size())}, {"bkg_levels", bg.active_levels()}, {"finest", fg.resolution(fg.active_levels() - 1)}, {"time_cells", fg.options().max_cells[3]}, {"field_params", fg.param_count() + bg.param_count()}, {"sparse_adam", to.sparse_adam}, {"lr_camera_rotation", to.lr_camera_rotation}, {"lr_camera_translation", to.lr_camera_translation},
               {"lr", {{"position", to.lr_position_init}, {"sh_dc", to.lr_sh_dc}, {"sh_rest", to.lr_sh_rest}, {"opacity", to.lr_opacity}, {"scale", to.lr_scale}, {"rotation", to.lr_rotation}, {"alpha", to.lr_alpha}, {"deformation", to.lr_deformation_init}, {"position_fine", to.lr_position_fine}, {"alpha_fine", to.lr_alpha_fine}, {"sh_fine", to.lr_sh_fine}, {"fine_from", to.lr_fine_from}, {"anneal_from", to.lr_anneal_from}, {"anneal_factor", to.lr_anneal_factor}}},
               {"loss", {{"lambda_dssim", to.lambda_dssim}, {"lambda_dssim_fine", to.lambda_dssim_fine ? nlohmann::ordered_json(*to.lambda_dssim_fine) : nlohmann::ordered_json()}, {"weight_frg", to.weight_frg}, {"weight_bkg", to.weight_bkg}, {"weight_merged", to.weight_merged}, {"detail", to.detail_weighted_l1}}},
               {"static_background", trainer.model().static_background}, {"alpha_mask", start(mo.alpha_mask)}, {"model_seed", start(mo.seed)}, {"bkg_colour", start(to_string(mo.background_colour))}, {"bkg_dense", start(mo.background_dense_stride)}, {"cull_unseen", start(mo.cull_unseen)}, {"cull_margin", start(mo.cull_margin)},
               {"densify_until", to.densify_until}, {"densify_grad_threshold", to.densify_grad_threshold}, {"max_gaussians", to.max_gaussians}, {"gaussians_per_pixel", to.gaussians_per_pixel}, {"foreground_share", round_to(to.foreground_share, 4)}, {"prune_weight", to.prune_weight}, {"prune_weight_from", to.prune_weight_from}, {"freeze_deformation_from", to.freeze_deformation_from}, {"freeze_background_from", to.freeze_background_from}, {"prune_efficiency", to.prune_efficiency}, {"prune_efficiency_at", to.prune_efficiency_at}, {"prune_efficiency_from", to.prune_efficiency_from}, {"prune_efficiency_bkg", to.prune_efficiency_bkg}, {"min_transmittance", to.min_transmittance}, {"blend_at_stop", to.blend_at_stop}, {"crop", to.crop},
               {"budget_frg", trainer.options().gaussian_budget(true, W, H)}, {"budget_bkg", trainer.options().gaussian_budget(false, W, H)},
               {"resolution_schedule", resolution_json(to)}, {"frg_init", frg0}, {"bkg_init", bkg0},
               {"frg", trainer.model().frg.size()}, {"bkg", trainer.model().bkg.size()}, {"cloned", s.cloned}, {"split", s.split},
               {"pruned", s.pruned}, {"skipped_steps", s.skipped_steps}, {"psnr", round_to(e.psnr, 3)}, {"ssim", round_to(e.ssim, 4)},
               {"psnr_frg", round_to(e.psnr_frg, 3)}, {"psnr_bkg", round_to(e.psnr_bkg, 3)}, {"psnr_per_frame", per_frame},
               {"alpha_inside", alpha_mean(0)},
               {"alpha_outside", alpha_mean(1)}, {"model_bytes", w.bytes().size()},
               {"wall_s", round_to(wall, 2)}, {"evaluate_s", round_to(evaluate_s, 2)},
               {"sum_s", {{"deformation", round_to(s.times.deformation, 2)}, {"raster_forward", round_to(s.times.raster_forward, 2)},
                          {"raster_backward", round_to(s.times.raster_backward, 2)}, {"loss", round_to(s.times.loss, 2)},
                          {"optimizer", round_to(s.times.optimizer, 2)}, {"densify", round_to(s.times.densify, 2)}}}});
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  synthetic::SyntheticClipOptions so;
  so.frames = 10;
  so.width = 128;
  so.height = 96;
  TrainOptions to = TrainOptions::preset(3000);
  to.iterations = 600;
  to.deformation_warmup = 200;
  to.densify_from = 100;
  to.densify_until = 450;
  to.sh_degree_interval = 200;
  ClipModelOptions mo;
  mo.background.points_per_shell = 3000;
  unsigned threads = 2;
  int every = 100, downscale_k = 0, first = 0, last = -1, tile = kTrainingTileSize;
  double scale = 0, frg_share = 0;  // 0: the masks' coverage (1 without masks)
  std::string images, sparse, masks, save;
  std::vector<int> evaluate_at;
  StateFiles state;
  for (int i = 1; i < argc; ++i)
    if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) {
      std::fputs(kUsage, stdout);
      return 0;
    }
  if ((argc - 1) % 2 != 0) {  // every option takes one value
    std::fprintf(stderr, "option %s has no value (--help lists the options)\n", argv[argc - 1]);
    return 2;
  }
  try {  // a malformed number (bench::parse_number) ends the program with its message
    for (int i = 1; i + 1 < argc; i += 2) {
      const std::string a = argv[i];
      // The value read as a number only by the options that take one (bench::parse_number: strict).
      // Each count is read as its own type: a value out of that type's range is an option error, not a wrap.
      const auto n = [&] { return bench::parse_number<int>(a, argv[i + 1]); };
      const auto u64 = [&] { return bench::parse_number<std::uint64_t>(a, argv[i + 1]); };
      const auto x = [&] { return bench::parse_number<double>(a, argv[i + 1]); };
      if (a == "--iterations") to.iterations = n();
      else if (a == "--scaled-iterations") to = to.with_iterations(n());
      else if (a == "--frames") so.frames = n();
      else if (a == "--width") so.width = n();
      else if (a == "--height") so.height = n();
      else if (a == "--threads") threads = bench::parse_number<unsigned>(a, argv[i + 1]);
      else if (a == "--seed") to.seed = so.seed = u64();
      else if (a == "--shell-points") mo.background.points_per_shell = std::size_t(u64());
      else if (a == "--warmup") to.deformation_warmup = n();
      else if (a == "--densify-from") to.densify_from = n();
      else if (a == "--densify-until") to.densify_until = n();
      else if (a == "--densify-grad") to.densify_grad_threshold = x();
      else if (a == "--sh-interval") to.sh_degree_interval = n();
      else if (a == "--every") every = std::max(1, n());
      else if (a == "--object") so.object_gaussians = n();
      else if (a == "--background") so.background_gaussians = n();
      else if (a == "--motion") so.motion = x();
      else if (a == "--points") so.foreground_points = n();
      else if (a == "--spin") so.spin_degrees = x();
      else if (a == "--lr-alpha") to.lr_alpha = x();
      else if (a == "--lr-deformation") to.lr_deformation_init = x();
      else if (a == "--lr-position") to.lr_position_init = x();
      else if (a == "--lr-sh-dc") to.lr_sh_dc = x();
      else if (a == "--lr-sh-rest") to.lr_sh_rest = x();
      else if (a == "--lr-opacity") to.lr_opacity = x();
      else if (a == "--lr-scale") to.lr_scale = x();
      else if (a == "--lr-rotation") to.lr_rotation = x();
      else if (a == "--lr-position-fine") to.lr_position_fine = x();
      else if (a == "--lr-sh-fine") to.lr_sh_fine = x();
      else if (a == "--lr-alpha-fine") to.lr_alpha_fine = x();
      else if (a == "--lr-fine-from") to.lr_fine_from = n();
      else if (a == "--lr-anneal-from") to.lr_anneal_from = n();
      else if (a == "--lr-anneal-factor") to.lr_anneal_factor = x();
      else if (a == "--freeze-deformation-from") to.freeze_deformation_from = n();
      else if (a == "--freeze-background-from") to.freeze_background_from = n();
      else if (a == "--prune-efficiency") to.prune_efficiency = x();
      else if (a == "--prune-efficiency-at") to.prune_efficiency_at = n();
      else if (a == "--prune-efficiency-from") to.prune_efficiency_from = n();
      else if (a == "--prune-efficiency-bkg") to.prune_efficiency_bkg = x();
      else if (a == "--lr-position-steps") to.lr_position_steps = n();
      else if (a == "--lr-deformation-steps") to.lr_deformation_steps = n();
      else if (a == "--weight-frg") to.weight_frg = x();
      else if (a == "--weight-bkg") to.weight_bkg = x();
      else if (a == "--lambda-dssim") to.lambda_dssim = x();
      else if (a == "--lambda-dssim-fine") to.lambda_dssim_fine = x();
      else if (a == "--detail") to.detail_weighted_l1 = n() != 0;
      else if (a == "--sparse-adam") to.sparse_adam = n() != 0;
      else if (a == "--lr-camera-rotation") to.lr_camera_rotation = x();
      else if (a == "--lr-camera-translation") to.lr_camera_translation = x();
      else if (a == "--max-gaussians") to.max_gaussians = std::size_t(u64());
      else if (a == "--budget") to.gaussians_per_pixel = x();
      else if (a == "--frg-share") frg_share = x();
      else if (a == "--prune-weight") to.prune_weight = x();
      else if (a == "--min-transmittance") to.min_transmittance = x();
      else if (a == "--blend-at-stop") to.blend_at_stop = n() != 0;
      else if (a == "--prune-weight-from") to.prune_weight_from = n();
      else if (a == "--crop") to.crop = x();
      else if (a == "--static-background") mo.static_background = n() != 0;
      else if (a == "--model-seed") mo.seed = u64();
      else if (a == "--alpha-mask") mo.alpha_mask = x();
      else if (a == "--alpha-outside") mo.alpha_outside = x();
      else if (a == "--bkg-colour") {
        const std::string c = argv[i + 1];
        if (c != "random" && c != "frames") {
          std::fprintf(stderr, "--bkg-colour takes random or frames, got %s\n", c.c_str());
          return 2;
        }
        mo.background_colour = c == "frames" ? BackgroundColour::frames : BackgroundColour::random;
      }
      else if (a == "--bkg-dense") mo.background_dense_stride = n();
      else if (a == "--cull-unseen") mo.cull_unseen = n() != 0;
      else if (a == "--cull-margin") mo.cull_margin = n();
      else if (a == "--resolution") {
        try {
          to = to.with_resolution_schedule(TrainOptions::parse_resolution_schedule(argv[i + 1]));
        } catch (const error& e) {
          std::fprintf(stderr, "%s\n", e.what());
          return 2;
        }
      }
      else if (a == "--log2-table") mo.frg_grid.log2_table_size = mo.bkg_grid.log2_table_size = n();
      else if (a == "--levels") mo.frg_grid.levels = mo.bkg_grid.levels = n();
      else if (a == "--frg-log2-table") mo.frg_grid.log2_table_size = n();
      else if (a == "--bkg-log2-table") mo.bkg_grid.log2_table_size = n();
      else if (a == "--frg-levels") mo.frg_grid.levels = n();
      else if (a == "--finest") mo.frg_grid.finest = mo.bkg_grid.finest = x();
      else if (a == "--time-cells") mo.frg_grid.time_cells = mo.bkg_grid.time_cells = n();
      else if (a == "--bkg-levels") mo.bkg_grid.levels = n();
      else if (a == "--images") images = argv[i + 1];
      else if (a == "--sparse") sparse = argv[i + 1];
      else if (a == "--downscale") downscale_k = std::max(1, n());
      else if (a == "--scale") scale = x();
      else if (a == "--masks") masks = argv[i + 1];
      else if (a == "--save") save = argv[i + 1];
      else if (a == "--save-state") state.save = argv[i + 1];
      else if (a == "--save-state-at") {
        state.save_at = n();
        if (state.save_at < 1) {
          std::fprintf(stderr, "bench_train_clip: [option.range] --save-state-at: an iteration >= 1, got %d\n", state.save_at);
          return 2;
        }
      }
      else if (a == "--resume") state.resume = argv[i + 1];
      else if (a == "--evaluate-at")
        for (const auto& k : bench::split_list(argv[i + 1])) evaluate_at.push_back(bench::parse_number<int>(a, k));
      else if (a == "--tile") {
        tile = n();
        if (tile != 8 && tile != 16 && tile != 32) {
          std::fprintf(stderr, "bench_train_clip: [option.range] --tile: 8, 16 or 32, got %d\n", tile);
          return 2;
        }
      }
      else if (a == "--first") first = n();
      else if (a == "--last") last = n();
      else if (a == "--preset") {
        const std::uint64_t seed = to.seed;
        to = TrainOptions::preset(argv[i + 1]);
        to.seed = seed;
        mo.background.points_per_shell = ClipModelOptions{}.background.points_per_shell;
      }
      else {
        std::fprintf(stderr, "unknown option %s\n", a.c_str());
        return 2;
      }
    }
  } catch (const error& e) {
    std::fprintf(stderr, "bench_train_clip: %s (--help lists the options)\n", e.what());
    return 2;
  }
  to.foreground_share = frg_share;
  if (state.save_at != 0 && state.save.empty()) {
    std::fprintf(stderr, "bench_train_clip: --save-state-at needs --save-state FILE\n");
    return 2;
  }
  try {
    Input in;
    if (!images.empty() || !sparse.empty()) {
#if defined(BENCH_HAVE_COLMAP)
      ThreadPool pool(threads);
      auto clip = colmap::load_clip_input(images, masks, sparse, FrameRange{first, last}, downscale_k > 0 ? 1.0 : (scale > 0 ? scale : 1.0), &pool);
      in.sfm = std::move(clip.sfm);
      in.masks = std::move(clip.masks);
      in.frames = std::move(clip.frames);
      if (downscale_k > 0) {  // box filter instead of the loader's area resampling
        const int W = clip.source_width / downscale_k, H = clip.source_height / downscale_k;
        for (auto& f : in.frames) f = downscale(f, downscale_k);
        for (auto& m : in.masks) m = resize_area(m, W, H);
        for (auto& c : in.sfm.cameras) c = c.resized(W, H);
      }
      in.source = "colmap:" + images;
#else
      std::fprintf(stderr, "bench_train_clip: built without the COLMAP adapter\n");
      return 2;
#endif
    } else {
      ThreadPool pool(threads);
      auto clip = synthetic::make_synthetic_clip<float>(so, &pool);
      in.sfm = clip.sfm_result();
      in.frames = std::move(clip.frames);
      in.masks = std::move(clip.masks);
      in.source = "synthetic";
    }
    // The rasterizer's tile size (the same images for each; gradients summed per tile: a speed knob
    // that changes the rounding).
    if (tile == 8) return run<8>(in, to, mo, threads, every, save, evaluate_at, state);
    if (tile == 16) return run<16>(in, to, mo, threads, every, save, evaluate_at, state);
    return run<32>(in, to, mo, threads, every, save, evaluate_at, state);
  } catch (const std::exception& ex) {
    std::fprintf(stderr, "bench_train_clip: %s\n", ex.what());
    return 1;
  }
}
