// End-to-end finite-difference check of one refinement step in double: the summed ensemble loss of a
// clip frame at frozen geometry against the gradients the refiner hands its optimiser (SH, opacity
// and the frame's alpha map), with and without a foreground set.
#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include <doctest/doctest.h>

#include "../tiny_clip.hpp"
#include "video3dgs/testing/grad_check.hpp"
#include "video3dgs/training/clip_trainer.hpp"
#include "video3dgs/refine/refine.hpp"

using namespace video3dgs;

namespace {

using test::TinyField;
using Model = test::TinyModel;

/// A 2-frame 32x24 synthetic clip trained briefly (deformation on, all SH bands), so that the
/// deformed geometry the refiner freezes differs from the canonical one.
Model trained_model(bool foreground) {
  auto clip = test::make_tiny_clip(foreground, false, 13);
  TrainOptions o;
  o.iterations = 4;
  o.deformation_warmup = 0;
  o.sh_degree_interval = 1;
  o.densify_from = 1000;
  o.lr_alpha = 0.3;
  o.seed = 3;
  ClipTrainer<Model> t(std::move(clip.model), std::move(clip.frames), o);
  t.train();
  return std::move(t.model());
}

/// Two "edits" of the clip: seeded noise around a colour shift of a flat grey, so the loss is far
/// from its minimum and every gradient entry is non-trivial.
std::vector<std::vector<Image<double, 3>>> edits(const Model& m) {
  std::vector<std::vector<Image<double, 3>>> t(2);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  for (auto& e : t)
    for (int i = 0; i < m.frame_count(); ++i) {
      Image<double, 3> img(m.width(), m.height());
      for (auto& v : img.storage()) v = 0.3 + 0.4 * u(rng);
      e.push_back(std::move(img));
    }
  return t;
}

void run_case(bool foreground) {
  Model m = trained_model(foreground);
  const auto targets = edits(m);
  RefineOptions o;
  o.train_alpha = true;
  o.weight_frg = 0.6;
  o.weight_bkg = 0.3;
  o.weight_merged = 1.2;
  ClipRefiner<double, 3, TinyField> r(m, targets, o);
  // Two steps first, so that SH rest bands and opacities have moved.
  (void)r.step(0, 0);
  (void)r.step(1, 1);
  for (int frame = 0; frame < 2; ++frame) {
    const double L0 = r.gradients_at(frame);
    REQUIRE(std::isfinite(L0));
    CHECK(r.loss_at(frame) == L0);
    // Every trained group, 30 entries each (the 6 largest analytic ones first); the alpha groups
    // share one gradient buffer, filled for `frame`.
    auto use = [&](const auto& g) { return g.name().rfind("alpha.", 0) != 0 || g.name() == "alpha." + std::to_string(frame); };
    const auto results = testing::check_optimizer_gradients(r.optimizer(), use, [&] { return r.loss_at(frame); }, {.rtol = 1e-5}, 30);
    std::vector<std::string> seen;
    for (const auto& res : results) {
      INFO("frame " << frame << ": " << res);
      CHECK(res.ok());
      CHECK(std::count_if(res.analytic.begin(), res.analytic.end(), [](double v) { return v != 0; }) > 0);
      seen.push_back(res.name);
    }
    std::vector<std::string> want = {"bkg.sh", "bkg.opacity"};
    if (foreground) {
      for (const char* w : {"frg.sh", "frg.opacity"}) want.push_back(w);
      want.push_back("alpha." + std::to_string(frame));
    }
    for (const auto& w : want) CHECK_MESSAGE(std::find(seen.begin(), seen.end(), w) != seen.end(), "group " << w << " not checked");
    CHECK(r.loss_at(frame) == L0);
  }
}

}  // namespace

TEST_CASE("ClipRefiner step gradient: end-to-end finite differences, foreground + background, ensemble of 2") { run_case(true); }

TEST_CASE("ClipRefiner step gradient: end-to-end finite differences, background only, ensemble of 2") { run_case(false); }
