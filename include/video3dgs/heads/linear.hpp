#pragma once
/// @file
/// `Linear<Scalar, In, Out>`: y = W x + b on a batch, Eigen-backed.
///
/// Batches are feature-major: X is N x In column-major (feature j of every point contiguous), the
/// layout the hash grid writes. Parameters are one contiguous buffer [W (Out x In, row-major), b (Out)].
///
///     Y = X W^T + 1 b^T            (N x Out)
///     dL/dW += dY^T X,   dL/db += 1^T dY,   dL/dX += dY W
///
/// Initialisation: `uniform_fan_in` draws W, b ~ U(-1/sqrt(In), 1/sqrt(In)) (PyTorch's nn.Linear, the
/// reference); `small` scales that by `small_scale`; `zero` starts at exactly 0 (a deformation head
/// then starts at the identity deformation).

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <random>
#include <span>
#include <type_traits>
#include <vector>

#include <Eigen/Core>

#include "video3dgs/core/assert.hpp"
#include "video3dgs/core/parallel.hpp"

namespace video3dgs {

enum class HeadInit { uniform_fan_in, small, zero };

struct HeadInitOptions {
  HeadInit init = HeadInit::uniform_fan_in;
  double small_scale = 1e-3;  ///< factor on the fan-in bound for HeadInit::small
  std::uint64_t seed = 7;
};

template <class Scalar>
using BatchMatrix = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;  ///< N x features, column-major
template <class Scalar>
using BatchMap = Eigen::Map<BatchMatrix<Scalar>>;
template <class Scalar>
using ConstBatchMap = Eigen::Map<const BatchMatrix<Scalar>>;

template <class Scalar, int In, int Out>
class Linear {
  static_assert(std::is_floating_point_v<Scalar>, "video3dgs: Linear<Scalar, In, Out> needs a floating-point Scalar");
  static_assert(In >= 1 && Out >= 1, "video3dgs: Linear needs In >= 1 and Out >= 1");

 public:
  using scalar_type = Scalar;
  static constexpr int kIn = In;
  static constexpr int kOut = Out;
  static constexpr std::size_t kParams = std::size_t(In) * Out + Out;
  using WeightMap = Eigen::Map<Eigen::Matrix<Scalar, Out, In, (In == 1 ? Eigen::ColMajor : Eigen::RowMajor)>>;
  using ConstWeightMap = Eigen::Map<const Eigen::Matrix<Scalar, Out, In, (In == 1 ? Eigen::ColMajor : Eigen::RowMajor)>>;
  using BiasMap = Eigen::Map<Eigen::Matrix<Scalar, Out, 1>>;
  using ConstBiasMap = Eigen::Map<const Eigen::Matrix<Scalar, Out, 1>>;

  Linear() : Linear(HeadInitOptions{}) {}
  /// Up to this many outputs forward/backward use column axpys and dots instead of a GEMM (no workspace
  /// allocation; the deformation heads have 3 and 4).
  static constexpr int kSmallOut = 8;
  /// Rows per block of the few-outputs path (In columns of a block stay in L2).
  static constexpr std::size_t kRowBlock = 2048;

  explicit Linear(const HeadInitOptions& init) : params_(kParams, Scalar(0)) { initialise(init); }

  void initialise(const HeadInitOptions& init) {
    double bound = 1.0 / std::sqrt(double(In));
    if (init.init == HeadInit::zero) bound = 0;
    if (init.init == HeadInit::small) bound *= init.small_scale;
    std::mt19937_64 rng(init.seed);
    for (auto& p : params_) {
      const double u = double(rng() >> 11) * 0x1.0p-53;
      p = Scalar((2 * u - 1) * bound);
    }
  }

  [[nodiscard]] std::span<Scalar> params() noexcept { return params_; }
  [[nodiscard]] std::span<const Scalar> params() const noexcept { return params_; }
  [[nodiscard]] WeightMap weight() noexcept { return WeightMap(params_.data()); }
  [[nodiscard]] ConstWeightMap weight() const noexcept { return ConstWeightMap(params_.data()); }
  [[nodiscard]] BiasMap bias() noexcept { return BiasMap(params_.data() + std::size_t(In) * Out); }
  [[nodiscard]] ConstBiasMap bias() const noexcept { return ConstBiasMap(params_.data() + std::size_t(In) * Out); }

  /// Y = X W^T + 1 b^T. X: N x In, Y: N x Out (Y is resized if needed; no allocation when it fits).
  /// With few outputs the rows go in blocks of kRowBlock (on `pool` when given): every element is
  /// the same sum b_o + w_o0 x_0 + w_o1 x_1 + ... in the same order, so the result does not depend on
  /// the pool or the thread count, and a block of X is read once from cache for all outputs instead of
  /// once per output from memory.
  template <class XMat, class YMat>
  void forward(const XMat& X, YMat& Y, ThreadPool* pool = nullptr) const {
    VIDEO3DGS_ASSERT(X.cols() == In, "Linear::forward: X must have In columns");
    if constexpr (Out <= kSmallOut) {
      const Eigen::Index n = X.rows();
      Y.resize(n, Out);
      parallel_for_chunks(pool, std::size_t(n), kRowBlock, [&](std::size_t, std::size_t b, std::size_t e) {
        forward_block(X, Y, Eigen::Index(b), Eigen::Index(e - b));
      });
    } else {
      Y.noalias() = X * weight().transpose();
      Y.rowwise() += bias().transpose();
    }
  }

  /// Rows are cut into this many fixed parts for the few-outputs path's dL/dW (kBackwardParts
  /// partial sums per entry, added in part order: the same bits whatever the pool or thread count).
  static constexpr std::size_t kBackwardParts = 32;

  /// Accumulates dL/dparams (same layout as params()) and, if dX is not null, dL/dX. With few
  /// outputs the rows are cut into kBackwardParts contiguous parts (each walked in blocks of
  /// kRowBlock rows, parts spread over `pool`); part k sums its rows' dY^T [X 1] into a partial, and
  /// each entry of dL/dW, dL/db adds the parts' partials in part order. A block of X is read once
  /// from memory for the weight gradient and dL/dX (rows of a block: dX += dY W, as the forward).
  template <class XMat, class GMat, class DXMat = BatchMatrix<Scalar>>
  void backward(const XMat& X, const GMat& dY, std::span<Scalar> dL_dparams, DXMat* dX = nullptr,
                ThreadPool* pool = nullptr) const {
    VIDEO3DGS_ASSERT(dL_dparams.size() == kParams, "Linear::backward: gradient buffer has the wrong size");
    if constexpr (Out <= kSmallOut) {
      // Few outputs (the deformation heads): per-part partial sums on the stack and axpys, which need
      // no GEMM workspace, so a warm iteration does not touch the heap.
      static_assert(sizeof(Scalar) * kBackwardParts * Out * (In + 1) <= 128 * 1024,
                    "video3dgs: Linear's few-outputs backward keeps its partial sums on the stack: In too large for it");
      const std::size_t n = std::size_t(dY.rows());
      Partials partial;
      parallel_for(pool, kBackwardParts, [&](std::size_t k) {
        clear(partial[k]);
        for_part_blocks(n, k, [&](Eigen::Index r0, Eigen::Index len) { backward_block(X, dY, partial[k], r0, len, dX); });
      }, 1);
      add_partials(partial, dL_dparams);
    } else {
      WeightMap dW(dL_dparams.data());
      BiasMap db(dL_dparams.data() + std::size_t(In) * Out);
      dW.noalias() += dY.transpose() * X;
      db += dY.colwise().sum().transpose();
      if (dX) dX->noalias() += dY * weight();
    }
  }

  // The few-outputs path in pieces (Out <= kSmallOut), so that several layers reading one X (the
  // deformation field's three heads) can walk its blocks together: each block of X is then read from
  // memory once for all of them, and every layer's outputs and gradients are the bits of its own
  // forward / backward (each element is the same sums in the same order; see deformation_field.hpp).

  /// Part k's sums of dY^T [X 1] (kBackwardParts of them per backward, added in part order).
  using Accumulator = Scalar[Out][In + 1];
  using Partials = Accumulator[kBackwardParts];

  /// Rows [r0, r0 + len) of Y = X W^T + 1 b^T.
  template <class XMat, class YMat>
  void forward_block(const XMat& X, YMat& Y, Eigen::Index r0, Eigen::Index len) const {
    static_assert(Out <= kSmallOut, "video3dgs: Linear's block functions are the few-outputs path");
    for (int o = 0; o < Out; ++o) {
      auto y = Y.col(o).segment(r0, len);
      y.setConstant(bias()(o));
      for (int j = 0; j < In; ++j) y += weight()(o, j) * X.col(j).segment(r0, len);
    }
  }

  /// Calls f(r0, len) for the blocks of kRowBlock rows of part k of n rows (kBackwardParts
  /// contiguous parts of ceil(n / kBackwardParts) rows each), first to last.
  template <class F>
  static void for_part_blocks(std::size_t n, std::size_t k, F&& f) {
    const std::size_t part = (n + kBackwardParts - 1) / kBackwardParts;
    const std::size_t pb = std::min(n, k * part), pe = std::min(n, pb + part);
    for (std::size_t b = pb; b < pe; b += kRowBlock) f(Eigen::Index(b), Eigen::Index(std::min(pe, b + kRowBlock) - b));
  }

  static void clear(Accumulator& acc) {
    for (int o = 0; o < Out; ++o)
      for (int j = 0; j <= In; ++j) acc[o][j] = Scalar(0);
  }

  /// One block of the backward: its rows' dY^T [X 1] into `acc`, and dX += dY W on its rows.
  template <class XMat, class GMat, class DXMat>
  void backward_block(const XMat& X, const GMat& dY, Accumulator& acc, Eigen::Index r0, Eigen::Index len, DXMat* dX) const {
    static_assert(Out <= kSmallOut, "video3dgs: Linear's block functions are the few-outputs path");
    for (int o = 0; o < Out; ++o) {
      const auto g = dY.col(o).segment(r0, len);
      for (int j = 0; j < In; ++j) acc[o][j] += g.dot(X.col(j).segment(r0, len));
      acc[o][In] += g.sum();
    }
    if (dX)
      for (int j = 0; j < In; ++j) {
        auto dx = dX->col(j).segment(r0, len);
        for (int o = 0; o < Out; ++o) dx += weight()(o, j) * dY.col(o).segment(r0, len);
      }
  }

  /// dL/dW, dL/db (layout of params()) += the parts' sums, added in part order.
  static void add_partials(const Partials& partial, std::span<Scalar> dL_dparams) {
    VIDEO3DGS_ASSERT(dL_dparams.size() == kParams, "Linear::add_partials: gradient buffer has the wrong size");
    WeightMap dW(dL_dparams.data());
    BiasMap db(dL_dparams.data() + std::size_t(In) * Out);
    for (int o = 0; o < Out; ++o)
      for (int j = 0; j <= In; ++j) {
        Scalar sum = 0;
        for (std::size_t k = 0; k < kBackwardParts; ++k) sum += partial[k][o][j];
        (j < In ? dW(o, j) : db(o)) += sum;
      }
  }

 private:
  std::vector<Scalar> params_;
};

}  // namespace video3dgs
