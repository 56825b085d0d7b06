#pragma once
/// @file
/// `AreaResampler`: exact area-weighted resampling between two image sizes, as a linear operator R
/// with its adjoint, for images that are resampled every iteration (a training resolution schedule:
/// the alpha logits of a frame at the render's size) and whose gradients flow back.
///
/// Continuous pixel coordinates: pixel i covers [i, i + 1) and its centre is i + 1/2 (the camera's
/// convention, `Camera::resized`). Along one axis of n_in -> n_out pixels, s = n_in / n_out; output
/// pixel o covers the source interval [o s, (o + 1) s) and its value is the coverage-weighted mean
///
///     out[o] = sum_i w_oi in[i],   w_oi = |[i, i + 1) ∩ [o s, (o + 1) s)| / s,   sum_i w_oi = 1,
///
/// applied along x, then along y (separable; R = R_y R_x). Any ratio, up or down. The adjoint
/// R^T = R_x^T R_y^T spreads each output value back with the same weights (<R a, b> = <a, R^T b>).
///
/// Sums run in double in a fixed order; one call is serial (deterministic; the maps it is meant for
/// cost about a millisecond at 854x480). The object keeps its scratch row buffer: once built, calls
/// do not allocate (one object per thread of use).

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"

namespace video3dgs {

class AreaResampler {
 public:
  AreaResampler() = default;
  /// @throws option_error `option.size` unless every size is >= 1.
  AreaResampler(int w_in, int h_in, int w_out, int h_out) : w_in_(w_in), h_in_(h_in), w_out_(w_out), h_out_(h_out) {
    if (w_in < 1 || h_in < 1 || w_out < 1 || h_out < 1) throw option_error("option.size", "resample", "sizes must be >= 1");
    x_ = axis(w_in, w_out);
    y_ = axis(h_in, h_out);
  }

  [[nodiscard]] int in_width() const noexcept { return w_in_; }
  [[nodiscard]] int in_height() const noexcept { return h_in_; }
  [[nodiscard]] int out_width() const noexcept { return w_out_; }
  [[nodiscard]] int out_height() const noexcept { return h_out_; }
  [[nodiscard]] bool maps(int w_in, int h_in, int w_out, int h_out) const noexcept {
    return w_in == w_in_ && h_in == h_in_ && w_out == w_out_ && h_out == h_out_;
  }

  /// out = R in (in: in_width x in_height, out: out_width x out_height). The pass along x is
  /// rounded to Scalar before the pass along y.
  template <class Scalar, int C>
  void forward(ConstImageView<Scalar, C> in, ImageView<Scalar, C> out) {
    check(in.width() == w_in_ && in.height() == h_in_ && out.width() == w_out_ && out.height() == h_out_, "forward");
    std::vector<double>& tmp = scratch(std::size_t(w_out_) * std::size_t(h_in_) * C);  // R_x in: h_in rows of w_out pixels
    for (int y = 0; y < h_in_; ++y) {
      const Scalar* src = in.row(y);
      double* dst = tmp.data() + std::size_t(y) * std::size_t(w_out_) * C;
      for (int x = 0; x < w_out_; ++x)
        for (int c = 0; c < C; ++c) {
          double v = 0;
          for (std::size_t k = x_.begin[std::size_t(x)]; k < x_.begin[std::size_t(x) + 1]; ++k)
            v += x_.weight[k] * double(src[std::size_t(x_.index[k]) * C + std::size_t(c)]);
          dst[std::size_t(x) * C + std::size_t(c)] = double(Scalar(v));
        }
    }
    const std::size_t n = std::size_t(w_out_) * C;
    for (int y = 0; y < h_out_; ++y) {
      Scalar* dst = out.row(y);
      for (std::size_t i = 0; i < n; ++i) {
        double v = 0;
        for (std::size_t k = y_.begin[std::size_t(y)]; k < y_.begin[std::size_t(y) + 1]; ++k)
          v += y_.weight[k] * tmp[std::size_t(y_.index[k]) * n + i];
        dst[i] = Scalar(v);
      }
    }
  }

  /// in_grad += R^T out_grad (out_grad: out_width x out_height, in_grad: in_width x in_height).
  template <class Scalar, int C>
  void adjoint_add(ConstImageView<Scalar, C> out_grad, ImageView<Scalar, C> in_grad) {
    check(out_grad.width() == w_out_ && out_grad.height() == h_out_ && in_grad.width() == w_in_ && in_grad.height() == h_in_, "adjoint_add");
    const std::size_t n = std::size_t(w_out_) * C;
    std::vector<double>& tmp = scratch(n * std::size_t(h_in_));  // R_y^T out_grad: h_in rows of w_out pixels
    std::fill_n(tmp.begin(), n * std::size_t(h_in_), 0.0);
    for (int y = 0; y < h_out_; ++y) {
      const Scalar* g = out_grad.row(y);
      for (std::size_t k = y_.begin[std::size_t(y)]; k < y_.begin[std::size_t(y) + 1]; ++k) {
        double* dst = tmp.data() + std::size_t(y_.index[k]) * n;
        const double w = y_.weight[k];
        for (std::size_t i = 0; i < n; ++i) dst[i] += w * double(g[i]);
      }
    }
    for (int y = 0; y < h_in_; ++y) {
      const double* g = tmp.data() + std::size_t(y) * n;
      Scalar* dst = in_grad.row(y);
      for (int x = 0; x < w_out_; ++x)
        for (std::size_t k = x_.begin[std::size_t(x)]; k < x_.begin[std::size_t(x) + 1]; ++k)
          for (int c = 0; c < C; ++c)
            dst[std::size_t(x_.index[k]) * C + std::size_t(c)] += Scalar(x_.weight[k] * g[std::size_t(x) * C + std::size_t(c)]);
    }
  }

 private:
  /// One axis's weights, output pixel o's taps at [begin[o], begin[o + 1]).
  struct Axis {
    std::vector<std::size_t> begin;
    std::vector<int> index;
    std::vector<double> weight;
  };

  static Axis axis(int n_in, int n_out) {
    Axis a;
    const double s = double(n_in) / double(n_out);
    a.begin.push_back(0);
    for (int o = 0; o < n_out; ++o) {
      const double lo = o * s, hi = (o + 1) * s;
      const std::size_t first = a.weight.size();
      double sum = 0;
      for (int i = static_cast<int>(std::floor(lo)); i < static_cast<int>(std::ceil(hi)) && i < n_in; ++i) {
        const double cover = std::min(hi, double(i + 1)) - std::max(lo, double(i));
        if (cover > 0) a.index.push_back(i), a.weight.push_back(cover), sum += cover;
      }
      for (std::size_t k = first; k < a.weight.size(); ++k) a.weight[k] /= sum;
      a.begin.push_back(a.weight.size());
    }
    return a;
  }

  /// The scratch buffer with at least n elements (grows, never shrinks).
  std::vector<double>& scratch(std::size_t n) {
    if (scratch_.size() < n) scratch_.resize(n);
    return scratch_;
  }

  static void check(bool ok, const char* what) {
    if (!ok) throw option_error("option.size", std::string("resample.") + what, "image sizes differ from the resampler's");
  }

  int w_in_ = 0, h_in_ = 0, w_out_ = 0, h_out_ = 0;
  Axis x_, y_;
  std::vector<double> scratch_;
};

/// Area-weighted resampling of `in` to w x h (any ratio; `AreaResampler`). @throws option_error `option.size`.
template <class Scalar, int C>
[[nodiscard]] Image<Scalar, C> resize_area(const Image<Scalar, C>& in, int w, int h) {
  if (w < 1 || h < 1 || in.width() < 1 || in.height() < 1) throw option_error("option.size", "resize", "sizes must be >= 1");
  if (w == in.width() && h == in.height()) return in;
  Image<Scalar, C> out(w, h);
  AreaResampler(in.width(), in.height(), w, h).forward<Scalar, C>(in, out);
  return out;
}

}  // namespace video3dgs
