// Every supported variant of the training path compiles and runs: float/double x SH degree 0..3 x
// tile 8/16/32 x SplitLrAdam/Adam/Sgd, as explicit instantiations of ClipGraph, ClipTrainer and
// ClipRefiner (so a member nobody calls still compiles), each then run for a few iterations on a
// tiny synthetic clip (finite losses, the optimiser's groups moved, a render). This folder is built at
// -O0 (tests/CMakeLists.txt): it checks compilation and plumbing, not speed.
#include <cmath>
#include <span>
#include <vector>

#include <doctest/doctest.h>

#include "video3dgs/graph/clip_graph.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/model/render_clip.hpp"
#include "video3dgs/synthetic/clip.hpp"
#include "video3dgs/training/clip_trainer.hpp"
#include "video3dgs/training/policy.hpp"
#include "video3dgs/refine/refine.hpp"

namespace video3dgs {
template <class S>
using SmallField = DeformationField<S, HashGrid4D<S, 10>>;
}  // namespace video3dgs

#define VIDEO3DGS_INSTANTIATE_TILE(S, D, T)                                                 \
  template class video3dgs::ClipGraph<S, D, video3dgs::SmallField<S>, T>;                 \
  template class video3dgs::ClipTrainer<video3dgs::ClipModel<S, D, video3dgs::SmallField<S>>, T, video3dgs::SplitLrAdam>; \
  template class video3dgs::ClipTrainer<video3dgs::ClipModel<S, D, video3dgs::SmallField<S>>, T, video3dgs::Adam>; \
  template class video3dgs::ClipTrainer<video3dgs::ClipModel<S, D, video3dgs::SmallField<S>>, T, video3dgs::Sgd>; \
  template class video3dgs::ClipRefiner<S, D, video3dgs::SmallField<S>, T, video3dgs::SplitLrAdam>; \
  template class video3dgs::ClipRefiner<S, D, video3dgs::SmallField<S>, T, video3dgs::Adam>; \
  template class video3dgs::ClipRefiner<S, D, video3dgs::SmallField<S>, T, video3dgs::Sgd>;
#define VIDEO3DGS_INSTANTIATE_SH(S, D) \
  VIDEO3DGS_INSTANTIATE_TILE(S, D, 8)  \
  VIDEO3DGS_INSTANTIATE_TILE(S, D, 16) \
  VIDEO3DGS_INSTANTIATE_TILE(S, D, 32)
#define VIDEO3DGS_INSTANTIATE(S) \
  VIDEO3DGS_INSTANTIATE_SH(S, 0) \
  VIDEO3DGS_INSTANTIATE_SH(S, 1) \
  VIDEO3DGS_INSTANTIATE_SH(S, 2) \
  VIDEO3DGS_INSTANTIATE_SH(S, 3)

VIDEO3DGS_INSTANTIATE(float)
VIDEO3DGS_INSTANTIATE(double)

using namespace video3dgs;

namespace {

template <class S, int D, int T, class P>
void run_variant() {
  using Model = ClipModel<S, D, SmallField<S>>;
  CAPTURE(sizeof(S));
  CAPTURE(D);
  CAPTURE(T);
  CAPTURE(P::name);
  synthetic::SyntheticClipOptions so;
  so.frames = 2, so.width = 24, so.height = 16;
  so.object_gaussians = 20, so.background_gaussians = 40, so.foreground_points = 20;
  const auto clip = synthetic::make_synthetic_clip<S>(so);
  ClipModelOptions mo;
  mo.background.points_per_shell = 20;
  TrainOptions o;
  o.iterations = 3, o.deformation_warmup = 1, o.sh_degree_interval = 1, o.densify_from = 1000, o.seed = 1;
  ClipTrainer<Model, T, P> t(make_clip_model<S, D, SmallField<S>>(clip.sfm_result(), mo, std::span<const Image<S, 1>>(clip.masks)), clip.frames,
                             o);
  const std::vector<S> before = t.model().bkg.sh;
  t.train();
  CHECK(t.stats().skipped_steps == 0);
  CHECK(std::isfinite(t.stats().last_loss));
  CHECK(t.model().bkg.sh != before);
  CHECK(std::isfinite(t.evaluate().psnr));
  Model m = clone_clip_model(t.model());
  const std::vector<std::vector<Image<S, 3>>> targets{clip.frames};
  RefineOptions ro;
  ro.iterations = 2;
  ClipRefiner<S, D, SmallField<S>, T, P> r(m, targets, ro);
  CHECK(std::isfinite(r.step(1, 0)));
  ClipRenderBuffers<S, SmallField<S>> buf;
  render_clip_frame<T>(m, 1, buf);
  CHECK(buf.merged.width() == so.width);
}

template <class S, int D, int T>
void run_policies() {
  run_variant<S, D, T, SplitLrAdam>();
  run_variant<S, D, T, Adam>();
  run_variant<S, D, T, Sgd>();
}

template <class S, int D>
void run_tiles() {
  run_policies<S, D, 8>();
  run_policies<S, D, 16>();
  run_policies<S, D, 32>();
}

}  // namespace

TEST_CASE("training variants: float, SH 0..3, tiles 8/16/32, SplitLrAdam/Adam/Sgd") {
  run_tiles<float, 0>();
  run_tiles<float, 1>();
  run_tiles<float, 2>();
  run_tiles<float, 3>();
}

TEST_CASE("training variants: double, SH 0..3, tiles 8/16/32, SplitLrAdam/Adam/Sgd") {
  run_tiles<double, 0>();
  run_tiles<double, 1>();
  run_tiles<double, 2>();
  run_tiles<double, 3>();
}
