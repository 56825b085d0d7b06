#pragma once
/// @file
/// Array-level operations on a `Tape`: one node per operation on whole buffers.
///
/// Adjoints (xbar = dL/dx, everything elementwise unless stated; shapes rows x cols, row-major):
///
///     y = a + b         abar += ybar,            bbar += ybar
///     y = a - b         abar += ybar,            bbar -= ybar
///     y = a * b         abar += ybar b,          bbar += ybar a
///     y = c a + d       abar += c ybar
///     y = a^2           abar += 2 a ybar
///     y = |a|           abar += sign(a) ybar     (sign(0) = 0)
///     y = exp(a)        abar += y ybar
///     y = log(a)        abar += ybar / a
///     y = sigmoid(a)    abar += y (1 - y) ybar
///     y = relu(a)       abar += [a > 0] ybar
///     y = sum(a)        abar += ybar (broadcast; y is 1 x 1)
///     y = x + 1 b^T     xbar += ybar,            bbar += column sums of ybar   (b: 1 x cols)
///     y = A B           Abar += ybar B^T,        Bbar += A^T ybar              (Eigen GEMM)
///     y_r = x_r/|x_r|   xbar_r += (ybar_r - y_r (y_r . ybar_r)) / |x_r|        (per row)
///     y_i = x_{idx_i}   xbar_{idx_i} += ybar_i                     (gather rows; serial scatter)
///     y_j = sum_{i: idx_i = j} x_i     xbar_i += ybar_{idx_i}      (scatter-add rows)
///
/// Every op checks shapes with `VIDEO3DGS_ASSERT` and records a backward step only if an input
/// requires a gradient. Results of ops without gradient flow are constants.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <span>

#include <Eigen/Core>

#include "video3dgs/autodiff/tape.hpp"

namespace video3dgs::autodiff {

namespace detail {

template <class Scalar>
using RowMajorMap = Eigen::Map<Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>;
template <class Scalar>
using ConstRowMajorMap = Eigen::Map<const Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>;

/// Shared body of unary elementwise ops: y_i = f(x_i); xbar_i += d(x_i, y_i) ybar_i.
template <class Scalar, class F, class D>
Var unary(Tape<Scalar>& t, Var a, F f, D d) {
  const std::size_t n = t.size(a);
  const bool rg = t.requires_grad(a);
  const Var y = t.make(t.rows(a), t.cols(a), rg);
  const Scalar* x = t.value(a);
  Scalar* yv = t.value(y);
  for (std::size_t i = 0; i < n; ++i) yv[i] = f(x[i]);
  if (rg) {
    Scalar* xg = t.grad(a);
    const Scalar* yg = t.grad(y);
    t.on_backward([=] {
      for (std::size_t i = 0; i < n; ++i) xg[i] += d(x[i], yv[i]) * yg[i];
    });
  }
  return y;
}

/// Shared body of binary elementwise ops with equal shapes.
template <class Scalar, class F, class Da, class Db>
Var binary(Tape<Scalar>& t, Var a, Var b, F f, Da da, Db db) {
  VIDEO3DGS_ASSERT(t.rows(a) == t.rows(b) && t.cols(a) == t.cols(b), "autodiff: elementwise op on different shapes");
  const std::size_t n = t.size(a);
  const bool rga = t.requires_grad(a), rgb = t.requires_grad(b);
  const Var y = t.make(t.rows(a), t.cols(a), rga || rgb);
  const Scalar* av = t.value(a);
  const Scalar* bv = t.value(b);
  Scalar* yv = t.value(y);
  for (std::size_t i = 0; i < n; ++i) yv[i] = f(av[i], bv[i]);
  if (rga || rgb) {
    Scalar* ag = t.grad(a);
    Scalar* bg = t.grad(b);
    const Scalar* yg = t.grad(y);
    t.on_backward([=] {
      if (ag)
        for (std::size_t i = 0; i < n; ++i) ag[i] += da(av[i], bv[i]) * yg[i];
      if (bg)
        for (std::size_t i = 0; i < n; ++i) bg[i] += db(av[i], bv[i]) * yg[i];
    });
  }
  return y;
}

}  // namespace detail

template <class Scalar>
Var add(Tape<Scalar>& t, Var a, Var b) {
  return detail::binary(t, a, b, [](Scalar x, Scalar y) { return x + y; }, [](Scalar, Scalar) { return Scalar(1); },
                        [](Scalar, Scalar) { return Scalar(1); });
}
template <class Scalar>
Var sub(Tape<Scalar>& t, Var a, Var b) {
  return detail::binary(t, a, b, [](Scalar x, Scalar y) { return x - y; }, [](Scalar, Scalar) { return Scalar(1); },
                        [](Scalar, Scalar) { return Scalar(-1); });
}
template <class Scalar>
Var mul(Tape<Scalar>& t, Var a, Var b) {
  return detail::binary(t, a, b, [](Scalar x, Scalar y) { return x * y; }, [](Scalar, Scalar y) { return y; },
                        [](Scalar x, Scalar) { return x; });
}
/// y = c a + d.
template <class Scalar>
Var affine(Tape<Scalar>& t, Var a, Scalar c, Scalar d = Scalar(0)) {
  return detail::unary(t, a, [c, d](Scalar x) { return c * x + d; }, [c](Scalar, Scalar) { return c; });
}
template <class Scalar>
Var square(Tape<Scalar>& t, Var a) {
  return detail::unary(t, a, [](Scalar x) { return x * x; }, [](Scalar x, Scalar) { return Scalar(2) * x; });
}
template <class Scalar>
Var abs(Tape<Scalar>& t, Var a) {
  return detail::unary(t, a, [](Scalar x) { return std::abs(x); },
                       [](Scalar x, Scalar) { return x > 0 ? Scalar(1) : (x < 0 ? Scalar(-1) : Scalar(0)); });
}
template <class Scalar>
Var exp(Tape<Scalar>& t, Var a) {
  return detail::unary(t, a, [](Scalar x) { return std::exp(x); }, [](Scalar, Scalar y) { return y; });
}
/// y = log(a); a must be positive (the caller guards, e.g. with a floor).
template <class Scalar>
Var log(Tape<Scalar>& t, Var a) {
  return detail::unary(t, a, [](Scalar x) { return std::log(x); }, [](Scalar x, Scalar) { return Scalar(1) / x; });
}
/// Numerically stable logistic function.
template <class Scalar>
Var sigmoid(Tape<Scalar>& t, Var a) {
  return detail::unary(
      t, a,
      [](Scalar x) {
        if (x >= 0) return Scalar(1) / (Scalar(1) + std::exp(-x));
        const Scalar e = std::exp(x);
        return e / (Scalar(1) + e);
      },
      [](Scalar, Scalar y) { return y * (Scalar(1) - y); });
}
template <class Scalar>
Var relu(Tape<Scalar>& t, Var a) {
  return detail::unary(t, a, [](Scalar x) { return x > 0 ? x : Scalar(0); },
                       [](Scalar x, Scalar) { return x > 0 ? Scalar(1) : Scalar(0); });
}

/// y = sum of all entries (1 x 1). Summed in index order (deterministic).
template <class Scalar>
Var sum(Tape<Scalar>& t, Var a) {
  const std::size_t n = t.size(a);
  const bool rg = t.requires_grad(a);
  const Var y = t.make(1, 1, rg);
  const Scalar* x = t.value(a);
  Scalar s = 0;
  for (std::size_t i = 0; i < n; ++i) s += x[i];
  t.value(y)[0] = s;
  if (rg) {
    Scalar* xg = t.grad(a);
    const Scalar* yg = t.grad(y);
    t.on_backward([=] {
      for (std::size_t i = 0; i < n; ++i) xg[i] += yg[0];
    });
  }
  return y;
}
/// y = mean of all entries (1 x 1).
template <class Scalar>
Var mean(Tape<Scalar>& t, Var a) {
  const std::size_t n = t.size(a);
  return affine(t, sum(t, a), n ? Scalar(1) / Scalar(n) : Scalar(0));
}

/// y = x + 1 b^T: adds the row vector b (1 x cols) to every row of x (rows x cols).
template <class Scalar>
Var add_row(Tape<Scalar>& t, Var x, Var b) {
  const std::size_t rows = t.rows(x), cols = t.cols(x);
  VIDEO3DGS_ASSERT(t.size(b) == cols, "autodiff: add_row needs a 1 x cols row");
  const bool rgx = t.requires_grad(x), rgb = t.requires_grad(b);
  const Var y = t.make(rows, cols, rgx || rgb);
  const Scalar* xv = t.value(x);
  const Scalar* bv = t.value(b);
  Scalar* yv = t.value(y);
  for (std::size_t r = 0; r < rows; ++r)
    for (std::size_t c = 0; c < cols; ++c) yv[r * cols + c] = xv[r * cols + c] + bv[c];
  if (rgx || rgb) {
    Scalar* xg = t.grad(x);
    Scalar* bg = t.grad(b);
    const Scalar* yg = t.grad(y);
    t.on_backward([=] {
      for (std::size_t r = 0; r < rows; ++r)
        for (std::size_t c = 0; c < cols; ++c) {
          if (xg) xg[r * cols + c] += yg[r * cols + c];
          if (bg) bg[c] += yg[r * cols + c];
        }
    });
  }
  return y;
}

/// y = A B (Eigen GEMM on row-major maps). A: m x k, B: k x n.
template <class Scalar>
Var matmul(Tape<Scalar>& t, Var a, Var b) {
  const std::size_t m = t.rows(a), k = t.cols(a), n = t.cols(b);
  VIDEO3DGS_ASSERT(t.rows(b) == k, "autodiff: matmul inner dimensions differ");
  const bool rga = t.requires_grad(a), rgb = t.requires_grad(b);
  const Var y = t.make(m, n, rga || rgb);
  using Map = detail::RowMajorMap<Scalar>;
  using CMap = detail::ConstRowMajorMap<Scalar>;
  const auto M = Eigen::Index(m), K = Eigen::Index(k), N = Eigen::Index(n);
  Map(t.value(y), M, N).noalias() = CMap(t.value(a), M, K) * CMap(t.value(b), K, N);
  if (rga || rgb) {
    const Scalar* av = t.value(a);
    const Scalar* bv = t.value(b);
    Scalar* ag = t.grad(a);
    Scalar* bg = t.grad(b);
    const Scalar* yg = t.grad(y);
    t.on_backward([=] {
      if (ag) Map(ag, M, K).noalias() += CMap(yg, M, N) * CMap(bv, K, N).transpose();
      if (bg) Map(bg, K, N).noalias() += CMap(av, M, K).transpose() * CMap(yg, M, N);
    });
  }
  return y;
}

/// Row-wise normalisation y_r = x_r / max(|x_r|, eps) (quaternions, directions).
template <class Scalar>
Var normalize_rows(Tape<Scalar>& t, Var x, Scalar eps = Scalar(1e-12)) {
  const std::size_t rows = t.rows(x), cols = t.cols(x);
  const bool rg = t.requires_grad(x);
  const Var y = t.make(rows, cols, rg);
  const Scalar* xv = t.value(x);
  Scalar* yv = t.value(y);
  Scalar* inv = rg ? t.template scratch<Scalar>(rows) : nullptr;
  for (std::size_t r = 0; r < rows; ++r) {
    Scalar s = 0;
    for (std::size_t c = 0; c < cols; ++c) s += xv[r * cols + c] * xv[r * cols + c];
    const Scalar norm = std::sqrt(s);
    const Scalar iv = Scalar(1) / std::max(norm, eps);
    for (std::size_t c = 0; c < cols; ++c) yv[r * cols + c] = xv[r * cols + c] * iv;
    // Below eps the map is y = x / eps (linear), whose adjoint is xbar += ybar / eps.
    if (inv) inv[r] = norm > eps ? iv : -iv;
  }
  if (rg) {
    Scalar* xg = t.grad(x);
    const Scalar* yg = t.grad(y);
    t.on_backward([=] {
      for (std::size_t r = 0; r < rows; ++r) {
        const Scalar* yr = yv + r * cols;
        const Scalar* gr = yg + r * cols;
        if (inv[r] < 0) {
          for (std::size_t c = 0; c < cols; ++c) xg[r * cols + c] += -inv[r] * gr[c];
          continue;
        }
        Scalar dot = 0;
        for (std::size_t c = 0; c < cols; ++c) dot += yr[c] * gr[c];
        for (std::size_t c = 0; c < cols; ++c) xg[r * cols + c] += (gr[c] - yr[c] * dot) * inv[r];
      }
    });
  }
  return y;
}

/// y_i = x_{idx_i} (rows). `idx` must outlive the backward pass (copy it with `tape.scratch`).
template <class Scalar>
Var gather_rows(Tape<Scalar>& t, Var x, std::span<const int> idx) {
  const std::size_t cols = t.cols(x), n = idx.size();
  [[maybe_unused]] const std::size_t xrows = t.rows(x);
  const bool rg = t.requires_grad(x);
  const Var y = t.make(n, cols, rg);
  const Scalar* xv = t.value(x);
  Scalar* yv = t.value(y);
  const int* ip = idx.data();
  for (std::size_t i = 0; i < n; ++i) {
    VIDEO3DGS_ASSERT(ip[i] >= 0 && std::size_t(ip[i]) < xrows, "autodiff: gather index out of range");
    std::copy_n(xv + std::size_t(ip[i]) * cols, cols, yv + i * cols);
  }
  if (rg) {
    Scalar* xg = t.grad(x);
    const Scalar* yg = t.grad(y);
    t.on_backward([=] {
      for (std::size_t i = 0; i < n; ++i)
        for (std::size_t c = 0; c < cols; ++c) xg[std::size_t(ip[i]) * cols + c] += yg[i * cols + c];
    });
  }
  return y;
}

/// y (out_rows x cols) with y_j = sum over i with idx_i = j of x_i; rows in index order.
template <class Scalar>
Var scatter_add_rows(Tape<Scalar>& t, Var x, std::span<const int> idx, std::size_t out_rows) {
  const std::size_t cols = t.cols(x), n = t.rows(x);
  VIDEO3DGS_ASSERT(idx.size() == n, "autodiff: scatter_add_rows needs one index per row");
  const bool rg = t.requires_grad(x);
  const Var y = t.make(out_rows, cols, rg);
  const Scalar* xv = t.value(x);
  Scalar* yv = t.value(y);
  std::fill_n(yv, out_rows * cols, Scalar(0));
  const int* ip = idx.data();
  for (std::size_t i = 0; i < n; ++i) {
    VIDEO3DGS_ASSERT(ip[i] >= 0 && std::size_t(ip[i]) < out_rows, "autodiff: scatter index out of range");
    for (std::size_t c = 0; c < cols; ++c) yv[std::size_t(ip[i]) * cols + c] += xv[i * cols + c];
  }
  if (rg) {
    Scalar* xg = t.grad(x);
    const Scalar* yg = t.grad(y);
    t.on_backward([=] {
      for (std::size_t i = 0; i < n; ++i)
        for (std::size_t c = 0; c < cols; ++c) xg[i * cols + c] += yg[std::size_t(ip[i]) * cols + c];
    });
  }
  return y;
}

/// Copies an index list into the tape's arena (so it outlives the caller's buffer until `clear()`).
template <class Scalar>
[[nodiscard]] std::span<const int> persist(Tape<Scalar>& t, std::span<const int> idx) {
  int* p = t.template scratch<int>(idx.size());
  std::copy(idx.begin(), idx.end(), p);
  return {p, idx.size()};
}

}  // namespace video3dgs::autodiff
