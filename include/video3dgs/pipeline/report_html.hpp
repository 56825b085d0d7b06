#pragma once
/// @file
/// `write_report_html(out, report)`: OUT/report.html, one page a person reads a reconstruction from,
/// with nothing from the network and no script (any browser opens it from the output folder; pictures
/// and videos are files of OUT by relative path):
///   - the summary: frames and size, mean PSNR and SSIM beside the mean-colour baseline, seconds per
///     stage (SfM, training, rendering, total);
///   - OUT/compare.mp4 as a video when it exists, else OUT/compare/00000.png when that exists;
///   - OUT/metrics.png (per-frame PSNR and SSIM);
///   - a table with one row per clip: frames, iterations, PSNR, SSIM, PSNR of each set alone, mean
///     alpha inside / outside the masks, Gaussians (foreground and background), model size, compact
///     size (with `--compact`), training seconds, SfM attempts, seconds and reprojection error, whether
///     SfM used the masks, and whether the clip was reused from an earlier run ("-" where unknown).
/// Text from outside (the folder's name) is HTML-escaped. Written atomically.

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/pipeline/reconstruct.hpp"

namespace video3dgs::pipeline {

namespace detail {
/// `s` with & < > " ' replaced by their character references.
[[nodiscard]] inline std::string html_escape(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&#39;"; break;
      default: out += c;
    }
  }
  return out;
}
/// printf-style number text (`fmt` takes one double); "-" for a value that is not finite.
[[nodiscard]] inline std::string html_number(const char* fmt, double v) {
  if (!std::isfinite(v)) return "-";
  char b[64];
  std::snprintf(b, sizeof(b), fmt, v);
  return b;
}
}  // namespace detail

/// The page's text (see the file comment); `has_video` / `has_compare_frame` choose the picture.
[[nodiscard]] inline std::string report_html(const std::string& title, const ReconstructReport& r, bool has_video, bool has_compare_frame) {
  using detail::html_number;
  std::string h;
  h += "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>video3dgs: " + detail::html_escape(title) + "</title>\n";
  h += "<style>\nbody{font-family:sans-serif;margin:1.5em;max-width:1400px}\n"
       "table{border-collapse:collapse;font-size:.9em}\nth,td{border:1px solid #bbb;padding:.25em .5em;text-align:right}\n"
       "td{white-space:nowrap}\n.wide{overflow-x:auto}\n"
       "th{background:#eee}\nimg,video{max-width:100%}\n.compare{width:100%}\n.note{color:#555;font-size:.9em}\n</style>\n</head>\n<body>\n";
  h += "<h1>Reconstruction of " + detail::html_escape(title) + "</h1>\n";
  h += "<p>" + std::to_string(r.frames) + " frames of " + std::to_string(r.width) + "&times;" + std::to_string(r.height) + " in " +
       std::to_string(r.clips.size()) + " clips (" + std::to_string(r.trained_clips) + " trained in this run). Mean PSNR <b>" +
       html_number("%.2f", r.psnr) + " dB</b>, SSIM <b>" + html_number("%.4f", r.ssim) + "</b> (each frame replaced by its mean colour: " +
       html_number("%.2f", r.psnr_mean_colour) + " dB).</p>\n";
  h += "<p>Seconds: SfM " + html_number("%.0f", r.seconds_sfm) + ", training " + html_number("%.0f", r.seconds_train) + ", rendering " +
       html_number("%.0f", r.seconds_render) + ", total " + html_number("%.0f", r.seconds_total) +
       " <span class=\"note\">(this run; with earlier runs' work: SfM " + html_number("%.0f", r.seconds_sfm_recorded) + ", training " +
       html_number("%.0f", r.seconds_train_recorded) + ")</span></p>\n";
  h += "<h2>Source, render and error</h2>\n";
  if (has_video)
    h += "<video class=\"compare\" src=\"compare.mp4\" controls loop muted></video>\n";
  else if (has_compare_frame)
    h += "<img class=\"compare\" src=\"compare/00000.png\" alt=\"first frame: source, render, error\">\n";
  else
    h += "<p class=\"note\">No compare video or frames in this folder.</p>\n";
  h += "<h2>Each frame</h2>\n<img src=\"metrics.png\" alt=\"per-frame PSNR and SSIM\">\n";
  h += "<p class=\"note\">The numbers: <a href=\"metrics.csv\">metrics.csv</a>, <a href=\"report.json\">report.json</a>.</p>\n";
  h += "<h2>Each clip</h2>\n<div class=\"wide\"><table>\n<tr><th>clip</th><th>frames</th><th>iterations</th><th>PSNR (dB)</th><th>SSIM</th>"
       "<th>PSNR fg / bg alone (dB)</th><th>alpha in / out of masks</th>"
       "<th>Gaussians fg</th><th>Gaussians bg</th><th>hash grids fg / bg (entries x levels)</th><th>model (MB)</th><th>compact (MB)</th>"
       "<th>training (s)</th><th>SfM attempts</th>"
       "<th>SfM (s)</th><th>SfM error (px)</th><th>SfM on masks</th><th>reused</th></tr>\n";
  auto opt = [](const char* fmt, const std::optional<double>& v) { return v ? html_number(fmt, *v) : std::string("-"); };
  auto grid = [](int log2_table, int levels) {
    return levels > 0 ? "2<sup>" + std::to_string(log2_table) + "</sup> x " + std::to_string(levels) : std::string("-");
  };
  for (std::size_t c = 0; c < r.clips.size(); ++c) {
    const ClipReport& k = r.clips[c];
    h += "<tr><td>" + std::to_string(c) + "</td><td>" + std::to_string(k.first) + "&ndash;" + std::to_string(k.last) + "</td><td>" +
         std::to_string(k.iterations) + "</td><td>" + html_number("%.2f", k.psnr) + "</td><td>" + html_number("%.4f", k.ssim) + "</td><td>" +
         opt("%.2f", k.psnr_frg) + " / " + opt("%.2f", k.psnr_bkg) + "</td><td>" + opt("%.2f", k.alpha_inside) + " / " +
         opt("%.2f", k.alpha_outside) + "</td><td>" + std::to_string(k.gaussians_frg) + "</td><td>" + std::to_string(k.gaussians_bkg) +
         "</td><td>" + grid(k.log2_table_frg, k.grid_levels_frg) + " / " + grid(k.log2_table_bkg, k.grid_levels_bkg) + "</td><td>" +
         html_number("%.1f", double(k.model_bytes) / 1e6) + "</td><td>" +
         (k.compact_bytes ? html_number("%.2f", double(k.compact_bytes->total) / 1e6) : std::string("-")) + "</td><td>" +
         html_number("%.0f", k.train_seconds) + "</td><td>" + std::to_string(k.sfm_attempts) + "</td><td>" +
         html_number("%.0f", k.sfm_seconds_recorded) + "</td><td>" + opt("%.2f", k.sfm_reprojection_error) + "</td><td>" +
         (k.sfm_masked ? (*k.sfm_masked ? "yes" : "no") : "-") + "</td><td>" + (k.reused ? "yes" : "no") + "</td></tr>\n";
  }
  h += "</table></div>\n</body>\n</html>\n";
  return h;
}

/// Writes OUT/report.html for `r` (see the file comment), choosing the picture by what OUT holds.
/// @throws io_error `io.unwritable`.
inline void write_report_html(const std::filesystem::path& out, const ReconstructReport& r) {
  std::error_code ec;
  const bool video = std::filesystem::is_regular_file(out / "compare.mp4", ec);
  const bool frame = std::filesystem::is_regular_file(out / "compare" / "00000.png", ec);
  std::filesystem::path folder = std::filesystem::absolute(out, ec).lexically_normal();
  if (folder.filename().empty()) folder = folder.parent_path();  // "out/" names "out"
  io::write_file_atomic(out / "report.html", report_html(folder.filename().string(), r, video, frame));
}

}  // namespace video3dgs::pipeline
