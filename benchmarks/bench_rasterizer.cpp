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
#include <chrono>
#include <ctime>
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "video3dgs/rasterizer.hpp"
#include "video3dgs/synthetic.hpp"

using namespace video3dgs;

namespace {
std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) if (!item.empty()) out.push_back(item);
  return out;
}
double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}
/// Process CPU time (all threads), ms: with a loaded machine it shows the work apart from waiting.
double cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return 1e3 * double(ts.tv_sec) + 1e-6 * double(ts.tv_nsec);
}
/// 1-minute load average (other processes competing for the cores), -1 if unknown.
double load_avg() {
  double l[1];
  return getloadavg(l, 1) == 1 ? l[0] : -1.0;
}
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
  std::vector<double> fwd, bwd, fwd_cpu, bwd_cpu;
  for (int it = 0; it <= cfg.runs; ++it) {
    const double c0 = cpu_ms();
    const auto t0 = std::chrono::steady_clock::now();
    r.forward(cam, cloud.params(), ctx, &pool);
    const double c1 = cpu_ms();
    const auto t1 = std::chrono::steady_clock::now();
    r.backward(ctx, dimg.cview(), {}, {}, grads, &pool);
    const double c2 = cpu_ms();
    const auto t2 = std::chrono::steady_clock::now();
    if (it == 0) continue;  // warm-up
    fwd.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
    bwd.push_back(std::chrono::duration<double, std::milli>(t2 - t1).count());
    fwd_cpu.push_back(c1 - c0);
    bwd_cpu.push_back(c2 - c1);
  }
  std::printf("{\"bench\":\"rasterizer\",\"scalar\":\"%s\",\"threads\":%u,\"tile\":%d,\"gaussians\":%zu,\"width\":%d,"
              "\"height\":%d,\"forward_ms\":%.3f,\"backward_ms\":%.3f,\"pairs\":%zu,\"tile_pairs\":%zu,\"visible\":%zu,"
              "\"runs\":%d,\"forward_cpu_ms\":%.3f,\"backward_cpu_ms\":%.3f,\"load_avg\":%.2f,\"simd\":\"%s\",\"simd_backward\":\"%s\"}\n",
              scalar_traits<Scalar>::name, threads, Tile, n, cfg.width, cfg.height, median(fwd), median(bwd),
              ctx.stats.evaluations, ctx.stats.tile_pairs, ctx.stats.visible, cfg.runs, median(fwd_cpu), median(bwd_cpu), load_avg(),
              raster_simd_name(resolve_raster_simd(cfg.simd)), raster_simd_name(resolve_raster_simd(cfg.simd, RasterPass::backward)));
  std::fflush(stdout);
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
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i], v = argv[i + 1];
    if (k == "--n") ns = split(v);
    else if (k == "--scalar") scalars = split(v);
    else if (k == "--threads") threads = split(v);
    else if (k == "--tiles") tiles = split(v);
    else if (k == "--runs") cfg.runs = std::max(1, std::atoi(v.c_str()));
    else if (k == "--width") cfg.width = std::atoi(v.c_str());
    else if (k == "--height") cfg.height = std::atoi(v.c_str());
    else if (k == "--simd") simds = split(v);
    else {
      std::fprintf(stderr, "usage: bench_rasterizer [--n a,b] [--scalar float,double] [--threads 1,2] [--tiles 8,16,32] [--runs 5] [--simd automatic,portable,avx2,avx512]\n");
      return 1;
    }
  }
  for (const auto& simd : simds) {
    bool known = false;
    for (RasterSimd c : {RasterSimd::automatic, RasterSimd::portable, RasterSimd::avx2, RasterSimd::avx512})
      if (simd == raster_simd_name(c)) cfg.simd = c, known = true;
    if (!known || !raster_simd_supported(cfg.simd)) {
      std::fprintf(stderr, "bench_rasterizer: simd '%s' unknown or not supported here\n", simd.c_str());
      continue;
    }
  for (const auto& n : ns)
    for (const auto& s : scalars)
      for (const auto& t : threads)
        for (const auto& tile : tiles) {
          const std::size_t count = std::stoull(n);
          const unsigned th = static_cast<unsigned>(std::stoul(t));
          if (s == "float") run_tile<float>(cfg, std::stoi(tile), count, th);
          else run_tile<double>(cfg, std::stoi(tile), count, th);
        }
  }
  return 0;
}
