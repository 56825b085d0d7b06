#include "video3dgs/core/parallel.hpp"

#include <numeric>
#include <stdexcept>
#include <vector>

#include <doctest/doctest.h>

using namespace video3dgs;

namespace {
// A float sum whose rounding depends on summation order: chunked partial sums reduced in chunk order.
float chunked_sum(ThreadPool* pool, const std::vector<float>& v) {
  const std::size_t grain = 1000;
  std::vector<float> partial(chunk_count(v.size(), grain), 0.f);
  parallel_for_chunks(pool, v.size(), grain, [&](std::size_t k, std::size_t b, std::size_t e) {
    float s = 0;
    for (std::size_t i = b; i < e; ++i) s += v[i];
    partial[k] = s;
  });
  float total = 0;
  for (float p : partial) total += p;
  return total;
}
}  // namespace

TEST_CASE("parallel: chunked reductions are bit-identical for any thread count") {
  std::vector<float> v(123457);
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = 1.0f / float(1 + (i * 7919) % 1013);
  const float serial = chunked_sum(nullptr, v);
  for (unsigned threads : {1u, 2u, 3u, 8u}) {
    ThreadPool pool(threads);
    CHECK(pool.size() == threads);
    for (int rep = 0; rep < 20; ++rep) CHECK(chunked_sum(&pool, v) == serial);
  }
}

TEST_CASE("parallel: every index visited once, nested loops and exceptions") {
  ThreadPool pool(4);
  std::vector<int> hits(10007, 0);
  parallel_for(&pool, hits.size(), [&](std::size_t i) { hits[i] += 1; }, 13);
  CHECK(std::accumulate(hits.begin(), hits.end(), 0) == 10007);
  CHECK(*std::min_element(hits.begin(), hits.end()) == 1);

  std::vector<int> nested(64, 0);
  parallel_for(&pool, 8, [&](std::size_t i) {
    parallel_for(&pool, 8, [&](std::size_t j) { nested[i * 8 + j] = 1; }, 1);
  }, 1);
  CHECK(std::accumulate(nested.begin(), nested.end(), 0) == 64);

  CHECK_THROWS_AS(parallel_for(&pool, 100, [](std::size_t i) { if (i == 57) throw std::runtime_error("x"); }, 1),
                  std::runtime_error);
  // The pool is still usable after an exception.
  int zero_tasks = 0;
  parallel_for(&pool, 0, [&](std::size_t) { ++zero_tasks; });
  CHECK(zero_tasks == 0);
  std::vector<int> after(100, 0);
  parallel_for(&pool, after.size(), [&](std::size_t i) { after[i] = 1; }, 3);
  CHECK(std::accumulate(after.begin(), after.end(), 0) == 100);
}
