#pragma once
/// @file
/// Adaptive density control of 3DGS (Kerbl et al. 2023, Sec. 5.2) on a `GaussianCloud`:
///
///   g_i  = accum_i / count_i                 mean 2D position-gradient norm over the views that saw i
///   selected_i = count_i > 0 and g_i >= threshold
///   clone   selected and max_k exp(s_ik) <= dense_scale:  append an exact copy of i
///   split   selected and max_k exp(s_ik) >  dense_scale:  append `children` copies with
///           mean = mu_i + R(q_i) (exp(s_i) . n),  n ~ N(0, I),   s = s_i - log(split_scale_divisor),
///           then remove i
///   prune   sigmoid(opacity_i) < prune_opacity (every row, new ones included), or, with blend
///           weights given and prune_weight > 0, count_i > 0 and weight_i < prune_weight (old rows;
///           such a row is never selected either). weight_i is the caller's measure of i's
///           contribution, for example its mean blend weight sum_p alpha_i T_i over the views that
///           saw it (rasterizer/backward.hpp); a row no view saw is not judged.
///
/// Rows are appended at the end (clones in index order, then each split's children) and then kept
/// in order, so a `RowEdit` callback can apply the same edit to the optimizer moments:
/// `on_rows(sources, keep)` with sources = the source row of every appended row and keep = the mask
/// over old + appended rows (Optimizer::append_rows then keep_rows).
///
/// Budget (`max_count`), never exceeded by the result and never below one Gaussian:
///   - when every selected clone and split fits (counted before the prune), all are taken (the
///     unbounded rule above);
///   - otherwise candidates that the prune would remove anyway are dropped, and the rest are taken in
///     decreasing g_i (ties: lower index first) while the cloud after pruning stays within max_count
///     (a clone costs one row, a split children - 1); rows keep their order as above;
///   - a cloud above max_count after pruning (e.g. one initialised above it) loses its most
///     transparent rows (ties: higher index first) down to max_count;
///   - a prune that would empty the cloud keeps its most opaque row (ties: lower index).

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numbers>
#include <random>
#include <span>
#include <utility>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/gaussian/activations.hpp"
#include "video3dgs/gaussian/cloud.hpp"

namespace video3dgs {

struct DensifyOptions {
  double grad_threshold = 2e-4;
  double dense_scale = 0.01;  ///< world units: percent_dense x extent
  int children = 2;
  double split_scale_divisor = 1.6;
  double prune_opacity = 0.005;
  double prune_weight = 0;  ///< > 0: prune old rows whose weight is below this (file comment)
  std::size_t max_count = 3'000'000;
};

struct DensifyResult {
  std::size_t cloned = 0, split = 0, pruned = 0;
};

/// Standard normal from a 64-bit engine (Box-Muller; portable, unlike std::normal_distribution).
template <class Rng>
[[nodiscard]] double portable_normal(Rng& rng) {
  const double u1 = 1.0 - double(rng() >> 11) * 0x1.0p-53;  // (0, 1]
  const double u2 = double(rng() >> 11) * 0x1.0p-53;
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
}

/// Clones, splits and prunes `cloud` (see the file comment). `accum`, `count` and `weight` (or an
/// empty `weight`: no pruning by weight) have one entry per Gaussian. Deterministic for a given
/// engine state.
template <class Scalar, int D, class Rng, class RowEdit>
DensifyResult densify_and_prune(GaussianCloud<Scalar, D>& cloud, std::span<const Scalar> accum, std::span<const Scalar> count,
                                std::span<const Scalar> weight, const DensifyOptions& o, Rng& rng, RowEdit&& on_rows) {
  const std::size_t n = cloud.size();
  constexpr std::size_t K3 = std::size_t(3 * sh::coeff_count(D));
  DensifyResult res;
  if (accum.size() != n || count.size() != n || (!weight.empty() && weight.size() != n))
    throw option_error("option.densify", "accum/count/weight", "need one entry per Gaussian");
  const bool by_weight = o.prune_weight > 0 && !weight.empty();
  auto light = [&](std::size_t i) { return by_weight && i < n && count[i] > 0 && !(weight[i] >= Scalar(o.prune_weight)); };
  std::vector<std::size_t> clones, splits;
  for (std::size_t i = 0; i < n; ++i) {
    if (!(count[i] > 0) || light(i)) continue;
    const Scalar g = accum[i] / count[i];
    if (!(g >= Scalar(o.grad_threshold))) continue;
    const Scalar ms = scale_from_log(std::max({cloud.log_scale[3 * i], cloud.log_scale[3 * i + 1], cloud.log_scale[3 * i + 2]}));
    (ms <= Scalar(o.dense_scale) ? clones : splits).push_back(i);
  }
  const std::size_t n_clones = clones.size();
  const std::size_t children = static_cast<std::size_t>(std::max(o.children, 1));
  const Scalar min_logit = logit(Scalar(o.prune_opacity));
  auto prunable = [&](std::size_t i) { return (o.prune_opacity > 0 && cloud.opacity_logit[i] < min_logit) || light(i); };
  if (n + clones.size() + splits.size() * children > o.max_count) {
    // Budget binds: rows that survive the prune, then candidates by decreasing mean gradient.
    std::size_t survivors = 0;
    for (std::size_t i = 0; i < n; ++i) survivors += prunable(i) ? 0 : 1;
    std::vector<std::pair<std::size_t, bool>> cand;  // (row, is a split)
    cand.reserve(clones.size() + splits.size());
    for (std::size_t j = 0; j < clones.size() + splits.size(); ++j) {
      const std::size_t i = j < n_clones ? clones[j] : splits[j - n_clones];
      if (!prunable(i)) cand.emplace_back(i, j >= n_clones);
    }
    // A total order (ties by row, then clone before split), so std::sort is deterministic; std::sort
    // rather than stable_sort, whose temporary buffer GCC 12's ASan reports as an alloc-dealloc mismatch.
    std::sort(cand.begin(), cand.end(), [&](const auto& a, const auto& b) {
      const Scalar ga = accum[a.first] / count[a.first], gb = accum[b.first] / count[b.first];
      return ga > gb || (ga == gb && (a.first < b.first || (a.first == b.first && a.second < b.second)));
    });
    std::vector<std::uint8_t> take(n, 0);
    std::size_t size = survivors;
    for (const auto& [i, is_split] : cand) {
      const std::size_t cost = is_split ? children - 1 : 1;
      if (size + cost > o.max_count) continue;  // a cheaper candidate further down may still fit
      size += cost;
      take[i] = 1;
    }
    std::erase_if(clones, [&](std::size_t i) { return !take[i]; });
    std::erase_if(splits, [&](std::size_t i) { return !take[i]; });
  }
  std::vector<std::size_t> sources;
  sources.reserve(clones.size() + splits.size() * children);
  for (std::size_t i : clones) sources.push_back(i);
  for (std::size_t i : splits)
    for (std::size_t c = 0; c < children; ++c) sources.push_back(i);
  const std::size_t total = n + sources.size();
  cloud.resize(total);
  const Scalar dlog = Scalar(std::log(o.split_scale_divisor));
  for (std::size_t j = 0; j < sources.size(); ++j) {
    const std::size_t s = sources[j], d = n + j;
    for (int k = 0; k < 3; ++k) cloud.mean[3 * d + k] = cloud.mean[3 * s + k];
    for (int k = 0; k < 3; ++k) cloud.log_scale[3 * d + k] = cloud.log_scale[3 * s + k];
    for (int k = 0; k < 4; ++k) cloud.rotation[4 * d + k] = cloud.rotation[4 * s + k];
    cloud.opacity_logit[d] = cloud.opacity_logit[s];
    for (std::size_t k = 0; k < K3; ++k) cloud.sh[K3 * d + k] = cloud.sh[K3 * s + k];
    if (j < clones.size()) continue;
    // Split child: sample inside the parent, shrink.
    std::array<Scalar, 4> q;
    Scalar inv;
    normalize_quaternion(cloud.rotation.data() + 4 * s, q, inv);
    const Scalar w = q[0], x = q[1], y = q[2], z = q[3];
    const Scalar R[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                            {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                            {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
    Scalar v[3];
    for (int k = 0; k < 3; ++k) v[k] = scale_from_log(cloud.log_scale[3 * s + k]) * Scalar(portable_normal(rng));
    for (int r = 0; r < 3; ++r) cloud.mean[3 * d + r] += R[r][0] * v[0] + R[r][1] * v[1] + R[r][2] * v[2];
    for (int k = 0; k < 3; ++k) cloud.log_scale[3 * d + k] -= dlog;
  }
  res.cloned = clones.size();
  res.split = splits.size();

  std::vector<std::uint8_t> keep(total, 1);
  for (std::size_t i : splits) keep[i] = 0;
  std::size_t kept = total - splits.size();
  for (std::size_t i = 0; i < total; ++i)
    if (keep[i] && prunable(i)) {
      keep[i] = 0;
      ++res.pruned;
      --kept;
    }
  if (kept > o.max_count) {  // above the budget without growth: drop the most transparent rows
    std::vector<std::size_t> order;
    order.reserve(kept);
    for (std::size_t i = 0; i < total; ++i)
      if (keep[i]) order.push_back(i);
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {  // a total order: ties by row
      return cloud.opacity_logit[a] < cloud.opacity_logit[b] || (cloud.opacity_logit[a] == cloud.opacity_logit[b] && a > b);
    });
    for (std::size_t j = 0; kept > std::max<std::size_t>(o.max_count, 1); ++j, --kept, ++res.pruned) keep[order[j]] = 0;
  }
  if (kept == 0 && total > 0) {  // never empty: keep the most opaque row that was pruned (not a split parent)
    std::vector<std::uint8_t> parent(total, 0);
    for (std::size_t i : splits) parent[i] = 1;
    std::size_t best = total;
    for (std::size_t i = 0; i < total; ++i)
      if (!parent[i] && (best == total || cloud.opacity_logit[i] > cloud.opacity_logit[best])) best = i;
    keep[best] = 1;  // exists: a split parent has children, which are never parents
    --res.pruned;
  }
  // Compact in place (order preserved).
  std::size_t out = 0;
  for (std::size_t i = 0; i < total; ++i) {
    if (!keep[i]) continue;
    if (out != i) {
      for (int k = 0; k < 3; ++k) cloud.mean[3 * out + k] = cloud.mean[3 * i + k];
      for (int k = 0; k < 3; ++k) cloud.log_scale[3 * out + k] = cloud.log_scale[3 * i + k];
      for (int k = 0; k < 4; ++k) cloud.rotation[4 * out + k] = cloud.rotation[4 * i + k];
      cloud.opacity_logit[out] = cloud.opacity_logit[i];
      for (std::size_t k = 0; k < K3; ++k) cloud.sh[K3 * out + k] = cloud.sh[K3 * i + k];
    }
    ++out;
  }
  cloud.resize(out);
  on_rows(std::span<const std::size_t>(sources), std::span<const std::uint8_t>(keep));
  return res;
}

/// `densify_and_prune` without blend weights.
template <class Scalar, int D, class Rng, class RowEdit>
DensifyResult densify_and_prune(GaussianCloud<Scalar, D>& cloud, std::span<const Scalar> accum, std::span<const Scalar> count,
                                const DensifyOptions& o, Rng& rng, RowEdit&& on_rows) {
  return densify_and_prune(cloud, accum, count, std::span<const Scalar>{}, o, rng, std::forward<RowEdit>(on_rows));
}

}  // namespace video3dgs
