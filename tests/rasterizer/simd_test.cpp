// The run-time dispatched compositing kernels (AVX2, AVX-512) against the portable one: images and every
// gradient bit-identical (no FMA contraction, block-width independent gradient sums), float and double.
#include <doctest/doctest.h>

#include <cstring>
#include <numbers>
#include <vector>

#include "scene_util.hpp"
#include "video3dgs/rasterizer.hpp"
#include "video3dgs/synthetic.hpp"

using namespace video3dgs;

namespace {

template <class Scalar>
struct Rendered {
  std::vector<Scalar> image, alpha, depth, final_T, grads;
  std::vector<std::uint32_t> last;
  std::size_t evaluations = 0;
};

template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

/// Forward + backward (all outputs and gradients, optionally with dL/dalpha and dL/ddepth) on `simd`.
template <class Scalar, int Tile>
Rendered<Scalar> render(RasterSimd simd, const Camera<Scalar>& cam, const GaussianCloud<Scalar, 3>& cloud, bool extra_outputs,
                        unsigned threads) {
  Rasterizer<Scalar, Tile> r;
  r.settings.simd = simd;
  r.settings.background = {Scalar(0.1), Scalar(0.2), Scalar(0.3)};
  RasterContext<Scalar, 3> ctx;
  ThreadPool pool(threads);
  r.forward(cam, cloud.params(), ctx, &pool);
  const std::size_t n = cloud.size();
  Image<Scalar, 3> dimg(cam.width, cam.height);
  Image<Scalar, 1> dalpha(cam.width, cam.height), ddepth(cam.width, cam.height);
  synthetic::Random rnd(7);
  for (auto& v : dimg.storage()) v = Scalar(rnd.uniform(-1, 1));
  for (auto& v : dalpha.storage()) v = Scalar(rnd.uniform(-1, 1));
  for (auto& v : ddepth.storage()) v = Scalar(rnd.uniform(-1, 1));
  GaussianCloudGrad<Scalar, 3> g(n);
  std::vector<Scalar> mean2d(2 * n), colors(3 * n), weight(extra_outputs ? 0 : n), evals(extra_outputs ? 0 : n);
  RasterGrads<Scalar, 3> grads;
  grads.gaussians = g.grads();
  grads.dL_dmean2d = mean2d;
  grads.dL_dcolors = colors;
  grads.blend_weight = weight;  // only without a depth gradient
  grads.blend_evals = evals;
  if (extra_outputs) r.backward(ctx, dimg.cview(), dalpha.cview(), ddepth.cview(), grads, &pool);
  else r.backward(ctx, dimg.cview(), {}, {}, grads, &pool);
  Rendered<Scalar> out;
  out.image = ctx.image.storage();
  out.alpha = ctx.alpha.storage();
  out.depth = ctx.depth.storage();
  out.final_T = ctx.final_T;
  out.last = ctx.last_contrib;
  out.evaluations = ctx.stats.evaluations;
  const auto& G = grads.gaussians;
  for (auto s : {G.dL_dmean, G.dL_dlog_scale, G.dL_drotation, G.dL_dopacity_logit, G.dL_dsh, grads.dL_dmean2d, grads.dL_dcolors,
                 grads.blend_weight, grads.blend_evals})
    out.grads.insert(out.grads.end(), s.begin(), s.end());
  out.grads.insert(out.grads.end(), grads.dL_dbackground.begin(), grads.dL_dbackground.end());
  return out;
}

template <class Scalar, int Tile>
void check_paths(const Camera<Scalar>& cam, const GaussianCloud<Scalar, 3>& cloud, bool extra_outputs, unsigned threads) {
  const auto ref = render<Scalar, Tile>(RasterSimd::portable, cam, cloud, extra_outputs, threads);
  bool nonzero = false;
  for (Scalar v : ref.grads) nonzero = nonzero || v != Scalar(0);
  CHECK(nonzero);
  for (RasterSimd simd : {RasterSimd::avx2, RasterSimd::avx512, RasterSimd::automatic}) {
    if (!raster_simd_supported(simd)) {
      MESSAGE("SIMD path " << raster_simd_name(simd) << " not supported here: skipped");
      continue;
    }
    CAPTURE(raster_simd_name(simd));
    CAPTURE(Tile);
    CAPTURE(extra_outputs);
    const auto got = render<Scalar, Tile>(simd, cam, cloud, extra_outputs, threads);
    CHECK(got.evaluations == ref.evaluations);
    CHECK(same_bits(got.image, ref.image));
    CHECK(same_bits(got.alpha, ref.alpha));
    CHECK(same_bits(got.depth, ref.depth));
    CHECK(same_bits(got.final_T, ref.final_T));
    CHECK(same_bits(got.last, ref.last));
    CHECK(same_bits(got.grads, ref.grads));
  }
}

}  // namespace

TEST_CASE("rasterizer simd: names, resolution, unsupported choice rejected") {
  CHECK(std::string(raster_simd_name(RasterSimd::portable)) == "portable");
  CHECK(std::string(raster_simd_name(RasterSimd::avx512)) == "avx512");
  const RasterSimd best = resolve_raster_simd(RasterSimd::automatic);
  CHECK(best != RasterSimd::automatic);
  CHECK(raster_simd_supported(best));
  CHECK(raster_simd_supported(RasterSimd::portable));
  const RasterSimd best_backward = resolve_raster_simd(RasterSimd::automatic, RasterPass::backward);
  CHECK(best_backward != RasterSimd::automatic);
  CHECK(raster_simd_supported(best_backward));
  CHECK(resolve_raster_simd(RasterSimd::portable, RasterPass::backward) == RasterSimd::portable);  // explicit choices kept
  for (RasterSimd s : {RasterSimd::avx2, RasterSimd::avx512}) {
    RasterSettings<float, 3> settings;
    settings.simd = s;
    if (raster_simd_supported(s)) CHECK_NOTHROW(settings.validate());
    else CHECK_THROWS_AS(settings.validate(), option_error);
  }
}

TEST_CASE_TEMPLATE("rasterizer simd: dispatched paths bit-identical to the portable one", Scalar, float, double) {
  {  // dense random view: many overlaps, saturated pixels, every tile size
    const auto cam = Camera<Scalar>::from_fov(150, 90, Scalar(60.0 * std::numbers::pi / 180.0));
    const auto cloud = synthetic::random_view_cloud<Scalar, 3>(cam, 1500, 99);
    check_paths<Scalar, 8>(cam, cloud, true, 2);
    check_paths<Scalar, 16>(cam, cloud, false, 2);
    check_paths<Scalar, 16>(cam, cloud, true, 1);
    check_paths<Scalar, 32>(cam, cloud, false, 1);
  }
  for (std::uint64_t seed = 1; seed <= 2; ++seed) {  // the hazard scenes of the other tests
    CAPTURE(seed);
    const auto cam = test::small_camera<Scalar>(70, 45);
    const auto cloud = test::random_scene<Scalar, 3>(cam, seed, 40);
    check_paths<Scalar, 8>(cam, cloud, true, 1);
    check_paths<Scalar, 16>(cam, cloud, true, 2);
    check_paths<Scalar, 32>(cam, cloud, false, 1);
  }
}
