#pragma once
/// @file
/// Small image products of the reconstruction job (pipeline/reconstruct.hpp), usable alone:
///
///   resize_area(image, w, h)          exact area-weighted resampling (each output pixel averages the
///                                     source area it covers; pixel-centre convention kept)
///   error_heat_map(a, b)              e = mean_c |a_c - b_c| mapped through black -> blue -> red ->
///                                     yellow -> white over e in [0, max_error] (default 0.25)
///   side_by_side({images})            images of one height placed left to right
///   plot_metrics(psnr, ssim, w, h)    a line plot without text: light grid (10 divisions), PSNR as a
///                                     blue polyline on [psnr_lo, psnr_hi], SSIM as a red polyline on
///                                     [ssim_lo, ssim_hi] (both ranges returned in `MetricsPlot`)
///   plot_metrics_gnuplot(csv, png, clips, program)
///                                     the same data as a plot people can read, drawn by gnuplot: axes
///                                     with ticks and units, a legend, clip boundaries; false when
///                                     gnuplot is missing or fails (the caller falls back to plot_metrics)
///   compare_header(panel_width, gap, max_error, scratch, program)
///                                     a strip naming the three panels of a compare frame, with the heat
///                                     map's colour ramp and scale (text by gnuplot; nullopt without it)
///   stack_vertical(top, bottom)       one image above another

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <initializer_list>
#include <optional>
#include <sstream>
#include <span>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/resample.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/io/process.hpp"
#include "video3dgs/scheduling/sfm_result.hpp"

namespace video3dgs::pipeline {

/// Area-weighted resampling (core/resample.hpp), here too for the callers of this header.
using video3dgs::resize_area;

/// Colour of e in [0, 1] on the black -> blue -> red -> yellow -> white ramp.
[[nodiscard]] inline std::array<float, 3> heat_colour(double e) {
  static constexpr std::array<std::array<float, 3>, 5> stops{{{0, 0, 0}, {0.1f, 0.1f, 0.8f}, {0.9f, 0.1f, 0.1f}, {1, 0.9f, 0.1f}, {1, 1, 1}}};
  e = std::clamp(std::isfinite(e) ? e : 1.0, 0.0, 1.0) * 4.0;
  const int i = std::min(3, static_cast<int>(e));
  const float t = static_cast<float>(e - i);
  std::array<float, 3> c{};
  for (int k = 0; k < 3; ++k) c[std::size_t(k)] = (1 - t) * stops[std::size_t(i)][std::size_t(k)] + t * stops[std::size_t(i + 1)][std::size_t(k)];
  return c;
}

/// error_heat_map's default top of the scale, side_by_side's default gap.
inline constexpr double kHeatMapMaxError = 0.25;
inline constexpr int kSideBySideGap = 2;

/// Per-pixel error heat map of two images of one size (see the file comment).
template <class Scalar, int C>
[[nodiscard]] Image<float, 3> error_heat_map(const Image<Scalar, C>& a, const Image<Scalar, C>& b, double max_error = kHeatMapMaxError) {
  if (a.width() != b.width() || a.height() != b.height()) throw option_error("option.size", "error_heat_map", "images differ in size");
  Image<float, 3> out(a.width(), a.height());
  for (int y = 0; y < a.height(); ++y)
    for (int x = 0; x < a.width(); ++x) {
      double e = 0;
      for (int c = 0; c < C; ++c) e += std::abs(double(a.pixel(0, y)[x * C + c]) - double(b.pixel(0, y)[x * C + c]));
      const auto col = heat_colour(e / C / max_error);
      for (int c = 0; c < 3; ++c) out.pixel(0, y)[x * 3 + c] = col[std::size_t(c)];
    }
  return out;
}

/// Images of one height, left to right, separated by `gap` black columns.
[[nodiscard]] inline Image<float, 3> side_by_side(std::initializer_list<const Image<float, 3>*> images, int gap = kSideBySideGap) {
  int w = 0, h = -1;
  for (const auto* im : images) {
    if (h >= 0 && im->height() != h) throw option_error("option.size", "side_by_side", "images differ in height");
    h = im->height();
    w += im->width();
  }
  w += gap * std::max<int>(0, static_cast<int>(images.size()) - 1);
  Image<float, 3> out(std::max(w, 1), std::max(h, 1));
  int x0 = 0;
  for (const auto* im : images) {
    for (int y = 0; y < h; ++y) std::copy(im->pixel(0, y), im->pixel(0, y) + 3 * im->width(), out.pixel(0, y) + 3 * x0);
    x0 += im->width() + gap;
  }
  return out;
}

/// Ranges of a metrics plot.
struct MetricsPlot {
  Image<float, 3> image;
  double psnr_lo = 0, psnr_hi = 0, ssim_lo = 0, ssim_hi = 0;
};

namespace detail {
inline void plot_line(Image<float, 3>& im, int x0, int y0, int x1, int y1, std::array<float, 3> c, int thick = 1) {
  const int dx = std::abs(x1 - x0), dy = -std::abs(y1 - y0), sx = x0 < x1 ? 1 : -1, sy = y0 < y1 ? 1 : -1;
  int err = dx + dy;
  for (;;) {
    for (int oy = -thick / 2; oy <= thick / 2; ++oy)
      for (int ox = -thick / 2; ox <= thick / 2; ++ox) {
        const int x = x0 + ox, y = y0 + oy;
        if (x >= 0 && y >= 0 && x < im.width() && y < im.height())
          for (int k = 0; k < 3; ++k) im.pixel(0, y)[x * 3 + k] = c[std::size_t(k)];
      }
    if (x0 == x1 && y0 == y1) break;
    const int e2 = 2 * err;
    if (e2 >= dy) err += dy, x0 += sx;
    if (e2 <= dx) err += dx, y0 += sy;
  }
}
inline std::pair<double, double> padded_range(const std::vector<double>& v, double fallback_lo, double fallback_hi) {
  double lo = 1e300, hi = -1e300;
  for (double x : v)
    if (std::isfinite(x)) lo = std::min(lo, x), hi = std::max(hi, x);
  if (lo > hi) return {fallback_lo, fallback_hi};
  const double pad = std::max(0.05 * (hi - lo), 1e-3 * std::max(1.0, std::abs(hi)));
  return {lo - pad, hi + pad};
}
}  // namespace detail

/// Line plot of per-frame PSNR (blue) and SSIM (red) (see the file comment). Non-finite values
/// (e.g. PSNR of identical frames) are left out of the polyline.
[[nodiscard]] inline MetricsPlot plot_metrics(const std::vector<double>& psnr, const std::vector<double>& ssim, int width = 640,
                                              int height = 240) {
  MetricsPlot p;
  p.image = Image<float, 3>(std::max(width, 32), std::max(height, 32), 1.0f);
  Image<float, 3>& im = p.image;
  const int m = 8, x0 = m, y0 = m, x1 = im.width() - 1 - m, y1 = im.height() - 1 - m;
  for (int k = 0; k <= 10; ++k) {
    const int x = x0 + (x1 - x0) * k / 10, y = y0 + (y1 - y0) * k / 10;
    detail::plot_line(im, x, y0, x, y1, {0.88f, 0.88f, 0.88f});
    detail::plot_line(im, x0, y, x1, y, {0.88f, 0.88f, 0.88f});
  }
  detail::plot_line(im, x0, y1, x1, y1, {0, 0, 0});
  detail::plot_line(im, x0, y0, x0, y1, {0, 0, 0});
  std::tie(p.psnr_lo, p.psnr_hi) = detail::padded_range(psnr, 0, 50);
  std::tie(p.ssim_lo, p.ssim_hi) = detail::padded_range(ssim, 0, 1);
  auto draw = [&](const std::vector<double>& v, double lo, double hi, std::array<float, 3> c) {
    const std::size_t n = v.size();
    int px = -1, py = -1;
    for (std::size_t i = 0; i < n; ++i) {
      if (!std::isfinite(v[i])) {
        px = -1;
        continue;
      }
      const int x = n > 1 ? x0 + static_cast<int>(std::lround(double(x1 - x0) * double(i) / double(n - 1))) : (x0 + x1) / 2;
      const int y = y1 - static_cast<int>(std::lround(double(y1 - y0) * (v[i] - lo) / (hi - lo)));
      if (px >= 0) detail::plot_line(im, px, py, x, y, c, 2);
      else detail::plot_line(im, x, y, x, y, c, 3);
      px = x, py = y;
    }
  };
  draw(psnr, p.psnr_lo, p.psnr_hi, {0.1f, 0.25f, 0.85f});
  draw(ssim, p.ssim_lo, p.ssim_hi, {0.85f, 0.15f, 0.1f});
  return p;
}

namespace detail {
/// `p` as a gnuplot single-quoted string (no escapes inside; a quote is doubled).
inline std::string gnuplot_quote(const std::filesystem::path& p) {
  std::string q = "'";
  for (char c : p.string()) q += c == '\'' ? std::string("''") : std::string(1, c);
  return q + "'";
}

/// Runs gnuplot (`program`) on `script_text`, whose output file must be `png` + ".part.png"; renames that
/// to `png`. The script and gnuplot's messages live beside `png` while it runs (png + ".gp", png + ".log";
/// the log stays when gnuplot fails). Returns false, `png` untouched, when the program is missing or fails.
inline bool run_gnuplot(const std::string& script_text, const std::filesystem::path& png, const std::filesystem::path& program) {
  namespace fs = std::filesystem;
  if (io::find_executable(program).empty()) return false;
  const fs::path script = png.string() + ".gp", tmp = png.string() + ".part.png", log = png.string() + ".log";
  io::write_file_atomic(script, script_text);
  std::error_code ec;
  io::ProcessResult r;
  try {
    r = io::run_process({program.string(), script.string()}, log, 60);
  } catch (const external_error&) {
    r = {};
  }
  fs::remove(script, ec);
  if (!r.ok() || !fs::is_regular_file(tmp, ec)) {
    fs::remove(tmp, ec);
    return false;
  }
  fs::rename(tmp, png, ec);
  if (ec) {
    fs::remove(tmp, ec);
    return false;
  }
  fs::remove(log, ec);
  return true;
}
}  // namespace detail

/// Draws `png` from `csv` (the render stage's metrics.csv: a header line, then frame,psnr,ssim; a
/// non-finite value written as null is left out) with gnuplot (`program`, searched on PATH): frame on x,
/// PSNR in dB on the left axis, SSIM on the right, ticks, a grid, a legend, and a dashed line at the
/// first frame of every clip after the first. The image is written under a temporary name and renamed.
/// @returns false, writing nothing, when the program is not installed or fails.
/// @throws io_error `io.unwritable` when the script cannot be written.
[[nodiscard]] inline bool plot_metrics_gnuplot(const std::filesystem::path& csv, const std::filesystem::path& png, std::span<const FrameRange> clips,
                                               const std::filesystem::path& program = "gnuplot") {
  std::string gp =
      "set terminal pngcairo size 960,360 font ',10'\n"
      "set output " + detail::gnuplot_quote(png.string() + ".part.png") + "\n"
      "set datafile separator ','\n"
      "set datafile missing 'null'\n"
      "set title 'Each frame rendered from the reconstruction, compared with its source'\n"
      "set xlabel 'frame'\n"
      "set ylabel 'PSNR (dB)'\n"
      "set y2label 'SSIM (1 = identical)'\n"
      "set ytics nomirror\n"
      "set y2tics\n"
      "set grid\n"
      "set key outside bottom center horizontal\n"
      "set bmargin 5\n";
  for (std::size_t c = 1; c < clips.size(); ++c)
    gp += "set arrow from " + std::to_string(clips[c].first) + ", graph 0 to " + std::to_string(clips[c].first) +
          ", graph 1 nohead dashtype 2 linecolor rgb '#909090'\n";
  gp += "plot " + detail::gnuplot_quote(csv) +
        " using 1:2 skip 1 with linespoints pointtype 7 pointsize 0.4 linewidth 1.5 linecolor rgb '#1f4fd8' title 'PSNR (dB, left axis)', \\\n"
        "  '' using 1:3 skip 1 axes x1y2 with linespoints pointtype 5 pointsize 0.4 linewidth 1.5 linecolor rgb '#d82a1a' title 'SSIM (right axis)'";
  if (clips.size() > 1) gp += ", \\\n  NaN with lines dashtype 2 linecolor rgb '#909090' title 'a new clip begins'";
  gp += "\n";
  return detail::run_gnuplot(gp, png, program);
}

/// compare_header's font size (points, about pixels at gnuplot's 72 dpi) for panels `panel_width` wide:
/// panel_width / 18 within [7, 14].
[[nodiscard]] inline int compare_header_font(int panel_width) { return std::clamp((panel_width + 9) / 18, 7, 14); }
/// Height of compare_header's strip in pixels: 4.4 font sizes (names, ramp, scale).
[[nodiscard]] inline int compare_header_height(int panel_width) { return (compare_header_font(panel_width) * 22 + 4) / 5; }

/// A white strip to stack above side_by_side({source, render, error_heat_map(render, source)}) frames of
/// panels `panel_width` wide and `gap` apart: each panel's name centred over it and, under the third,
/// the heat map's colour ramp (60 % of the panel, drawn here with heat_colour) with its scale at the
/// ends, 0 and max_error (and above), and max_error / 2 in the middle when there is room; the error is
/// the mean absolute difference per channel of RGB in [0, 1], as the third name says when the panel is
/// wide enough (>= 300 px). Font and height follow the panel width (compare_header_font, _height). The
/// text is drawn by gnuplot (`program`) into `scratch_png`, which is removed. Returns nullopt without
/// the program.
[[nodiscard]] inline std::optional<Image<float, 3>> compare_header(int panel_width, int gap, double max_error, const std::filesystem::path& scratch_png,
                                                                  const std::filesystem::path& program = "gnuplot") {
  namespace fs = std::filesystem;
  const int w = 3 * panel_width + 2 * gap, h = compare_header_height(panel_width), font = compare_header_font(panel_width);
  auto sx = [&](double x) { return std::to_string(x / w); };      // pixel column -> gnuplot screen x
  auto sy = [&](double y) { return std::to_string(1 - y / h); };  // pixel row (from the top) -> screen y
  auto num = [](double v) {
    std::ostringstream t;
    t << v;
    return t.str();
  };
  const double centre[3] = {0.5 * panel_width, 1.5 * panel_width + gap, 2.5 * panel_width + 2 * gap};
  const double ramp0 = 2 * (panel_width + gap) + 0.2 * panel_width, ramp1 = ramp0 + 0.6 * panel_width;
  const int ramp_top = 2 * font, ramp_bottom = ramp_top + (4 * font) / 5;
  std::string gp = "set terminal pngcairo size " + std::to_string(w) + "," + std::to_string(h) + " font '," + std::to_string(font) +
                   "' background '#ffffff'\n" + "set output " + detail::gnuplot_quote(scratch_png.string() + ".part.png") + "\n" +
                   "unset border\nunset tics\nunset key\nset margins 0, 0, 0, 0\n";
  const std::string names[3] = {"source", "render", panel_width >= 300 ? "error: mean |render - source| per channel" : "error"};
  for (int k = 0; k < 3; ++k) gp += "set label '" + names[k] + "' at screen " + sx(centre[k]) + ", screen " + sy(0.9 * font) + " center\n";
  const bool middle = ramp1 - ramp0 >= 10 * font;
  for (int k = 0; k <= 2; ++k) {
    if (k == 1 && !middle) continue;
    gp += "set label '" + num(max_error * k / 2) + (k == 2 ? "+" : "") + "' at screen " + sx(ramp0 + (ramp1 - ramp0) * k / 2) + ", screen " +
          sy(3.5 * font) + " center\n";
  }
  gp += "plot [0:1][0:1] 2 notitle\n";
  if (!detail::run_gnuplot(gp, scratch_png, program)) return std::nullopt;
  Image<float, 3> strip = io::read_image<3>(scratch_png);
  std::error_code ec;
  fs::remove(scratch_png, ec);
  if (strip.width() != w || strip.height() != h) return std::nullopt;
  for (int y = ramp_top; y < ramp_bottom; ++y)
    for (int x = static_cast<int>(ramp0); x < static_cast<int>(ramp1); ++x) {
      const auto c = heat_colour((x - ramp0) / (ramp1 - ramp0));
      for (int k = 0; k < 3; ++k) strip.pixel(x, y)[k] = c[std::size_t(k)];
    }
  return strip;
}

/// `top` above `bottom` (same width).
[[nodiscard]] inline Image<float, 3> stack_vertical(const Image<float, 3>& top, const Image<float, 3>& bottom) {
  if (top.width() != bottom.width()) throw option_error("option.size", "stack_vertical", "images differ in width");
  Image<float, 3> out(top.width(), top.height() + bottom.height());
  std::copy(top.data(), top.data() + top.size(), out.data());
  std::copy(bottom.data(), bottom.data() + bottom.size(), out.data() + top.size());
  return out;
}

}  // namespace video3dgs::pipeline
