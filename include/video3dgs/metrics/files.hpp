#pragma once
/// @file
/// PSNR and SSIM of image files (8-bit or 16-bit PNG, JPEG, ...) and of frame folders, as the
/// `video3dgs metrics` command reports them. Files are read as RGB in [0, 1] (io::read_image<3>;
/// grayscale is replicated, which leaves PSNR and SSIM unchanged), metrics are computed in double.
///
/// Folders: the frames of both folders (io::list_frames, natural order) are paired by position; the
/// summary is the mean of the per-frame values (PSNR is +infinity if any pair is identical).
///
/// Errors: those of io::read_image / io::list_frames, plus `io.size_mismatch` (a pair differs in size,
/// names the second file) and `io.count_mismatch` (the folders hold different numbers of frames).

#include <cstddef>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/io/frame_folder.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/loss/ssim.hpp"
#include "video3dgs/metrics/psnr.hpp"
#include "video3dgs/metrics/ssim.hpp"

namespace video3dgs::metrics {

/// Metrics of one image pair.
struct PairMetrics {
  double psnr = 0;  ///< dB, data range 1; +infinity when identical
  double ssim = 0;  ///< mean SSIM over pixels and channels
};

/// Metrics of a sequence of pairs.
struct SequenceMetrics {
  double psnr = 0;                          ///< mean of the per-frame PSNRs
  double ssim = 0;                          ///< mean of the per-frame SSIMs
  std::vector<std::filesystem::path> a, b;  ///< the paired files
  std::vector<PairMetrics> per_frame;

  [[nodiscard]] std::size_t frames() const noexcept { return per_frame.size(); }
};

/// PSNR and SSIM of two RGB images of the same size (computed in double).
/// @param ctx reusable SSIM workspace
[[nodiscard]] inline PairMetrics compare_images(const Image<float, 3>& a, const Image<float, 3>& b,
                                                loss::SsimContext<double, 3>& ctx, ThreadPool* pool = nullptr) {
  const Image<double, 3> ad = a.cast<double>();
  const Image<double, 3> bd = b.cast<double>();
  PairMetrics m;
  m.psnr = psnr<double, 3>(ad.view(), bd.view(), pool);
  m.ssim = static_cast<double>(loss::ssim_value<double, 3>(ad.view(), bd.view(), ctx, pool));
  return m;
}

/// PSNR and SSIM of two image files, reusing the SSIM workspace `ctx`.
/// @throws io_error (see the file comment)
[[nodiscard]] inline PairMetrics compare_image_files(const std::filesystem::path& a, const std::filesystem::path& b,
                                                     loss::SsimContext<double, 3>& ctx, ThreadPool* pool = nullptr) {
  const Image<float, 3> ia = io::read_image<3>(a);
  const Image<float, 3> ib = io::read_image<3>(b);
  if (ia.width() != ib.width() || ia.height() != ib.height())
    throw io_error("io.size_mismatch", b.string(),
                   "is " + std::to_string(ib.width()) + "x" + std::to_string(ib.height()) + " but " + a.filename().string() +
                       " is " + std::to_string(ia.width()) + "x" + std::to_string(ia.height()));
  return compare_images(ia, ib, ctx, pool);
}

/// PSNR and SSIM of two image files.
/// @throws io_error (see the file comment)
[[nodiscard]] inline PairMetrics compare_image_files(const std::filesystem::path& a, const std::filesystem::path& b,
                                                     ThreadPool* pool = nullptr) {
  loss::SsimContext<double, 3> ctx;
  return compare_image_files(a, b, ctx, pool);
}

/// Per-frame and mean PSNR / SSIM of two lists of image files paired by position.
/// Frames are processed in parallel (one pair per task, each computed serially): results do not
/// depend on the pool. The error of the lowest failing pair is reported.
/// @throws io_error `io.count_mismatch`, `io.size_mismatch`, and the errors of io::read_image
[[nodiscard]] inline SequenceMetrics compare_file_lists(const std::vector<std::filesystem::path>& a,
                                                        const std::vector<std::filesystem::path>& b,
                                                        ThreadPool* pool = nullptr) {
  if (a.size() != b.size())
    throw io_error("io.count_mismatch", b.empty() ? std::string() : b.front().parent_path().string(),
                   std::to_string(b.size()) + " frames to compare with " + std::to_string(a.size()));
  SequenceMetrics out;
  out.a = a;
  out.b = b;
  // SSIM workspaces are recycled between tasks (they are scratch only, so results do not depend on
  // which task gets which).
  std::mutex mutex;
  std::vector<std::unique_ptr<loss::SsimContext<double, 3>>> spare;
  out.per_frame = io::detail::load_all<PairMetrics>(a.size(), pool, [&](std::size_t i) {
    std::unique_ptr<loss::SsimContext<double, 3>> ctx;
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (!spare.empty()) {
        ctx = std::move(spare.back());
        spare.pop_back();
      }
    }
    if (!ctx) ctx = std::make_unique<loss::SsimContext<double, 3>>();
    const PairMetrics m = compare_image_files(a[i], b[i], *ctx, nullptr);
    std::lock_guard<std::mutex> lock(mutex);
    spare.push_back(std::move(ctx));
    return m;
  });
  double sp = 0, ss = 0;
  for (const auto& m : out.per_frame) {
    sp += m.psnr;
    ss += m.ssim;
  }
  const double n = static_cast<double>(out.per_frame.size());
  out.psnr = n > 0 ? sp / n : 0.0;
  out.ssim = n > 0 ? ss / n : 0.0;
  return out;
}

/// Per-frame and mean PSNR / SSIM of two frame folders (see the file comment).
[[nodiscard]] inline SequenceMetrics compare_frame_folders(const std::filesystem::path& a, const std::filesystem::path& b,
                                                           ThreadPool* pool = nullptr) {
  const io::FrameList la = io::list_frames(a);
  const io::FrameList lb = io::list_frames(b);
  if (la.size() != lb.size())
    throw io_error("io.count_mismatch", b.string(),
                   "holds " + std::to_string(lb.size()) + " frames but " + a.string() + " holds " + std::to_string(la.size()));
  return compare_file_lists(la.frames, lb.frames, pool);
}

}  // namespace video3dgs::metrics
