#pragma once
/// @file
/// Learning-rate schedules. `LrSchedule::exponential` is the log-linear decay of 3DGS
/// (`get_expon_lr_func`), with an optional warm-up delay:
///
///     r(k)   = clamp(k / K, 0, 1)
///     lr(k)  = delay(k) * exp((1 - r) log lr_0 + r log lr_1)
///     delay(k) = m + (1 - m) sin(pi/2 clamp(k / D, 0, 1))    if D > 0, else 1
///
/// (k: step, K: max_steps, D: delay_steps, m: delay_mult). lr(k) = 0 for k < 0 or lr_0 = lr_1 = 0.
///
/// Either kind may carry one step (`with_step(S, f)`): lr(k) x f for k >= S (TrainOptions::
/// lr_position_fine and lr_alpha_fine: rates changed once the frames are trained at full size),
/// and one anneal (`with_anneal(A, B, a)`): lr(k) x a^clamp((k - A) / (B - A), 0, 1) for k >= A, a
/// log-linear descent to a times the rate at B that stays there after B (TrainOptions::lr_anneal_from).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>

#include "video3dgs/core/error.hpp"

namespace video3dgs {

struct LrSchedule {
  enum class Kind { constant, exponential };
  Kind kind = Kind::constant;
  double lr_init = 0;
  double lr_final = 0;
  double max_steps = 1;
  double delay_steps = 0;
  double delay_mult = 1;
  double step_from = -1;  ///< < 0: no step
  double step_factor = 1;
  double anneal_from = -1;  ///< < 0: no anneal
  double anneal_until = 0;
  double anneal_factor = 1;

  [[nodiscard]] static LrSchedule constant(double lr) {
    if (!(lr >= 0) || !std::isfinite(lr)) throw option_error("option.optimizer", "lr", "learning rate must be finite and >= 0");
    return {Kind::constant, lr, lr, 1, 0, 1};
  }
  /// @throws option_error `option.optimizer` if a rate is negative/non-finite or max_steps is 0.
  [[nodiscard]] static LrSchedule exponential(double lr_init, double lr_final, std::int64_t max_steps,
                                              std::int64_t delay_steps = 0, double delay_mult = 1) {
    if (!(lr_init >= 0) || !(lr_final >= 0) || !std::isfinite(lr_init) || !std::isfinite(lr_final))
      throw option_error("option.optimizer", "lr", "learning rates must be finite and >= 0");
    if ((lr_init == 0) != (lr_final == 0))
      throw option_error("option.optimizer", "lr", "log-linear decay needs both rates > 0 (or both 0)");
    if (max_steps <= 0) throw option_error("option.optimizer", "max_steps", "must be > 0");
    if (delay_steps < 0) throw option_error("option.optimizer", "delay_steps", "must be >= 0");
    return {Kind::exponential, lr_init, lr_final, double(max_steps), double(delay_steps), delay_mult};
  }

  /// This schedule with its rate multiplied by `factor` from step `from` on.
  /// @throws option_error `option.optimizer` if from < 0 or factor is negative/non-finite.
  [[nodiscard]] LrSchedule with_step(std::int64_t from, double factor) const {
    if (from < 0) throw option_error("option.optimizer", "step_from", "must be >= 0");
    if (!(factor >= 0) || !std::isfinite(factor)) throw option_error("option.optimizer", "step_factor", "must be finite and >= 0");
    LrSchedule s = *this;
    s.step_from = double(from);
    s.step_factor = factor;
    return s;
  }

  /// This schedule with its rate multiplied by factor^clamp((k - from) / (until - from), 0, 1) from
  /// step `from` on: from 1 at `from` down (or up) to `factor` at `until`, `factor` after it.
  /// @throws option_error `option.optimizer` if from < 0, until <= from, or factor is not finite and > 0.
  [[nodiscard]] LrSchedule with_anneal(std::int64_t from, std::int64_t until, double factor) const {
    if (from < 0) throw option_error("option.optimizer", "anneal_from", "must be >= 0");
    if (until <= from) throw option_error("option.optimizer", "anneal_until", "must be > anneal_from");
    if (!(factor > 0) || !std::isfinite(factor)) throw option_error("option.optimizer", "anneal_factor", "must be finite and > 0");
    LrSchedule s = *this;
    s.anneal_from = double(from);
    s.anneal_until = double(until);
    s.anneal_factor = factor;
    return s;
  }

  /// Learning rate at step k (k counts iterations from 0).
  [[nodiscard]] double operator()(std::int64_t k) const noexcept {
    const double step = step_from >= 0 && double(k) >= step_from ? step_factor : 1.0;
    double anneal = 1;  // exactly 1 before the anneal (and without one): the rates keep their bits
    if (anneal_from >= 0 && double(k) >= anneal_from)
      anneal = std::exp(std::log(anneal_factor) * std::clamp((double(k) - anneal_from) / (anneal_until - anneal_from), 0.0, 1.0));
    return step * unstepped(k) * anneal;
  }

 private:
  [[nodiscard]] double unstepped(std::int64_t k) const noexcept {
    if (kind == Kind::constant) return lr_init;
    if (k < 0 || (lr_init == 0 && lr_final == 0)) return 0;
    double delay = 1;
    if (delay_steps > 0)
      delay = delay_mult + (1 - delay_mult) * std::sin(0.5 * std::numbers::pi * std::clamp(double(k) / delay_steps, 0.0, 1.0));
    const double r = std::clamp(double(k) / max_steps, 0.0, 1.0);
    return delay * std::exp(std::log(lr_init) * (1 - r) + std::log(lr_final) * r);
  }
};

}  // namespace video3dgs
