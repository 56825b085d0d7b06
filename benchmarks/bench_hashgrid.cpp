// Hash-grid (and deformation-field) forward/backward timings. One JSON line per configuration:
// {"bench":"hashgrid","dims":4,"levels":16,"log2_table":19,"points":100000,"threads":2,"forward_ms":..,"backward_ms":..}
// Medians of 7 runs; float; uniform random points in [0,1]^4; backward = zeroing the table gradient +
// the table scatter-add, as a training step pays it (the trainer zeroes the gradients every iteration);
// zero_grad_ms is the zeroing alone (inside backward_ms, "backward_includes_zero_grad":true).
// *_ms is wall time; *_cpu_ms the process CPU time (all threads) and load1 the load average, so a run
// on a shared machine can be read: with no contention wall ~ cpu / threads for these loops.
// Last line: {"bench":"deformation",...}: DeformationField (grid 2^19 + three linear heads + composition),
// 100k Gaussians, forward and backward (grid table, heads, canonical parameters); its backward_ms also
// includes zeroing the field's and the canonical gradients (field.zero_grad() and the three canonical
// buffers, as ClipTrainer does every iteration), zero_grad_ms that zeroing alone.
// {"bench":"deformation_clip",...}: the same field as a clip trains it: 2^16 entries per level (the
// model's default), the time axis capped at 9 cells (one slice per frame of a 10-frame clip) and the
// times of the clip's frames, t = i / 9 (every frame on a vertex of the time axis), 290k Gaussians (both
// sets of a full-size DAVIS clip); medians over 20 runs, two per frame.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

#include "video3dgs/deformation.hpp"
#include "video3dgs/hash_grid.hpp"

#include "bench_common.hpp"

namespace {

namespace bench = video3dgs::bench;

template <int Log2>
void bench_grid(std::size_t n, unsigned threads, int runs) {
  using Grid = video3dgs::HashGrid<float, 4, 16, 2, Log2>;
  Grid grid;
  std::mt19937 rng(42);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  std::vector<float> x(n * 4);
  for (auto& v : x) v = u(rng);
  std::vector<float> out(Grid::kOutputs * n), gout(Grid::kOutputs * n), gtable(grid.param_count());
  for (auto& v : gout) v = u(rng) - 0.5f;
  video3dgs::ThreadPool pool(threads);
  bench::Samples fwd, bwd, zero;
  for (int r = 0; r < runs; ++r) {
    bench::measure(fwd, [&] { grid.forward(x.data(), n, out.data(), &pool); });
    bench::measure(bwd, [&] {
      bench::measure(zero, [&] { std::fill(gtable.begin(), gtable.end(), 0.f); });
      grid.backward(x.data(), n, gout.data(), gtable.data(), nullptr, &pool);
    });
  }
  using bench::round_to;
  bench::emit({{"bench", "hashgrid"}, {"dims", 4}, {"levels", 16}, {"log2_table", Log2}, {"points", n}, {"threads", threads},
               {"forward_ms", round_to(fwd.wall_ms(), 3)}, {"backward_ms", round_to(bwd.wall_ms(), 3)},
               {"forward_cpu_ms", round_to(fwd.cpu_ms(), 3)}, {"backward_cpu_ms", round_to(bwd.cpu_ms(), 3)},
               {"load1", round_to(bench::load_avg(), 2)}, {"zero_grad_ms", round_to(zero.wall_ms(), 3)},
               {"zero_grad_cpu_ms", round_to(zero.cpu_ms(), 3)}, {"backward_includes_zero_grad", true}});
}

/// The whole deformation field (grid + three linear heads + parameter composition) on n Gaussians;
/// `clip`: as a 10-frame clip trains it (see the file comment).
void bench_deformation(std::size_t n, unsigned threads, int runs, bool clip) {
  using Field = video3dgs::DeformationField<float, video3dgs::HashGrid4D<float, 19>>;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  std::vector<float> mean(n * 3), ls(n * 3), rot(n * 4);
  for (auto& v : mean) v = u(rng);
  for (auto& v : ls) v = -3.f + 0.5f * u(rng);
  for (auto& v : rot) v = u(rng);
  video3dgs::DeformationOptions opts;
  opts.head_init.init = video3dgs::HeadInit::uniform_fan_in;
  if (clip) {
    opts.grid.log2_table_size = 16;
    opts.grid.max_cells[3] = 9;
  }
  Field field(mean, opts);
  std::vector<float> m(n * 3), s(n * 3), q(n * 4), gm(n * 3), gs(n * 3), gq(n * 4);
  std::vector<float> dm(n * 3), ds(n * 3), dq(n * 4);
  for (auto& v : dm) v = u(rng);
  for (auto& v : ds) v = u(rng);
  for (auto& v : dq) v = u(rng);
  Field::Context ctx;
  video3dgs::ThreadPool pool(threads);
  bench::Samples fwd, bwd, zero;
  for (int r = 0; r < runs; ++r) {
    const float t = clip ? float(r % 10) / 9.f : float(r) / float(runs);
    bench::measure(fwd, [&] { field.forward({mean.data(), ls.data(), rot.data(), n, t}, {m.data(), s.data(), q.data()}, ctx, &pool); });
    // As ClipTrainer's step: zero the canonical gradients and the field's, then backward (which adds).
    bench::measure(bwd, [&] {
      bench::measure(zero, [&] {
        std::fill(gm.begin(), gm.end(), 0.f);
        std::fill(gs.begin(), gs.end(), 0.f);
        std::fill(gq.begin(), gq.end(), 0.f);
        field.zero_grad();
      });
      field.backward(ctx, dm.data(), ds.data(), dq.data(), {gm.data(), gs.data(), gq.data()}, &pool);
    });
  }
  using bench::round_to;
  bench::emit({{"bench", clip ? "deformation_clip" : "deformation"}, {"dims", 4}, {"levels", 16}, {"log2_table", clip ? 16 : 19},
               {"time_cells", clip ? 9 : 0}, {"points", n}, {"threads", threads},
               {"forward_ms", round_to(fwd.wall_ms(), 3)}, {"backward_ms", round_to(bwd.wall_ms(), 3)},
               {"forward_cpu_ms", round_to(fwd.cpu_ms(), 3)}, {"backward_cpu_ms", round_to(bwd.cpu_ms(), 3)},
               {"load1", round_to(bench::load_avg(), 2)}, {"zero_grad_ms", round_to(zero.wall_ms(), 3)},
               {"zero_grad_cpu_ms", round_to(zero.cpu_ms(), 3)}, {"backward_includes_zero_grad", true}});
}

}  // namespace

// Usage: bench_hashgrid [log2_table (14|16|19; 1 = deformation only; 2 = deformation_clip only; 0 = all)]
//                       [threads (0 = 1 and 2)]
int main(int argc, char** argv) {
  const std::size_t n = 100000;
  const int runs = 7;
  int only_log2 = 0;
  unsigned only_threads = 0;
  try {
    if (argc > 1) only_log2 = bench::parse_number<int>("log2_table", argv[1]);
    if (argc > 2) only_threads = bench::parse_number<unsigned>("threads", argv[2]);
  } catch (const video3dgs::error& e) {
    std::fprintf(stderr, "bench_hashgrid: %s\n", e.what());
    return 2;
  }
  for (unsigned threads : {1u, 2u}) {
    if (only_threads && threads != only_threads) continue;
    if (!only_log2 || only_log2 == 14) bench_grid<14>(n, threads, runs);
    if (!only_log2 || only_log2 == 16) bench_grid<16>(n, threads, runs);
    if (!only_log2 || only_log2 == 19) bench_grid<19>(n, threads, runs);
  }
  if (!only_log2 || only_log2 == 1) bench_deformation(n, only_threads ? only_threads : 2u, runs, false);
  if (!only_log2 || only_log2 == 2) bench_deformation(290000, only_threads ? only_threads : 2u, 20, true);
  return 0;
}
