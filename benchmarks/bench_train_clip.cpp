// Stage-1 training of one clip (ClipTrainer) on the synthetic clip (synthetic/clip.hpp): prints JSON
// lines — one "progress" line every --every iterations, then one "stages" line with the median
// per-iteration time of each stage (deformation, rasterize forward/backward, loss, optimizer,
// densify; medians over the iterations of each phase: before/after the deformation warm-up), and one
// "result" line with the Gaussian counts, the final PSNR/SSIM over the clip's frames (merged, Frg-only,
// Bkg-only), the model size in bytes and the wall time.
//
// Usage: bench_train_clip [--iterations N] [--frames N] [--width W] [--height H] [--threads T]
//          [--seed S] [--shell-points N] [--warmup N] [--densify-from N] [--densify-until N]
//          [--sh-interval N] [--every N] [--object N] [--background N]
// (A real clip from a frame folder + COLMAP sparse model needs the COLMAP adapter's SfmResult reader;
// this program takes the synthetic clip only.)
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "video3dgs/core/parallel.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/model/clip_model_io.hpp"
#include "video3dgs/synthetic/clip.hpp"
#include "video3dgs/training/clip_trainer.hpp"

using namespace video3dgs;

namespace {

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
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
  int every = 100;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    const long v = std::strtol(argv[i + 1], nullptr, 10);
    const double x = std::strtod(argv[i + 1], nullptr);
    if (a == "--iterations") to.iterations = int(v);
    else if (a == "--frames") so.frames = int(v);
    else if (a == "--width") so.width = int(v);
    else if (a == "--height") so.height = int(v);
    else if (a == "--threads") threads = unsigned(v);
    else if (a == "--seed") to.seed = std::uint64_t(v), so.seed = std::uint64_t(v);
    else if (a == "--shell-points") mo.background.points_per_shell = std::size_t(v);
    else if (a == "--warmup") to.deformation_warmup = int(v);
    else if (a == "--densify-from") to.densify_from = int(v);
    else if (a == "--densify-until") to.densify_until = int(v);
    else if (a == "--sh-interval") to.sh_degree_interval = int(v);
    else if (a == "--every") every = std::max(1, int(v));
    else if (a == "--object") so.object_gaussians = int(v);
    else if (a == "--background") so.background_gaussians = int(v);
    else if (a == "--motion") so.motion = x;
    else if (a == "--points") so.foreground_points = int(v);
    else if (a == "--spin") so.spin_degrees = x;
    else if (a == "--lr-alpha") to.lr_alpha = x;
    else if (a == "--lr-deformation") to.lr_deformation_init = x;
    else if (a == "--weight-frg") to.weight_frg = x;
    else if (a == "--weight-bkg") to.weight_bkg = x;
    else if (a == "--detail") to.detail_weighted_l1 = v != 0;
    else {
      std::fprintf(stderr, "unknown option %s\n", a.c_str());
      return 2;
    }
  }
  try {
    ThreadPool pool(threads);
    ThreadPool* p = threads > 1 ? &pool : nullptr;
    const auto clip = synthetic::make_synthetic_clip<float>(so, p);
    auto model = make_clip_model<float>(clip.sfm_result(), mo, std::span<const Image<float, 1>>(clip.masks), p);
    const std::size_t frg0 = model.frg.size(), bkg0 = model.bkg.size();
    ClipTrainer<ClipModel<float>> trainer(std::move(model), clip.frames, to, p);
    std::vector<double> st[2][7];  // [phase][stage] ms
    const auto t0 = std::chrono::steady_clock::now();
    trainer.train([&](const IterationInfo& it) {
      const int ph = it.iteration < to.deformation_warmup ? 0 : 1;
      const auto& t = it.times;
      const double v[7] = {t.deformation, t.raster_forward, t.raster_backward, t.loss, t.optimizer, t.densify, t.total};
      for (int k = 0; k < 7; ++k)
        if (k != 5 || it.densified) st[ph][k].push_back(1e3 * v[k]);
      if ((it.iteration + 1) % every == 0)
        std::printf("{\"bench\":\"train_clip\",\"kind\":\"progress\",\"iteration\":%d,\"loss\":%.5f,\"psnr\":%.3f,\"frg\":%zu,\"bkg\":%zu}\n",
                    it.iteration + 1, it.loss, it.psnr, it.frg_count, it.bkg_count);
      return true;
    });
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const char* names[2] = {"warmup", "deformed"};
    for (int ph = 0; ph < 2; ++ph) {
      if (st[ph][6].empty()) continue;
      std::printf("{\"bench\":\"train_clip\",\"kind\":\"stages\",\"phase\":\"%s\",\"iterations\":%zu,\"threads\":%u,"
                  "\"median_ms\":{\"deformation\":%.3f,\"raster_forward\":%.3f,\"raster_backward\":%.3f,\"loss\":%.3f,"
                  "\"optimizer\":%.3f,\"densify_per_event\":%.3f,\"total\":%.3f}}\n",
                  names[ph], st[ph][6].size(), threads, median(st[ph][0]), median(st[ph][1]), median(st[ph][2]),
                  median(st[ph][3]), median(st[ph][4]), median(st[ph][5]), median(st[ph][6]));
    }
    const auto e = trainer.evaluate();
    io::BinaryWriter w(kClipModelMagic, kClipModelVersion);
    write_clip_model(w, trainer.model());
    const auto& s = trainer.stats();
    std::printf("{\"bench\":\"train_clip\",\"kind\":\"result\",\"frames\":%d,\"width\":%d,\"height\":%d,\"iterations\":%d,"
                "\"threads\":%u,\"frg_init\":%zu,\"bkg_init\":%zu,\"frg\":%zu,\"bkg\":%zu,\"cloned\":%zu,\"split\":%zu,"
                "\"pruned\":%zu,\"skipped_steps\":%zu,\"psnr\":%.3f,\"ssim\":%.4f,\"psnr_frg\":%.3f,\"psnr_bkg\":%.3f,"
                "\"model_bytes\":%zu,\"wall_s\":%.2f,\"sum_s\":{\"deformation\":%.2f,\"raster_forward\":%.2f,"
                "\"raster_backward\":%.2f,\"loss\":%.2f,\"optimizer\":%.2f,\"densify\":%.2f}}\n",
                so.frames, so.width, so.height, s.iterations, threads, frg0, bkg0, trainer.model().frg.size(),
                trainer.model().bkg.size(), s.cloned, s.split, s.pruned, s.skipped_steps, e.psnr, e.ssim, e.psnr_frg,
                e.psnr_bkg, w.bytes().size(), wall, s.times.deformation, s.times.raster_forward, s.times.raster_backward,
                s.times.loss, s.times.optimizer, s.times.densify);
  } catch (const std::exception& ex) {
    std::fprintf(stderr, "bench_train_clip: %s\n", ex.what());
    return 1;
  }
  return 0;
}
