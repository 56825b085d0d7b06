#pragma once
/// @file
/// WarpSSIM: temporal consistency of an edited video measured through the motion of its source.
/// For frames t = 0..n-2, with g_t the source flow from frame t+1 to frame t and f_t the flow from
/// frame t to t+1 (flow/warp.hpp conventions):
///
///   W_t(x)   = E_t(x + g_t(x))                   edited frame t warped onto frame t+1 (bilinear)
///   V_t(x)   = forward-backward check of (f_t, g_t) at x and x + g_t(x) inside the frame
///   S_t      = mean over { x : V_t(x) = 1 } of SSIM-map(E_{t+1}, W_t)(x)   (channels averaged)
///   WarpSSIM = 1/(n-1) sum_t S_t
///
/// The SSIM map is the metric's (11x11 Gaussian window, sigma 1.5, C1 = 0.01^2, C2 = 0.03^2, zero
/// padding, computed in double). Occluded pixels of W_t are replaced by E_{t+1} before filtering, so
/// that they cannot pull down the SSIM of their visible neighbours, and are excluded from the mean.
/// A pair with no visible pixel is skipped (and counted in `skipped_pairs`).
///
/// Flows come from Middlebury .flo files (`read_video_flows`, e.g. written by RAFT) or from the
/// built-in estimator (`estimate_video_flows`, flow/horn_schunck.hpp).

#include <cmath>
#include <cstddef>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/flow/flo_io.hpp"
#include "video3dgs/flow/horn_schunck.hpp"
#include "video3dgs/flow/warp.hpp"
#include "video3dgs/loss/ssim.hpp"

namespace video3dgs::metrics {

/// Source-video flows of consecutive frames: forward[t] = t -> t+1, backward[t] = t+1 -> t.
struct VideoFlows {
  std::vector<flow::FlowFieldF> forward, backward;
  [[nodiscard]] std::size_t pairs() const noexcept { return forward.size(); }
};

/// Both flows of every consecutive pair of `source` with the built-in estimator (pairs in parallel,
/// each serial: the result does not depend on the pool).
/// @throws option_error `option.flow` (fewer than 2 frames, unequal sizes, bad options)
[[nodiscard]] inline VideoFlows estimate_video_flows(const std::vector<Image<float, 3>>& source,
                                                     const flow::HornSchunckOptions& o = {}, ThreadPool* pool = nullptr) {
  o.validate();
  if (source.size() < 2) throw option_error("option.flow", "source", "needs at least 2 frames");
  for (const auto& f : source)
    if (f.width() != source[0].width() || f.height() != source[0].height())
      throw option_error("option.flow", "source", "frames differ in size");
  const std::size_t n = source.size() - 1;
  VideoFlows out;
  out.forward.resize(n);
  out.backward.resize(n);
  parallel_for(pool, 2 * n, [&](std::size_t j) {
    const std::size_t t = j / 2;
    if (j % 2 == 0)
      out.forward[t] = flow::estimate_flow<float>(source[t], source[t + 1], o, nullptr);
    else
      out.backward[t] = flow::estimate_flow<float>(source[t + 1], source[t], o, nullptr);
  }, 1);
  return out;
}

/// Reads flows from two folders of .flo files (natural order): `forward_dir` holds t -> t+1 and
/// `backward_dir` t+1 -> t, one file per pair.
/// @throws io_error (flo_io.hpp errors, `io.count_mismatch`)
[[nodiscard]] inline VideoFlows read_video_flows(const std::filesystem::path& forward_dir, const std::filesystem::path& backward_dir) {
  VideoFlows out;
  for (const auto& p : flow::list_flo_files(forward_dir)) out.forward.push_back(flow::read_flo(p));
  for (const auto& p : flow::list_flo_files(backward_dir)) out.backward.push_back(flow::read_flo(p));
  if (out.forward.size() != out.backward.size())
    throw io_error("io.count_mismatch", backward_dir.string(),
                   std::to_string(out.backward.size()) + " backward flows for " + std::to_string(out.forward.size()) + " forward flows");
  return out;
}

struct WarpSsimOptions {
  flow::ConsistencyOptions consistency{};
  loss::SsimOptions ssim{};
};

struct WarpSsimResult {
  double value = 0;                     ///< mean of per_pair over the counted pairs
  std::vector<double> per_pair;         ///< S_t (NaN for a skipped pair)
  std::vector<double> visible_fraction; ///< share of pixels counted per pair
  std::size_t skipped_pairs = 0;
};

namespace detail {

/// Separable Gaussian filter of a double plane with zero padding.
inline void gauss_filter(const std::vector<double>& in, std::vector<double>& tmp, std::vector<double>& out, int w, int h,
                         const std::vector<double>& k, int r) {
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double a = 0;
      for (int i = -r; i <= r; ++i) {
        const int xx = x + i;
        if (xx >= 0 && xx < w) a += k[std::size_t(i + r)] * in[std::size_t(y) * std::size_t(w) + std::size_t(xx)];
      }
      tmp[std::size_t(y) * std::size_t(w) + std::size_t(x)] = a;
    }
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double a = 0;
      for (int i = -r; i <= r; ++i) {
        const int yy = y + i;
        if (yy >= 0 && yy < h) a += k[std::size_t(i + r)] * tmp[std::size_t(yy) * std::size_t(w) + std::size_t(x)];
      }
      out[std::size_t(y) * std::size_t(w) + std::size_t(x)] = a;
    }
}

}  // namespace detail

/// Mean of the SSIM map of `a` against `b` (channels averaged) over the pixels where `mask` > 0.5.
/// @return the masked mean SSIM, NaN if the mask selects nothing
template <class Scalar, int C>
[[nodiscard]] double masked_ssim(ConstImageView<Scalar, C> a, ConstImageView<Scalar, C> b, ConstImageView<Scalar, 1> mask,
                                 const loss::SsimOptions& o = {}) {
  if (a.width() != b.width() || a.height() != b.height() || mask.width() != a.width() || mask.height() != a.height())
    throw option_error("option.size", "masked_ssim", "images and mask differ in size");
  const int w = a.width(), h = a.height(), r = o.radius;
  const std::size_t n = a.pixel_count();
  std::vector<double> k(std::size_t(2 * r + 1));
  double ks = 0;
  for (int i = -r; i <= r; ++i) ks += k[std::size_t(i + r)] = std::exp(-0.5 * i * i / (o.sigma * o.sigma));
  for (double& v : k) v /= ks;
  std::vector<double> x(n), y(n), tmp(n), mx(n), my(n), exx(n), eyy(n), exy(n), prod(n), map(n, 0.0);
  for (int c = 0; c < C; ++c) {
    for (int yy = 0; yy < h; ++yy)
      for (int xx = 0; xx < w; ++xx) {
        const std::size_t p = std::size_t(yy) * std::size_t(w) + std::size_t(xx);
        x[p] = double(a.row(yy)[xx * C + c]);
        y[p] = double(b.row(yy)[xx * C + c]);
      }
    detail::gauss_filter(x, tmp, mx, w, h, k, r);
    detail::gauss_filter(y, tmp, my, w, h, k, r);
    for (std::size_t p = 0; p < n; ++p) prod[p] = x[p] * x[p];
    detail::gauss_filter(prod, tmp, exx, w, h, k, r);
    for (std::size_t p = 0; p < n; ++p) prod[p] = y[p] * y[p];
    detail::gauss_filter(prod, tmp, eyy, w, h, k, r);
    for (std::size_t p = 0; p < n; ++p) prod[p] = x[p] * y[p];
    detail::gauss_filter(prod, tmp, exy, w, h, k, r);
    for (std::size_t p = 0; p < n; ++p) {
      const double a1 = 2 * mx[p] * my[p] + o.c1, a2 = 2 * (exy[p] - mx[p] * my[p]) + o.c2;
      const double b1 = mx[p] * mx[p] + my[p] * my[p] + o.c1, b2 = (exx[p] - mx[p] * mx[p]) + (eyy[p] - my[p] * my[p]) + o.c2;
      map[p] += a1 * a2 / (b1 * b2) / C;
    }
  }
  double s = 0;
  std::size_t cnt = 0;
  for (int yy = 0; yy < h; ++yy)
    for (int xx = 0; xx < w; ++xx)
      if (mask.row(yy)[xx] > Scalar(0.5)) {
        s += map[std::size_t(yy) * std::size_t(w) + std::size_t(xx)];
        ++cnt;
      }
  return cnt ? s / double(cnt) : std::numeric_limits<double>::quiet_NaN();
}

/// WarpSSIM of `edited` (n frames) with the source flows `flows` (n - 1 pairs), see the file comment.
/// Pairs are evaluated in parallel (each serially): the result does not depend on the pool.
/// @throws option_error `option.warp_ssim` (fewer than 2 frames, pair count or size mismatch)
[[nodiscard]] inline WarpSsimResult warp_ssim(const std::vector<Image<float, 3>>& edited, const VideoFlows& flows,
                                              const WarpSsimOptions& o = {}, ThreadPool* pool = nullptr) {
  if (edited.size() < 2) throw option_error("option.warp_ssim", "edited", "needs at least 2 frames");
  if (flows.forward.size() != edited.size() - 1 || flows.backward.size() != edited.size() - 1)
    throw option_error("option.warp_ssim", "flows",
                       std::to_string(flows.forward.size()) + " flow pairs for " + std::to_string(edited.size()) + " frames");
  const int w = edited[0].width(), h = edited[0].height();
  for (std::size_t t = 0; t < edited.size(); ++t)
    if (edited[t].width() != w || edited[t].height() != h)
      throw option_error("option.warp_ssim", "frame " + std::to_string(t), "edited frames differ in size");
  for (std::size_t t = 0; t + 1 < edited.size(); ++t)
    for (const auto* f : {&flows.forward[t], &flows.backward[t]})
      if (f->width() != w || f->height() != h)
        throw option_error("option.warp_ssim", "flow " + std::to_string(t),
                           "is " + std::to_string(f->width()) + "x" + std::to_string(f->height()) + ", frames are " +
                               std::to_string(w) + "x" + std::to_string(h));
  const std::size_t pairs = edited.size() - 1;
  WarpSsimResult out;
  out.per_pair.assign(pairs, 0.0);
  out.visible_fraction.assign(pairs, 0.0);
  parallel_for(pool, pairs, [&](std::size_t t) {
    Image<float, 1> vis = flow::consistency_mask<float>(flows.forward[t].view(), flows.backward[t].view(), o.consistency);
    Image<float, 3> warped(w, h);
    Image<float, 1> inside(w, h);
    flow::warp_bilinear<float, 3, float>(edited[t].view(), flows.backward[t].view(), warped.view(), inside.view());
    std::size_t cnt = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        float& v = vis(x, y);
        v = (v > 0.5f && inside(x, y) > 0.5f) ? 1.f : 0.f;
        if (v > 0.5f) {
          ++cnt;
        } else {
          for (int c = 0; c < 3; ++c) warped(x, y, c) = edited[t + 1](x, y, c);
        }
      }
    out.visible_fraction[t] = double(cnt) / double(std::size_t(w) * std::size_t(h));
    out.per_pair[t] = masked_ssim<float, 3>(edited[t + 1].view(), warped.view(), vis.view(), o.ssim);
  }, 1);
  double s = 0;
  std::size_t counted = 0;
  for (double v : out.per_pair) {
    if (std::isfinite(v)) {
      s += v;
      ++counted;
    } else {
      ++out.skipped_pairs;
    }
  }
  out.value = counted ? s / double(counted) : std::numeric_limits<double>::quiet_NaN();
  return out;
}

}  // namespace video3dgs::metrics
