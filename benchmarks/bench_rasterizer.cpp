// Rasterizer benchmark: a seeded synthetic scene (N Gaussians filling the view at depths 2..6, projected
// sigma 1-4 px, random rotations, opacity 0.1-0.9, SH degree 3) at 854x480; forward and backward
// (all gradients) medians over --runs runs after one warm-up. One JSON line per configuration.
//
//   bench_rasterizer [--n 10000,100000,1000000] [--scalar float,double] [--threads 1,2]
//                    [--tiles 8,16,32] [--runs 5] [--width 854] [--height 480]
//                    [--simd automatic,portable,avx2,avx512]
// "simd" / "simd_backward" name the compositing paths that ran in the forward / backward pass
// (RasterSettings::simd resolved, rasterizer/simd.hpp).
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <string>
#include <vector>

#include "video3dgs/rasterizer.hpp"
#include "video3dgs/synthetic.hpp"

#include "bench_common.hpp"

using namespace video3dgs;

namespace {
using bench::split_list;
struct Config {
  int width = 854, height = 480, runs = 5;
  RasterSimd simd = RasterSimd::automatic;
};

template <class Scalar, int Tile>
void run(const Config& cfg, std::size_t n, unsigned threads) {
  const auto cam = Camera<Scalar>::from_fov(cfg.width, cfg.height, Scalar(60.0 * std::numbers::pi / 180.0));
  const auto cloud = synthetic::random_view_cloud<Scalar, 3>(cam, n, 12345);
  Rasterizer<Scalar, Tile> r;
  r.settings.simd = cfg.simd;
  RasterContext<Scalar, 3> ctx;
  ThreadPool pool(threads);
  Image<Scalar, 3> dimg(cfg.width, cfg.height);
  synthetic::Random rnd(7);
  for (auto& v : dimg.storage()) v = Scalar(rnd.uniform(-1, 1));
  GaussianCloudGrad<Scalar, 3> g(n);
  std::vector<Scalar> m2d(2 * n);
  RasterGrads<Scalar, 3> grads;
  grads.gaussians = g.grads();
  grads.dL_dmean2d = m2d;
  bench::Samples warm_up, fwd, bwd;
  for (int it = 0; it <= cfg.runs; ++it) {
    bench::measure(it == 0 ? warm_up : fwd, [&] { r.forward(cam, cloud.params(), ctx, &pool); });
    bench::measure(it == 0 ? warm_up : bwd, [&] { r.backward(ctx, dimg.cview(), {}, {}, grads, &pool); });
  }
  using bench::round_to;
  bench::emit({{"bench", "rasterizer"}, {"scalar", scalar_traits<Scalar>::name}, {"threads", threads}, {"tile", Tile}, {"gaussians", n},
               {"width", cfg.width}, {"height", cfg.height}, {"forward_ms", round_to(fwd.wall_ms(), 3)},
               {"backward_ms", round_to(bwd.wall_ms(), 3)}, {"pairs", ctx.stats.evaluations}, {"tile_pairs", ctx.stats.tile_pairs},
               {"visible", ctx.stats.visible}, {"runs", cfg.runs}, {"forward_cpu_ms", round_to(fwd.cpu_ms(), 3)},
               {"backward_cpu_ms", round_to(bwd.cpu_ms(), 3)}, {"load_avg", round_to(bench::load_avg(), 2)},
               {"simd", raster_simd_name(resolve_raster_simd(cfg.simd))},
               {"simd_backward", raster_simd_name(resolve_raster_simd(cfg.simd, RasterPass::backward))}});
}

template <class Scalar>
void run_tile(const Config& cfg, int tile, std::size_t n, unsigned threads) {
  if (tile == 8) run<Scalar, 8>(cfg, n, threads);
  else if (tile == 16) run<Scalar, 16>(cfg, n, threads);
  else if (tile == 32) run<Scalar, 32>(cfg, n, threads);
  else std::fprintf(stderr, "bench_rasterizer: tile %d not in {8,16,32}\n", tile);
}
}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> ns = {"10000", "100000", "1000000"}, scalars = {"float", "double"}, threads = {"1", "2"},
                           tiles = {"8", "16", "32"}, simds = {"automatic"};
  Config cfg;
  using bench::parse_number;
  try {  // a malformed number ends the program with its message
    for (int i = 1; i + 1 < argc; i += 2) {
      const std::string k = argv[i], v = argv[i + 1];
      if (k == "--n") ns = split_list(v);
      else if (k == "--scalar") scalars = split_list(v);
      else if (k == "--threads") threads = split_list(v);
      else if (k == "--tiles") tiles = split_list(v);
      else if (k == "--runs") cfg.runs = std::max(1, parse_number<int>(k, v));
      else if (k == "--width") cfg.width = parse_number<int>(k, v);
      else if (k == "--height") cfg.height = parse_number<int>(k, v);
      else if (k == "--simd") simds = split_list(v);
      else {
        std::fprintf(stderr, "usage: bench_rasterizer [--n a,b] [--scalar float,double] [--threads 1,2] [--tiles 8,16,32] [--runs 5] [--simd automatic,portable,avx2,avx512]\n");
        return 1;
      }
    }
    // Every list's numbers are read before the first configuration runs.
    std::vector<std::size_t> counts;
    std::vector<unsigned> thread_counts;
    std::vector<int> tile_sizes;
    for (const auto& n : ns) counts.push_back(parse_number<std::size_t>("--n", n));
    for (const auto& t : threads) thread_counts.push_back(parse_number<unsigned>("--threads", t));
    for (const auto& tile : tiles) tile_sizes.push_back(parse_number<int>("--tiles", tile));
    for (const auto& simd : simds) {
      bool known = false;
      for (RasterSimd c : {RasterSimd::automatic, RasterSimd::portable, RasterSimd::avx2, RasterSimd::avx512})
        if (simd == raster_simd_name(c)) cfg.simd = c, known = true;
      if (!known || !raster_simd_supported(cfg.simd)) {
        std::fprintf(stderr, "bench_rasterizer: simd '%s' unknown or not supported here\n", simd.c_str());
        continue;
      }
      for (const std::size_t count : counts)
        for (const auto& s : scalars)
          for (const unsigned th : thread_counts)
            for (const int tile : tile_sizes) {
              if (s == "float") run_tile<float>(cfg, tile, count, th);
              else run_tile<double>(cfg, tile, count, th);
            }
    }
  } catch (const error& e) {
    std::fprintf(stderr, "bench_rasterizer: %s\n", e.what());
    return 2;
  }
  return 0;
}
