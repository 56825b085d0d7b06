#pragma once
/// @file
/// `Mlp<Scalar, In, Out, Hidden, HiddenLayers, Activation>`: a small multilayer perceptron head.
///
///     H_0 = X,  Z_i = H_{i-1} W_i^T + 1 b_i^T,  H_i = act(Z_i)  (i = 1..HiddenLayers),
///     Y = H_L W_out^T + 1 b_out^T                   (HiddenLayers = 0: a single Linear<In, Out>)
///
/// Backward: dZ_i = dH_i . act'(Z_i, H_i), then the Linear adjoints layer by layer, last first.
/// Batches are feature-major (N x features, column-major), as in linear.hpp. The activation is a
/// policy (see `MlpActivation`); the last layer has none. The context keeps the hidden activations of
/// the last forward; its matrices are reused (no allocation when N does not change).

#include <array>
#include <cmath>
#include <concepts>
#include <cstddef>
#include <span>
#include <type_traits>

#include "video3dgs/heads/linear.hpp"

namespace video3dgs {

/// An activation policy: y = A::value(z) and dL/dz = A::derivative(z, y) dL/dy.
template <class A, class Scalar>
concept MlpActivation = requires(Scalar z) {
  { A::value(z) } -> std::convertible_to<Scalar>;
  { A::derivative(z, z) } -> std::convertible_to<Scalar>;
};

struct Relu {
  template <class S> static S value(S z) { return z > S(0) ? z : S(0); }
  template <class S> static S derivative(S z, S) { return z > S(0) ? S(1) : S(0); }
};
/// Softplus with beta = 1, log(1 + e^z), written to avoid overflow.
struct Softplus {
  template <class S> static S value(S z) { return z > S(20) ? z : std::log1p(std::exp(z)); }
  template <class S> static S derivative(S z, S) { return z >= 0 ? S(1) / (S(1) + std::exp(-z)) : std::exp(z) / (S(1) + std::exp(z)); }
};
struct Identity {
  template <class S> static S value(S z) { return z; }
  template <class S> static S derivative(S, S) { return S(1); }
};

template <class Scalar, int In, int Out, int Hidden = 64, int HiddenLayers = 0, class Activation = Relu>
class Mlp {
  static_assert(MlpActivation<Activation, Scalar>,
                "video3dgs: Mlp's Activation must provide static value(z) and derivative(z, y) (see Relu)");
  static_assert(HiddenLayers >= 0, "video3dgs: Mlp HiddenLayers must be >= 0");
  static_assert(HiddenLayers == 0 || Hidden >= 1, "video3dgs: Mlp needs Hidden >= 1 when it has hidden layers");

 public:
  using scalar_type = Scalar;
  static constexpr int kIn = In;
  static constexpr int kOut = Out;
  static constexpr int kHiddenLayers = HiddenLayers;
  using First = Linear<Scalar, In, (HiddenLayers == 0 ? Out : Hidden)>;
  using Middle = Linear<Scalar, Hidden, Hidden>;
  using Last = Linear<Scalar, Hidden, Out>;
  static constexpr std::size_t kMiddle = HiddenLayers > 1 ? std::size_t(HiddenLayers - 1) : 0;
  static constexpr std::size_t kParams =
      First::kParams + (HiddenLayers >= 1 ? kMiddle * Middle::kParams + Last::kParams : 0);

  /// Saved activations of one forward pass.
  struct Context {
    std::array<BatchMatrix<Scalar>, HiddenLayers + 1> z;  ///< pre-activations (z[0] unused)
    std::array<BatchMatrix<Scalar>, HiddenLayers + 1> h;  ///< h[i] = act(z[i]), i >= 1
    BatchMatrix<Scalar> dh, dz;                            ///< backward scratch
  };

  /// `hidden_init` for the hidden layers, `out_init` for the last one (zero/small: near-zero output).
  Mlp() : Mlp(HeadInitOptions{}, HeadInitOptions{}) {}
  Mlp(const HeadInitOptions& hidden_init, const HeadInitOptions& out_init) {
    HeadInitOptions h = hidden_init;
    if constexpr (HiddenLayers == 0) {
      first_.initialise(out_init);
    } else {
      first_.initialise(h);
      for (std::size_t i = 0; i < kMiddle; ++i) {
        h.seed = hidden_init.seed + 1 + i;
        middle_[i].initialise(h);
      }
      last_.initialise(out_init);
    }
  }

  /// Number of parameter segments (one per layer) and segment i's buffer.
  [[nodiscard]] static constexpr std::size_t segment_count() noexcept { return HiddenLayers == 0 ? 1 : 2 + kMiddle; }
  [[nodiscard]] std::span<Scalar> segment(std::size_t i) noexcept {
    if (i == 0) return first_.params();
    if constexpr (HiddenLayers > 0) {
      if (i <= kMiddle) return middle_[i - 1].params();
      return last_.params();
    }
    return {};
  }
  [[nodiscard]] std::size_t segment_size(std::size_t i) const noexcept {
    if (i == 0) return First::kParams;
    return i <= kMiddle ? Middle::kParams : Last::kParams;
  }
  [[nodiscard]] First& first() noexcept { return first_; }
  [[nodiscard]] const First& first() const noexcept { return first_; }
  [[nodiscard]] Last& last() noexcept { return last_; }
  [[nodiscard]] const Last& last() const noexcept { return last_; }

  /// Y (N x Out) from X (N x In). `pool` is used by a single few-output layer (HiddenLayers == 0, see
  /// Linear; the same result with or without it) and ignored otherwise.
  template <class XMat, class YMat>
  void forward(const XMat& X, YMat& Y, Context& ctx, ThreadPool* pool = nullptr) const {
    if constexpr (HiddenLayers == 0) {
      first_.forward(X, Y, pool);
    } else {
      first_.forward(X, ctx.z[1]);
      activate(ctx.z[1], ctx.h[1]);
      for (std::size_t i = 0; i < kMiddle; ++i) {
        middle_[i].forward(ctx.h[i + 1], ctx.z[i + 2]);
        activate(ctx.z[i + 2], ctx.h[i + 2]);
      }
      last_.forward(ctx.h[HiddenLayers], Y);
    }
  }

  /// Accumulates dL/dparams into `grads` (segment i into grads[i]) and, if dX is not null, dL/dX.
  template <class XMat, class GMat, class DXMat = BatchMatrix<Scalar>>
  void backward(const XMat& X, const GMat& dY, Context& ctx, std::span<const std::span<Scalar>> grads,
                DXMat* dX = nullptr, ThreadPool* pool = nullptr) const {
    VIDEO3DGS_ASSERT(grads.size() == segment_count(), "Mlp::backward: one gradient buffer per segment");
    if constexpr (HiddenLayers == 0) {
      first_.backward(X, dY, grads[0], dX, pool);
    } else {
      const Eigen::Index n = dY.rows();
      ctx.dh.setZero(n, Hidden);
      last_.backward(ctx.h[HiddenLayers], dY, grads[segment_count() - 1], &ctx.dh);
      for (std::size_t i = kMiddle; i-- > 0;) {
        d_activate(ctx.z[i + 2], ctx.h[i + 2], ctx.dh, ctx.dz);
        ctx.dh.setZero(n, Hidden);
        middle_[i].backward(ctx.h[i + 1], ctx.dz, grads[i + 1], &ctx.dh);
      }
      d_activate(ctx.z[1], ctx.h[1], ctx.dh, ctx.dz);
      first_.backward(X, ctx.dz, grads[0], dX);
    }
  }

 private:
  static void activate(const BatchMatrix<Scalar>& z, BatchMatrix<Scalar>& h) {
    h.resize(z.rows(), z.cols());
    for (Eigen::Index i = 0; i < z.size(); ++i) h.data()[i] = Activation::value(z.data()[i]);
  }
  static void d_activate(const BatchMatrix<Scalar>& z, const BatchMatrix<Scalar>& h, const BatchMatrix<Scalar>& dh,
                         BatchMatrix<Scalar>& dz) {
    dz.resize(z.rows(), z.cols());
    for (Eigen::Index i = 0; i < z.size(); ++i)
      dz.data()[i] = Activation::derivative(z.data()[i], h.data()[i]) * dh.data()[i];
  }

  First first_;
  std::array<Middle, kMiddle> middle_;
  Last last_;
};

}  // namespace video3dgs
