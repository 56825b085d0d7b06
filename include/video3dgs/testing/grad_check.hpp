#pragma once
/// @file
/// Finite-difference gradient checking, used by every backward test.
///
///   g_fd[i] = (L(x + h e_i) - L(x - h e_i)) / (2h)          (central differences, double)
///   entry i passes  iff  |g[i] - g_fd[i]| <= atol + rtol |g_fd[i]|
///
/// rtol bounds the relative error of every entry whose gradient is well above atol / rtol, so a wrong
/// small gradient (a 100% error on a 1e-5-sized entry) fails unless atol was raised on purpose; atol
/// (default 1e-9) only absorbs the finite-difference noise of entries that are (nearly) zero: with L in
/// double and h = 1e-6 that noise is ~ eps |L| / h ~ 1e-10 |L|. A caller that raises atol says why
/// (a float loss, truncation error of a large step, a kink) next to it.
///
///     const auto r = testing::check_gradient("mean", params, grad, loss, {.rtol = 1e-6});
///     INFO(r);          // names the tolerance, the failing entries and the worst one
///     CHECK(r.ok());
///
/// The result keeps every entry's analytic and numeric value and says which passed; the worst entry is
/// the one with the largest normalised error |g - g_fd| / (atol + rtol |g_fd|) (ok() iff <= 1, every
/// value finite, and at most a quarter of the entries on jumps, see below).
///
/// Jumps. A loss with a jump J between x - h and x + h (a rasterizer's footprint cutoff crossing a
/// pixel centre) gives g_fd = g + J / (2h) there. An entry that fails at h is measured again at h/10
/// and h/100, with excesses e_k = g_fd(h / 10^k) - g:
///   - passes at h/10: that value is kept (the jump lay between h/10 and h);
///   - passes at h/100 and e_1 grew >= 5x over e_0 with the same sign: kept (between h/100 and h/10);
///   - e_0, e_1, e_2 finite, of one sign and growing >= 5x per tenth of the step (the 1/h signature a
///     derivative never has): the entry sits on a jump within h/100. It is then checked one-sidedly:
///     one of (L(x + h/100) - L(x)) / (h/100) and (L(x) - L(x - h/100)) / (h/100), the side away from
///     the jump, must match g within 10x the tolerance (the truncation error of a one-sided
///     difference); if so it counts in `kinks`, else it fails. ok() also requires at most a quarter
///     of the entries to be kinks.
/// Any other failure stays a failure.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <ostream>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "video3dgs/core/hash.hpp"

namespace video3dgs::testing {

/// Entry i passes iff |g - g_fd| <= atol + rtol |g_fd|.
struct GradTolerance {
  double rtol = 1e-6;
  double atol = 1e-9;
};

/// |analytic - numeric| / (atol + rtol |numeric|): an entry passes iff this is <= 1. Infinite if either
/// value is not finite (or if atol = rtol = 0 and the values differ).
[[nodiscard]] inline double normalised_error(double analytic, double numeric, const GradTolerance& tol) {
  if (!std::isfinite(analytic) || !std::isfinite(numeric)) return std::numeric_limits<double>::infinity();
  const double diff = std::abs(analytic - numeric);
  const double bound = tol.atol + tol.rtol * std::abs(numeric);
  if (diff == 0) return 0;
  return bound > 0 ? diff / bound : std::numeric_limits<double>::infinity();
}

/// Whether `analytic` matches `numeric` under `tol` (both finite).
[[nodiscard]] inline bool within(double analytic, double numeric, const GradTolerance& tol) {
  return normalised_error(analytic, numeric, tol) <= 1;
}

struct GradCheckResult {
  std::string name;               ///< what was checked (for messages)
  GradTolerance tolerance;        ///< what the entries were checked against
  std::size_t count = 0;          ///< entries checked
  std::vector<double> analytic;   ///< per entry: the gradient under test
  std::vector<double> numeric;    ///< per entry: its central difference
  std::size_t failures = 0;       ///< entries that fail (non-finite ones included)
  std::size_t kinks = 0;          ///< entries on a jump of the loss, checked one-sidedly (file comment)
  std::vector<char> kink;         ///< per entry: 1 if on a jump (`numeric` is then the one-sided value that matched)
  double max_error = 0;           ///< worst normalised error (<= 1: every entry passes)
  std::size_t worst_index = 0;    ///< entry with the worst normalised error (the first non-finite one if any)
  double analytic_at_worst = 0;
  double numeric_at_worst = 0;
  bool finite = true;             ///< every analytic and numeric entry finite

  /// Whether entry i passes: |analytic - numeric| <= atol + rtol |numeric|, both finite.
  [[nodiscard]] bool passed(std::size_t i) const {
    return (i < kink.size() && kink[i]) || within(analytic[i], numeric[i], tolerance);
  }
  /// Every entry passes (or sits on a jump), and at most a quarter of them sit on jumps.
  [[nodiscard]] bool ok() const { return finite && max_error <= 1 && failures == 0 && 4 * kinks <= count; }
  /// The tolerance is given to check_gradient (GradTolerance), not here.
  bool ok(double) const = delete;
};

inline std::ostream& operator<<(std::ostream& os, const GradCheckResult& r) {
  os << "grad_check(" << r.name << "): " << r.count << " entries, |g - g_fd| <= " << r.tolerance.atol << " + "
     << r.tolerance.rtol << " |g_fd|: " << r.failures << " fail";
  if (r.kinks > 0)
    os << ", " << r.kinks << " on a jump of the loss (checked one-sidedly" << (4 * r.kinks > r.count ? "; more than a quarter: not ok)" : ")");
  if (r.failures > 0 && r.analytic.size() == r.count && r.numeric.size() == r.count) {
    os << " (";
    std::size_t shown = 0;
    for (std::size_t i = 0; i < r.count && shown < 5; ++i)
      if (!r.passed(i)) os << (shown++ ? ", " : "") << "[" << i << "] " << r.analytic[i] << " vs " << r.numeric[i];
    if (r.failures > shown) os << ", ...";
    os << ")";
  }
  return os << "; worst [" << r.worst_index << "] analytic " << r.analytic_at_worst << " vs numeric " << r.numeric_at_worst
            << ", normalised error " << r.max_error << (r.finite ? "" : " (NON-FINITE values)");
}

/// Compares `analytic` (dL/dparams) against central differences of `loss()` taken by perturbing
/// `params` in place (each entry is restored afterwards). `loss` reads `params` (directly or through
/// a structure that shares its storage) and returns L in double.
/// @param tol   per-entry tolerance (required: say what the check can promise).
/// @param step  the finite-difference step h; with L in double, 1e-6 balances truncation and rounding.
template <class Loss>
[[nodiscard]] GradCheckResult check_gradient(std::string name, std::span<double> params,
                                             std::span<const double> analytic, Loss&& loss, GradTolerance tol,
                                             double step = 1e-6) {
  GradCheckResult r;
  r.name = std::move(name);
  r.tolerance = tol;
  r.count = params.size();
  if (analytic.size() != params.size()) {
    r.finite = false;
    r.failures = r.count;
    r.max_error = std::numeric_limits<double>::infinity();
    return r;
  }
  r.analytic.assign(analytic.begin(), analytic.end());
  r.numeric.resize(params.size());
  r.kink.assign(params.size(), 0);
  bool have_worst = false;  // the worst entry so far (kinks are not candidates)
  for (std::size_t i = 0; i < params.size(); ++i) {
    const double x0 = params[i];
    auto central = [&](double h) {
      params[i] = x0 + h;
      const double lp = loss();
      params[i] = x0 - h;
      const double lm = loss();
      params[i] = x0;
      return (lp - lm) / (2 * h);
    };
    double numeric = central(step);
    const double a = analytic[i];
    double e = normalised_error(a, numeric, tol);
    if (!(e <= 1) && std::isfinite(numeric) && std::isfinite(a)) {  // a jump within +-h? (file comment)
      const double n1 = central(step / 10), n2 = central(step / 100);
      const double e0 = numeric - a, e1 = n1 - a, e2 = n2 - a;
      auto grows = [](double lo, double hi) { return std::isfinite(hi) && lo != 0 && hi / lo >= 5; };  // same sign, >= 5x
      if (within(a, n1, tol)) {
        numeric = n1;
      } else if (within(a, n2, tol) && grows(e0, e1)) {
        numeric = n2;
      } else if (grows(e0, e1) && grows(e1, e2)) {
        const double h = step / 100, l0 = loss();
        params[i] = x0 + h;
        const double forward = (loss() - l0) / h;
        params[i] = x0 - h;
        const double backward = (l0 - loss()) / h;
        params[i] = x0;
        const GradTolerance one_sided{10 * tol.rtol, 10 * tol.atol};
        const bool fwd = within(a, forward, one_sided);
        if (fwd || within(a, backward, one_sided)) {
          r.kink[i] = 1;
          ++r.kinks;
          r.numeric[i] = fwd ? forward : backward;
          continue;
        }
      }
      e = normalised_error(a, numeric, tol);
    }
    r.numeric[i] = numeric;
    if (!(e <= 1)) ++r.failures;
    const bool nonfinite = !std::isfinite(numeric) || !std::isfinite(a);
    if (nonfinite) {
      if (r.finite) {  // the first non-finite entry is the worst
        r.worst_index = i;
        r.analytic_at_worst = a;
        r.numeric_at_worst = numeric;
        r.max_error = e;
      }
      r.finite = false;
      continue;
    }
    if (r.finite && (e > r.max_error || !have_worst)) {
      have_worst = true;
      r.max_error = e;
      r.worst_index = i;
      r.analytic_at_worst = a;
      r.numeric_at_worst = numeric;
    }
  }
  return r;
}

/// Convenience for vectors.
template <class Loss>
[[nodiscard]] GradCheckResult check_gradient(std::string name, std::vector<double>& params,
                                             const std::vector<double>& analytic, Loss&& loss, GradTolerance tol,
                                             double step = 1e-6) {
  return check_gradient(std::move(name), std::span<double>(params), std::span<const double>(analytic),
                        std::forward<Loss>(loss), tol, step);
}

/// Samples `per_group` entries of each optimiser group that `use(group)` accepts (the `largest`
/// entries by |gradient| first, the rest drawn uniformly by an engine seeded with `seed`) and checks
/// the group's gradient buffers against central differences of `loss()`, perturbing the group's
/// parameter buffers in place (restored afterwards). For end-to-end checks of a whole graph (a
/// training or refinement step), where every entry would cost a forward each. `Opt` is an
/// `Optimizer<double, Policy>` (or anything whose groups have a name and (value, grad) segments).
/// Returns one result per checked group, named after it; `count` is the number of samples.
template <class Opt, class Use, class Loss>
[[nodiscard]] std::vector<GradCheckResult> check_optimizer_gradients(const Opt& opt, Use&& use, Loss&& loss, GradTolerance tol,
                                                                     std::size_t per_group = 24, std::size_t largest = 6,
                                                                     std::uint64_t seed = 42, double step = 1e-6) {
  std::vector<GradCheckResult> out;
  std::uint64_t state = seed;
  auto next = [&state] {  // splitmix64 (core/hash.hpp): a fixed sequence on every standard library
    const std::uint64_t r = splitmix64(state);
    state += kSplitmix64Gamma;
    return r;
  };
  for (const auto& g : opt.groups()) {
    if (!use(g)) continue;
    std::vector<double*> value;
    std::vector<double> grad;
    for (const auto& seg : g.segments())
      for (std::size_t i = 0; i < seg.value.size(); ++i) {
        value.push_back(&seg.value[i]);
        grad.push_back(double(seg.grad[i]));
      }
    std::vector<std::size_t> order(value.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {  // largest first, ties by index
      return std::abs(grad[a]) > std::abs(grad[b]) || (std::abs(grad[a]) == std::abs(grad[b]) && a < b);
    });
    std::vector<std::size_t> pick(order.begin(), order.begin() + std::ptrdiff_t(std::min(largest, order.size())));
    std::vector<char> taken(value.size(), 0);  // distinct entries: a repeated one would undo its own perturbation
    for (std::size_t i : pick) taken[i] = 1;
    while (pick.size() < std::min(per_group, value.size())) {
      const std::size_t i = std::size_t(next() % value.size());
      if (!taken[i]) taken[i] = 1, pick.push_back(i);
    }
    std::vector<double> x(pick.size()), a(pick.size());
    for (std::size_t k = 0; k < pick.size(); ++k) x[k] = *value[pick[k]], a[k] = grad[pick[k]];
    auto loss_at_x = [&] {
      for (std::size_t k = 0; k < pick.size(); ++k) *value[pick[k]] = x[k];
      return loss();
    };
    out.push_back(check_gradient(g.name(), std::span<double>(x), std::span<const double>(a), loss_at_x, tol, step));
    for (std::size_t k = 0; k < pick.size(); ++k) *value[pick[k]] = x[k];
  }
  return out;
}

}  // namespace video3dgs::testing
