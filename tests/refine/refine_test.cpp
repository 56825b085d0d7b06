// Tests of include/video3dgs/refine/refine.hpp and editor.hpp on a synthetic two-clip video:
// frozen parameters stay bit-identical, the flickering test editor's edit becomes more consistent
// (WarpSSIM up) and closer to the clean style (PSNR up), ensembles and recursive phases run, the
// command editor runs an external program without a shell, and bad inputs give clear errors.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <span>
#include <vector>

#include <doctest/doctest.h>

#include "refine_fixture.hpp"

#include "video3dgs/metrics/psnr.hpp"
#include "video3dgs/metrics/warp_ssim.hpp"
#include "video3dgs/synthetic/clip.hpp"
#include "video3dgs/training/clip_trainer.hpp"
#include "video3dgs/refine/editor.hpp"
#include "video3dgs/refine/refine.hpp"

using namespace video3dgs;

namespace {

using test::Clip;
using test::SmallField;
using test::Video;
using Fixture = test::RefineFixture;

/// A 9-frame 64x48 synthetic video reconstructed as two clips [0, 4] and [4, 8] (shared frame 4).
const Fixture& fixture() {
  static const Fixture fx = test::make_refine_fixture(FrameRange{0, 4}, FrameRange{4, 8}, 1);
  return fx;
}

RefineOptions quick(int iterations) {
  RefineOptions o;
  o.iterations = iterations;
  o.seed = 11;
  return o;
}

std::vector<Image<float, 3>> styled(const FlickerEditor& ed, const std::vector<Image<float, 3>>& frames) {
  std::vector<Image<float, 3>> out;
  for (const auto& f : frames) out.push_back(ed.style(f));
  return out;
}

template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0;
}

}  // namespace

TEST_CASE("refine_video: frozen parameters are bit-identical; SH and opacity change") {
  const Fixture& fx = fixture();
  ThreadPool pool(2);
  FlickerEditor ed;
  const auto edited = ed.edit(fx.clip.frames, {});
  RefineStats st;
  Video refined = refine_video(fx.model, {edited}, quick(40), &pool, &st);
  REQUIRE(refined.clips.size() == 2);
  REQUIRE(st.clips.size() == 2);
  for (std::size_t c = 0; c < 2; ++c) {
    const Clip& a = fx.model.clips[c];
    Clip& b = refined.clips[c];
    CHECK(st.clips[c].iterations == 40);
    CHECK(st.clips[c].skipped_steps == 0);
    CHECK(st.clips[c].last_loss < st.clips[c].first_loss);
    for (GaussianSet s : {GaussianSet::foreground, GaussianSet::background}) {
      CHECK(same_bits(a.cloud(s).mean, b.cloud(s).mean));
      CHECK(same_bits(a.cloud(s).log_scale, b.cloud(s).log_scale));
      CHECK(same_bits(a.cloud(s).rotation, b.cloud(s).rotation));
      CHECK_FALSE(same_bits(a.cloud(s).sh, b.cloud(s).sh));
      CHECK_FALSE(same_bits(a.cloud(s).opacity_logit, b.cloud(s).opacity_logit));
      auto sa = const_cast<Clip&>(a).field(s).segments();
      auto sb = b.field(s).segments();
      REQUIRE(sa.size() == sb.size());
      for (std::size_t k = 0; k < sa.size(); ++k)
        CHECK(std::memcmp(sa[k].value.data(), sb[k].value.data(), sa[k].value.size_bytes()) == 0);
    }
    for (std::size_t i = 0; i < a.alpha_logit.size(); ++i) CHECK(same_bits(a.alpha_logit[i].storage(), b.alpha_logit[i].storage()));
    CHECK(a.deformation_enabled == b.deformation_enabled);
  }
  // train_alpha moves the alpha maps but still not the geometry
  RefineOptions oa = quick(10);
  oa.train_alpha = true;
  oa.train_sh = false;
  oa.train_opacity = false;
  Video ra = refine_video(fx.model, {edited}, oa, &pool);
  CHECK(same_bits(fx.model.clips[0].frg.sh, ra.clips[0].frg.sh));
  CHECK_FALSE(same_bits(fx.model.clips[0].alpha_logit[0].storage(), ra.clips[0].alpha_logit[0].storage()));
}

TEST_CASE("refine_video: the whole refined model is byte-identical with no pool and with 3 threads") {
  const Fixture& fx = fixture();
  FlickerEditor ed;
  const auto edited = ed.edit(fx.clip.frames, {});
  RefineOptions o = quick(30);
  o.train_alpha = true;  // every trained group: SH, opacity and the alpha maps
  ThreadPool pool(3);
  const Video serial = refine_video(fx.model, {edited}, o, nullptr);
  const Video threaded = refine_video(fx.model, {edited}, o, &pool);
  REQUIRE(serial.clips.size() == threaded.clips.size());
  for (std::size_t c = 0; c < serial.clips.size(); ++c) {
    // The clip's binary record: clouds, fields, alpha maps, cameras, range.
    io::BinaryWriter a(kClipModelMagic, kClipModelVersion), b(kClipModelMagic, kClipModelVersion);
    write_clip_model(a, const_cast<Clip&>(serial.clips[c]));
    write_clip_model(b, const_cast<Clip&>(threaded.clips[c]));
    INFO("clip " << c);
    CHECK(a.bytes().size() == b.bytes().size());
    CHECK((a.bytes() == b.bytes()));
    // ... and refinement changed it (the comparison is not of two copies of the source).
    io::BinaryWriter src(kClipModelMagic, kClipModelVersion);
    write_clip_model(src, const_cast<Clip&>(fx.model.clips[c]));
    CHECK_FALSE((src.bytes() == a.bytes()));
  }
}

TEST_CASE("refine_video: a flickering edit becomes consistent (WarpSSIM up) and closer to the clean style") {
  const Fixture& fx = fixture();
  ThreadPool pool(2);
  FlickerEditor ed;
  const auto edited = ed.edit(fx.clip.frames, {});
  const auto style = styled(ed, fx.clip.frames);
  const Video refined = refine_video(fx.model, {edited}, quick(120), &pool);
  const auto frames = render_video(refined, &pool);
  const double w_edit = metrics::warp_ssim(edited, fx.flows).value;
  const double w_ref = metrics::warp_ssim(frames, fx.flows).value;
  const double w_style = metrics::warp_ssim(style, fx.flows).value;
  const double p_edit = test::mean_psnr(edited, style), p_ref = test::mean_psnr(frames, style);
  const double p_ref_edit = test::mean_psnr(frames, edited);
  std::printf("{\"refine_synthetic\":1,\"warp_ssim_edited\":%.4f,\"warp_ssim_refined\":%.4f,\"warp_ssim_style\":%.4f,"
              "\"psnr_edited_vs_style\":%.2f,\"psnr_refined_vs_style\":%.2f,\"psnr_refined_vs_edited\":%.2f}\n",
              w_edit, w_ref, w_style, p_edit, p_ref, p_ref_edit);
  // Measured (2026-11-23): WarpSSIM 0.9409 -> 0.9890 (+0.048), PSNR vs style 22.51 -> 30.50 dB (+7.99).
  // Floors 12-17 % under the gains.
  CHECK(w_ref > w_edit + 0.04);
  CHECK(p_ref > p_edit + 7.0);
  CHECK(p_ref > 27.0);
}

TEST_CASE("refine_video: ensembles sum the loss over several edits") {
  const Fixture& fx = fixture();
  ThreadPool pool(2);
  std::vector<std::vector<Image<float, 3>>> edits;
  FlickerEditor ed;
  for (std::uint64_t s : {1u, 2u, 3u}) {
    ed.seed = s;
    edits.push_back(ed.edit(fx.clip.frames, {}));
  }
  const auto style = styled(ed, fx.clip.frames);
  RefineStats st;
  const Video ens = refine_video(fx.model, edits, quick(100), &pool, &st);
  const Video one = refine_video(fx.model, {edits[0]}, quick(100), &pool);
  const double p_ens = test::mean_psnr(render_video(ens, &pool), style), p_one = test::mean_psnr(render_video(one, &pool), style);
  std::printf("{\"refine_ensemble\":3,\"psnr_vs_style_ensemble\":%.2f,\"psnr_vs_style_single\":%.2f}\n", p_ens, p_one);
  // three independent flickers average out: the ensemble is closer to the clean style
  CHECK(p_ens > p_one + 5.0);  // measured 36.17 vs 30.32 dB (+5.85, 2026-11-23); floor ~15 % under
  CHECK(st.clips[0].first_loss > 0);
}

TEST_CASE("refine_recursive: N_r = 2 phases with the flickering editor") {
  const Fixture& fx = fixture();
  ThreadPool pool(2);
  FlickerEditor ed;
  RecursiveRefineOptions ro;
  ro.refine = quick(60);
  const auto r = refine_recursive(fx.model, fx.clip.frames, ed, ro, &pool);
  REQUIRE(r.edited.size() == 2);
  REQUIRE(r.refined.size() == 2);
  REQUIRE(r.stats.size() == 2);
  CHECK(r.refined[1].size() == 9);
  // phase 1 edits the refined video: its editor output differs from phase 0's
  CHECK(r.edited[0][3].storage() != r.edited[1][3].storage());
  const double w0 = metrics::warp_ssim(r.edited[0], fx.flows).value;
  const double w2 = metrics::warp_ssim(r.refined[1], fx.flows).value;
  std::printf("{\"refine_recursive\":2,\"warp_ssim_edited_phase0\":%.4f,\"warp_ssim_refined_phase1\":%.4f}\n", w0, w2);
  CHECK(w2 > w0 + 0.037);  // measured 0.9409 -> 0.9856 (+0.0447, 2026-11-23); floor ~17 % under
}

TEST_CASE("refine: option and input errors") {
  const Fixture& fx = fixture();
  FlickerEditor ed;
  const auto edited = ed.edit(fx.clip.frames, {});
  auto id_of = [](auto&& f) {
    try {
      f();
    } catch (const error& e) {
      return e.id();
    }
    return std::string("none");
  };
  RefineOptions none = quick(1);
  none.train_sh = none.train_opacity = none.train_alpha = false;
  CHECK(id_of([&] { (void)refine_video(fx.model, {edited}, none); }) == "option.refine");
  RefineOptions neg = quick(1);
  neg.lr_sh_dc = -1;
  CHECK(id_of([&] { (void)refine_video(fx.model, {edited}, neg); }) == "option.refine");
  std::vector<Image<float, 3>> short_edit(edited.begin(), edited.begin() + 5);
  CHECK(id_of([&] { (void)refine_video(fx.model, {short_edit}, quick(1)); }) == "option.refine");
  CHECK(id_of([&] { (void)refine_video(fx.model, {}, quick(1)); }) == "option.refine");
  auto wrong_size = edited;
  wrong_size[2] = Image<float, 3>(10, 10);
  CHECK(id_of([&] { (void)refine_video(fx.model, {wrong_size}, quick(1)); }) == "option.refine");
  RecursiveRefineOptions r0;
  r0.phases = 0;
  CHECK(id_of([&] { (void)refine_recursive(fx.model, fx.clip.frames, ed, r0); }) == "option.refine");
  // a zero-iteration refinement is a plain copy
  const Video copy = refine_video(fx.model, {edited}, quick(0));
  CHECK(same_bits(copy.clips[0].frg.sh, fx.model.clips[0].frg.sh));
  // a non-finite target is skipped, never reaches a parameter
  auto nan_edit = edited;
  for (auto& f : nan_edit) f(3, 3, 0) = std::nanf("");
  RefineStats st;
  const Video guarded = refine_video(fx.model, {nan_edit}, quick(5), nullptr, &st);
  CHECK(st.clips[0].skipped_steps == 5);
  CHECK(same_bits(guarded.clips[0].frg.sh, fx.model.clips[0].frg.sh));
}
