#include "video3dgs/colmap/sfm.hpp"

#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include <doctest/doctest.h>

#include "../io/jpeg_writer.hpp"
#include "../io/png_writer.hpp"  // write_bytes
#include "../test_data.hpp"
#include "video3dgs/io/frame_folder.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/scheduling.hpp"
#include "video3dgs/synthetic/clip.hpp"

using namespace video3dgs;
namespace fs = std::filesystem;

namespace {

bool have_colmap() { return !colmap::find_executable("colmap").empty(); }

/// Writes frame f and its mask as dir/f<f>.png, dir/m<f>.png and appends their paths.
void write_frame(const fs::path& dir, int f, const Image<float, 3>& img, const Image<float, 1>& m, std::vector<fs::path>& frames,
                 std::vector<fs::path>& masks) {
  frames.push_back(dir / ("f" + std::to_string(f) + ".png"));
  masks.push_back(dir / ("m" + std::to_string(f) + ".png"));
  io::write_png(frames.back(), img);
  io::write_png(masks.back(), m);
}

/// A textured synthetic video of `n` frames, 128x96, on a 24-degree camera arc: COLMAP registers it.
synthetic::SyntheticClip<float> textured_clip(int n) {
  synthetic::SyntheticClipOptions so;
  so.frames = n;
  so.width = 128;
  so.height = 96;
  so.texture_frequency = 4.0;
  so.object_gaussians = 6000;
  so.background_gaussians = 20000;
  so.arc_degrees = 24;
  return synthetic::make_synthetic_clip<float>(so);
}

/// textured_clip(n) written to dir (frames and masks, write_frame); returns the clip.
synthetic::SyntheticClip<float> write_textured_video(const fs::path& dir, int n, std::vector<fs::path>& frames, std::vector<fs::path>& masks) {
  auto clip = textured_clip(n);
  for (int f = 0; f < n; ++f) write_frame(dir, f, clip.frames[std::size_t(f)], clip.masks[std::size_t(f)], frames, masks);
  return clip;
}

/// textured_clip(n) whose "foreground" masks cover a flat grey band (30% of each frame): masked SIFT
/// finds no features there, so only the full frames can succeed.
void grey_band_video(const fs::path& dir, int n, std::vector<fs::path>& frames, std::vector<fs::path>& masks) {
  const auto clip = textured_clip(n);
  const int width = clip.frames[0].width(), height = clip.frames[0].height();
  const int band = width * 3 / 10;
  for (int f = 0; f < n; ++f) {
    Image<float, 3> img = clip.frames[static_cast<std::size_t>(f)];
    Image<float, 1> m(width, height, 0.f);
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < band; ++x) {
        m(x, y) = 1.f;
        for (int c = 0; c < 3; ++c) img.pixel(x, y)[c] = 0.5f;
      }
    write_frame(dir, f, img, m, frames, masks);
  }
}

}  // namespace

TEST_CASE("ColmapSfm: a missing colmap program says how to install it") {
  const auto dir = test::fresh_dir("sfm_test_missing");
  colmap::ColmapSfmOptions o;
  o.executable = "/nonexistent/colmap";
  o.work_dir = dir;
  colmap::ColmapSfm sfm({dir / "a.png", dir / "b.png"}, {}, o);
  try {
    (void)sfm(FrameRange{0, 1});
    FAIL("expected an error");
  } catch (const external_error& e) {
    CHECK(e.id() == "colmap.missing");
    CHECK(std::string(e.what()).find("apt-get install colmap") != std::string::npos);
  }
  // Scheduling with it propagates the error (no endless retries).
  CHECK_THROWS_AS((void)schedule_clips(2, sfm), external_error);
  CHECK_THROWS_AS(colmap::ColmapSfm({}, {}, colmap::ColmapSfmOptions{}), option_error);  // no work folder
  fs::remove_all(dir);
}

TEST_CASE("ColmapSfm: tiny masks fall back to the full frame; featureless clips fail softly" *
          doctest::test_suite("needs_program")) {
  if (!have_colmap()) {
    test::skip("program 'colmap' is not installed");
    return;
  }
  const auto dir = test::fresh_dir("sfm_test_fallback");
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  std::vector<fs::path> frames, masks;
  for (int f = 0; f < 3; ++f) {
    Image<float, 3> img(96, 64);
    for (auto& v : img.storage()) v = u(rng);
    Image<float, 1> m(96, 64, 0.f);
    for (int y = 0; y < 4; ++y)
      for (int x = 0; x < 4; ++x) m(x, y) = 1.f;  // 16 of 6144 pixels: far below 10 %
    write_frame(dir, f, img, m, frames, masks);
  }
  colmap::ColmapSfmOptions o;
  o.work_dir = dir / "work";
  o.threads = 1;
  o.relaxed_retry = false;
  colmap::ColmapSfm sfm(frames, masks, o);
  const auto r = sfm(FrameRange{0, 2});
  CHECK(r.status == SfmStatus::soft_failure);  // random noise has no consistent geometry
  REQUIRE(sfm.attempts().size() == 1);
  const auto& a = sfm.attempts()[0];
  CHECK_FALSE(a.masked);
  CHECK(a.mask_area == doctest::Approx(16.0 / (96 * 64)));
  CHECK_FALSE(fs::exists(sfm.attempt_dir({0, 2}) / "masks"));
  CHECK(fs::exists(sfm.attempt_dir({0, 2}) / "images" / "000000.png"));
  CHECK(fs::exists(sfm.attempt_dir({0, 2}) / "extract.log"));
  CHECK_FALSE(a.fallback_tried);  // 0.26 % is below masked_fallback_min_area (5 %) too
  CHECK_FALSE(sfm.shared_intrinsics().has_value());

  // Masks of 6.6 % (below the method's min_mask_area of 10 %, above masked_fallback_min_area): with
  // the method's rule (masked_fallback_after 0) the failed full-frame pass is repeated with them in
  // masked/ at once, and the clip still fails softly.
  std::vector<fs::path> masks7;
  for (int f = 0; f < 3; ++f) {
    Image<float, 1> m(96, 64, 0.f);
    for (int y = 0; y < 17; ++y)
      for (int x = 0; x < 24; ++x) m(x, y) = 1.f;  // 408 of 6144 pixels
    masks7.push_back(dir / ("m7_" + std::to_string(f) + ".png"));
    io::write_png(masks7.back(), m);
  }
  o.work_dir = dir / "work7";
  o.min_mask_area = 0.1;
  o.masked_fallback_after = 0;
  colmap::ColmapSfm sfm7(frames, masks7, o);
  const auto r7 = sfm7(FrameRange{0, 2});
  CHECK(r7.status == SfmStatus::soft_failure);
  const auto& a7 = sfm7.attempts().back();
  CHECK(a7.fallback_tried);
  CHECK_FALSE(a7.fallback_succeeded);
  CHECK(fs::exists(sfm7.attempt_dir({0, 2}) / "masks" / "000000.png.png"));
  CHECK(fs::exists(sfm7.attempt_dir({0, 2}) / "masked" / "extract.log"));
  CHECK(r7.message.find("masked pass") != std::string::npos);

  // By default the masked pass waits until the clip has grown from masked_fallback_after failed
  // whole-frame attempts (here 1, grown at the front): frames 1-2 fail on whole frames alone, frames
  // 0-2 then try the masks as well.
  o = colmap::ColmapSfmOptions{};
  o.work_dir = dir / "work7b";
  o.threads = 1;
  o.relaxed_retry = false;
  o.masked_fallback_after = 1;
  colmap::ColmapSfm grown(frames, masks7, o);
  CHECK(grown(FrameRange{1, 2}).status == SfmStatus::soft_failure);
  CHECK_FALSE(grown.attempts().back().masked);
  CHECK_FALSE(grown.attempts().back().fallback_tried);
  CHECK_FALSE(fs::exists(grown.attempt_dir({1, 2}) / "masked"));
  CHECK(grown(FrameRange{0, 2}).status == SfmStatus::soft_failure);
  CHECK(grown.attempts().back().fallback_tried);
  CHECK(fs::exists(grown.attempt_dir({0, 2}) / "masked" / "extract.log"));
  // A clip that did not grow from a failure (frames 0-1 here) waits again.
  CHECK(grown(FrameRange{0, 1}).status == SfmStatus::soft_failure);
  CHECK_FALSE(grown.attempts().back().fallback_tried);
  o.masked_fallback_after = -1;
  CHECK_THROWS_WITH_AS(colmap::ColmapSfm(frames, masks7, o), doctest::Contains("masked_fallback_after"), option_error);
  fs::remove_all(dir);
}

TEST_CASE("ColmapSfm: a masked pass that finds nothing falls back to the full frames" *
          doctest::test_suite("needs_program")) {
  if (!have_colmap()) {
    test::skip("program 'colmap' is not installed");
    return;
  }
  constexpr int n = 6;
  const auto dir = test::fresh_dir("sfm_test_full_frames");
  std::vector<fs::path> frames, masks;
  grey_band_video(dir, n, frames, masks);
  colmap::ColmapSfmOptions o;
  o.work_dir = dir / "work";
  o.threads = 1;
  o.relaxed_tries = 1;
  o.min_mask_area = 0.1;  // the method's rule: the 30 % masks make the first pass a masked one
  SUBCASE("without the fallback the clip fails") {
    o.full_frame_fallback = false;
    colmap::ColmapSfm sfm(frames, masks, o);
    const auto r = sfm(FrameRange{0, n - 1});
    CHECK(r.status == SfmStatus::soft_failure);
    CHECK(sfm.attempts().back().masked);
    CHECK_FALSE(sfm.attempts().back().fallback_tried);
  }
  SUBCASE("with it every frame registers from the full frames") {
    colmap::ColmapSfm sfm(frames, masks, o);
    const auto r = sfm(FrameRange{0, n - 1});
    const auto& a = sfm.attempts().back();
    MESSAGE("registered " << a.registered << "/" << n << ", " << a.points << " points, " << a.seconds() << " s: " << a.message);
    CHECK(r.status == SfmStatus::success);
    CHECK(r.frames.size() == static_cast<std::size_t>(n));
    CHECK(a.fallback_tried);
    CHECK(a.fallback_succeeded);
    CHECK_FALSE(a.masked);  // the kept model came from the whole frames
    CHECK(fs::exists(sfm.attempt_dir({0, n - 1}) / "full_frames" / "mapper.log"));
    // A second object with the same settings reuses the finished attempt, fallback flags included.
    colmap::ColmapSfm again(frames, masks, o);
    const auto r2 = again(FrameRange{0, n - 1});
    CHECK(again.attempts().back().reused);
    CHECK(again.attempts().back().fallback_succeeded);
    CHECK(r2.frames.size() == r.frames.size());
  }
  fs::remove_all(dir);
}

TEST_CASE("ColmapSfm: JPEG frames stored turned (EXIF orientation 6) reach COLMAP upright" * doctest::test_suite("needs_program")) {
  if (!have_colmap()) {
    test::skip("program 'colmap' is not installed");
    return;
  }
  constexpr int n = 6;
  const auto clip = textured_clip(n);
  const int width = clip.frames[0].width(), height = clip.frames[0].height();
  const auto dir = test::fresh_dir("sfm_test_exif");
  std::vector<fs::path> frames;
  for (int f = 0; f < n; ++f) {
    // Stored a quarter turn counter-clockwise (96x128), tagged "turn clockwise to show": what a phone writes.
    const auto stored = test::as_displayed(clip.frames[static_cast<std::size_t>(f)], 8);
    frames.push_back(dir / ("IMG_" + std::to_string(f) + ".jpg"));
    test::write_bytes(frames.back(), test::with_exif_orientation(test::encode_test_jpeg(stored.width(), stored.height(), 3,
                                                                                        test::to_bytes(stored)), 6, true));
  }
  colmap::ColmapSfmOptions o;
  o.work_dir = dir / "work";
  o.threads = 1;
  o.keep_work = true;
  colmap::ColmapSfm sfm(frames, {}, o);
  const auto r = sfm(FrameRange{0, n - 1});
  const auto& a = sfm.attempts().back();
  MESSAGE("registered " << a.registered << "/" << n << ", " << a.points << " points: " << a.message);
  CHECK(r.status == SfmStatus::success);
  CHECK(r.frames.size() == static_cast<std::size_t>(n));
  for (const auto& cam : r.cameras) {
    CHECK(cam.width == width);
    CHECK(cam.height == height);
  }
  // COLMAP was given upright PNG copies, not links to the turned JPEGs.
  const auto staged = sfm.attempt_dir({0, n - 1}) / "images" / "000000.png";
  REQUIRE(fs::exists(staged));
  CHECK(io::read_image_info(staged).width == width);
  CHECK_FALSE(fs::exists(staged.parent_path() / "000000.jpg"));
  fs::remove_all(dir);
}

TEST_CASE("MC-COLMAP: the first 10 frames of motocross-jump with masks are covered by fully registered clips" *
          doctest::test_suite("shared_data")) {
  const auto frames_dir = test::shared_data_or_skip("motocross-jump/frames");
  const auto masks_dir = test::shared_data_or_skip("motocross-jump/masks");
  if (frames_dir.empty() || masks_dir.empty()) return;
  if (!have_colmap()) {
    test::skip("program 'colmap' is not installed");
    return;
  }
  constexpr int kFrames = 10;
  io::FrameList list = io::list_frames(frames_dir, masks_dir);
  REQUIRE(list.size() >= std::size_t(kFrames));
  list.frames.resize(kFrames);
  list.masks.resize(kFrames);
  const auto dir = test::fresh_dir("sfm_test_motocross10");
  colmap::ColmapSfmOptions o;
  o.work_dir = dir;
  // One thread: COLMAP's results then depend on the frames and options alone (docs/scheduling-and-colmap.md).
  o.threads = 1;
  colmap::ColmapSfm sfm(list.frames, list.masks, o);
  std::vector<ScheduleProgress> progress;
  // One clip over the 10 frames keeps the CI run short (motocross-jump's camera pans, so SfM finds its
  // initial pair at once: about 25 s, where blackswan's nearly static first frames took 156 s for one
  // attempt). The scheduler's growth and tail logic is covered by the scripted back ends in
  // tests/scheduling.
  ScheduleOptions so;
  so.initial_frames = kFrames;
  so.progress = [&](const ScheduleProgress& p) {
    progress.push_back(p);
    MESSAGE("frames " << p.range.first << "-" << p.range.last << ": " << std::string(to_string(p.status)) << " in " << p.seconds << " s "
                      << p.message);
  };
  const auto s = schedule_clips(kFrames, sfm, so);
  REQUIRE(!s.clips.empty());
  CHECK(s.clips.front().range.first == 0);
  CHECK(s.clips.back().range.last == kFrames - 1);
  for (std::size_t i = 0; i < s.clips.size(); ++i) {
    const auto& c = s.clips[i];
    CHECK(c.succeeded);
    CHECK(c.result.complete());
    CHECK(c.result.frames.size() == static_cast<std::size_t>(c.range.size()));
    CHECK(c.result.cameras.size() == c.result.frames.size());
    CHECK(!c.result.points.empty());
    if (i > 0) CHECK(c.range.first <= s.clips[i - 1].range.last);
    for (const auto& cam : c.result.cameras) {
      CHECK_NOTHROW(cam.validate());
      CHECK(cam.width == 854);
      CHECK(cam.height == 480);
    }
    for (const auto& p : c.result.points) {
      CHECK(p.track_length >= 2);
      CHECK(p.xyz.allFinite());
    }
    // Later clips reuse the first clip's intrinsics exactly.
    CHECK(c.result.cameras.front().fx == s.clips.front().result.cameras.front().fx);
    CHECK(c.result.cameras.front().cx == s.clips.front().result.cameras.front().cx);
  }
  REQUIRE(sfm.shared_intrinsics().has_value());
  CHECK(progress.size() == static_cast<std::size_t>(s.stats.attempts));

  // A second scheduler run over the same work folder reuses every finished attempt.
  colmap::ColmapSfm again(list.frames, list.masks, o);
  const auto s2 = schedule_clips(kFrames, again, so);
  REQUIRE(s2.clips.size() == s.clips.size());
  for (const auto& a : again.attempts()) CHECK(a.reused);
  for (std::size_t i = 0; i < s.clips.size(); ++i) {
    CHECK(s2.clips[i].range == s.clips[i].range);
    CHECK(s2.clips[i].result.points.size() == s.clips[i].result.points.size());
    CHECK(s2.clips[i].result.cameras.front().t == s.clips[i].result.cameras.front().t);
  }
  fs::remove_all(dir);
}

TEST_CASE("ColmapSfm: a grown clip starts from the database of the attempt it grew from" *
          doctest::test_suite("needs_program")) {
  if (!have_colmap()) {
    test::skip("program 'colmap' is not installed");
    return;
  }
  const auto dir = test::fresh_dir("sfm_test_grow");
  std::vector<fs::path> frames, masks;
  grey_band_video(dir, 6, frames, masks);
  colmap::ColmapSfmOptions o;
  o.work_dir = dir / "work";
  o.threads = 1;
  o.relaxed_retry = false;
  o.min_mask_area = 0.1;  // the method's rule: masked passes first (30 % masks), ...
  o.masked_fallback_after = 0;
  o.keep_work = false;  // as in `video3dgs reconstruct`: failed attempts keep only their databases
  SUBCASE("masked passes (failing) hand their database on") {
    o.full_frame_fallback = false;
    colmap::ColmapSfm sfm(frames, masks, o);
    CHECK(sfm(FrameRange{0, 3}).status == SfmStatus::soft_failure);
    const auto first_db = sfm.attempt_dir({0, 3}) / "database.db";
    CHECK(fs::exists(first_db));
    CHECK_FALSE(fs::exists(sfm.attempt_dir({0, 3}) / "images"));
    CHECK(sfm(FrameRange{0, 4}).status == SfmStatus::soft_failure);
    CHECK(sfm.attempts().back().databases_reused == 1);
    CHECK_FALSE(fs::exists(first_db));  // moved on, not copied
    const std::string log = [&] {
      std::ifstream in(sfm.attempt_dir({0, 4}) / "extract.log");
      return std::string(std::istreambuf_iterator<char>(in), {});
    }();
    std::size_t skips = 0;
    for (auto at = log.find("already extracted"); at != std::string::npos; at = log.find("already extracted", at + 1)) ++skips;
    CHECK(skips == 4);  // frames 0-3 came with the database
  }
  SUBCASE("both passes of a one-frame attempt are reused by its two-frame successor") {
    o.keep_work = true;  // keeps the logs (a success would delete full_frames/); databases are copied
    colmap::ColmapSfm sfm(frames, masks, o);
    CHECK(sfm(FrameRange{0, 0}).status == SfmStatus::soft_failure);  // one frame: no model in either pass
    CHECK(sfm.attempts().back().fallback_tried);
    CHECK(fs::exists(sfm.attempt_dir({0, 0}) / "full_frames" / "database.db"));
    (void)sfm(FrameRange{0, 1});
    CHECK(sfm.attempts().back().databases_reused == 2);
    std::ifstream in(sfm.attempt_dir({0, 1}) / "full_frames" / "extract.log");
    const std::string log(std::istreambuf_iterator<char>(in), {});
    CHECK(log.find("already extracted") != std::string::npos);
  }
  SUBCASE("other SIFT settings make another database key: nothing is reused") {
    o.full_frame_fallback = false;
    colmap::ColmapSfm a(frames, masks, o);
    (void)a(FrameRange{0, 2});
    o.max_num_features = 4000;
    colmap::ColmapSfm b(frames, masks, o);
    (void)b(FrameRange{0, 3});
    CHECK(b.attempts().back().databases_reused == 0);
  }
  fs::remove_all(dir);
}

TEST_CASE("ColmapSfm: a known focal length is used as given; an estimated one that is no lens fails the attempt" *
          doctest::test_suite("needs_program")) {
  if (!have_colmap()) {
    test::skip("program 'colmap' is not installed");
    return;
  }
  constexpr int n = 6;
  const auto dir = test::fresh_dir("sfm_test_focal");
  std::vector<fs::path> frames, masks;
  const auto clip = write_textured_video(dir, n, frames, masks);
  colmap::ColmapSfmOptions o;
  o.work_dir = dir / "work";
  o.threads = 1;
  SUBCASE("--focal: every camera has it, principal point at the centre, not refined") {
    o.focal = double(clip.cameras[0].fx);  // 110.85 px: the generator's 60-degree field of view at 128 px
    colmap::ColmapSfm sfm(frames, {}, o);
    REQUIRE(sfm.shared_intrinsics());
    const auto r = sfm(FrameRange{0, n - 1});
    MESSAGE(sfm.attempts().back().message);
    CHECK(r.status == SfmStatus::success);
    for (const auto& cam : r.cameras) {
      CHECK(cam.fx == doctest::Approx(o.focal).epsilon(1e-9));
      CHECK(cam.cx == doctest::Approx(64.0));
      CHECK(cam.cy == doctest::Approx(48.0));
    }
  }
  SUBCASE("an estimate outside [min, max] x the longer side is a soft failure and is not shared") {
    o.min_focal_ratio = 50;  // any estimate for a 128-px frame is below 6,400 px
    colmap::ColmapSfm sfm(frames, {}, o);
    const auto r = sfm(FrameRange{0, n - 1});
    CHECK(r.status == SfmStatus::soft_failure);
    CHECK(r.message.find("is no lens") != std::string::npos);
    CHECK(sfm.attempts().back().status == SfmStatus::soft_failure);
    CHECK_FALSE(sfm.shared_intrinsics());
  }
  SUBCASE("bad values are option errors") {
    o.focal = -1;
    CHECK_THROWS_AS(colmap::ColmapSfm(frames, {}, o), option_error);
    o.focal = 0;
    o.max_focal_ratio = 0.05;
    CHECK_THROWS_AS(colmap::ColmapSfm(frames, {}, o), option_error);
  }
  fs::remove_all(dir);
}

TEST_CASE("ColmapSfm: a model with every frame registered but too few points or a large reprojection error is no success; the retries run" *
          doctest::test_suite("needs_program")) {
  if (!have_colmap()) {
    test::skip("program 'colmap' is not installed");
    return;
  }
  constexpr int n = 6;
  const auto dir = test::fresh_dir("sfm_test_min_points");
  std::vector<fs::path> frames, masks;
  (void)write_textured_video(dir, n, frames, masks);
  colmap::ColmapSfmOptions o;
  o.work_dir = dir / "work";
  o.threads = 1;
  o.relaxed_tries = 1;
  SUBCASE("the default floor passes a textured clip") {
    colmap::ColmapSfm sfm(frames, {}, o);
    const auto r = sfm(FrameRange{0, n - 1});
    CHECK(r.status == SfmStatus::success);
    CHECK(r.points.size() >= std::size_t(2 * n));
  }
  SUBCASE("a floor above what SfM finds: soft failure after the relaxed retry, saying why") {
    o.min_points_per_frame = 1e5;
    colmap::ColmapSfm sfm(frames, {}, o);
    const auto r = sfm(FrameRange{0, n - 1});
    CHECK(r.status == SfmStatus::soft_failure);
    CHECK(r.message.find("too few to trust the cameras") != std::string::npos);
    CHECK(sfm.attempts().back().relaxed_tried);
    CHECK(sfm.attempts().back().relaxed_runs == 1);
    CHECK_FALSE(sfm.shared_intrinsics());
  }
  SUBCASE("out of range: an option error") {
    o.min_points_per_frame = -1;
    CHECK_THROWS_WITH_AS(colmap::ColmapSfm(frames, {}, o), doctest::Contains("min_points_per_frame"), option_error);
    o.min_points_per_frame = 2;
    o.max_reprojection_error = -1;
    CHECK_THROWS_WITH_AS(colmap::ColmapSfm(frames, {}, o), doctest::Contains("max_reprojection_error"), option_error);
  }
  SUBCASE("a mean reprojection error above the limit: no success; the relaxed retry and the other pass run") {
    o.min_mask_area = 0;  // masked pass first, then the whole frames
    o.max_reprojection_error = 1e-6;
    colmap::ColmapSfm sfm(frames, masks, o);
    const auto r = sfm(FrameRange{0, n - 1});
    CHECK(r.status == SfmStatus::soft_failure);
    CHECK(r.message.find("mean reprojection error") != std::string::npos);
    CHECK(r.message.find("cameras not trusted") != std::string::npos);
    const auto& a = sfm.attempts().back();
    CHECK(a.relaxed_tried);
    CHECK(a.fallback_tried);
    CHECK_FALSE(a.fallback_succeeded);
    // A limit the clip meets changes nothing but the attempt's key: the same cameras and points as
    // without a limit.
    o.max_reprojection_error = 50;
    o.work_dir = dir / "work_lax";
    colmap::ColmapSfm lax(frames, masks, o);
    const auto rl = lax(FrameRange{0, n - 1});
    CHECK(rl.status == SfmStatus::success);
    o.max_reprojection_error = 0;
    o.work_dir = dir / "work_none";
    colmap::ColmapSfm none(frames, masks, o);
    const auto rn = none(FrameRange{0, n - 1});
    CHECK(rn.status == SfmStatus::success);
    REQUIRE(rl.points.size() == rn.points.size());
    REQUIRE(rl.cameras.size() == rn.cameras.size());
    for (std::size_t i = 0; i < rl.cameras.size(); ++i) {
      CHECK(rl.cameras[i].R == rn.cameras[i].R);
      CHECK(rl.cameras[i].t == rn.cameras[i].t);
    }
    CHECK(lax.attempts().back().mean_reprojection_error > 0);
    CHECK(lax.attempts().back().mean_reprojection_error <= 50);
  }
  fs::remove_all(dir);
}

TEST_CASE("ColmapSfm: deterministic by default: two runs on 1 and 2 threads write the same database matches and model files" *
          doctest::test_suite("needs_program")) {
  if (!have_colmap()) {
    test::skip("program 'colmap' is not installed");
    return;
  }
  constexpr int n = 8;
  const auto dir = test::fresh_dir("sfm_test_determinism");
  std::vector<fs::path> frames, masks;
  (void)write_textured_video(dir, n, frames, masks);
  auto bytes = [](const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    REQUIRE(in);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  std::vector<std::string> models, lists;
  for (int threads : {1, 2}) {
    colmap::ColmapSfmOptions o;
    o.work_dir = dir / ("work_" + std::to_string(threads));
    o.threads = threads;
    o.use_masks = false;
    colmap::ColmapSfm sfm(frames, masks, o);
    const auto r = sfm(FrameRange{0, n - 1});
    REQUIRE(r.status == SfmStatus::success);
    CHECK_FALSE(sfm.attempts().back().reused);
    const auto attempt = sfm.attempt_dir({0, n - 1});
    lists.push_back(bytes(attempt / "matches.txt"));
    std::string model;
    for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"}) model += bytes(r.model_dir / f);
    models.push_back(model);
    // The extraction, verification and mapper ran on one thread whatever `threads` says.
    for (const char* log : {"extract.log", "match.log", "mapper.log"}) {
      const std::string text = bytes(attempt / log);
      CHECK(text.find("num_threads 1") != std::string::npos);
    }
  }
  CHECK_FALSE(lists[0].empty());
  CHECK(lists[0] == lists[1]);
  CHECK(models[0] == models[1]);
  fs::remove_all(dir);
}
