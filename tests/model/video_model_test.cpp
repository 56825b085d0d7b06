// VideoModel: blend weights (linear cross-fade on two-clip overlaps, sums, video ends, 3 clips on a
// frame), rendering = weighted sum of the clips' renders, folder round trip, manifest errors.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

#include <doctest/doctest.h>

#include "video3dgs/model/video_model.hpp"

using namespace video3dgs;

namespace {

using SmallField = DeformationField<float, HashGrid4D<float, 10>>;
using Video = VideoModel<float, 1, SmallField>;

std::filesystem::path temp_dir(const std::string& name) {
  const auto d = std::filesystem::temp_directory_path() / ("video3dgs_vm_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(d);
  std::filesystem::create_directories(d);
  return d;
}

ClipModel<float, 1, SmallField> small_clip(FrameRange r, std::uint64_t seed) {
  std::vector<Camera<float>> cams;
  for (int f = r.first; f <= r.last; ++f) {
    auto c = Camera<float>::from_fov(24, 18, 1.0f);
    const float a = 0.05f * float(f);
    c.look_at({5 * std::sin(a), 0, -5 * std::cos(a)}, {0, 0, 0});
    cams.push_back(c);
  }
  std::vector<SfmPoint<double>> pts;
  for (int i = 0; i < 30; ++i) {
    SfmPoint<double> p;
    p.xyz = {0.05 * (i % 5) - 0.1, 0.05 * (i / 5) - 0.15, 0.02 * double(seed)};
    p.rgb = {std::uint8_t(40 * (i % 6)), 120, std::uint8_t(200 - 5 * i)};
    pts.push_back(p);
  }
  ClipModelOptions o;
  o.background.points_per_shell = 40;
  o.seed = seed;
  return make_clip_model<float, 1, SmallField>(r, std::span<const Camera<float>>(cams), std::span<const SfmPoint<double>>(pts), o);
}

}  // namespace

TEST_CASE("blend_weights: two clips cross-fade linearly over their overlap, weights sum to 1") {
  const std::vector<FrameRange> r{{0, 9}, {2, 11}};  // MC-COLMAP with an extended tail clip
  for (int f = 0; f < 12; ++f) {
    const auto w = blend_weights(r, 12, f);
    double sum = 0;
    for (const auto& x : w) sum += x.weight;
    CHECK(sum == doctest::Approx(1.0));
    if (f < 2 || f > 9) {
      REQUIRE(w.size() == 1);
      CHECK(w[0].clip == (f < 2 ? 0 : 1));
    } else {
      REQUIRE(w.size() == 2);
      // overlap [a, b] = [2, 9]: w_later = (f - a + 1) / (b - a + 2)
      CHECK(w[1].weight == doctest::Approx((f - 2 + 1) / 9.0));
    }
  }
  // One shared frame: an even mix.
  const auto w = blend_weights({{0, 9}, {9, 18}}, 19, 9);
  REQUIRE(w.size() == 2);
  CHECK(w[0].weight == doctest::Approx(0.5));
  CHECK(blend_weights({{0, 9}}, 10, 10).empty());
  // A frame in three clips: still a convex combination, the middle clip's interior dominates.
  const auto w3 = blend_weights({{0, 6}, {3, 9}, {5, 11}}, 12, 5);
  REQUIRE(w3.size() == 3);
  double s3 = 0;
  for (const auto& x : w3) {
    s3 += x.weight;
    CHECK(x.weight > 0);
  }
  CHECK(s3 == doctest::Approx(1.0));
  CHECK(w3[1].weight > w3[0].weight);
  CHECK(w3[1].weight > w3[2].weight);
}

TEST_CASE("VideoModel: render_frame blends the clips' renders; folder round trip is bit-identical") {
  Video v;
  v.frame_count = 7;
  v.width = 24;
  v.height = 18;
  v.clips.push_back(small_clip({0, 4}, 1));
  v.clips.push_back(small_clip({3, 6}, 2));
  v.validate();
  VideoRenderBuffers<float, SmallField> buf;
  ClipRenderBuffers<float, SmallField> cb;
  // Frame 4 is in both clips: weights 1/3 (clip 0) and 2/3 (clip 1).
  const Image<float, 3> blended = v.render_frame(4, buf);
  render_clip_frame(v.clips[0], 4, cb);
  const Image<float, 3> a = cb.merged;
  render_clip_frame(v.clips[1], 1, cb);
  const Image<float, 3> b = cb.merged;
  double diff_ab = 0;
  for (std::size_t i = 0; i < blended.size(); ++i) {
    CHECK(blended.data()[i] == doctest::Approx(a.data()[i] / 3.0 + 2.0 * b.data()[i] / 3.0).epsilon(1e-5));
    diff_ab += std::abs(a.data()[i] - b.data()[i]);
  }
  CHECK(diff_ab > 0);  // the two clips differ, so the test sees the blend
  // Frame 1 is clip 0 alone.
  render_clip_frame(v.clips[0], 1, cb);
  CHECK(v.render_frame(1, buf).storage() == cb.merged.storage());
  CHECK(v.main_clip(3) == 0);
  CHECK(v.main_clip(4) == 1);
  CHECK_THROWS_AS((void)v.render_frame(7, buf), option_error);

  const auto dir = temp_dir("roundtrip");
  save_video_model(dir / "model", v);
  const Video back = load_video_model<float, 1, SmallField>(dir / "model");
  CHECK(back.frame_count == 7);
  REQUIRE(back.clips.size() == 2);
  VideoRenderBuffers<float, SmallField> buf2;
  for (int f = 0; f < 7; ++f) CHECK(back.render_frame(f, buf2).storage() == v.render_frame(f, buf).storage());
  const auto g = back.frame_gaussians(5, GaussianSet::background);
  CHECK(g.size() == back.clips[1].bkg.size());

  // Errors: no manifest, malformed manifest, coverage gap, clip file range mismatch.
  auto load = [](const std::filesystem::path& p) { return load_video_model<float, 1, SmallField>(p); };
  CHECK_THROWS_WITH_AS((void)load(dir / "nothing"), doctest::Contains("[io.missing]"), io_error);
  std::ofstream(dir / "model" / "manifest.txt") << "video3dgs-video-model 1\nframes 7\nwidth 24\nheight 18\nclips 2\nclip 0 4 clip_000.model\n";
  CHECK_THROWS_WITH_AS((void)load(dir / "model"), doctest::Contains("[io.format]"), io_error);
  std::ofstream(dir / "model" / "manifest.txt") << "video3dgs-video-model 1\nframes 7\nwidth 24\nheight 18\nclips 2\nclip 0 4 clip_000.model\nclip 3 6 clip_000.model\n";
  CHECK_THROWS_WITH_AS((void)load(dir / "model"), doctest::Contains("range differs"), io_error);
  std::ofstream(dir / "model" / "manifest.txt") << "something else\n";
  CHECK_THROWS_WITH_AS((void)load(dir / "model"), doctest::Contains("[io.format]"), io_error);
  Video gap = std::move(v);
  gap.clips.erase(gap.clips.begin());
  CHECK_THROWS_WITH_AS(gap.validate(), doctest::Contains("in no clip"), io_error);
  std::filesystem::remove_all(dir);
}

TEST_CASE("VideoModelFolder: renders equal load_video_model's, at most the clips of one frame loaded; bad folders") {
  Video v;
  v.frame_count = 9;
  v.width = 24;
  v.height = 18;
  v.clips.push_back(small_clip({0, 3}, 1));
  v.clips.push_back(small_clip({3, 6}, 2));
  v.clips.push_back(small_clip({5, 8}, 3));
  v.validate();
  const auto dir = temp_dir("folder");
  save_video_model(dir / "model", v);
  VideoModelFolder<float, 1, SmallField> folder(dir / "model");
  CHECK(folder.frame_count() == 9);
  CHECK(folder.clip_count() == 3);
  CHECK(folder.loaded_clips() == 0);  // the constructor reads the manifest only
  VideoRenderBuffers<float, SmallField> a, b;
  for (int f = 0; f < 9; ++f) {
    CHECK(folder.render_frame(f, a).storage() == v.render_frame(f, b).storage());
    CHECK(folder.loaded_clips() == v.weights(f).size());  // frame 3: clips 0 and 1; frame 4: clip 1 alone
  }
  // Out of order works too (clips are reloaded), and a frame outside the video is an error.
  CHECK(folder.render_frame(1, a).storage() == v.render_frame(1, b).storage());
  CHECK(folder.loaded_clips() == 1);
  CHECK_THROWS_AS((void)folder.render_frame(9, a), option_error);
  CHECK(&folder.clip(2) == &folder.clip(2));
  folder.release();
  CHECK(folder.loaded_clips() == 0);

  // A clip file that disagrees with the manifest fails when it is loaded, naming the file.
  std::filesystem::copy_file(dir / "model" / "clip_000.model", dir / "model" / "clip_002.model",
                             std::filesystem::copy_options::overwrite_existing);
  VideoModelFolder<float, 1, SmallField> swapped(dir / "model");
  CHECK_NOTHROW((void)swapped.render_frame(0, a));
  CHECK_THROWS_WITH_AS((void)swapped.render_frame(8, a), doctest::Contains("clip_002.model"), io_error);
  // The manifest is checked up front: missing, and clips that leave a gap.
  using Folder = VideoModelFolder<float, 1, SmallField>;
  CHECK_THROWS_WITH_AS((void)Folder(dir / "nothing"), doctest::Contains("[io.missing]"), io_error);
  std::ofstream(dir / "model" / "manifest.txt") << "video3dgs-video-model 1\nframes 9\nwidth 24\nheight 18\nclips 2\nclip 0 3 clip_000.model\nclip 5 8 clip_002.model\n";
  CHECK_THROWS_WITH_AS((void)Folder(dir / "model"), doctest::Contains("in no clip"), io_error);
  std::filesystem::remove_all(dir);
}
