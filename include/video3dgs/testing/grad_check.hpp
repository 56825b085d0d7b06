#pragma once
/// @file
/// Finite-difference gradient checking, used by every backward test.
///
///   g_fd[i] = (L(x + h e_i) - L(x - h e_i)) / (2h)          (central differences, double)
///   err[i]  = |g[i] - g_fd[i]| / max(1, |g_fd[i]|)
///
/// The check reports the worst entry so a failing test says where to look.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <ostream>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace video3dgs::testing {

struct GradCheckResult {
  std::string name;               ///< what was checked (for messages)
  std::size_t count = 0;          ///< entries checked
  double max_error = 0;           ///< worst relative error
  std::size_t worst_index = 0;    ///< entry with the worst error
  double analytic_at_worst = 0;
  double numeric_at_worst = 0;
  bool finite = true;             ///< every analytic and numeric entry finite

  [[nodiscard]] bool ok(double tolerance) const { return finite && max_error <= tolerance; }
};

inline std::ostream& operator<<(std::ostream& os, const GradCheckResult& r) {
  return os << "grad_check(" << r.name << "): " << r.count << " entries, max rel error " << r.max_error
            << " at [" << r.worst_index << "] analytic " << r.analytic_at_worst << " vs numeric "
            << r.numeric_at_worst << (r.finite ? "" : " (NON-FINITE values)");
}

/// The relative error used throughout: |g - g_fd| / max(1, |g_fd|).
[[nodiscard]] inline double relative_error(double analytic, double numeric) {
  return std::abs(analytic - numeric) / std::max(1.0, std::abs(numeric));
}

/// Compares `analytic` (dL/dparams) against central differences of `loss()` taken by perturbing
/// `params` in place (each entry is restored afterwards). `loss` reads `params` (directly or through
/// a structure that shares its storage) and returns L in double.
/// @param step  the finite-difference step h; with L in double, 1e-6 balances truncation and rounding.
template <class Loss>
[[nodiscard]] GradCheckResult check_gradient(std::string name, std::span<double> params,
                                             std::span<const double> analytic, Loss&& loss,
                                             double step = 1e-6) {
  GradCheckResult r;
  r.name = std::move(name);
  r.count = params.size();
  if (analytic.size() != params.size()) {
    r.finite = false;
    r.max_error = std::numeric_limits<double>::infinity();
    return r;
  }
  for (std::size_t i = 0; i < params.size(); ++i) {
    const double x0 = params[i];
    params[i] = x0 + step;
    const double lp = loss();
    params[i] = x0 - step;
    const double lm = loss();
    params[i] = x0;
    const double numeric = (lp - lm) / (2 * step);
    const double a = analytic[i];
    if (!std::isfinite(numeric) || !std::isfinite(a)) {
      if (r.finite) {
        r.worst_index = i;
        r.analytic_at_worst = a;
        r.numeric_at_worst = numeric;
      }
      r.finite = false;
      continue;
    }
    const double e = relative_error(a, numeric);
    if (e >= r.max_error && r.finite) {
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
                                             const std::vector<double>& analytic, Loss&& loss,
                                             double step = 1e-6) {
  return check_gradient(std::move(name), std::span<double>(params), std::span<const double>(analytic),
                        std::forward<Loss>(loss), step);
}

}  // namespace video3dgs::testing
