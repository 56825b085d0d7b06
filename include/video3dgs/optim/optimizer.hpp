#pragma once
/// @file
/// `Optimizer<Scalar, Policy>`: named parameter groups, each with its own learning-rate schedule and
/// hyperparameters, stepped by an `OptimizerPolicy` (Adam, Sgd, ...).
///
/// A group binds caller-owned buffers (parameters + gradient accumulators), as one or more segments;
/// it owns the policy's moment buffers (one value per parameter), its step count k and a frozen flag.
/// `step(iteration)` sets lr = schedule(iteration) and, for every group that is not frozen, runs
/// k <- k + 1 and the policy update; a frozen group's parameters and moments never change.
///
/// Rows. A single-segment group is a table of rows of `row_width` scalars (one row per Gaussian).
/// When the densifier edits the cloud, the moments follow with the same edit:
///   - `append_rows(name, sources, RowMoments)`: rows appended at the end, in order, one per entry of
///     `sources` (clone/split); their moments are zero (`RowMoments::zero`, the reference 3DGS
///     behaviour) or copies of the source rows' moments (`RowMoments::copy`);
///   - `keep_rows(name, keep)`: drops the rows with keep[r] == 0, preserving order (prune; a split
///     appends the children then drops the parent).
/// The step count is per group and is not changed by row edits (as in 3DGS: new rows share the
/// group's bias correction). Afterwards the caller `bind`s the resized buffers (step() checks sizes).
///
/// Lazy groups (`GroupOptions::lazy`, the sparse Adam of Taming 3DGS and the lazy Adam of hash tables):
/// a row whose gradient is exactly zero in every column did not take part in this iteration (a
/// Gaussian nothing rendered, a table entry no point reached); its parameters and moments are left as
/// they are. Every other row gets exactly the update a dense step gives it, with the group's step count
/// k (one bias correction for all rows, as in Taming 3DGS and PyTorch's SparseAdam). A dense step
/// would instead decay an untouched row's moments and keep moving it along its old momentum. The
/// group's step count still advances every step. Each segment of a lazy group must hold whole rows.
///
/// Checkpoints: `groups()` exposes each group's name, rows, step count and moment buffers;
/// `set_step_count` and the mutable `moment(k)` restore them. No allocation happens in `step()`.

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <span>
#include <string>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/autodiff/param_segment.hpp"
#include "video3dgs/optim/policies.hpp"
#include "video3dgs/optim/schedule.hpp"

namespace video3dgs {

enum class RowMoments { zero, copy };

template <class Scalar, class Policy = Adam>
class Optimizer {
  static_assert(OptimizerPolicy<Policy, Scalar> || PositionalOptimizerPolicy<Policy, Scalar>,
                "video3dgs: Optimizer's Policy must provide kMoments, name, a Hyper struct and a static "
                "update<Scalar>(hyper, lr, step, param, grad, moments, n) (see Adam)");

 public:
  using scalar_type = Scalar;
  using policy_type = Policy;
  using Hyper = typename Policy::Hyper;
  static constexpr int kMoments = Policy::kMoments;

  struct GroupOptions {
    std::string name;
    LrSchedule schedule = LrSchedule::constant(1e-3);
    Hyper hyper{};
    std::size_t row_width = 1;  ///< scalars per row (3 for means, 4 for quaternions, ...)
    bool lazy = false;          ///< rows with an all-zero gradient are not stepped (see the file comment)
  };

  class Group {
   public:
    [[nodiscard]] const std::string& name() const noexcept { return options_.name; }
    [[nodiscard]] const GroupOptions& options() const noexcept { return options_; }
    [[nodiscard]] GroupOptions& options() noexcept { return options_; }
    [[nodiscard]] std::size_t size() const noexcept { return size_; }
    [[nodiscard]] std::size_t row_width() const noexcept { return options_.row_width; }
    [[nodiscard]] std::size_t rows() const noexcept { return size_ / options_.row_width; }
    [[nodiscard]] std::uint64_t step_count() const noexcept { return step_; }
    void set_step_count(std::uint64_t k) noexcept { step_ = k; }
    [[nodiscard]] bool frozen() const noexcept { return frozen_; }
    /// The learning rate used by the last step (0 before the first).
    [[nodiscard]] double last_lr() const noexcept { return last_lr_; }
    /// Moment buffer k (Adam: 0 = first moment m, 1 = second moment v), size() scalars.
    [[nodiscard]] std::span<Scalar> moment(int k) noexcept { return moments_[std::size_t(k)]; }
    [[nodiscard]] std::span<const Scalar> moment(int k) const noexcept { return moments_[std::size_t(k)]; }
    [[nodiscard]] const std::vector<ParamSegment<Scalar>>& segments() const noexcept { return segments_; }

   private:
    friend class Optimizer;
    GroupOptions options_;
    std::vector<ParamSegment<Scalar>> segments_;
    std::array<std::vector<Scalar>, kMoments> moments_;
    std::size_t size_ = 0;
    std::uint64_t step_ = 0;
    bool frozen_ = false;
    double last_lr_ = 0;
  };

  /// Adds a group over one buffer (rows of `options.row_width`).
  /// @throws option_error `option.optimizer` on a duplicate name, mismatched sizes or a bad width.
  Group& add_group(const GroupOptions& options, std::span<Scalar> value, std::span<Scalar> grad) {
    return add_group(options, std::vector<ParamSegment<Scalar>>{{value, grad}});
  }
  /// Adds a group over several buffers (a network: grid table + head layers). Row edits need one segment.
  Group& add_group(const GroupOptions& options, std::vector<ParamSegment<Scalar>> segments) {
    if (options.name.empty()) throw option_error("option.optimizer", "name", "a group needs a name");
    if (find(options.name)) throw option_error("option.optimizer", options.name, "duplicate group name");
    if (options.row_width == 0) throw option_error("option.optimizer", options.name, "row_width must be > 0");
    Group& g = groups_.emplace_back();
    g.options_ = options;
    try {
      set_segments(g, std::move(segments), true);
    } catch (...) {
      groups_.pop_back();
      throw;
    }
    return g;
  }

  [[nodiscard]] bool has_group(const std::string& name) const noexcept { return find(name) != nullptr; }
  /// @throws option_error `option.optimizer` if there is no such group.
  [[nodiscard]] Group& group(const std::string& name) { return must_find(name); }
  [[nodiscard]] const Group& group(const std::string& name) const { return const_cast<Optimizer*>(this)->must_find(name); }
  [[nodiscard]] std::deque<Group>& groups() noexcept { return groups_; }
  [[nodiscard]] const std::deque<Group>& groups() const noexcept { return groups_; }

  /// Re-points a group at its (possibly reallocated) buffers; the total size must equal the moments'.
  void bind(const std::string& name, std::span<Scalar> value, std::span<Scalar> grad) {
    set_segments(must_find(name), {{value, grad}}, false);
  }
  void bind(const std::string& name, std::vector<ParamSegment<Scalar>> segments) {
    set_segments(must_find(name), std::move(segments), false);
  }

  void freeze(const std::string& name) { must_find(name).frozen_ = true; }
  void unfreeze(const std::string& name) { must_find(name).frozen_ = false; }
  [[nodiscard]] bool frozen(const std::string& name) const { return group(name).frozen_; }

  /// One optimisation step at `iteration` (the schedules' step index) for every unfrozen group.
  /// @throws option_error `option.optimizer` (before changing anything) if a group's rows were edited
  /// and its buffers not re-bound.
  void step(std::int64_t iteration, ThreadPool* pool = nullptr) {
    for (const Group& g : groups_) {  // validate everything first: a throw leaves every group untouched
      if (g.frozen_) continue;
      std::size_t bound = 0;
      for (const auto& s : g.segments_) bound += s.value.size();
      if (bound != g.size_)
        throw option_error("option.optimizer", g.name(), "rows were edited but the buffers were not re-bound");
      if (g.options_.lazy)
        for (const auto& s : g.segments_)
          if (s.value.size() % g.row_width() != 0)
            throw option_error("option.optimizer", g.name(), "a lazy group's segments must hold whole rows of row_width scalars");
    }
    for (Group& g : groups_) {
      if (g.frozen_) continue;
      const double lr = g.options_.schedule(iteration);
      g.last_lr_ = lr;
      ++g.step_;
      std::size_t offset = 0;
      for (const auto& s : g.segments_) {
        std::array<Scalar*, kMoments> m;
        for (int k = 0; k < kMoments; ++k) m[std::size_t(k)] = g.moments_[std::size_t(k)].data() + offset;
        Scalar* p = s.value.data();
        const Scalar* gr = s.grad.data();
        const std::uint64_t k = g.step_;
        auto moments_at = [&](std::size_t b) {
          std::array<Scalar*, kMoments> mb;
          for (int j = 0; j < kMoments; ++j) mb[std::size_t(j)] = m[std::size_t(j)] + b;
          return mb;
        };
        // Elements [b, e) of this segment. A policy that offers its per-step constants
        // (`PreparedOptimizerPolicy`) has them computed once here, not once per range.
        auto update = [&] {
          if constexpr (PreparedOptimizerPolicy<Policy, Scalar>) {
            return [&, prepared = typename Policy::template Prepared<Scalar>(g.options_.hyper, lr, k)](std::size_t b, std::size_t e) {
              prepared(p + b, gr + b, moments_at(b), e - b, offset + b);
            };
          } else {
            return [&](std::size_t b, std::size_t e) {
              if constexpr (PositionalOptimizerPolicy<Policy, Scalar>)
                Policy::template update<Scalar>(g.options_.hyper, lr, k, p + b, gr + b, moments_at(b), e - b, offset + b);
              else
                Policy::template update<Scalar>(g.options_.hyper, lr, k, p + b, gr + b, moments_at(b), e - b);
            };
          }
        }();
        if (!g.options_.lazy) {
          parallel_for_chunks(pool, s.value.size(), kGrain, [&](std::size_t, std::size_t b, std::size_t e) { update(b, e); });
        } else {
          // Runs of consecutive touched rows, each stepped as one range (rows never straddle chunks).
          const std::size_t w = g.row_width();
          auto touched = [&](std::size_t r) {
            for (std::size_t j = 0; j < w; ++j)
              if (gr[r * w + j] != Scalar(0)) return true;
            return false;
          };
          parallel_for_chunks(pool, s.value.size() / w, std::max<std::size_t>(1, kGrain / w), [&](std::size_t, std::size_t rb, std::size_t re) {
            for (std::size_t r = rb; r < re;) {
              while (r < re && !touched(r)) ++r;
              std::size_t e = r;
              while (e < re && touched(e)) ++e;
              if (e > r) update(r * w, e * w);
              r = e;
            }
          });
        }
        offset += s.value.size();
      }
    }
  }

  /// Appends one row per entry of `sources` (row indices) to the group's moments, zeroed or copied.
  void append_rows(const std::string& name, std::span<const std::size_t> sources, RowMoments init = RowMoments::zero) {
    Group& g = must_find(name);
    require_rows(g, "append_rows");
    const std::size_t w = g.row_width(), rows = g.rows();
    for (std::size_t s : sources)
      if (s >= rows) throw option_error("option.optimizer", name, "append_rows: source row " + std::to_string(s) + " out of range");
    for (auto& mom : g.moments_) {
      mom.resize((rows + sources.size()) * w);
      for (std::size_t i = 0; i < sources.size(); ++i) {
        Scalar* dst = mom.data() + (rows + i) * w;
        if (init == RowMoments::copy)
          std::copy_n(mom.data() + sources[i] * w, w, dst);
        else
          std::fill_n(dst, w, Scalar(0));
      }
    }
    g.size_ = (rows + sources.size()) * w;
  }

  /// Keeps the rows with keep[r] != 0 (in order); keep.size() must equal rows().
  void keep_rows(const std::string& name, std::span<const std::uint8_t> keep) {
    Group& g = must_find(name);
    require_rows(g, "keep_rows");
    const std::size_t w = g.row_width(), rows = g.rows();
    if (keep.size() != rows) throw option_error("option.optimizer", name, "keep_rows: mask size differs from the row count");
    std::size_t out = 0;
    for (std::size_t r = 0; r < rows; ++r) {
      if (!keep[r]) continue;
      if (out != r)
        for (auto& mom : g.moments_) std::copy_n(mom.data() + r * w, w, mom.data() + out * w);
      ++out;
    }
    for (auto& mom : g.moments_) mom.resize(out * w);
    g.size_ = out * w;
  }

  /// Zeroes every bound gradient buffer.
  void zero_grad() {
    for (Group& g : groups_)
      for (auto& s : g.segments_) std::fill(s.grad.begin(), s.grad.end(), Scalar(0));
  }

 private:
  static constexpr std::size_t kGrain = std::size_t(1) << 16;

  Group* find(const std::string& name) noexcept {
    for (Group& g : groups_)
      if (g.options_.name == name) return &g;
    return nullptr;
  }
  const Group* find(const std::string& name) const noexcept { return const_cast<Optimizer*>(this)->find(name); }
  Group& must_find(const std::string& name) {
    Group* g = find(name);
    if (!g) throw option_error("option.optimizer", name, "no such parameter group");
    return *g;
  }
  static void require_rows(const Group& g, const char* what) {
    if (g.segments_.size() != 1)
      throw option_error("option.optimizer", g.name(), std::string(what) + " needs a single-segment group");
  }
  static void set_segments(Group& g, std::vector<ParamSegment<Scalar>> segments, bool fresh) {
    std::size_t total = 0;
    for (const auto& s : segments) {
      if (s.value.size() != s.grad.size())
        throw option_error("option.optimizer", g.name(), "parameter and gradient buffers differ in size");
      total += s.value.size();
    }
    if (total % g.row_width() != 0)
      throw option_error("option.optimizer", g.name(), "buffer size is not a multiple of row_width");
    if (fresh) {
      for (auto& m : g.moments_) m.assign(total, Scalar(0));
      g.size_ = total;
    } else if (total != g.size_) {
      throw option_error("option.optimizer", g.name(),
                         "bound buffers hold " + std::to_string(total) + " scalars, the moments " + std::to_string(g.size_));
    }
    g.segments_ = std::move(segments);
  }

  std::deque<Group> groups_;  // deque: references to groups stay valid when groups are added
};

template <class Scalar>
using AdamOptimizer = Optimizer<Scalar, Adam>;
using AdamOptimizerF = Optimizer<float, Adam>;
using AdamOptimizerD = Optimizer<double, Adam>;

}  // namespace video3dgs
