// ClipGraph (graph/clip_graph.hpp) on its own: every kind of tape node (deformation, rasterization,
// alpha merge, loss, weighted sum) checked against central differences in double, each isolated by
// the loss weights and the gradient sinks, then the whole graph with an ensemble of targets and a
// detail weight; the render-only forward; frozen geometry; a non-finite image gradient.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include <doctest/doctest.h>

#include "../tiny_clip.hpp"
#include "video3dgs/autodiff/param_segment.hpp"
#include "video3dgs/core/resample.hpp"
#include "video3dgs/graph/clip_graph.hpp"
#include "video3dgs/testing/grad_check.hpp"

using namespace video3dgs;

namespace {

using Graph = ClipGraph<double, 3, test::TinyField>;
using Context = ClipGraphContext<double, test::TinyField>;

/// Named (value, gradient) buffers in the shape `testing::check_optimizer_gradients` reads.
struct Group {
  std::string n;
  std::vector<ParamSegment<double>> segs;
  [[nodiscard]] const std::string& name() const { return n; }
  [[nodiscard]] const std::vector<ParamSegment<double>>& segments() const { return segs; }
};
struct Groups {
  std::vector<Group> list;
  [[nodiscard]] const std::vector<Group>& groups() const { return list; }
};

/// Which parameters receive gradients.
struct Sinks {
  bool geometry = false, appearance = false, field = false, alpha = false;
  bool frg = true, bkg = true;  ///< which sets
  bool bkg_field = true;        ///< with `field`: the background's field too
};

/// Gradient buffers of a model and the groups that pair them with the parameters.
struct Buffers {
  std::vector<double> frg[5], bkg[5], alpha;
  ClipGradients<double, test::TinyField> grads;
  Groups groups;

  Buffers(test::TinyModel& m, int frame, const Sinks& s) {
    for (GaussianSet set : {GaussianSet::foreground, GaussianSet::background}) {
      const bool f = set == GaussianSet::foreground;
      if ((f && !m.has_foreground) || !(f ? s.frg : s.bkg)) continue;
      auto& c = m.cloud(set);
      std::vector<double>* b = f ? frg : bkg;
      GaussianGrads<double>& g = f ? grads.frg : grads.bkg;
      std::vector<double>* values[5] = {&c.mean, &c.log_scale, &c.rotation, &c.opacity_logit, &c.sh};
      const char* names[5] = {"mean", "log_scale", "rotation", "opacity", "sh"};
      std::span<double>* spans[5] = {&g.dL_dmean, &g.dL_dlog_scale, &g.dL_drotation, &g.dL_dopacity_logit, &g.dL_dsh};
      for (int k = 0; k < 5; ++k) {
        if (k < 3 ? !s.geometry : !s.appearance) continue;
        b[k].assign(values[k]->size(), 0.0);
        *spans[k] = b[k];
        groups.list.push_back({std::string(to_string(set)) + "." + names[k], {{*values[k], b[k]}}});
      }
      if (s.field && (f || s.bkg_field)) {
        (f ? grads.frg_field : grads.bkg_field) = &m.field(set);
        groups.list.push_back({std::string(to_string(set)) + ".deformation", m.field(set).segments()});
      }
    }
    if (s.alpha && m.has_foreground) {
      alpha.assign(m.alpha_logit[std::size_t(frame)].size(), 0.0);
      grads.alpha = alpha;
      groups.list.push_back({"alpha", {{m.alpha_logit[std::size_t(frame)].storage(), alpha}}});
    }
  }
};

/// A tiny clip whose alpha maps, SH, scales and rotations are not at their uniform start (so every path carries a
/// non-trivial gradient), deformation on.
test::TinyClip make_clip(bool foreground, std::uint64_t seed = 21) {
  auto c = test::make_tiny_clip(foreground, true, seed);
  std::uint64_t state = seed;
  auto u = [&state] {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return double(state >> 11) * 0x1.0p-53 - 0.5;
  };
  for (auto& a : c.model.alpha_logit)
    for (std::size_t i = 0; i < a.size(); ++i) a.data()[i] += 2 * u();
  for (auto* cl : {&c.model.frg, &c.model.bkg}) {
    for (double& v : cl->sh) v += 0.1 * u();
    for (double& v : cl->log_scale) v += 0.3 * u();  // anisotropic and turned: rotations matter
    for (double& v : cl->rotation) v += 0.2 * u();
  }
  c.model.deformation_enabled = true;
  return c;
}

/// FD check of every group of `sinks` for the graph's loss of `frame` against `targets`.
void check(test::TinyModel& m, Graph& graph, std::span<const ConstImageView<double, 3>> targets, const Sinks& sinks,
           ConstImageView<double, 1> detail = {}, const char* what = "", PixelWindow window = {}) {
  Context ctx;
  const int frame = 1;
  Buffers b(m, frame, sinks);
  const double L0 = graph.forward(m, frame, targets, ctx, b.grads, detail, nullptr, window).total;
  REQUIRE(std::isfinite(L0));
  REQUIRE(graph.backward(ctx));
  Context fd;
  auto loss = [&] { return graph.forward(m, frame, targets, fd, {}, detail, nullptr, window).total; };
  CHECK(loss() == L0);
  const auto results = testing::check_optimizer_gradients(b.groups, [](const Group&) { return true; }, loss, {.rtol = 1e-5});
  CHECK(loss() == L0);
  REQUIRE(!results.empty());
  for (const auto& r : results) {
    INFO(what << ": " << r);
    CHECK(r.ok());
    CHECK(std::count_if(r.analytic.begin(), r.analytic.end(), [](double v) { return v != 0; }) > 0);
  }
}

/// Every gradient a backward left in `b`'s sinks (the fields' included) and both sets' dL/dmean2d.
std::vector<std::vector<double>> gradients_of(const Buffers& b, const Context& ctx) {
  std::vector<std::vector<double>> out;
  for (const Group& g : b.groups.list)
    for (const auto& seg : g.segs) out.emplace_back(seg.grad.begin(), seg.grad.end());
  out.push_back(ctx.frg_mean2d);
  out.push_back(ctx.bkg_mean2d);
  return out;
}

}  // namespace

TEST_CASE("ClipGraph nodes: deformation + rasterization + one set loss (foreground term only)") {
  auto c = make_clip(true);
  Graph g;
  g.weights = {1.0, 0.0, 0.0};
  const ConstImageView<double, 3> t(c.frames[1]);
  check(c.model, g, {&t, 1}, {.geometry = true, .appearance = true, .field = true, .bkg = false}, {}, "frg term");
}

TEST_CASE("ClipGraph nodes: alpha merge + merged loss (merged term only, canonical sets)") {
  auto c = make_clip(true);
  c.model.deformation_enabled = false;
  Graph g;
  g.weights = {0.0, 0.0, 1.0};
  const ConstImageView<double, 3> t(c.frames[1]);
  check(c.model, g, {&t, 1}, {.geometry = true, .appearance = true, .alpha = true}, {}, "merged term");
}

TEST_CASE("ClipGraph: the whole graph, an ensemble of two targets and a detail weight") {
  auto c = make_clip(true);
  Graph g;
  g.weights = {0.7, 0.4, 1.3, 0.3};
  Image<double, 3> edit = c.frames[1];
  for (std::size_t i = 0; i < edit.size(); ++i) edit.data()[i] = 0.8 * edit.data()[i] + (i % 3 == 0 ? 0.15 : 0.0);
  Image<double, 1> w(edit.width(), edit.height());
  for (int y = 0; y < w.height(); ++y)
    for (int x = 0; x < w.width(); ++x) w.pixel(x, y)[0] = 1.0 + double((x * 7 + y * 3) % 5) / 4;
  const ConstImageView<double, 3> t[2] = {ConstImageView<double, 3>(c.frames[1]), ConstImageView<double, 3>(edit)};
  check(c.model, g, t, {.geometry = true, .appearance = true, .field = true, .alpha = true}, w, "ensemble");
}

TEST_CASE("ClipGraph: the targets' shared SSIM statistics change no bit of the losses or gradients (ensembles, background only, sizes, threads)") {
  struct Case {
    bool fg;
    ClipLossWeights w;
    bool detail;
    std::size_t targets;
    bool smaller;  ///< targets at 21 x 17 instead of the model's 32 x 24
    bool shares;   ///< two or more terms per target
    const char* what;
  };
  const Case cases[] = {
      {true, {0.7, 0.4, 1.3, 0.3}, true, 2, false, true, "three terms, two targets, detail"},
      {true, {0.0, 0.4, 1.3, 0.2}, false, 1, true, true, "bkg + merged, smaller targets"},
      {false, {0.7, 0.4, 1.3, 0.2}, true, 2, false, true, "background only, detail: two nodes"},
      {false, {0.7, 0.4, 1.3, 0.2}, false, 1, false, false, "background only: one node"},
      {true, {1.0, 0.0, 0.0, 0.2}, false, 1, false, false, "frg term only"},
  };
  ThreadPool two(2);
  for (const Case& k : cases) {
    INFO(k.what);
    auto c = make_clip(k.fg);
    Graph shared;
    shared.weights = k.w;
    Graph separate = shared;
    separate.share_target_statistics = false;
    const int w = k.smaller ? 21 : 32, h = k.smaller ? 17 : 24;
    std::vector<Image<double, 3>> images = {resize_area(c.frames[1], w, h), resize_area(c.frames[0], w, h)};
    for (std::size_t i = 0; i < images[1].size(); ++i) images[1].data()[i] = 0.8 * images[1].data()[i] + (i % 3 == 0 ? 0.15 : 0.0);
    const std::vector<ConstImageView<double, 3>> t(images.begin(), images.begin() + std::ptrdiff_t(k.targets));
    Image<double, 1> detail;
    if (k.detail) {
      detail.resize(w, h);
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) detail.pixel(x, y)[0] = 1.0 + double((x * 7 + y * 3) % 5) / 4;
    }
    Buffers b(c.model, 1, {.geometry = true, .appearance = true, .field = true, .alpha = true});
    std::vector<std::vector<double>> first;
    double first_total = 0;
    for (ThreadPool* pool : {static_cast<ThreadPool*>(nullptr), &two}) {
      INFO("pool " << (pool != nullptr));
      Context cs, cp;
      const ClipLosses Ls = shared.forward(c.model, 1, t, cs, b.grads, detail, pool);
      REQUIRE(shared.backward(cs, pool));
      const auto gs = gradients_of(b, cs);
      const ClipLosses Lp = separate.forward(c.model, 1, t, cp, b.grads, detail, pool);
      REQUIRE(separate.backward(cp, pool));
      const auto gp = gradients_of(b, cp);
      CHECK(cs.ssim_target.size() == (k.shares ? t.size() : 0));
      CHECK(cp.ssim_target.empty());
      CHECK(Ls.total == Lp.total);
      CHECK(Ls.frg == Lp.frg);
      CHECK(Ls.bkg == Lp.bkg);
      CHECK(Ls.merged == Lp.merged);
      CHECK(gs == gp);
      std::size_t nonzero = 0;
      for (const auto& v : gs) nonzero += std::size_t(std::count_if(v.begin(), v.end(), [](double x) { return x != 0; }));
      CHECK(nonzero > 100);
      if (!pool) first = gs, first_total = Ls.total;
      CHECK(Ls.total == first_total);  // and for any thread count
      CHECK(gs == first);
    }
  }
}

TEST_CASE("ClipGraph: a target changed in place, or resized, between forwards of one context gives a fresh context's losses and gradients") {
  // The targets' statistics are filled by every forward: nothing stale survives in the context.
  auto c = make_clip(true);
  Graph g;
  g.weights = {0.7, 0.4, 1.3};
  Image<double, 3> target = c.frames[1];
  Buffers b(c.model, 1, {.appearance = true, .alpha = true});
  Context ctx;
  double previous = 0;
  for (int step = 0; step < 3; ++step) {
    INFO("step " << step);
    if (step == 1)
      for (auto& v : target.storage()) v = 0.8 * v + 0.1;  // new pixels in the same buffer
    if (step == 2) target = resize_area(target, 21, 17);    // a smaller stage of a resolution schedule
    const ConstImageView<double, 3> t(target);
    const ClipLosses L = g.forward(c.model, 1, {&t, 1}, ctx, b.grads);
    REQUIRE(g.backward(ctx));
    const auto grads = gradients_of(b, ctx);
    Context fresh;
    const ClipLosses F = g.forward(c.model, 1, {&t, 1}, fresh, b.grads);
    REQUIRE(g.backward(fresh));
    CHECK(L.total == F.total);
    CHECK(L.frg == F.frg);
    CHECK(L.bkg == F.bkg);
    CHECK(L.merged == F.merged);
    CHECK(grads == gradients_of(b, fresh));
    CHECK(L.total != previous);
    previous = L.total;
  }
}

TEST_CASE("ClipGraph: a D-SSIM weight changed between passes takes effect in a context that has run before") {
  // The trainer changes lambda at the fine phase's first iteration (TrainOptions::lambda_dssim_at) and
  // keeps its context: the loss must be the new lambda's, as a fresh context computes it.
  auto c = make_clip(true);
  Graph g;
  const ConstImageView<double, 3> t(c.frames[1]);
  Context ctx;
  const double at02 = g.forward(c.model, 1, {&t, 1}, ctx).total;
  g.weights.lambda_dssim = 0.6;
  const double at06 = g.forward(c.model, 1, {&t, 1}, ctx).total;
  Context fresh;
  CHECK(at06 == g.forward(c.model, 1, {&t, 1}, fresh).total);
  CHECK(at06 != at02);
  // Each term is (1 - lambda) L1 + lambda D-SSIM, so the total is affine in lambda.
  g.weights.lambda_dssim = 1.0;
  const double at10 = g.forward(c.model, 1, {&t, 1}, ctx).total;
  CHECK(at06 == doctest::Approx(at02 + (at10 - at02) * (0.6 - 0.2) / 0.8).epsilon(1e-12));
}

TEST_CASE("ClipGraph: background only, with and without a detail weight (one shared loss node without)") {
  auto c = make_clip(false);
  Graph g;
  g.weights = {0.7, 0.4, 1.3};
  const ConstImageView<double, 3> t(c.frames[1]);
  check(c.model, g, {&t, 1}, {.geometry = true, .appearance = true, .field = true}, {}, "bkg only");
  Context ctx;
  (void)g.forward(c.model, 1, {&t, 1}, ctx);
  const std::size_t steps_shared = ctx.tape.step_count();
  Image<double, 1> w(t.width(), t.height(), 1.5);
  check(c.model, g, {&t, 1}, {.appearance = true}, w, "bkg only, detail");
  Buffers b(c.model, 1, {.appearance = true});
  (void)g.forward(c.model, 1, {&t, 1}, ctx, b.grads, w);
  CHECK(ctx.tape.step_count() > 0);
  // Without W the two terms are one node: the losses agree and the total is (w_b + w_m) l.
  const ClipLosses L = g.forward(c.model, 1, {&t, 1}, ctx);
  CHECK(L.bkg == L.merged);
  CHECK(L.total == doctest::Approx(1.7 * L.bkg).epsilon(1e-12));
  (void)steps_shared;
}

TEST_CASE("ClipGraph: frozen geometry gives the same renders and the appearance gradients") {
  auto c = make_clip(true);
  Graph g;
  const ConstImageView<double, 3> t(c.frames[0]);
  Context live, frozen;
  const double L_live = g.forward(c.model, 0, {&t, 1}, live).total;
  g.freeze_geometry(c.model, frozen);
  REQUIRE(!frozen.frg_frozen.empty());
  REQUIRE(frozen.bkg_frozen.mean.size() == 2);
  const double L_frozen = g.forward(c.model, 0, {&t, 1}, frozen).total;
  CHECK(L_frozen == L_live);
  CHECK(frozen.merged.storage() == live.merged.storage());
  // Appearance and alpha through the frozen path.
  Buffers b(c.model, 0, {.appearance = true, .alpha = true});
  (void)g.forward(c.model, 0, {&t, 1}, frozen, b.grads);
  REQUIRE(g.backward(frozen));
  Context fd;
  g.freeze_geometry(c.model, fd);
  auto loss = [&] { return g.forward(c.model, 0, {&t, 1}, fd).total; };
  for (const auto& r : testing::check_optimizer_gradients(b.groups, [](const Group&) { return true; }, loss, {.rtol = 1e-5})) {
    INFO("frozen: " << r);
    CHECK(r.ok());
  }
}

TEST_CASE("ClipGraph: a set's kept renders (freeze_render) give rendering's losses and gradients, and apply only where the set is a constant") {
  auto c = make_clip(true);
  Graph g;
  const int W = c.model.width(), H = c.model.height();
  const ConstImageView<double, 3> t(c.frames[1]);
  // The foreground and the alpha maps train; the background is a constant of the graph.
  const Sinks frg_only{.geometry = true, .appearance = true, .field = true, .alpha = true, .bkg = false};
  Buffers live_b(c.model, 1, frg_only);
  Context live;
  const double L_live = g.forward(c.model, 1, {&t, 1}, live, live_b.grads).total;
  REQUIRE(g.backward(live));
  REQUIRE(live.bkg.stats.evaluations > 0);
  Context kept;
  g.freeze_render(c.model, GaussianSet::background, W, H, kept);
  REQUIRE(kept.bkg_rendered.image.size() == std::size_t(c.model.frame_count()));
  CHECK(g.has_frozen_render(c.model, kept, GaussianSet::background, W, H));
  CHECK_FALSE(g.has_frozen_render(c.model, kept, GaussianSet::foreground, W, H));
  CHECK_FALSE(g.has_frozen_render(c.model, kept, GaussianSet::background, W - 1, H));
  Buffers kept_b(c.model, 1, frg_only);
  CHECK(g.forward(c.model, 1, {&t, 1}, kept, kept_b.grads).total == L_live);
  CHECK(kept.bkg.stats.evaluations == 0);  // read, not rasterized
  CHECK(kept.bkg.image.storage() == live.bkg.image.storage());
  CHECK(kept.merged.storage() == live.merged.storage());
  REQUIRE(g.backward(kept));
  CHECK(gradients_of(kept_b, kept) == gradients_of(live_b, live));
  // Every frame's render is the one rendering gives.
  for (int i = 0; i < c.model.frame_count(); ++i) {
    Context r;
    (void)g.forward(c.model, i, {}, r);
    CHECK(kept.bkg_rendered.image[std::size_t(i)].storage() == r.bkg.image.storage());
  }
  // Where the renders do not apply the set is rendered: with a sink for it or the camera, in a
  // window, at another size, another SH degree or deformation state.
  Buffers all(c.model, 1, {.appearance = true});
  (void)g.forward(c.model, 1, {&t, 1}, kept, all.grads);
  CHECK(kept.bkg.stats.evaluations > 0);
  Buffers cam_b(c.model, 1, frg_only);
  std::vector<double> dxi(6, 0.0);
  cam_b.grads.camera = dxi;
  (void)g.forward(c.model, 1, {&t, 1}, kept, cam_b.grads);
  CHECK(kept.bkg.stats.evaluations > 0);
  const PixelWindow win{2, 3, W / 2, H / 2};
  Image<double, 3> part(win.width, win.height);
  for (int y = 0; y < win.height; ++y)
    for (int x = 0; x < win.width; ++x)
      for (int ch = 0; ch < 3; ++ch) part(x, y, ch) = c.frames[1](win.x + x, win.y + y, ch);
  const ConstImageView<double, 3> tw(part);
  (void)g.forward(c.model, 1, {&tw, 1}, kept, {}, {}, nullptr, win);
  CHECK(kept.bkg.stats.evaluations > 0);
  c.model.deformation_enabled = false;
  CHECK_FALSE(g.has_frozen_render(c.model, kept, GaussianSet::background, W, H));
  (void)g.forward(c.model, 1, {&t, 1}, kept);
  CHECK(kept.bkg.stats.evaluations > 0);
  c.model.deformation_enabled = true;
  const Image<double, 3> small = resize_area(c.frames[1], W / 2, H / 2);
  const ConstImageView<double, 3> ts(small);
  (void)g.forward(c.model, 1, {&ts, 1}, kept);
  CHECK(kept.bkg.stats.evaluations > 0);
  Graph g0 = g;
  g0.settings.active_sh_degree = g.settings.active_sh_degree == 0 ? 1 : 0;
  CHECK_FALSE(g0.has_frozen_render(c.model, kept, GaussianSet::background, W, H));
  (void)g0.forward(c.model, 1, {&t, 1}, kept);
  CHECK(kept.bkg.stats.evaluations > 0);
  (void)g.forward(c.model, 1, {&t, 1}, kept);
  CHECK(kept.bkg.stats.evaluations == 0);
  Graph::thaw_render(kept, GaussianSet::background);
  CHECK(kept.bkg_rendered.empty());
  CHECK_THROWS_AS(g.freeze_render(c.model, GaussianSet::background, 0, H, kept), option_error);
}

TEST_CASE("ClipGraph: render-only forward records nothing and merges A I_frg + (1 - A) I_bkg") {
  auto c = make_clip(true);
  Graph g;
  Context ctx;
  const ClipLosses L = g.forward(c.model, 1, {}, ctx);
  CHECK(L.total == 0);
  CHECK(ctx.tape.step_count() == 0);
  const auto& a = c.model.alpha_logit[1];
  std::size_t checked = 0;
  for (int y = 0; y < a.height(); y += 5)
    for (int x = 0; x < a.width(); x += 3)
      for (int ch = 0; ch < 3; ++ch) {
        const double A = stable_sigmoid(a.pixel(x, y)[0]);
        CHECK(ctx.merged.pixel(x, y)[ch] == doctest::Approx(A * ctx.frg.image.pixel(x, y)[ch] + (1 - A) * ctx.bkg.image.pixel(x, y)[ch]));
        ++checked;
      }
  CHECK(checked > 50);
  // The same frame again, in the same context: the same bits.
  const std::vector<double> first = ctx.merged.storage();
  (void)g.forward(c.model, 1, {}, ctx);
  CHECK(ctx.merged.storage() == first);
}

TEST_CASE("ClipGraph: a static background renders its canonical Gaussians at every frame; the graph FD-checked with it") {
  auto c = make_clip(true);
  c.model.static_background = true;
  CHECK(c.model.deforms(GaussianSet::foreground));
  CHECK(!c.model.deforms(GaussianSet::background));
  Graph g;
  Context a, b;
  (void)g.forward(c.model, 0, {}, a);
  (void)g.forward(c.model, 1, {}, b);
  test::TinyModel::DeformScratch scratch;
  const auto canonical = c.model.deformed(GaussianSet::background, 1, scratch);
  CHECK(canonical.mean.data() == c.model.bkg.mean.data());  // no copy, no field
  c.model.deformation_enabled = false;
  Context off;
  (void)g.forward(c.model, 0, {}, off);
  CHECK(a.bkg.image.storage() == off.bkg.image.storage());  // background as without deformation
  CHECK(a.frg.image.storage() != off.frg.image.storage());  // the foreground still deformed
  c.model.deformation_enabled = true;
  g.weights = {0.7, 0.4, 1.3};
  const ConstImageView<double, 3> t(c.frames[1]);
  check(c.model, g, {&t, 1}, {.geometry = true, .appearance = true, .field = true, .alpha = true, .bkg_field = false}, {}, "static bkg");
  // The background's field is no sink: given as one, it receives nothing.
  Buffers buf(c.model, 1, {.geometry = true, .appearance = true, .field = true, .alpha = true});
  for (auto& seg : c.model.bkg_field->segments()) std::fill(seg.grad.begin(), seg.grad.end(), 0.0);
  Context ctx;
  (void)g.forward(c.model, 1, {&t, 1}, ctx, buf.grads);
  REQUIRE(g.backward(ctx));
  for (const auto& seg : c.model.bkg_field->segments()) CHECK(std::all_of(seg.grad.begin(), seg.grad.end(), [](double v) { return v == 0; }));
}

TEST_CASE("ClipGraph: smaller targets render at their size (resized camera, alpha logits resampled); the graph FD-checked there") {
  auto c = make_clip(true);
  Graph g;
  g.weights = {0.7, 0.4, 1.3};
  const int w = 21, h = 17;  // from 32 x 24: ratios 32/21 and 24/17, pixels straddle
  const Image<double, 3> small = resize_area(c.frames[1], w, h);
  const ConstImageView<double, 3> t(small);
  Context a;
  (void)g.forward(c.model, 1, {&t, 1}, a);
  CHECK(a.merged.width() == w);
  CHECK(a.merged.height() == h);
  CHECK(a.frg.image.width() == w);
  CHECK(a.bkg.image.height() == h);
  // The same as a model whose frame-1 camera and alpha map were made at that size: bit for bit.
  const Camera<double> cam1 = c.model.cameras[1];
  const Image<double, 1> alpha1 = c.model.alpha_logit[1];
  c.model.cameras[1] = cam1.resized(w, h);
  c.model.alpha_logit[1] = resize_area(alpha1, w, h);
  Context b;
  (void)g.forward(c.model, 1, {&t, 1}, b);
  CHECK(a.merged.storage() == b.merged.storage());
  c.model.cameras[1] = cam1;
  c.model.alpha_logit[1] = alpha1;
  // Every parameter, alpha through the resample node (its gradient is W x H).
  const Image<double, 1> detail(w, h, 1.5);
  check(c.model, g, {&t, 1}, {.geometry = true, .appearance = true, .field = true, .alpha = true}, detail, "smaller targets");
  // Sizes that do not fit are refused.
  const Image<double, 3> other(w, h + 1);
  const ConstImageView<double, 3> two[2] = {t, ConstImageView<double, 3>(other)};
  CHECK_THROWS_WITH_AS((void)g.forward(c.model, 1, {two, 2}, a), doctest::Contains("[option.clip]"), option_error);
  const Image<double, 1> bad_detail(w + 1, h, 1.0);
  CHECK_THROWS_WITH_AS((void)g.forward(c.model, 1, {&t, 1}, a, {}, bad_detail), doctest::Contains("detail"), option_error);
}

TEST_CASE("ClipGraph: a window renders that part of the frame (cropped camera, alpha window); the graph FD-checked there") {
  auto c = make_clip(true);
  Graph g;
  g.weights = {0.7, 0.4, 1.3};
  const PixelWindow win{5, 3, 19, 14};  // of 32 x 24, off-centre
  Image<double, 3> crop(win.width, win.height);
  for (int y = 0; y < win.height; ++y)
    for (int x = 0; x < win.width; ++x)
      for (int ch = 0; ch < 3; ++ch) crop(x, y, ch) = c.frames[1](win.x + x, win.y + y, ch);
  const ConstImageView<double, 3> t(crop);
  Context a;
  (void)g.forward(c.model, 1, {&t, 1}, a, {}, {}, nullptr, win);
  CHECK(a.merged.width() == win.width);
  CHECK(a.merged.height() == win.height);
  // The same as a model whose frame-1 camera and alpha map were cut to the window, rendered with the
  // whole frame's clamp bounds: bit for bit.
  const Camera<double> cam1 = c.model.cameras[1];
  const Image<double, 1> alpha1 = c.model.alpha_logit[1];
  c.model.cameras[1] = cam1.cropped(win.x, win.y, win.width, win.height);
  c.model.alpha_logit[1] = Image<double, 1>(win.width, win.height);
  for (int y = 0; y < win.height; ++y)
    for (int x = 0; x < win.width; ++x) c.model.alpha_logit[1](x, y) = alpha1(win.x + x, win.y + y);
  Graph cut = g;
  cut.settings.clamp_frame_x = win.x, cut.settings.clamp_frame_y = win.y, cut.settings.clamp_frame_width = 32,
  cut.settings.clamp_frame_height = 24;
  Context b;
  (void)cut.forward(c.model, 1, {&t, 1}, b);
  CHECK(a.merged.storage() == b.merged.storage());
  c.model.cameras[1] = cam1;
  c.model.alpha_logit[1] = alpha1;
  // The window's pixels are the whole render's, up to rounding of the shifted pixel coordinates (the
  // clamp keeps the whole frame's bounds; a tight clamp makes it bind).
  Graph tight = g;
  tight.settings.fov_clamp = 1.01;
  for (const Graph* gr : {&g, &tight}) {
    Context whole, part;
    (void)gr->forward(c.model, 1, {}, whole);
    (void)gr->forward(c.model, 1, {}, part, {}, {}, nullptr, win);
    for (int y = 0; y < win.height; ++y)
      for (int x = 0; x < win.width; ++x)
        for (int ch = 0; ch < 3; ++ch) CHECK(part.merged(x, y, ch) == doctest::Approx(whole.merged(win.x + x, win.y + y, ch)).epsilon(1e-9));
  }
  // Every parameter, alpha through the window node (its gradient is W x H, zero outside the window).
  const Image<double, 1> detail(win.width, win.height, 1.5);
  check(c.model, g, {&t, 1}, {.geometry = true, .appearance = true, .field = true, .alpha = true}, detail, "window", win);
  {
    Context ctx;
    Buffers buf(c.model, 1, {.alpha = true});
    (void)g.forward(c.model, 1, {&t, 1}, ctx, buf.grads, {}, nullptr, win);
    REQUIRE(g.backward(ctx));
    CHECK(buf.alpha[0] == 0.0);                                 // (0, 0) is outside the window
    CHECK(buf.alpha[std::size_t(4 * 32 + 6)] != 0.0);           // (6, 4) is inside
  }
  // A window outside the frame, or of another size than the targets, is refused.
  CHECK_THROWS_WITH_AS((void)g.forward(c.model, 1, {&t, 1}, a, {}, {}, nullptr, PixelWindow{14, 3, 19, 14}), doctest::Contains("window"),
                       option_error);
  CHECK_THROWS_WITH_AS((void)g.forward(c.model, 1, {&t, 1}, a, {}, {}, nullptr, PixelWindow{5, 3, 18, 14}), doctest::Contains("window"),
                       option_error);
}

TEST_CASE("ClipGraph: a non-finite image gradient makes backward return false") {
  auto c = make_clip(true);
  Graph g;
  Image<double, 3> bad = c.frames[0];
  bad.pixel(3, 4)[1] = std::numeric_limits<double>::infinity();
  const ConstImageView<double, 3> t(bad);
  Context ctx;
  Buffers b(c.model, 0, {.appearance = true});
  (void)g.forward(c.model, 0, {&t, 1}, ctx, b.grads);
  CHECK_FALSE(g.backward(ctx));
  CHECK_THROWS_AS(g.forward(c.model, 2, {&t, 1}, ctx), option_error);
}

TEST_CASE("ClipGraph: geometry gradients through a deformation without the field as a sink are refused") {
  auto c = make_clip(true);
  Graph g;
  const ConstImageView<double, 3> t(c.frames[0]);
  Context ctx;
  Buffers b(c.model, 0, {.geometry = true});
  try {
    (void)g.forward(c.model, 0, {&t, 1}, ctx, b.grads);
    FAIL("no exception");
  } catch (const option_error& e) {
    CHECK(std::string(e.id()) == "option.graph");
  }
  c.model.deformation_enabled = false;  // canonical geometry: no field involved
  CHECK_NOTHROW((void)g.forward(c.model, 0, {&t, 1}, ctx, b.grads));
}

TEST_CASE("ClipGraph: a field declared constant is no sink; with grid input gradients it is refused at the forward") {
  // The bit equality with the field as a sink is checked where the field has no grid input gradient:
  // tests/deformation (backward_canonical) and tests/training (freeze_deformation_from, end to end).
  auto c = make_clip(true);
  Graph g;
  const ConstImageView<double, 3> t(c.frames[1]);
  Context ctx;
  Buffers b(c.model, 1, {.geometry = true, .appearance = true});
  b.grads.frg_field_constant = b.grads.bkg_field_constant = true;
  REQUIRE(c.model.field(GaussianSet::foreground).options().grid_input_gradient);
  CHECK_THROWS_WITH_AS((void)g.forward(c.model, 1, {&t, 1}, ctx, b.grads), doctest::Contains("grid_input_gradient"), option_error);
  // Appearance alone needs no geometry gradient: a constant field is then fine.
  Buffers e(c.model, 1, {.appearance = true});
  e.grads.frg_field_constant = e.grads.bkg_field_constant = true;
  (void)g.forward(c.model, 1, {&t, 1}, ctx, e.grads);
  CHECK(g.backward(ctx));
  // A constant field is no sink: declaring both is refused, naming the flag.
  Buffers d(c.model, 1, {.geometry = true, .field = true});
  d.grads.frg_field_constant = true;
  CHECK_THROWS_WITH_AS((void)g.forward(c.model, 1, {&t, 1}, ctx, d.grads), doctest::Contains("frg_field_constant"), option_error);
}

namespace {

/// The camera node's forward at xi, applied by hand: every Gaussian of `mean` / `rotation` (N x 3,
/// N x 4) moved by T_xi(x) = c + E (x - c) + tau, q -> q_omega (x) q (E, q_omega: rotation vector omega).
void move_world(std::span<double> mean, std::span<double> rotation, const Eigen::Vector3d& c, const std::vector<double>& xi) {
  const Eigen::Vector3d omega(xi[0], xi[1], xi[2]), tau(xi[3], xi[4], xi[5]);
  const double a = omega.norm();
  const Eigen::AngleAxisd aa(a, a > 0 ? Eigen::Vector3d(omega / a) : Eigen::Vector3d::UnitX());
  const Eigen::Matrix3d E = aa.toRotationMatrix();
  const Eigen::Quaterniond qe(aa);
  for (std::size_t i = 0; i < mean.size() / 3; ++i) {
    const Eigen::Vector3d x(mean[3 * i], mean[3 * i + 1], mean[3 * i + 2]);
    const Eigen::Vector3d y = c + E * (x - c) + tau;
    for (int k = 0; k < 3; ++k) mean[3 * i + std::size_t(k)] = y[k];
    const Eigen::Quaterniond q(rotation[4 * i], rotation[4 * i + 1], rotation[4 * i + 2], rotation[4 * i + 3]);
    const Eigen::Quaterniond r = qe * q;  // Hamilton product, no normalisation
    rotation[4 * i] = r.w(), rotation[4 * i + 1] = r.x(), rotation[4 * i + 2] = r.y(), rotation[4 * i + 3] = r.z();
  }
}

/// FD check of the camera sink (and of every group in `sinks`) with the loss of frame 1 evaluated on
/// the Gaussians moved by T_xi: canonical ones (`frozen` false; deformation must be off) or the
/// frozen deformed geometry of frame 1.
void check_camera(test::TinyModel& m, Graph& g, const ConstImageView<double, 3>& target, const Sinks& sinks, bool frozen, const char* what) {
  const int frame = 1;
  Buffers b(m, frame, sinks);
  std::vector<double> xi(6, 0.0), dxi(6, 0.0);
  b.grads.camera = dxi;
  b.groups.list.push_back({"camera", {{xi, dxi}}});
  Context ctx;
  if (frozen) g.freeze_geometry(m, ctx);
  const double L0 = g.forward(m, frame, {&target, 1}, ctx, b.grads).total;
  REQUIRE(g.backward(ctx));
  const Eigen::Vector3d centre = m.cameras[std::size_t(frame)].center();
  Context fd;
  auto loss = [&] {
    if (frozen) {
      g.freeze_geometry(m, fd);
      for (auto* fz : {&fd.frg_frozen, &fd.bkg_frozen})
        if (!fz->empty()) move_world(fz->mean[std::size_t(frame)], fz->rotation[std::size_t(frame)], centre, xi);
      return g.forward(m, frame, {&target, 1}, fd).total;
    }
    std::vector<double> kept[4] = {m.frg.mean, m.frg.rotation, m.bkg.mean, m.bkg.rotation};
    move_world(m.frg.mean, m.frg.rotation, centre, xi);
    move_world(m.bkg.mean, m.bkg.rotation, centre, xi);
    const double L = g.forward(m, frame, {&target, 1}, fd).total;
    m.frg.mean = kept[0], m.frg.rotation = kept[1], m.bkg.mean = kept[2], m.bkg.rotation = kept[3];
    return L;
  };
  CHECK(loss() == doctest::Approx(L0).epsilon(1e-12));  // xi = 0: the node is the identity
  const auto results = testing::check_optimizer_gradients(b.groups, [](const Group&) { return true; }, loss, {.rtol = 1e-5});
  REQUIRE(!results.empty());
  bool camera_seen = false;
  for (const auto& r : results) {
    INFO(what << ": " << r);
    CHECK(r.ok());
    CHECK(std::count_if(r.analytic.begin(), r.analytic.end(), [](double v) { return v != 0; }) > 0);
  }
  for (const auto& r : results) camera_seen |= r.name == "camera";
  CHECK(camera_seen);
  for (double v : dxi) CHECK(std::isfinite(v));
}

}  // namespace

TEST_CASE("ClipGraph: the camera node's gradient is the rigid world move's (FD, canonical and deformed geometry); without a camera sink nothing changes") {
  auto c = make_clip(true);
  Graph g;
  g.weights = {0.7, 0.4, 1.3};
  const ConstImageView<double, 3> t(c.frames[1]);
  Context plain, with_node;
  const double L_plain = g.forward(c.model, 1, {&t, 1}, plain).total;
  std::vector<double> dxi(6, 0.0);
  ClipGradients<double, test::TinyField> only_camera;
  only_camera.camera = dxi;
  const double L_node = g.forward(c.model, 1, {&t, 1}, with_node, only_camera).total;
  CHECK(L_node == L_plain);  // the identity at xi = 0, bit for bit
  CHECK(with_node.merged.storage() == plain.merged.storage());
  REQUIRE(g.backward(with_node));
  CHECK(std::count_if(dxi.begin(), dxi.end(), [](double v) { return v != 0; }) == 6);

  SUBCASE("canonical Gaussians: camera, geometry (passed through the node), appearance, alpha") {
    c.model.deformation_enabled = false;
    check_camera(c.model, g, t, {.geometry = true, .appearance = true, .alpha = true}, false, "canonical");
  }
  SUBCASE("frozen deformed geometry: camera, appearance, alpha") {
    check_camera(c.model, g, t, {.appearance = true, .alpha = true}, true, "frozen");
  }
  SUBCASE("the background alone") {
    auto b = make_clip(false);
    b.model.deformation_enabled = false;
    const ConstImageView<double, 3> tb(b.frames[1]);
    check_camera(b.model, g, tb, {.geometry = true}, false, "background only");
  }
}

TEST_CASE("ClipGraph: folding a world move into the camera renders the same at SH degree 0") {
  auto c = make_clip(true);
  c.model.deformation_enabled = false;
  Graph g;
  g.settings.active_sh_degree = 0;
  const int frame = 1;
  const std::vector<double> xi = {0.02, -0.03, 0.015, 0.04, -0.02, 0.03};
  const Camera<double> kept = c.model.cameras[std::size_t(frame)];
  const Eigen::Vector3d centre = kept.center();
  c.model.cameras[std::size_t(frame)] = kept.world_moved({xi[0], xi[1], xi[2]}, {xi[3], xi[4], xi[5]});
  Context folded;
  (void)g.forward(c.model, frame, {}, folded);
  c.model.cameras[std::size_t(frame)] = kept;
  move_world(c.model.frg.mean, c.model.frg.rotation, centre, xi);
  move_world(c.model.bkg.mean, c.model.bkg.rotation, centre, xi);
  Context moved;
  (void)g.forward(c.model, frame, {}, moved);
  double diff = 0, sum = 0;
  for (std::size_t i = 0; i < moved.merged.size(); ++i)
    diff = std::max(diff, std::abs(moved.merged.data()[i] - folded.merged.data()[i])), sum += moved.merged.data()[i];
  CHECK(sum > 1);      // something is rendered
  CHECK(diff < 1e-9);  // the same image up to rounding
}
