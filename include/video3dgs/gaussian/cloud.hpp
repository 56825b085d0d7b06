#pragma once
/// @file
/// `Gaussian<Scalar, SHDegree>` (one primitive), `GaussianCloud<Scalar, SHDegree>` (structure of arrays),
/// and the non-owning views the rasterizer consumes: `GaussianParams<Scalar>` (const spans) and
/// `GaussianGrads<Scalar>` (mutable spans, field by field the mirror of the parameters).
///
/// Per Gaussian i (docs/method.md):
///   mean            [3i .. 3i+3)        world position
///   log_scale       [3i .. 3i+3)        s = exp(log_scale) (activations.hpp)
///   rotation        [4i .. 4i+4)        unnormalised quaternion (w, x, y, z)
///   opacity_logit   [i]                 o = sigmoid(opacity_logit)
///   sh              [3Ki .. 3K(i+1))    K = (SHDegree+1)² coefficients x 3 channels, `sh[3(Ki + k) + c]`
///
/// The views let a caller render per-iteration deformed parameters (e.g. mean + dxyz from a deformation
/// field) from its own buffers without copying into a cloud.

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/sh/basis.hpp"

namespace video3dgs {

/// Non-owning read-only view of N Gaussians' parameters (SoA). `sh_degree` is the storage degree:
/// each Gaussian has coeff_count(sh_degree) x 3 SH coefficients.
template <class Scalar>
struct GaussianParams {
  std::size_t count = 0;
  int sh_degree = 0;
  std::span<const Scalar> mean;           ///< N x 3
  std::span<const Scalar> log_scale;      ///< N x 3
  std::span<const Scalar> rotation;       ///< N x 4 (w, x, y, z)
  std::span<const Scalar> opacity_logit;  ///< N
  std::span<const Scalar> sh;             ///< N x K x 3

  [[nodiscard]] int sh_coeffs() const noexcept { return sh::coeff_count(sh_degree); }
  /// Throws `option.gaussians` if a span's size does not match `count`.
  void validate(const char* where = "gaussians") const {
    auto bad = [&](const char* field, std::size_t got, std::size_t want) {
      throw option_error("option.gaussians", std::string(where) + "." + field,
                         "has " + std::to_string(got) + " values, expected " + std::to_string(want));
    };
    if (sh_degree < 0 || sh_degree > sh::kMaxDegree)
      throw option_error("option.gaussians", std::string(where) + ".sh_degree", "must be in 0..3");
    if (mean.size() != 3 * count) bad("mean", mean.size(), 3 * count);
    if (log_scale.size() != 3 * count) bad("log_scale", log_scale.size(), 3 * count);
    if (rotation.size() != 4 * count) bad("rotation", rotation.size(), 4 * count);
    if (opacity_logit.size() != count) bad("opacity_logit", opacity_logit.size(), count);
    const std::size_t K = static_cast<std::size_t>(sh_coeffs());
    if (sh.size() != 3 * K * count) bad("sh", sh.size(), 3 * K * count);
  }
};

/// Non-owning mutable view of gradients, mirroring `GaussianParams` field by field. An empty span means
/// "not wanted" (the rasterizer then skips that output).
template <class Scalar>
struct GaussianGrads {
  std::span<Scalar> dL_dmean;           ///< N x 3
  std::span<Scalar> dL_dlog_scale;      ///< N x 3
  std::span<Scalar> dL_drotation;       ///< N x 4
  std::span<Scalar> dL_dopacity_logit;  ///< N
  std::span<Scalar> dL_dsh;             ///< N x K x 3
};

/// One Gaussian with SH degree fixed at compile time.
template <class Scalar, int SHDegree>
struct Gaussian {
  static_assert(SHDegree >= 0 && SHDegree <= 3, "video3dgs: Gaussian<Scalar, SHDegree> needs SHDegree in 0..3");
  static constexpr int sh_coeffs = sh::coeff_count(SHDegree);
  std::array<Scalar, 3> mean{};
  std::array<Scalar, 3> log_scale{};
  std::array<Scalar, 4> rotation{Scalar(1), Scalar(0), Scalar(0), Scalar(0)};
  Scalar opacity_logit = 0;
  std::array<Scalar, 3 * sh_coeffs> sh{};  ///< sh[3k + c]

  /// Sets the DC band so that the view-independent colour is `rgb` (other bands untouched).
  void set_rgb(Scalar r, Scalar g, Scalar b) {
    sh[0] = sh::rgb_to_dc(r);
    sh[1] = sh::rgb_to_dc(g);
    sh[2] = sh::rgb_to_dc(b);
  }
};

/// Structure-of-arrays cloud of Gaussians with a compile-time SH degree.
template <class Scalar, int SHDegree>
class GaussianCloud {
  static_assert(SHDegree >= 0 && SHDegree <= 3, "video3dgs: GaussianCloud<Scalar, SHDegree> needs SHDegree in 0..3");

 public:
  using scalar_type = Scalar;
  using value_type = Gaussian<Scalar, SHDegree>;
  static constexpr int sh_degree = SHDegree;
  static constexpr int sh_coeffs = sh::coeff_count(SHDegree);

  std::vector<Scalar> mean, log_scale, rotation, opacity_logit, sh;

  GaussianCloud() = default;
  explicit GaussianCloud(std::size_t n) { resize(n); }

  [[nodiscard]] std::size_t size() const noexcept { return opacity_logit.size(); }
  [[nodiscard]] bool empty() const noexcept { return opacity_logit.empty(); }
  /// Resizes every array; new Gaussians are at the origin, unit scale, identity rotation, opacity 1/2,
  /// SH zero (grey 0.5).
  void resize(std::size_t n) {
    const std::size_t old = size();
    mean.resize(3 * n, Scalar(0));
    log_scale.resize(3 * n, Scalar(0));
    rotation.resize(4 * n, Scalar(0));
    for (std::size_t i = old; i < n; ++i) rotation[4 * i] = Scalar(1);
    opacity_logit.resize(n, Scalar(0));
    sh.resize(3 * sh_coeffs * n, Scalar(0));
  }
  void reserve(std::size_t n) {
    mean.reserve(3 * n);
    log_scale.reserve(3 * n);
    rotation.reserve(4 * n);
    opacity_logit.reserve(n);
    sh.reserve(3 * sh_coeffs * n);
  }
  void clear() { resize(0); }

  void push_back(const value_type& g) {
    mean.insert(mean.end(), g.mean.begin(), g.mean.end());
    log_scale.insert(log_scale.end(), g.log_scale.begin(), g.log_scale.end());
    rotation.insert(rotation.end(), g.rotation.begin(), g.rotation.end());
    opacity_logit.push_back(g.opacity_logit);
    sh.insert(sh.end(), g.sh.begin(), g.sh.end());
  }
  [[nodiscard]] value_type get(std::size_t i) const {
    value_type g;
    for (int k = 0; k < 3; ++k) g.mean[k] = mean[3 * i + k], g.log_scale[k] = log_scale[3 * i + k];
    for (int k = 0; k < 4; ++k) g.rotation[k] = rotation[4 * i + k];
    g.opacity_logit = opacity_logit[i];
    for (int k = 0; k < 3 * sh_coeffs; ++k) g.sh[k] = sh[3 * sh_coeffs * i + k];
    return g;
  }
  void set(std::size_t i, const value_type& g) {
    for (int k = 0; k < 3; ++k) mean[3 * i + k] = g.mean[k], log_scale[3 * i + k] = g.log_scale[k];
    for (int k = 0; k < 4; ++k) rotation[4 * i + k] = g.rotation[k];
    opacity_logit[i] = g.opacity_logit;
    for (int k = 0; k < 3 * sh_coeffs; ++k) sh[3 * sh_coeffs * i + k] = g.sh[k];
  }

  /// Drops the rows with keep[i] == 0, preserving the order of the others.
  /// @throws option_error `option.gaussians` if keep.size() != size()
  void keep_rows(std::span<const std::uint8_t> keep) {
    if (keep.size() != size())
      throw option_error("option.gaussians", "keep", "has " + std::to_string(keep.size()) + " entries for " + std::to_string(size()) + " rows");
    constexpr std::size_t K3 = 3 * static_cast<std::size_t>(sh_coeffs);
    std::size_t out = 0;
    for (std::size_t i = 0; i < keep.size(); ++i) {
      if (!keep[i]) continue;
      if (out != i) {
        std::copy_n(&mean[3 * i], 3, &mean[3 * out]);
        std::copy_n(&log_scale[3 * i], 3, &log_scale[3 * out]);
        std::copy_n(&rotation[4 * i], 4, &rotation[4 * out]);
        opacity_logit[out] = opacity_logit[i];
        std::copy_n(&sh[K3 * i], K3, &sh[K3 * out]);
      }
      ++out;
    }
    resize(out);
  }

  /// Read-only view for the rasterizer (valid until the cloud is resized).
  [[nodiscard]] GaussianParams<Scalar> params() const noexcept {
    return {size(), SHDegree, mean, log_scale, rotation, opacity_logit, sh};
  }
};

/// Owning gradient buffers mirroring `GaussianCloud` (zero-initialised).
template <class Scalar, int SHDegree>
struct GaussianCloudGrad {
  static constexpr int sh_coeffs = sh::coeff_count(SHDegree);
  std::vector<Scalar> dL_dmean, dL_dlog_scale, dL_drotation, dL_dopacity_logit, dL_dsh;

  GaussianCloudGrad() = default;
  explicit GaussianCloudGrad(std::size_t n) { resize(n); }
  void resize(std::size_t n) {
    dL_dmean.assign(3 * n, Scalar(0));
    dL_dlog_scale.assign(3 * n, Scalar(0));
    dL_drotation.assign(4 * n, Scalar(0));
    dL_dopacity_logit.assign(n, Scalar(0));
    dL_dsh.assign(3 * sh_coeffs * n, Scalar(0));
  }
  [[nodiscard]] std::size_t size() const noexcept { return dL_dopacity_logit.size(); }
  [[nodiscard]] GaussianGrads<Scalar> grads() noexcept {
    return {dL_dmean, dL_dlog_scale, dL_drotation, dL_dopacity_logit, dL_dsh};
  }
};

template <int D> using GaussianCloudF = GaussianCloud<float, D>;
template <int D> using GaussianCloudD = GaussianCloud<double, D>;
template <int D> using GaussianF = Gaussian<float, D>;
template <int D> using GaussianD = Gaussian<double, D>;

}  // namespace video3dgs
