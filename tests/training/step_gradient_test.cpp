// End-to-end finite-difference check of one training step in double: the loss of a clip frame
// (deform -> rasterize Frg and Bkg -> alpha merge -> three weighted L1 + D-SSIM losses) against the
// gradients the trainer hands its optimiser, sampled in every optimiser group, with and without a
// foreground set, with and without detail-weighted L1.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <doctest/doctest.h>

#include "../tiny_clip.hpp"
#include "video3dgs/testing/grad_check.hpp"
#include "video3dgs/training/clip_trainer.hpp"

using namespace video3dgs;

namespace {

using StepTrainer = ClipTrainer<test::TinyModel>;

struct Case {
  bool foreground = true;
  bool detail = false;
  /// The field's `grid_input_gradient`: with it, dL/dmean includes the path through the field's
  /// input x = (mu - lo) / (hi - lo), and the trainer's gradient is the loss's full derivative. The
  /// default (false, the reference's choice) stops that path on purpose: dL/dmean then differs from
  /// central differences, so the mean groups are left out of the check in that configuration.
  bool input_gradient = true;
  double crop = 0;  ///< TrainOptions::crop: the step on a window of the frame
  /// Camera refinement on (frame 1's camera groups checked; frame 0 has none). The SH degree stays 0:
  /// only there is the folded camera, which `loss_at` renders, exactly the graph's world move.
  bool cameras = false;
};

/// A 2-frame 32x24 synthetic clip, trained for a few iterations (deformation on from the start, all
/// SH bands active at iteration 3) so that every group's parameters and gradients are non-trivial.
std::unique_ptr<StepTrainer> make_trainer(const Case& c) {
  auto clip = test::make_tiny_clip(c.foreground, c.input_gradient, 11);
  TrainOptions o;
  o.iterations = 100;
  o.deformation_warmup = 0;
  o.sh_degree_interval = 1;
  o.densify_from = 1000;  // no densification: the groups keep their rows
  o.densify_until = 1000;
  o.opacity_reset_interval = 1000;
  // Unequal weights, so that a weight applied to the wrong term shows.
  o.weight_frg = 0.7;
  o.weight_bkg = 0.4;
  o.weight_merged = 1.3;
  o.detail_weighted_l1 = c.detail;
  o.lr_alpha = 0.3;  // alpha maps away from their constant start
  // The loss has jumps where a Gaussian's footprint cutoff crosses a pixel centre (~1e-6 in L); the
  // checker measures such entries at smaller steps or one-sidedly (testing/grad_check.hpp).
  o.seed = 5;
  o.crop = c.crop;
  if (c.cameras) o.lr_camera_rotation = o.lr_camera_translation = 1e-3, o.sh_degree_interval = 1000;
  auto t = std::make_unique<StepTrainer>(std::move(clip.model), std::move(clip.frames), o);
  for (int k = 0; k < 4; ++k) (void)t->step();
  return t;
}

/// Every group the step would update, sampled (24 entries: the 6 largest analytic ones, the rest
/// uniform), against central differences of `loss_at(frame)` (h = 1e-6, rtol 1e-5, atol 1e-9).
void run_case(const Case& c) {
  const auto trainer = make_trainer(c);
  StepTrainer& t = *trainer;
  // Expected groups: per set mean, log_scale, rotation, opacity, sh, deformation; one alpha per frame.
  std::vector<std::string> want;
  for (const char* set : {"frg.", "bkg."}) {
    if (!c.foreground && std::string(set) == "frg.") continue;
    for (const char* g : {"mean", "log_scale", "rotation", "opacity", "sh", "deformation"})
      if (c.input_gradient || std::string(g) != "mean") want.push_back(std::string(set) + g);
  }
  for (int frame = 0; frame < 2; ++frame) {
    const double L0 = t.gradients_at(frame);
    REQUIRE(std::isfinite(L0));
    CHECK(t.loss_at(frame) == L0);  // the forward alone gives the same loss
    auto use = [&](const auto& g) {
      const std::string& n = g.name();
      // All alpha groups share one gradient buffer, filled for the frame of the step.
      if (n.rfind("alpha.", 0) == 0) return n == "alpha." + std::to_string(frame);
      // So do the camera groups (rotation, translation).
      if (n.rfind("camera_", 0) == 0) return n.substr(n.find('.') + 1) == std::to_string(frame);
      return c.input_gradient || n.substr(4) != "mean";
    };
    const auto results = testing::check_optimizer_gradients(t.optimizer(), use, [&] { return t.loss_at(frame); }, {.rtol = 1e-5});
    CHECK(t.loss_at(frame) == L0);  // every perturbation was undone
    std::vector<std::string> seen;
    for (const auto& r : results) {
      INFO("frame " << frame << ": " << r);
      CHECK(r.ok());
      CHECK(std::count_if(r.analytic.begin(), r.analytic.end(), [](double v) { return v != 0; }) > 0);  // not trivially zero
      seen.push_back(r.name);
    }
    for (const auto& w : want) CHECK_MESSAGE(std::find(seen.begin(), seen.end(), w) != seen.end(), "group " << w << " not checked");
    if (c.foreground) CHECK(std::find(seen.begin(), seen.end(), "alpha." + std::to_string(frame)) != seen.end());
    for (const char* g : {"camera_rotation.", "camera_translation."})
      CHECK(std::count(seen.begin(), seen.end(), g + std::to_string(frame)) == (c.cameras && frame == 1 ? 1 : 0));
  }
}

}  // namespace

TEST_CASE("ClipTrainer step gradient: end-to-end finite differences, foreground + background") { run_case({true, false}); }

TEST_CASE("ClipTrainer step gradient: end-to-end finite differences, default field (input path stopped), means left out") {
  run_case({true, false, false});
}

TEST_CASE("ClipTrainer step gradient: end-to-end finite differences, foreground + detail-weighted L1") { run_case({true, true}); }

TEST_CASE("ClipTrainer step gradient: end-to-end finite differences, background only") { run_case({false, false}); }

TEST_CASE("ClipTrainer step gradient: end-to-end finite differences, background only + detail-weighted L1") {
  run_case({false, true});
}

TEST_CASE("ClipTrainer step gradient: end-to-end finite differences on a training crop, foreground + detail-weighted L1") {
  run_case({.foreground = true, .detail = true, .input_gradient = true, .crop = 0.6});
}

TEST_CASE("ClipTrainer step gradient: end-to-end finite differences with camera refinement, foreground + background") {
  run_case({.foreground = true, .cameras = true});
}

TEST_CASE("ClipTrainer step gradient: end-to-end finite differences with camera refinement, background only") {
  run_case({.foreground = false, .cameras = true});
}
