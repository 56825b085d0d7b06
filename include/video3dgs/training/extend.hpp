#pragma once
/// @file
/// A quality floor for one clip: more full-schedule iterations only where the clip needs them.
///
/// With base length N (the trainer's options' iterations), floor P dB, extra budget E and step S:
///   train to N; then, at every checkpoint k in {N, N + S, N + 2S, ...} (and N + E, the last):
///     evaluate the merged render over the clip's frames (ClipTrainer::evaluate, PSNR p_k);
///     stop if p_k >= P or k = N + E, else lengthen the run to min(k + S, N + E) and go on.
/// The iterations after N follow the same per-iteration schedules as the first N (every schedule is
/// by iteration index: a preset's last resolution, no densification past densify_until, the learning
/// rates' decays continued), so a clip extended to N + e is the clip trained with N + e iterations;
/// an anneal (TrainOptions::lr_anneal_from) ends at N, and the extension goes on at its final factor.
///
/// The decisions depend on the model alone, and evaluations leave the training state as it was, so
/// the result does not depend on the thread count, and a run stopped anywhere and resumed from its
/// checkpoint (a trainer whose stats() passed N but not the next checkpoint first trains up to that
/// checkpoint) ends where the uninterrupted run ends. P = 0 or E = 0: the base run alone.

#include <algorithm>
#include <optional>

#include "video3dgs/core/error.hpp"
#include "video3dgs/training/clip_trainer.hpp"

namespace video3dgs {

struct ExtendOptions {
  double below_psnr = 0;     ///< P: extend while the clip's PSNR (dB) is below this; 0 = never
  int max_iterations = 2000; ///< E: at most this many iterations beyond the base length
  int step = 500;            ///< S: iterations between two evaluations

  [[nodiscard]] bool active() const noexcept { return below_psnr > 0 && max_iterations > 0; }

  /// @throws option_error `option.extend` naming the field.
  void validate() const {
    if (!(below_psnr >= 0 && below_psnr <= 200)) throw option_error("option.extend", "below_psnr", "must be in [0, 200] dB (0 = off)");
    if (max_iterations < 0 || max_iterations > 1000000) throw option_error("option.extend", "max_iterations", "must be in 0..1000000");
    if (step < 1 || step > 1000000) throw option_error("option.extend", "step", "must be in 1..1000000");
  }
};

/// Trains `trainer` to its options' length, then extends it as the file comment says. `callback` is
/// `ClipTrainer::train`'s (return false to stop). Returns the last evaluation, or nothing when the
/// callback stopped the run (the trainer then holds the state to checkpoint). A PSNR that is not a
/// number ends the extension (it is not below P).
/// Precondition: `trainer.options().iterations` is the base length N on entry. Call it once per
/// trainer; to go on after a stop, build the trainer again from its checkpoint with the base options
/// (as the pipeline does), not by calling this again on a trainer it has lengthened.
template <class Trainer, class Callback>
[[nodiscard]] std::optional<ClipEvaluation> train_with_extension(Trainer& trainer, const ExtendOptions& x, const Callback& callback) {
  x.validate();
  const int base = trainer.options().iterations;
  const int last = x.active() ? base + x.max_iterations : base;
  // The next checkpoint after iteration k (> base): base + S ceil((k - base) / S), capped at last.
  const auto next_checkpoint = [&](int k) { return std::min(last, base + x.step * ((k - base + x.step - 1) / x.step)); };
  for (;;) {
    trainer.train(callback);
    if (trainer.stats().stopped_early || !trainer.done()) return std::nullopt;
    const int k = trainer.stats().iterations;
    if (k > base && k < last && next_checkpoint(k) != k) {  // resumed between two checkpoints
      trainer.extend_to(next_checkpoint(k));
      continue;
    }
    ClipEvaluation e = trainer.evaluate();
    if (!x.active() || k >= last || !(e.psnr < x.below_psnr)) return e;
    trainer.extend_to(std::min(last, k + x.step));
  }
}

}  // namespace video3dgs
