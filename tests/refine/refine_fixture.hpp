#pragma once
// Shared by the tests of tests/refine: a 9-frame 64x48 synthetic video reconstructed as two
// overlapping clips (stage 1, 200 iterations each), with its source flows.
#include <chrono>
#include <cstdint>
#include <span>
#include <vector>

#include <doctest/doctest.h>

#include "video3dgs/metrics/psnr.hpp"
#include "video3dgs/metrics/warp_ssim.hpp"
#include "video3dgs/synthetic/clip.hpp"
#include "video3dgs/training/clip_trainer.hpp"
#include "video3dgs/refine/refine.hpp"

namespace video3dgs::test {

/// Mean PSNR (dB) of the frames of `a` against those of `b`.
inline double mean_psnr(const std::vector<Image<float, 3>>& a, const std::vector<Image<float, 3>>& b) {
  double s = 0;
  for (std::size_t i = 0; i < a.size(); ++i) s += metrics::psnr<float, 3>(a[i], b[i]);
  return s / double(a.size());
}

using SmallField = DeformationField<float, HashGrid4D<float, 12>>;
using Clip = ClipModel<float, 3, SmallField>;
using Video = VideoModel<float, 3, SmallField>;

struct RefineFixture {
  synthetic::SyntheticClip<float> clip;
  Video model;
  metrics::VideoFlows flows;
};

/// The video (generator seed `seed`) reconstructed as clips `a` and `b`.
inline RefineFixture make_refine_fixture(FrameRange a, FrameRange b, std::uint64_t seed) {
  const auto t0 = std::chrono::steady_clock::now();
  ThreadPool pool(2);
  RefineFixture f;
  synthetic::SyntheticClipOptions so;
  so.frames = 9;
  so.width = 64;
  so.height = 48;
  so.object_gaussians = 600;
  so.background_gaussians = 1500;
  so.foreground_points = 250;
  so.seed = seed;
  f.clip = synthetic::make_synthetic_clip<float>(so, &pool);
  f.model.frame_count = 9;
  f.model.width = 64;
  f.model.height = 48;
  for (FrameRange r : {a, b}) {
    ClipModelOptions mo;
    mo.background.points_per_shell = 800;
    const std::span<const Camera<float>> cams(f.clip.cameras.data() + r.first, std::size_t(r.size()));
    const std::span<const Image<float, 1>> masks(f.clip.masks.data() + r.first, std::size_t(r.size()));
    Clip m = make_clip_model<float, 3, SmallField, double>(r, cams, std::span<const SfmPoint<double>>(f.clip.points), mo, masks, &pool);
    std::vector<Image<float, 3>> frames(f.clip.frames.begin() + r.first, f.clip.frames.begin() + r.last + 1);
    TrainOptions o;
    o.iterations = 200;
    o.deformation_warmup = 80;
    o.sh_degree_interval = 80;
    o.densify_from = 50;
    o.densify_until = 150;
    o.densify_interval = 50;
    o.lr_alpha = 0.2;
    o.seed = 5;
    ClipTrainer<Clip> tr(std::move(m), std::move(frames), o, &pool);
    tr.train();
    MESSAGE("stage-1 clip [" << r.first << "," << r.last << "] psnr " << tr.evaluate().psnr);
    f.model.clips.push_back(std::move(tr.model()));
  }
  f.flows = metrics::estimate_video_flows(f.clip.frames, {}, &pool);
  MESSAGE("fixture " << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() << " s");
  return f;
}

}  // namespace video3dgs::test
