// Timing of the photometric losses at video size (854x480x3): SSIM forward (value only), SSIM
// forward+backward, L1 forward+backward and the combined 0.8 L1 + 0.2 D-SSIM forward+backward, for
// float and double and 1..2 threads. One JSON line per configuration, median of `--runs` (default 7)
// after one warm-up; wall time and process CPU time (the latter is robust to other load).   Usage: bench_loss [--runs N] [--width W] [--height H]
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/loss.hpp"

#include "bench_common.hpp"

using namespace video3dgs;

namespace {

struct Timing {
  double wall_ms = 0;  ///< median wall time
  double cpu_ms = 0;   ///< median process CPU time (all threads): robust to other load on the machine
};

Timing median_ms(int runs, const std::function<void()>& f) {
  f();  // warm-up (also sizes the reusable contexts)
  bench::Samples s;
  for (int i = 0; i < runs; ++i) bench::measure(s, f);
  return {s.wall_ms(), s.cpu_ms()};
}

template <class Scalar>
void run(int w, int h, int runs, unsigned threads, const char* name) {
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> d(0.0, 1.0);
  Image<Scalar, 3> x(w, h), y(w, h), g(w, h);
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double v = d(rng);
    y.data()[i] = static_cast<Scalar>(v);
    x.data()[i] = static_cast<Scalar>(0.8 * v + 0.2 * d(rng));
  }
  ThreadPool pool(threads);
  ThreadPool* p = threads > 1 ? &pool : nullptr;
  loss::SsimContext<Scalar, 3> sctx;
  loss::L1Context<Scalar, 3> lctx;
  loss::L1DssimContext<Scalar, 3> cctx;
  volatile Scalar sink = 0;
  const Timing ssim_value = median_ms(runs, [&] { sink = loss::ssim_value<Scalar, 3>(x, y, sctx, p); });
  const Timing ssim_fb = median_ms(runs, [&] {
    sink = loss::ssim_forward<Scalar, 3>(x, y, sctx, p);
    loss::ssim_backward<Scalar, 3>(sctx, Scalar(1), g, p);
  });
  const Timing l1_fb = median_ms(runs, [&] {
    sink = loss::l1_forward<Scalar, 3>(x, y, lctx, p);
    loss::l1_backward<Scalar, 3>(lctx, Scalar(1), g, p);
  });
  const Timing comb_fb = median_ms(runs, [&] {
    sink = loss::l1_dssim_forward<Scalar, 3>(x, y, cctx, p);
    loss::l1_dssim_backward<Scalar, 3>(cctx, Scalar(1), g, p);
  });
  (void)sink;
  using bench::round_to;
  bench::emit({{"bench", "loss"}, {"scalar", name}, {"width", w}, {"height", h}, {"channels", 3}, {"threads", threads}, {"runs", runs},
               {"ssim_value_ms", round_to(ssim_value.wall_ms, 2)}, {"ssim_fwd_bwd_ms", round_to(ssim_fb.wall_ms, 2)},
               {"l1_fwd_bwd_ms", round_to(l1_fb.wall_ms, 2)}, {"l1_dssim_fwd_bwd_ms", round_to(comb_fb.wall_ms, 2)},
               {"ssim_value_cpu_ms", round_to(ssim_value.cpu_ms, 2)}, {"ssim_fwd_bwd_cpu_ms", round_to(ssim_fb.cpu_ms, 2)},
               {"l1_fwd_bwd_cpu_ms", round_to(l1_fb.cpu_ms, 2)}, {"l1_dssim_fwd_bwd_cpu_ms", round_to(comb_fb.cpu_ms, 2)}});
}

}  // namespace

int main(int argc, char** argv) {
  int runs = 7, w = 854, h = 480;
  try {
    for (int i = 1; i + 1 < argc; i += 2) {
      const std::string k = argv[i];
      if (k == "--runs") runs = std::max(1, bench::parse_number<int>(k, argv[i + 1]));
      else if (k == "--width") w = bench::parse_number<int>(k, argv[i + 1]);
      else if (k == "--height") h = bench::parse_number<int>(k, argv[i + 1]);
    }
  } catch (const error& e) {
    std::fprintf(stderr, "bench_loss: %s\n", e.what());
    return 2;
  }
  for (unsigned threads : {1u, 2u}) run<float>(w, h, runs, threads, "float");
  for (unsigned threads : {1u, 2u}) run<double>(w, h, runs, threads, "double");
  return 0;
}
