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
///   prune   sigmoid(opacity_i) < prune_opacity (every row, new ones included)
///
/// Rows are appended at the end (clones in index order, then each split's children) and then kept
/// in order, so a `RowEdit` callback can apply the same edit to the optimizer moments:
/// `on_rows(sources, keep)` with sources = the source row of every appended row and keep = the mask
/// over old + appended rows (Optimizer::append_rows then keep_rows). Growth that would take the
/// cloud beyond `max_count` is skipped (pruning still runs).

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numbers>
#include <random>
#include <span>
#include <vector>

#include "video3dgs/gaussian/activations.hpp"
#include "video3dgs/gaussian/cloud.hpp"

namespace video3dgs {

struct DensifyOptions {
  double grad_threshold = 2e-4;
  double dense_scale = 0.01;  ///< world units: percent_dense x extent
  int children = 2;
  double split_scale_divisor = 1.6;
  double prune_opacity = 0.005;
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

/// Clones, splits and prunes `cloud` (see the file comment). `accum` and `count` have one entry per
/// Gaussian. Deterministic for a given engine state.
template <class Scalar, int D, class Rng, class RowEdit>
DensifyResult densify_and_prune(GaussianCloud<Scalar, D>& cloud, std::span<const Scalar> accum, std::span<const Scalar> count,
                                const DensifyOptions& o, Rng& rng, RowEdit&& on_rows) {
  const std::size_t n = cloud.size();
  constexpr std::size_t K3 = std::size_t(3 * sh::coeff_count(D));
  DensifyResult res;
  std::vector<std::size_t> clones, splits;
  for (std::size_t i = 0; i < n; ++i) {
    if (!(count[i] > 0)) continue;
    const Scalar g = accum[i] / count[i];
    if (!(g >= Scalar(o.grad_threshold))) continue;
    const Scalar ms = scale_from_log(std::max({cloud.log_scale[3 * i], cloud.log_scale[3 * i + 1], cloud.log_scale[3 * i + 2]}));
    (ms <= Scalar(o.dense_scale) ? clones : splits).push_back(i);
  }
  const std::size_t children = static_cast<std::size_t>(std::max(o.children, 1));
  if (n + clones.size() + splits.size() * children > o.max_count) {
    clones.clear();
    splits.clear();
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
  const Scalar min_logit = logit(Scalar(o.prune_opacity));
  for (std::size_t i = 0; i < total; ++i)
    if (keep[i] && (o.prune_opacity > 0 && cloud.opacity_logit[i] < min_logit)) {
      keep[i] = 0;
      ++res.pruned;
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

}  // namespace video3dgs
