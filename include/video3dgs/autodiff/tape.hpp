#pragma once
/// @file
/// `Tape<Scalar>`: array-level reverse-mode automatic differentiation.
///
/// A node is a whole buffer (rows x cols, row-major) with a value and, if it requires a gradient, a
/// gradient buffer of the same shape. Nodes either borrow external buffers (parameters and their
/// gradient accumulators) or take them from the tape's `Arena`. Each operation records one backward
/// step: a closure that reads the output adjoint and accumulates (+=) into its inputs' adjoints.
/// Accumulation is the ONE gradient convention of every step, hand-written kernels included (they
/// are called in their accumulate mode), so a buffer read by several operations sums their
/// contributions in the reverse order of recording, whatever the operations are.
/// `backward(loss)` seeds dL/dloss = 1 and replays the steps in reverse order of recording:
///
///     y = f(x1, ..., xk)   =>   xbar_i += (dy/dx_i)^T ybar,  steps run last-recorded first.
///
/// A hand-written kernel (the rasterizer, SSIM, the hash grid) is ONE node: `custom(...)` takes its
/// forward and backward as two callables. Closures live in the arena (no heap allocation per step);
/// `clear()` rewinds the arena and keeps its memory, so an identical iteration allocates nothing.
/// `Scope` is a nested tape: nodes and steps recorded inside it can be back-propagated alone
/// (`Scope::backward`) and are discarded when the scope ends.

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

#include "video3dgs/autodiff/arena.hpp"
#include "video3dgs/core/assert.hpp"
#include "video3dgs/core/scalar_traits.hpp"

namespace video3dgs::autodiff {

/// Handle of a tape node (an index; valid until the tape is cleared or its scope ends).
struct Var {
  static constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
  std::uint32_t id = kNone;
  [[nodiscard]] bool valid() const noexcept { return id != kNone; }
};

template <class Scalar>
class Tape {
  static_assert(std::is_floating_point_v<Scalar>, "video3dgs: Tape<Scalar> needs a floating-point Scalar (float or double)");

 public:
  using scalar_type = Scalar;

  struct Node {
    Scalar* value = nullptr;
    Scalar* grad = nullptr;  ///< nullptr: no gradient flows to this node (a constant)
    std::size_t rows = 0;
    std::size_t cols = 0;
    bool borrowed = false;   ///< value/grad are owned by the caller
    [[nodiscard]] std::size_t size() const noexcept { return rows * cols; }
  };

  /// A position on the tape (nodes, steps and arena), see `mark()` / `rewind()`.
  struct Mark {
    std::size_t nodes = 0;
    std::size_t steps = 0;
    Arena::Mark arena;
  };

  explicit Tape(std::size_t arena_bytes = std::size_t(1) << 20) : arena_(arena_bytes) {}
  Tape(const Tape&) = delete;
  Tape& operator=(const Tape&) = delete;
  /// Moves nodes, steps and arena blocks (closures live in the blocks, which do not move).
  Tape(Tape&& o) noexcept : arena_(std::move(o.arena_)), nodes_(std::move(o.nodes_)), steps_(std::move(o.steps_)) { o.steps_.clear(); }
  Tape& operator=(Tape&&) = delete;
  ~Tape() { destroy_steps(0); }

  // ---- nodes -------------------------------------------------------------------------------------

  /// A node on caller-owned buffers. `grad == nullptr` makes it a constant. Gradients accumulate into
  /// `grad` (zero it yourself, or call `zero_grad()`, between iterations).
  Var leaf(Scalar* value, Scalar* grad, std::size_t rows, std::size_t cols = 1) {
    return push({value, grad, rows, cols, true});
  }
  /// A constant node viewing caller-owned data (never written).
  Var constant(const Scalar* value, std::size_t rows, std::size_t cols = 1) {
    return push({const_cast<Scalar*>(value), nullptr, rows, cols, true});
  }
  /// The output node of an operation that writes its value into caller-owned storage `value` (an
  /// image of a reusable context, say) and gets an arena-owned gradient (zero) if `requires_grad`.
  /// An operation with several outputs makes one such node per output and records one step.
  Var output(Scalar* value, std::size_t rows, std::size_t cols, bool requires_grad) {
    Scalar* g = nullptr;
    if (requires_grad) {
      g = arena_.allocate_array<Scalar>(rows * cols);
      std::memset(static_cast<void*>(g), 0, rows * cols * sizeof(Scalar));
    }
    return push({value, g, rows, cols, true});
  }
  /// A node with arena-owned buffers; the value is uninitialised, the gradient (if any) zero.
  Var make(std::size_t rows, std::size_t cols, bool requires_grad) {
    const std::size_t n = rows * cols;
    Scalar* v = arena_.allocate_array<Scalar>(n);
    Scalar* g = nullptr;
    if (requires_grad) {
      g = arena_.allocate_array<Scalar>(n);
      std::memset(static_cast<void*>(g), 0, n * sizeof(Scalar));
    }
    return push({v, g, rows, cols, false});
  }
  /// A node with arena-owned buffers holding a copy of `data` (a constant unless `requires_grad`).
  Var copy_of(const Scalar* data, std::size_t rows, std::size_t cols, bool requires_grad = false) {
    const Var v = make(rows, cols, requires_grad);
    std::memcpy(static_cast<void*>(value(v)), data, rows * cols * sizeof(Scalar));
    return v;
  }

  [[nodiscard]] const Node& node(Var v) const noexcept {
    VIDEO3DGS_ASSERT(v.id < nodes_.size(), "tape: stale or invalid Var");
    return nodes_[v.id];
  }
  [[nodiscard]] Scalar* value(Var v) const noexcept { return node(v).value; }
  [[nodiscard]] Scalar* grad(Var v) const noexcept { return node(v).grad; }
  [[nodiscard]] std::size_t rows(Var v) const noexcept { return node(v).rows; }
  [[nodiscard]] std::size_t cols(Var v) const noexcept { return node(v).cols; }
  [[nodiscard]] std::size_t size(Var v) const noexcept { return node(v).size(); }
  [[nodiscard]] bool requires_grad(Var v) const noexcept { return node(v).grad != nullptr; }
  [[nodiscard]] std::size_t node_count() const noexcept { return nodes_.size(); }
  [[nodiscard]] std::size_t step_count() const noexcept { return steps_.size(); }

  /// Scratch memory from the arena, released by `clear()` (for a custom node's saved context).
  template <class T>
  [[nodiscard]] T* scratch(std::size_t n) {
    static_assert(std::is_trivially_destructible_v<T>, "video3dgs: Tape::scratch<T> needs a trivially destructible T");
    return arena_.allocate_array<T>(n);
  }

  // ---- steps -------------------------------------------------------------------------------------

  /// Records a backward step `f()` (runs during `backward`, after every step recorded later).
  template <class F>
  void on_backward(F&& f) {
    using Fn = std::decay_t<F>;
    void* mem = arena_.allocate(sizeof(Fn), alignof(Fn) <= 64 ? alignof(Fn) : 64);
    Fn* fn = ::new (mem) Fn(std::forward<F>(f));
    Step s;
    s.closure = fn;
    s.invoke = [](void* p) { (*static_cast<Fn*>(p))(); };
    if constexpr (!std::is_trivially_destructible_v<Fn>) s.destroy = [](void* p) { static_cast<Fn*>(p)->~Fn(); };
    steps_.push_back(s);
  }

  /// Registers a hand-written kernel as one node of shape rows x cols.
  /// `forward(Scalar* out)` fills the output now; `backward(const Scalar* out, const Scalar* dout)`
  /// accumulates into the inputs' gradients (which it captures) during `backward()`.
  template <class Forward, class Backward>
  Var custom(std::size_t rows, std::size_t cols, bool requires_grad, Forward&& forward, Backward&& backward) {
    const Var out = make(rows, cols, requires_grad);
    Scalar* o = value(out);
    forward(o);
    if (requires_grad) {
      Scalar* g = grad(out);
      on_backward([o, g, bw = std::forward<Backward>(backward)]() mutable { bw(static_cast<const Scalar*>(o), static_cast<const Scalar*>(g)); });
    }
    return out;
  }

  // ---- replay ------------------------------------------------------------------------------------

  /// Seeds dL/d`loss` with `seed` (every entry) and replays all steps in reverse.
  void backward(Var loss, Scalar seed = Scalar(1)) { backward_since(loss, Mark{}, seed); }

  /// Like `backward`, but replays only the steps recorded after `m` (a nested scope).
  void backward_since(Var loss, Mark m, Scalar seed = Scalar(1)) {
    const Node& n = node(loss);
    VIDEO3DGS_ASSERT(n.grad != nullptr, "tape: backward from a node that does not require a gradient");
    for (std::size_t i = 0; i < n.size(); ++i) n.grad[i] += seed;
    for (std::size_t i = steps_.size(); i-- > m.steps;) steps_[i].invoke(steps_[i].closure);
  }

  /// Sets every gradient on the tape to zero (arena-owned and borrowed alike).
  void zero_grad() noexcept {
    for (const Node& n : nodes_)
      if (n.grad) std::memset(static_cast<void*>(n.grad), 0, n.size() * sizeof(Scalar));
  }

  [[nodiscard]] Mark mark() const noexcept { return {nodes_.size(), steps_.size(), arena_.mark()}; }
  /// Drops nodes and steps recorded after `m` and releases their arena memory.
  void rewind(Mark m) {
    destroy_steps(m.steps);
    steps_.resize(m.steps);
    nodes_.resize(m.nodes);
    arena_.rewind(m.arena);
  }
  /// Drops everything (next iteration). Keeps the memory of the node/step lists and of the arena.
  void clear() {
    destroy_steps(0);
    steps_.clear();
    nodes_.clear();
    arena_.reset();
  }

  [[nodiscard]] const Arena& arena() const noexcept { return arena_; }

  /// A nested tape: everything recorded while it lives can be back-propagated on its own and is
  /// dropped (nodes, steps, arena memory) when it ends. Vars created inside must not escape it.
  class Scope {
   public:
    explicit Scope(Tape& tape) : tape_(tape), mark_(tape.mark()) {}
    Scope(const Scope&) = delete;
    Scope& operator=(const Scope&) = delete;
    ~Scope() { tape_.rewind(mark_); }
    /// Replays only this scope's steps, seeding dL/d`loss` = seed.
    void backward(Var loss, Scalar seed = Scalar(1)) { tape_.backward_since(loss, mark_, seed); }
    [[nodiscard]] const Mark& mark() const noexcept { return mark_; }

   private:
    Tape& tape_;
    Mark mark_;
  };

 private:
  struct Step {
    void* closure = nullptr;
    void (*invoke)(void*) = nullptr;
    void (*destroy)(void*) = nullptr;
  };

  Var push(const Node& n) {
    VIDEO3DGS_ASSERT(nodes_.size() < Var::kNone, "tape: too many nodes");
    nodes_.push_back(n);
    return Var{static_cast<std::uint32_t>(nodes_.size() - 1)};
  }
  void destroy_steps(std::size_t from) noexcept {
    for (std::size_t i = steps_.size(); i-- > from;)
      if (steps_[i].destroy) steps_[i].destroy(steps_[i].closure);
  }

  Arena arena_;
  std::vector<Node> nodes_;
  std::vector<Step> steps_;
};

using TapeF = Tape<float>;
using TapeD = Tape<double>;

}  // namespace video3dgs::autodiff
