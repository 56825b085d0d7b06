// Timing of the photometric losses at video size (854x480x3): SSIM forward (value only), SSIM
// forward+backward, L1 forward+backward and the combined 0.8 L1 + 0.2 D-SSIM forward+backward, for
// float and double and 1..2 threads. One JSON line per configuration, median of `--runs` (default 7)
// after one warm-up; wall time and process CPU time (the latter is robust to other load).
// A second line per configuration ("bench":"loss_shared_target") times the clip graph's pattern:
// three SSIM forward+backward passes of three renders against one target, each filtering the target
// itself ("separate") or all reading one `SsimTarget` filled once per pass ("shared", the fill
// included), the two alternating run by run; "identical" says both gave the same bits.
//
//   bench_loss [--runs N] [--width W] [--height H] [--scalar float,double] [--threads 1,2]
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

struct SharedTiming {
  Timing separate, shared, fill;
  bool identical = false;
};

/// Three SSIM forward+backward passes of renders x_k = x + small offsets against y: each against y
/// itself, or against one SsimTarget filled once per pass; interleaved run by run.
template <class Scalar>
SharedTiming time_shared_target(const Image<Scalar, 3>& x, const Image<Scalar, 3>& y, int runs, ThreadPool* p) {
  constexpr int K = 3;
  std::vector<Image<Scalar, 3>> xs(K, x), ga(K, Image<Scalar, 3>(x.width(), x.height())), gb = ga;
  for (int k = 1; k < K; ++k)
    for (std::size_t i = 0; i < x.size(); ++i) xs[k].data()[i] = static_cast<Scalar>(0.9 * double(x.data()[i]) + 0.05 * k);
  std::vector<loss::SsimContext<Scalar, 3>> ca(K), cb(K);
  loss::SsimTarget<Scalar, 3> target;
  Scalar va[K], vb[K];
  auto separate = [&] {
    for (int k = 0; k < K; ++k) {
      va[k] = loss::ssim_forward<Scalar, 3>(xs[k], y, ca[k], p);
      ga[k].fill(Scalar(0));
      loss::ssim_backward<Scalar, 3>(ca[k], Scalar(1), ga[k], p);
    }
  };
  auto shared = [&] {
    loss::fill_ssim_target<Scalar, 3>(y, target, {}, p);
    for (int k = 0; k < K; ++k) {
      vb[k] = loss::ssim_forward<Scalar, 3>(xs[k], target, cb[k], p);
      gb[k].fill(Scalar(0));
      loss::ssim_backward<Scalar, 3>(cb[k], Scalar(1), gb[k], p);
    }
  };
  separate();  // warm-up (sizes the contexts)
  shared();
  SharedTiming out;
  out.identical = true;
  for (int k = 0; k < K; ++k) out.identical = out.identical && va[k] == vb[k] && ga[k].storage() == gb[k].storage();
  bench::Samples sa, sb, sf;
  for (int i = 0; i < runs; ++i) {
    bench::measure(sa, separate);
    bench::measure(sb, shared);
    bench::measure(sf, [&] { loss::fill_ssim_target<Scalar, 3>(y, target, {}, p); });
  }
  out.separate = {sa.wall_ms(), sa.cpu_ms()};
  out.shared = {sb.wall_ms(), sb.cpu_ms()};
  out.fill = {sf.wall_ms(), sf.cpu_ms()};
  return out;
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
  const SharedTiming shared = time_shared_target<Scalar>(x, y, runs, p);
  using bench::round_to;
  bench::emit({{"bench", "loss"}, {"scalar", name}, {"width", w}, {"height", h}, {"channels", 3}, {"threads", threads}, {"runs", runs},
               {"ssim_value_ms", round_to(ssim_value.wall_ms, 2)}, {"ssim_fwd_bwd_ms", round_to(ssim_fb.wall_ms, 2)},
               {"l1_fwd_bwd_ms", round_to(l1_fb.wall_ms, 2)}, {"l1_dssim_fwd_bwd_ms", round_to(comb_fb.wall_ms, 2)},
               {"ssim_value_cpu_ms", round_to(ssim_value.cpu_ms, 2)}, {"ssim_fwd_bwd_cpu_ms", round_to(ssim_fb.cpu_ms, 2)},
               {"l1_fwd_bwd_cpu_ms", round_to(l1_fb.cpu_ms, 2)}, {"l1_dssim_fwd_bwd_cpu_ms", round_to(comb_fb.cpu_ms, 2)}});
  bench::emit({{"bench", "loss_shared_target"}, {"scalar", name}, {"width", w}, {"height", h}, {"channels", 3}, {"threads", threads},
               {"runs", runs}, {"terms", 3}, {"separate_ms", round_to(shared.separate.wall_ms, 2)},
               {"shared_ms", round_to(shared.shared.wall_ms, 2)}, {"fill_ms", round_to(shared.fill.wall_ms, 2)},
               {"separate_cpu_ms", round_to(shared.separate.cpu_ms, 2)}, {"shared_cpu_ms", round_to(shared.shared.cpu_ms, 2)},
               {"fill_cpu_ms", round_to(shared.fill.cpu_ms, 2)}, {"identical", shared.identical}, {"load", round_to(bench::load_avg(), 2)}});
}

}  // namespace

int main(int argc, char** argv) {
  int runs = 7, w = 854, h = 480;
  std::vector<std::string> scalars = {"float", "double"};
  std::vector<unsigned> thread_counts = {1, 2};
  try {
    for (int i = 1; i + 1 < argc; i += 2) {
      const std::string k = argv[i];
      if (k == "--runs") runs = std::max(1, bench::parse_number<int>(k, argv[i + 1]));
      else if (k == "--width") w = bench::parse_number<int>(k, argv[i + 1]);
      else if (k == "--height") h = bench::parse_number<int>(k, argv[i + 1]);
      else if (k == "--scalar") scalars = bench::split_list(argv[i + 1]);
      else if (k == "--threads") {
        thread_counts.clear();
        for (const auto& t : bench::split_list(argv[i + 1])) thread_counts.push_back(std::max(1u, bench::parse_number<unsigned>(k, t)));
      }
    }
    for (const auto& s : scalars)
      if (s != "float" && s != "double") throw option_error("option.range", "--scalar", "expected float or double, got \"" + s + "\"");
  } catch (const error& e) {
    std::fprintf(stderr, "bench_loss: %s\n", e.what());
    return 2;
  }
  for (const auto& s : scalars)
    for (unsigned threads : thread_counts) {
      if (s == "float") run<float>(w, h, runs, threads, "float");
      else run<double>(w, h, runs, threads, "double");
    }
  return 0;
}
