#pragma once
/// @file
/// `Image<Scalar, Channels>`: an owning row-major image with interleaved channels, and
/// `ImageView` / `ConstImageView`: non-owning views with an explicit stride.
///
/// Layout: element (x, y, c) is at `data[y * stride + x * Channels + c]`, `stride` counted in
/// scalars (>= width * Channels). Values are linear floats, nominally in [0, 1]. Pixel (x, y) covers
/// [x, x+1) x [y, y+1); its centre is (x + 0.5, y + 0.5) (see camera.hpp).

#include <algorithm>
#include <cstddef>
#include <type_traits>
#include <vector>

#include "video3dgs/core/assert.hpp"
#include "video3dgs/core/scalar_traits.hpp"

namespace video3dgs {

/// A window of an image (a training crop, graph/clip_graph.hpp): pixels [x, x + width) x [y, y + height). Empty (width or
/// height 0): the whole image.
struct PixelWindow {
  int x = 0, y = 0, width = 0, height = 0;
  [[nodiscard]] bool empty() const noexcept { return width <= 0 || height <= 0; }
  friend bool operator==(const PixelWindow&, const PixelWindow&) = default;
};


template <class Scalar, int Channels, class Pointer>
class BasicImageView {
  static_assert(Channels >= 1, "video3dgs: an image needs at least one channel");

 public:
  using scalar_type = Scalar;
  static constexpr int channels = Channels;

  BasicImageView() = default;
  BasicImageView(Pointer data, int width, int height, std::ptrdiff_t stride)
      : data_(data), width_(width), height_(height), stride_(stride) {
    VIDEO3DGS_ASSERT(width >= 0 && height >= 0 && stride >= static_cast<std::ptrdiff_t>(width) * Channels,
                     "image view: bad size or stride");
  }
  BasicImageView(Pointer data, int width, int height)
      : BasicImageView(data, width, height, static_cast<std::ptrdiff_t>(width) * Channels) {}
  /// Views of mutable images convert to views of const images.
  template <class P>
    requires(!std::is_same_v<P, Pointer> && std::is_convertible_v<P, Pointer>)
  BasicImageView(const BasicImageView<Scalar, Channels, P>& o)  // NOLINT(google-explicit-constructor)
      : data_(o.data()), width_(o.width()), height_(o.height()), stride_(o.stride()) {}

  [[nodiscard]] int width() const noexcept { return width_; }
  [[nodiscard]] int height() const noexcept { return height_; }
  [[nodiscard]] std::ptrdiff_t stride() const noexcept { return stride_; }
  [[nodiscard]] std::size_t pixel_count() const noexcept {
    return static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_);
  }
  [[nodiscard]] bool empty() const noexcept { return width_ == 0 || height_ == 0; }
  [[nodiscard]] Pointer data() const noexcept { return data_; }
  [[nodiscard]] Pointer row(int y) const noexcept { return data_ + static_cast<std::ptrdiff_t>(y) * stride_; }
  [[nodiscard]] Pointer pixel(int x, int y) const noexcept { return row(y) + static_cast<std::ptrdiff_t>(x) * Channels; }
  [[nodiscard]] decltype(auto) operator()(int x, int y, int c = 0) const noexcept {
    VIDEO3DGS_ASSERT(x >= 0 && x < width_ && y >= 0 && y < height_ && c >= 0 && c < Channels, "image index out of range");
    return pixel(x, y)[c];
  }
  /// A sub-rectangle [x0, x0+w) x [y0, y0+h), sharing storage.
  [[nodiscard]] BasicImageView crop(int x0, int y0, int w, int h) const noexcept {
    VIDEO3DGS_ASSERT(x0 >= 0 && y0 >= 0 && w >= 0 && h >= 0 && x0 + w <= width_ && y0 + h <= height_, "crop out of range");
    return BasicImageView(pixel(x0, y0), w, h, stride_);
  }

 private:
  Pointer data_ = nullptr;
  int width_ = 0;
  int height_ = 0;
  std::ptrdiff_t stride_ = 0;
};

template <class Scalar, int Channels>
using ImageView = BasicImageView<Scalar, Channels, Scalar*>;
template <class Scalar, int Channels>
using ConstImageView = BasicImageView<Scalar, Channels, const Scalar*>;

/// Owning, contiguous image (stride == width * Channels).
template <class Scalar, int Channels>
class Image {
  static_assert(Channels >= 1, "video3dgs: an image needs at least one channel");

 public:
  using scalar_type = Scalar;
  static constexpr int channels = Channels;

  Image() = default;
  Image(int width, int height, Scalar fill = Scalar(0)) { resize(width, height, fill); }

  /// Resizes and fills every element with `fill` (contents are not preserved).
  void resize(int width, int height, Scalar fill = Scalar(0)) {
    VIDEO3DGS_ASSERT(width >= 0 && height >= 0, "negative image size");
    width_ = width;
    height_ = height;
    data_.assign(static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * Channels, fill);
  }
  void fill(Scalar v) { std::fill(data_.begin(), data_.end(), v); }

  [[nodiscard]] int width() const noexcept { return width_; }
  [[nodiscard]] int height() const noexcept { return height_; }
  [[nodiscard]] std::ptrdiff_t stride() const noexcept { return static_cast<std::ptrdiff_t>(width_) * Channels; }
  [[nodiscard]] std::size_t pixel_count() const noexcept {
    return static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_);
  }
  [[nodiscard]] std::size_t size() const noexcept { return data_.size(); }
  [[nodiscard]] bool empty() const noexcept { return data_.empty(); }
  [[nodiscard]] Scalar* data() noexcept { return data_.data(); }
  [[nodiscard]] const Scalar* data() const noexcept { return data_.data(); }
  [[nodiscard]] Scalar* pixel(int x, int y) noexcept { return data_.data() + (static_cast<std::ptrdiff_t>(y) * width_ + x) * Channels; }
  [[nodiscard]] const Scalar* pixel(int x, int y) const noexcept {
    return data_.data() + (static_cast<std::ptrdiff_t>(y) * width_ + x) * Channels;
  }
  [[nodiscard]] Scalar& operator()(int x, int y, int c = 0) noexcept {
    VIDEO3DGS_ASSERT(x >= 0 && x < width_ && y >= 0 && y < height_ && c >= 0 && c < Channels, "image index out of range");
    return pixel(x, y)[c];
  }
  [[nodiscard]] Scalar operator()(int x, int y, int c = 0) const noexcept {
    VIDEO3DGS_ASSERT(x >= 0 && x < width_ && y >= 0 && y < height_ && c >= 0 && c < Channels, "image index out of range");
    return pixel(x, y)[c];
  }
  [[nodiscard]] std::vector<Scalar>& storage() noexcept { return data_; }
  [[nodiscard]] const std::vector<Scalar>& storage() const noexcept { return data_; }

  [[nodiscard]] ImageView<Scalar, Channels> view() noexcept { return {data(), width_, height_}; }
  [[nodiscard]] ConstImageView<Scalar, Channels> view() const noexcept { return {data(), width_, height_}; }
  [[nodiscard]] ConstImageView<Scalar, Channels> cview() const noexcept { return view(); }
  operator ImageView<Scalar, Channels>() noexcept { return view(); }                   // NOLINT
  operator ConstImageView<Scalar, Channels>() const noexcept { return view(); }        // NOLINT

  /// Deep copy of a view (any stride).
  static Image from_view(ConstImageView<Scalar, Channels> v) {
    Image img(v.width(), v.height());
    for (int y = 0; y < v.height(); ++y) std::copy_n(v.row(y), static_cast<std::size_t>(v.width()) * Channels, img.pixel(0, y));
    return img;
  }

  /// Element type conversion (e.g. float <-> double), value by value.
  template <class Other>
  [[nodiscard]] Image<Other, Channels> cast() const {
    Image<Other, Channels> out(width_, height_);
    std::transform(data_.begin(), data_.end(), out.data(), [](Scalar v) { return static_cast<Other>(v); });
    return out;
  }

 private:
  int width_ = 0;
  int height_ = 0;
  std::vector<Scalar> data_;
};

template <class Scalar>
using Mask = Image<Scalar, 1>;
using ImageF3 = Image<float, 3>;
using ImageD3 = Image<double, 3>;
using ImageF1 = Image<float, 1>;
using ImageD1 = Image<double, 1>;

}  // namespace video3dgs
