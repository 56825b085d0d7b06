// The hash grid's run-time dispatched AVX2 level kernels against the portable ones: outputs, table
// gradients and input gradients bit-identical (no FMA in either copy), float and double, dense and
// hashed levels, linear and smoothstep, the 2-feature vector path and the generic one.
#include <doctest/doctest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "../test_data.hpp"
#include "video3dgs/hash_grid/hash_grid.hpp"

using namespace video3dgs;

namespace {

template <class Scalar>
struct Encoded {
  std::vector<Scalar> out, dtable, dinputs;
};

template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

/// Forward + backward (table and inputs) of a grid built with `o` on the path `simd`.
template <class Grid>
Encoded<typename Grid::scalar_type> encode(HashGridOptions o, GridSimd simd, const std::vector<typename Grid::scalar_type>& x,
                                           const std::vector<typename Grid::scalar_type>& g, unsigned threads) {
  using Scalar = typename Grid::scalar_type;
  o.simd = simd;
  const Grid grid(o);
  const std::size_t n = x.size() / Grid::kDims;
  ThreadPool pool(threads);
  Encoded<Scalar> e;
  e.out.assign(Grid::kOutputs * n, Scalar(0));
  e.dtable.assign(grid.param_count(), Scalar(0));
  e.dinputs.assign(x.size(), Scalar(0));
  grid.forward(x.data(), n, e.out.data(), &pool);
  grid.backward(x.data(), n, g.data(), e.dtable.data(), e.dinputs.data(), &pool);
  return e;
}

/// `last_axis_cells`: HashGridOptions::max_cells of the last axis (0 = none).
template <class Grid>
void check_paths(GridInterpolation interp, std::uint64_t seed, std::uint32_t last_axis_cells = 0) {
  using Scalar = typename Grid::scalar_type;
  CAPTURE(seed);
  CAPTURE(Grid::kDims);
  CAPTURE(Grid::kFeatures);
  CAPTURE(interp == GridInterpolation::smoothstep);
  CAPTURE(last_axis_cells);
  HashGridOptions o;
  o.max_cells[Grid::kDims - 1] = last_axis_cells;
  o.base_resolution = 5;
  o.per_level_scale = 1.7;  // dense coarse levels, hashed fine ones
  o.interpolation = interp;
  o.init_range = 0.5;
  o.seed = seed;
  auto rng = test::seeded_rng(seed);
  std::uniform_real_distribution<double> u(-0.03, 1.03), ug(-1, 1);  // a few points outside [0, 1]
  const std::size_t n = 1000 + 37;  // whole batches and a partial one
  std::vector<Scalar> x(n * Grid::kDims), g(Grid::kOutputs * n);
  for (auto& v : x) v = Scalar(u(rng));
  x[5] = Scalar(1), x[6] = Scalar(0), x[7] = std::numeric_limits<Scalar>::quiet_NaN();  // edges and NaN
  for (auto& v : g) v = Scalar(ug(rng));
  {
    const Grid grid(o);
    bool dense = false, hashed = false;
    for (int l = 0; l < Grid::kLevels; ++l) (grid.dense(l) ? dense : hashed) = true;
    CHECK(dense);
    CHECK(hashed);
  }
  const auto ref = encode<Grid>(o, GridSimd::portable, x, g, 2);
  bool nonzero = false;
  for (Scalar v : ref.dinputs) nonzero = nonzero || v != Scalar(0);
  CHECK(nonzero);
  for (GridSimd simd : {GridSimd::avx2, GridSimd::automatic}) {
    if (!grid_simd_supported(simd)) {
      MESSAGE("hash grid SIMD path " << grid_simd_name(simd) << " not supported here: skipped");
      continue;
    }
    const std::string path = grid_simd_name(simd);
    CAPTURE(path);
    for (unsigned threads : {1u, 2u}) {
      CAPTURE(threads);
      const auto got = encode<Grid>(o, simd, x, g, threads);
      CHECK(same_bits(got.out, ref.out));
      CHECK(same_bits(got.dtable, ref.dtable));
      CHECK(same_bits(got.dinputs, ref.dinputs));
    }
  }
}

}  // namespace

TEST_CASE("hash grid simd: names, support, unsupported choice rejected") {
  CHECK(std::string(grid_simd_name(GridSimd::automatic)) == "automatic");
  CHECK(std::string(grid_simd_name(GridSimd::portable)) == "portable");
  CHECK(std::string(grid_simd_name(GridSimd::avx2)) == "avx2");
  CHECK(grid_simd_supported(GridSimd::automatic));
  CHECK(grid_simd_supported(GridSimd::portable));
  HashGridOptions o;
  o.simd = GridSimd::avx2;
  if (grid_simd_supported(GridSimd::avx2)) {
    CHECK_NOTHROW((HashGrid<float, 2, 2, 2, 8>(o)));
  } else {
    CHECK(test::error_id([&] { HashGrid<float, 2, 2, 2, 8> grid(o); }) == "option.hash_grid");
  }
}

TEST_CASE_TEMPLATE("hash grid simd: the AVX2 path is bit-identical to the portable one", Scalar, float, double) {
  for (auto interp : {GridInterpolation::linear, GridInterpolation::smoothstep}) {
    check_paths<HashGrid<Scalar, 4, 8, 2, 12>>(interp, 11);  // the deformation grid's shape: 2-lane vector path
    check_paths<HashGrid<Scalar, 3, 6, 3, 11>>(interp, 12);  // generic feature loop
    check_paths<HashGrid<Scalar, 2, 5, 1, 9>>(interp, 13);
    check_paths<HashGrid<Scalar, 4, 8, 2, 12>>(interp, 14, 9);  // time capped as for a 10-frame clip
  }
}
