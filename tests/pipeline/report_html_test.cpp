// pipeline/report_html.hpp: the page's structure (one table row per clip, balanced tags, the picture
// chosen by what the folder holds, nothing from the network), escaping, an atomic write.
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <unistd.h>

#include <doctest/doctest.h>

#include "video3dgs/pipeline/report_html.hpp"

using namespace video3dgs;
using namespace video3dgs::pipeline;

namespace {

std::size_t html_count(const std::string& s, const std::string& what) {
  std::size_t n = 0;
  for (auto at = s.find(what); at != std::string::npos; at = s.find(what, at + 1)) ++n;
  return n;
}

ReconstructReport html_test_report() {
  ReconstructReport r;
  r.frames = 19, r.width = 96, r.height = 72;
  r.psnr = 31.25, r.ssim = 0.9321, r.psnr_mean_colour = 12.5;
  r.seconds_sfm = 12, r.seconds_train = 300, r.seconds_render = 4, r.seconds_total = 316;
  r.trained_clips = 1;
  ClipReport a;
  a.first = 0, a.last = 9, a.iterations = 3000, a.psnr = 32.5, a.ssim = 0.95, a.gaussians_frg = 1200, a.gaussians_bkg = 60000;
  a.model_bytes = 12'345'678, a.train_seconds = 250, a.sfm_attempts = 2, a.sfm_masked = true;
  a.psnr_frg = 25.126, a.psnr_bkg = 30.5, a.alpha_inside = 0.876, a.alpha_outside = 0.061, a.sfm_reprojection_error = 0.623;
  a.compact_bytes = CompactSizes{1, 2, 3, 4, 9'870'000};
  a.log2_table_frg = 16, a.grid_levels_frg = 16, a.log2_table_bkg = 2, a.grid_levels_bkg = 1;  // a static background
  ClipReport b = a;
  b.first = 9, b.last = 18, b.reused = true, b.sfm_masked.reset(), b.psnr = std::numeric_limits<double>::infinity();
  r.clips = {a, b};
  return r;
}

}  // namespace

TEST_CASE("report_html: one row per clip, balanced tags, figures, no network, escaped title") {
  const ReconstructReport r = html_test_report();
  const std::string h = report_html("my <video> & 'takes'", r, true, true);
  CHECK(h.rfind("<!DOCTYPE html>", 0) == 0);
  CHECK(html_count(h, "<tr>") == 3);  // header + 2 clips
  for (const char* tag : {"table", "tr", "p", "h1", "h2", "html", "body", "head", "style", "title", "div"})
    CHECK_MESSAGE(html_count(h, "<" + std::string(tag) + ">") + html_count(h, "<" + std::string(tag) + " ") == html_count(h, "</" + std::string(tag) + ">"),
                  tag);
  CHECK(h.find("my &lt;video&gt; &amp; &#39;takes&#39;") != std::string::npos);
  CHECK(h.find("<video>") == std::string::npos);
  CHECK(h.find("31.25 dB") != std::string::npos);
  CHECK(h.find("0.9321") != std::string::npos);
  CHECK(h.find("<td>0&ndash;9</td>") != std::string::npos);
  CHECK(h.find("<td>12.3</td>") != std::string::npos);  // model MB
  CHECK(h.find("<td>25.13 / 30.50</td>") != std::string::npos);  // each set alone
  CHECK(h.find("<td>0.88 / 0.06</td>") != std::string::npos);    // alpha inside / outside the masks
  CHECK(h.find("<td>9.87</td>") != std::string::npos);           // compact MB
  CHECK(h.find("<td>0.62</td>") != std::string::npos);           // SfM reprojection error
  CHECK(h.find("<td>2<sup>16</sup> x 16 / 2<sup>2</sup> x 1</td>") != std::string::npos);  // hash grids
  CHECK(h.find("<td>- / -</td>") == std::string::npos);          // b copies a's figures
  CHECK(h.find("<td>-</td>") != std::string::npos);     // infinite PSNR, unknown SfM masks
  CHECK(h.find("http") == std::string::npos);
  CHECK(h.find("<script") == std::string::npos);
  CHECK(h.find("src=\"compare.mp4\"") != std::string::npos);
  // Without the video: the first compare frame; without either: a sentence.
  CHECK(report_html("t", r, false, true).find("src=\"compare/00000.png\"") != std::string::npos);
  const std::string none = report_html("t", r, false, false);
  CHECK(none.find("compare/00000.png") == std::string::npos);
  CHECK(none.find("compare.mp4") == std::string::npos);
}

TEST_CASE("write_report_html: OUT/report.html named after the folder, picture by what the folder holds") {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("video3dgs report é " + std::to_string(::getpid())) / "sortie 1";
  fs::remove_all(dir.parent_path());
  fs::create_directories(dir / "compare");
  std::ofstream(dir / "compare" / "00000.png") << "x";
  write_report_html(dir / "", html_test_report());
  std::ifstream in(dir / "report.html");
  const std::string h(std::istreambuf_iterator<char>(in), {});
  CHECK(h.find("<title>video3dgs: sortie 1</title>") != std::string::npos);
  CHECK(h.find("src=\"compare/00000.png\"") != std::string::npos);
  CHECK(std::distance(fs::directory_iterator(dir), fs::directory_iterator{}) == 2);  // compare/ and report.html: no temporary left
  fs::remove_all(dir.parent_path());
}
