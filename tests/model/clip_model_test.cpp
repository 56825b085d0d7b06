// ClipModel: initialisation from SfM points (colours, kNN scales, opacity, shells, radius, boxes),
// Bkg-only clips, model files (round trip, errors), PLY export of a deformed set, frame rendering.
#include <cmath>
#include <cstring>
#include <filesystem>
#include <string>

#include <unistd.h>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "video3dgs/io/ply.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/model/clip_model_io.hpp"
#include "video3dgs/model/compact_io.hpp"
#include "video3dgs/model/render_clip.hpp"

using namespace video3dgs;

namespace {

using SmallField = DeformationField<float, HashGrid4D<float, 10>>;
using Model = ClipModel<float, 1, SmallField>;

std::vector<Camera<float>> arc_cameras(int n, int w = 40, int h = 30) {
  std::vector<Camera<float>> cams;
  for (int i = 0; i < n; ++i) {
    auto c = Camera<float>::from_fov(w, h, 1.0f);
    const float a = 0.1f * float(i);
    c.look_at({5 * std::sin(a), 0, -5 * std::cos(a)}, {0, 0, 0});
    cams.push_back(c);
  }
  return cams;
}

std::vector<SfmPoint<double>> grid_points(double step) {
  std::vector<SfmPoint<double>> pts;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      for (int k = 0; k < 4; ++k) {
        SfmPoint<double> p;
        p.xyz = {step * i, step * j, step * k};
        p.rgb = {std::uint8_t(60 * i), std::uint8_t(60 * j), 200};
        pts.push_back(p);
      }
  return pts;
}

ClipModelOptions small_options() {
  ClipModelOptions o;
  o.background.points_per_shell = 50;
  return o;
}

/// True when `call()` throws an option_error whose message names `field`.
template <class F>
bool refused_naming(F&& call, const char* field) {
  try {
    (void)call();
  } catch (const option_error& e) {
    return std::string(e.what()).find(field) != std::string::npos;
  }
  return false;
}

/// n frames of 40 x 30 whose red and green ramp with x and y (blue 0), the same in every frame.
std::vector<Image<float, 3>> ramp_frames(int n) {
  std::vector<Image<float, 3>> frames(std::size_t(n), Image<float, 3>(40, 30));
  for (auto& im : frames)
    for (int y = 0; y < 30; ++y)
      for (int x = 0; x < 40; ++x) im(x, y, 0) = float(x) / 40.0f, im(x, y, 1) = float(y) / 30.0f;
  return frames;
}

/// A 3-frame clip on arc_cameras(3) and grid_points(0.3) with options `o` and `frames`.
Model arc_model_with_frames(const ClipModelOptions& o, std::span<const Image<float, 3>> frames) {
  const auto cams = arc_cameras(3);
  const auto pts = grid_points(0.3);
  return make_clip_model<float, 1, SmallField>(FrameRange{0, 2}, std::span<const Camera<float>>(cams),
                                               std::span<const SfmPoint<double>>(pts), o, {}, nullptr, frames);
}

/// A 3-frame clip on arc_cameras(3) and grid_points(0.3) with options `o`.
Model arc_model(const ClipModelOptions& o = small_options()) {
  const auto cams = arc_cameras(3);
  const auto pts = grid_points(0.3);
  return make_clip_model<float, 1, SmallField>(FrameRange{0, 2}, std::span<const Camera<float>>(cams),
                                               std::span<const SfmPoint<double>>(pts), o);
}

/// `o` with both grids' time uncapped (the grids before GridSize::time_cells, which versions 1-2 store).
ClipModelOptions uncapped(ClipModelOptions o) {
  o.frg_grid.time_cells = o.bkg_grid.time_cells = 0;
  return o;
}

std::filesystem::path temp_file(const char* name) {
  return std::filesystem::temp_directory_path() / (std::string("video3dgs_model_") + name + "_" + std::to_string(::getpid()));
}

}  // namespace

TEST_CASE("make_clip_model: the reference initialisation") {
  const auto cams = arc_cameras(5);
  const auto pts = grid_points(0.2);
  auto m = make_clip_model<float, 1, SmallField>(FrameRange{10, 14}, std::span<const Camera<float>>(cams),
                                                 std::span<const SfmPoint<double>>(pts), small_options());
  REQUIRE(m.has_foreground);
  CHECK(m.warnings.empty());
  REQUIRE(m.frg.size() == pts.size());
  CHECK(m.bkg.size() == 100);
  CHECK(m.frame_count() == 5);
  CHECK(m.time_of(0) == 0.0f);
  CHECK(m.time_of(4) == 1.0f);
  CHECK(m.time_of(2) == doctest::Approx(0.5));
  CHECK(m.index_of_frame(12) == 2);
  CHECK_THROWS_AS((void)m.index_of_frame(15), option_error);
  // Colour, opacity, rotation, scale (interior grid point: 3 neighbours at 0.2 -> scale 0.2).
  const auto g = m.frg.get(21);  // (1, 1, 1)
  CHECK(sigmoid(g.opacity_logit) == doctest::Approx(0.1).epsilon(1e-5));
  CHECK(sh::dc_to_rgb(g.sh[0]) == doctest::Approx(60 / 255.0).epsilon(1e-5));
  CHECK(sh::dc_to_rgb(g.sh[2]) == doctest::Approx(200 / 255.0).epsilon(1e-5));
  CHECK(g.sh[3] == 0.0f);
  CHECK(g.rotation[0] == 1.0f);
  CHECK(std::exp(g.log_scale[0]) == doctest::Approx(0.2).epsilon(1e-4));
  // Shells centred on the foreground box (centre 0.3), radii 1x and 3x its side (0.6).
  for (std::size_t i = 0; i < m.bkg.size(); ++i) {
    const Eigen::Vector3f p(m.bkg.mean[3 * i] - 0.3f, m.bkg.mean[3 * i + 1] - 0.3f, m.bkg.mean[3 * i + 2] - 0.3f);
    CHECK(p.norm() == doctest::Approx(i < 50 ? 0.6 : 1.8).epsilon(1e-4));
  }
  // Radius: 1.1 x max distance of a camera centre from the mean centre.
  Eigen::Vector3f mean = Eigen::Vector3f::Zero();
  for (const auto& c : cams) mean += c.center();
  mean /= 5;
  float md = 0;
  for (const auto& c : cams) md = std::max(md, (c.center() - mean).norm());
  CHECK(m.scene_radius == doctest::Approx(1.1 * md).epsilon(1e-5));
  CHECK(m.extent() == doctest::Approx(4 * m.scene_radius));
  // Field boxes: the initial means' bounding boxes.
  CHECK(m.frg_box_min[0] == 0.0f);
  CHECK(m.frg_box_max[2] == doctest::Approx(0.6f));
  // Alpha maps: 0.5 everywhere.
  REQUIRE(m.alpha_logit.size() == 5);
  CHECK(m.alpha_logit[3](7, 9) == 0.0f);
}

TEST_CASE("make_clip_model: single camera floors the radius; no points or empty masks -> background only") {
  const auto cams = arc_cameras(1);
  const auto pts = grid_points(0.2);
  auto m = make_clip_model<float, 1, SmallField>(FrameRange{0, 0}, std::span<const Camera<float>>(cams),
                                                 std::span<const SfmPoint<double>>(pts), small_options());
  CHECK(m.scene_radius > 0.0f);
  CHECK(m.time_of(0) == 0.0f);
  CHECK_FALSE(m.warnings.empty());

  const std::vector<SfmPoint<double>> none;
  auto b = make_clip_model<float, 1, SmallField>(FrameRange{0, 0}, std::span<const Camera<float>>(cams),
                                                 std::span<const SfmPoint<double>>(none), small_options());
  CHECK_FALSE(b.has_foreground);
  CHECK(b.frg.empty());
  CHECK(b.bkg.size() == 100);
  CHECK(stable_sigmoid(b.alpha_logit[0](0, 0)) < 1e-6f);

  const std::vector<Image<float, 1>> masks(1, Image<float, 1>(40, 30, 0.0f));
  auto e = make_clip_model<float, 1, SmallField>(FrameRange{0, 0}, std::span<const Camera<float>>(cams),
                                                 std::span<const SfmPoint<double>>(pts), small_options(),
                                                 std::span<const Image<float, 1>>(masks));
  CHECK_FALSE(e.has_foreground);

  CHECK_THROWS_AS((void)make_clip_model<float>(FrameRange{0, 1}, std::span<const Camera<float>>(cams),
                                               std::span<const SfmPoint<double>>(pts)),
                  option_error);
}

TEST_CASE("make_clip_model: alpha maps from the masks (alpha_mask), resampled to the frames' size; bad values refused") {
  const auto cams = arc_cameras(2);
  const auto pts = grid_points(0.2);
  std::vector<Image<float, 1>> masks(2, Image<float, 1>(40, 30, 0.0f));
  masks[0](3, 4) = 1.0f;
  masks[0](5, 6) = 0.5f;
  masks[1](7, 8) = std::nanf("");  // unreadable values count as background
  masks[1](9, 10) = 1.0f;
  auto make = [&](const ClipModelOptions& o, std::span<const Image<float, 1>> mk) {
    return make_clip_model<float, 1, SmallField>(FrameRange{0, 1}, std::span<const Camera<float>>(cams),
                                                 std::span<const SfmPoint<double>>(pts), o, mk);
  };
  ClipModelOptions o = small_options();
  // Off (the reference): the masks do not touch the maps.
  auto ref = make(o, masks);
  CHECK(ref.alpha_logit[0](3, 4) == 0.0f);
  CHECK(ref.alpha_logit[1](0, 0) == 0.0f);
  // On: A = outside + (inside - outside) m, stored as logits.
  o.alpha_mask = 0.9;
  o.alpha_outside = 0.2;
  auto m = make(o, masks);
  CHECK(stable_sigmoid(m.alpha_logit[0](3, 4)) == doctest::Approx(0.9).epsilon(1e-5));
  CHECK(stable_sigmoid(m.alpha_logit[0](5, 6)) == doctest::Approx(0.55).epsilon(1e-5));
  CHECK(stable_sigmoid(m.alpha_logit[0](0, 0)) == doctest::Approx(0.2).epsilon(1e-5));
  CHECK(stable_sigmoid(m.alpha_logit[1](7, 8)) == doctest::Approx(0.2).epsilon(1e-5));
  CHECK(stable_sigmoid(m.alpha_logit[1](9, 10)) == doctest::Approx(0.9).epsilon(1e-5));
  CHECK(stable_sigmoid(m.alpha_logit[1](3, 4)) == doctest::Approx(0.2).epsilon(1e-5));
  // No masks: the uniform alpha_init.
  auto none = make(o, {});
  CHECK(none.alpha_logit[0](3, 4) == 0.0f);
  // Masks of another size than the frames (reconstruct --scale) are area-resampled to theirs: the
  // left half of a 20x15 mask covers the left half of the 40x30 maps.
  std::vector<Image<float, 1>> small(2, Image<float, 1>(20, 15, 0.0f));
  for (int y = 0; y < 15; ++y)
    for (int x = 0; x < 10; ++x) small[1](x, y) = 1.0f;
  auto rs = make(o, small);
  CHECK(stable_sigmoid(rs.alpha_logit[1](0, 0)) == doctest::Approx(0.9).epsilon(1e-5));
  CHECK(stable_sigmoid(rs.alpha_logit[1](19, 29)) == doctest::Approx(0.9).epsilon(1e-5));
  CHECK(stable_sigmoid(rs.alpha_logit[1](20, 0)) == doctest::Approx(0.2).epsilon(1e-5));
  CHECK(stable_sigmoid(rs.alpha_logit[0](5, 5)) == doctest::Approx(0.2).epsilon(1e-5));
  // Values outside (0, 1) are refused by name.
  auto refused = [&](const ClipModelOptions& oo, std::span<const Image<float, 1>> mk, const char* field) {
    try {
      (void)make(oo, mk);
    } catch (const option_error& e) {
      return std::string(e.what()).find(field) != std::string::npos;
    }
    return false;
  };
  for (double bad : {-0.1, 1.0, 1.5, std::nan("")}) {
    ClipModelOptions b = o;
    b.alpha_mask = bad;
    CHECK(refused(b, masks, "alpha_mask"));
  }
  for (double bad : {0.0, 1.0}) {
    ClipModelOptions b = o;
    b.alpha_outside = bad;
    CHECK(refused(b, masks, "alpha_outside"));
  }
}

TEST_CASE("colours_from_frames: the frames' colour where each point projects, masked pixels left out, a mean for points no frame shows") {
  const auto cams = arc_cameras(2);
  // Frame f: colour (0.1 + 0.4 f, 0.2, 0.3) everywhere except pixel P of each frame.
  std::vector<Image<float, 3>> frames;
  for (int f = 0; f < 2; ++f) {
    Image<float, 3> im(40, 30);
    for (int y = 0; y < 30; ++y)
      for (int x = 0; x < 40; ++x) im(x, y, 0) = 0.1f + 0.4f * float(f), im(x, y, 1) = 0.2f, im(x, y, 2) = 0.3f;
    frames.push_back(im);
  }
  using V3 = Eigen::Matrix<float, 3, 1>;
  const V3 origin(0, 0, 0);             // seen by both cameras
  const V3 behind = cams[0].center() * 2.0f;  // behind both (they look at the origin from ~5 units)
  std::array<int, 2> p[2];
  for (int f = 0; f < 2; ++f) {
    const auto uv = cams[f].world_to_pixel(origin);
    p[f] = {int(std::floor(uv.x())), int(std::floor(uv.y()))};
    for (int c = 0; c < 3; ++c) frames[f](p[f][0], p[f][1], c) = 0.9f;  // the origin's pixel only
  }
  const std::vector<V3> pts{origin, behind};
  const auto span_c = std::span<const Camera<float>>(cams);
  const auto span_f = std::span<const Image<float, 3>>(frames);
  auto no_masks = colours_from_frames<float>(pts, span_c, span_f);
  CHECK(no_masks[0][0] == doctest::Approx(0.9f));
  CHECK(no_masks[0][2] == doctest::Approx(0.9f));
  // Behind every camera: the mean of all pixels of both frames.
  const double n = 40.0 * 30.0;
  CHECK(no_masks[1][0] == doctest::Approx((0.1 * (n - 1) + 0.9 + 0.5 * (n - 1) + 0.9) / (2 * n)).epsilon(1e-5));
  // Frame 0's mask covers the origin's pixel: only frame 1 colours it. Then both masked: the mean of
  // the unmasked pixels.
  std::vector<Image<float, 1>> masks(2, Image<float, 1>(40, 30, 0.0f));
  masks[0](p[0][0], p[0][1]) = 1.0f;
  auto one = colours_from_frames<float>(pts, span_c, span_f, std::span<const Image<float, 1>>(masks));
  CHECK(one[0][0] == doctest::Approx(0.9f));
  frames[1](p[1][0], p[1][1], 0) = 0.7f;
  one = colours_from_frames<float>(pts, span_c, span_f, std::span<const Image<float, 1>>(masks));
  CHECK(one[0][0] == doctest::Approx(0.7f));
  masks[1](p[1][0], p[1][1]) = 1.0f;
  auto both = colours_from_frames<float>(pts, span_c, span_f, std::span<const Image<float, 1>>(masks));
  CHECK(both[0][0] == doctest::Approx((0.1 + 0.5) * (n - 1) / (2 * (n - 1))).epsilon(1e-5));
  CHECK(both[0][1] == doctest::Approx(0.2f));
  // A half-weight mask value weighs the pixel by one half.
  masks[0](p[0][0], p[0][1]) = 0.5f;
  masks[1](p[1][0], p[1][1]) = 0.0f;
  auto half = colours_from_frames<float>(pts, span_c, span_f, std::span<const Image<float, 1>>(masks));
  CHECK(half[0][0] == doctest::Approx((0.5 * 0.9 + 0.7) / 1.5).epsilon(1e-5));
  // The pixel holding the projection is the floor of its continuous coordinates (pixel i covers
  // [i, i + 1)): a point at (7.9, 4.2) in camera 0 reads pixel (7, 4), not its rounded neighbour (8, 4).
  {
    Image<float, 3> im(40, 30, 0.0f);
    im(7, 4, 0) = 0.25f;
    im(8, 4, 0) = 0.75f;
    const std::vector<V3> one_pt{cams[0].pixel_to_world({7.9f, 4.2f}, 3.0f)};
    const std::vector<Image<float, 3>> one_frame{im};
    CHECK(colours_from_frames<float>(one_pt, span_c.first(1), std::span<const Image<float, 3>>(one_frame))[0][0] == 0.25f);
    // The same in double.
    const auto cd = cams[0].cast<double>();
    Image<double, 3> imd(40, 30, 0.0);
    imd(7, 4, 0) = 0.25;
    imd(8, 4, 0) = 0.75;
    const std::vector<Eigen::Vector3d> pd{cd.pixel_to_world({7.9, 4.2}, 3.0)};
    CHECK(colours_from_frames<double>(pd, std::span<const Camera<double>>(&cd, 1), std::span<const Image<double, 3>>(&imd, 1))[0][0] == 0.25);
  }
  // The same for any thread count (one result per point).
  ThreadPool pool(2);
  std::vector<V3> many;
  for (int i = 0; i < 1000; ++i) many.push_back(V3(0.01f * float(i % 37) - 0.2f, 0.01f * float(i % 23) - 0.1f, 0.3f * float(i % 7)));
  CHECK(colours_from_frames<float>(many, span_c, span_f, std::span<const Image<float, 1>>(masks)) ==
        colours_from_frames<float>(many, span_c, span_f, std::span<const Image<float, 1>>(masks), &pool));
  // Wrong counts and sizes are refused by field.
  const auto refused = [](auto&& call, const char* field) { return refused_naming(call, field); };
  CHECK(refused([&] { return colours_from_frames<float>(pts, span_c, span_f.first(1)); }, "frames"));
  CHECK(refused([&] { return colours_from_frames<float>(pts, span_c, span_f, std::span<const Image<float, 1>>(masks).first(1)); }, "masks"));
  std::vector<Image<float, 3>> small(2, Image<float, 3>(20, 15));
  CHECK(refused([&] { return colours_from_frames<float>(pts, span_c, std::span<const Image<float, 3>>(small)); }, "frame 0"));
}

TEST_CASE("make_clip_model: background colours from the frames do not depend on the seed; without frames they are refused") {
  const auto cams = arc_cameras(3);
  const auto pts = grid_points(0.3);
  const auto frames = ramp_frames(3);
  const auto make = arc_model_with_frames;
  ClipModelOptions o = small_options();
  const auto random0 = make(o, {});
  o.seed = 7;
  const auto random7 = make(o, {});
  CHECK(random0.bkg.sh != random7.bkg.sh);  // the reference draws them
  o.background_colour = BackgroundColour::frames;
  const auto span_f = std::span<const Image<float, 3>>(frames);
  const auto frames7 = make(o, span_f);
  o.seed = 0;
  const auto frames0 = make(o, span_f);
  CHECK(frames0.bkg.sh == frames7.bkg.sh);
  CHECK(frames0.bkg.mean == random0.bkg.mean);  // only the colours change
  CHECK(frames0.frg.sh == random0.frg.sh);
  // Each DC band is the colour colours_from_frames gives the point.
  std::vector<Eigen::Matrix<float, 3, 1>> bpts;
  for (std::size_t i = 0; i < frames0.bkg.size(); ++i)
    bpts.emplace_back(frames0.bkg.mean[3 * i], frames0.bkg.mean[3 * i + 1], frames0.bkg.mean[3 * i + 2]);
  const std::size_t stride = std::size_t(3 * GaussianCloud<float, 1>::sh_coeffs);
  auto dc_match = [&](const Model& m, const std::vector<std::array<float, 3>>& rgb) {
    for (std::size_t i = 0; i < bpts.size(); ++i)
      for (int c = 0; c < 3; ++c)
        if (m.bkg.sh[stride * i + std::size_t(c)] != sh::rgb_to_dc(rgb[i][std::size_t(c)])) return false;
    return true;
  };
  CHECK(dc_match(frames0, colours_from_frames<float>(bpts, std::span<const Camera<float>>(cams), span_f)));
  // With masks, the model's colours are the masked ones (the left half of every frame is foreground).
  std::vector<Image<float, 1>> masks(3, Image<float, 1>(40, 30, 0.0f));
  for (auto& mk : masks)
    for (int y = 0; y < 30; ++y)
      for (int x = 0; x < 20; ++x) mk(x, y) = 1.0f;
  const auto span_m = std::span<const Image<float, 1>>(masks);
  const auto masked = make_clip_model<float, 1, SmallField>(FrameRange{0, 2}, std::span<const Camera<float>>(cams),
                                                            std::span<const SfmPoint<double>>(pts), o, span_m, nullptr, span_f);
  const auto masked_rgb = colours_from_frames<float>(bpts, std::span<const Camera<float>>(cams), span_f, span_m);
  CHECK(masked_rgb != colours_from_frames<float>(bpts, std::span<const Camera<float>>(cams), span_f));
  CHECK(dc_match(masked, masked_rgb));
  try {
    (void)make(o, {});
    FAIL("no frames accepted");
  } catch (const option_error& e) {
    CHECK(std::string(e.what()).find("background_colour") != std::string::npos);
  }
}

TEST_CASE("clip model files: round trip, deformed render identical; errors name the file") {
  const auto cams = arc_cameras(3);
  const auto pts = grid_points(0.3);
  auto m = make_clip_model<float, 1, SmallField>(FrameRange{0, 2}, std::span<const Camera<float>>(cams),
                                                 std::span<const SfmPoint<double>>(pts), small_options());
  // Perturb the field so that deformation does something, and an alpha map.
  for (auto& s : m.frg_field->segments())
    for (std::size_t i = 0; i < s.value.size(); ++i) s.value[i] += 1e-3f * float((i * 7919) % 13) - 6e-3f;
  m.deformation_enabled = true;
  m.alpha_logit[1](3, 4) = 2.5f;
  const auto path = temp_file("roundtrip");
  save_clip_model(path, m);
  auto back = load_clip_model<float, 1, SmallField>(path);
  CHECK(back.frg.mean == m.frg.mean);
  CHECK(back.bkg.sh == m.bkg.sh);
  CHECK(back.alpha_logit[1].storage() == m.alpha_logit[1].storage());
  CHECK(back.scene_radius == m.scene_radius);
  CHECK(back.deformation_enabled);
  ClipRenderBuffers<float, SmallField> b1, b2;
  render_clip_frame(m, 1, b1);
  render_clip_frame(back, 1, b2);
  CHECK(b1.merged.storage() == b2.merged.storage());
  // The merge: I = A F + (1 - A) B.
  const float A = stable_sigmoid(2.5f);
  for (int c = 0; c < 3; ++c)
    CHECK(b1.merged(3, 4, c) == doctest::Approx(A * b1.frg.image(3, 4, c) + (1 - A) * b1.bkg.image(3, 4, c)).epsilon(1e-5));
  // Wrong template arguments, truncation, bad magic.
  CHECK_THROWS_AS(((void)load_clip_model<float, 2, SmallField>(path)), io_error);
  using DoubleField = DeformationField<double, HashGrid4D<double, 10>>;
  CHECK_THROWS_AS(((void)load_clip_model<double, 1, DoubleField>(path)), io_error);
  const std::string bytes = read_file_bytes(path);
  io::write_file_atomic(path, std::string_view(bytes).substr(0, bytes.size() - 10));
  try {
    (void)load_clip_model<float, 1, SmallField>(path);
    FAIL("no exception");
  } catch (const io_error& e) {
    CHECK(e.id() == "io.truncated");
    CHECK(std::string(e.what()).find(path.string()) != std::string::npos);
  }
  io::write_file_atomic(path, "not a model at all");
  CHECK_THROWS_AS(((void)load_clip_model<float, 1, SmallField>(path)), io_error);
  std::filesystem::remove(path);
}

TEST_CASE("clip model files: a static background is kept in the flags byte; unknown flags are refused") {
  auto o = small_options();
  o.static_background = true;
  auto m = arc_model(o);
  CHECK(m.static_background);
  for (auto* f : {m.frg_field.get(), m.bkg_field.get()})
    for (auto& s : f->segments())
      for (std::size_t i = 0; i < s.value.size(); ++i) s.value[i] += 0.01f;
  m.deformation_enabled = true;
  CHECK(m.deformed_cloud(GaussianSet::background, 1).mean == m.bkg.mean);  // not deformed
  CHECK(m.deformed_cloud(GaussianSet::foreground, 1).mean != m.frg.mean);
  const auto path = temp_file("static_bkg");
  save_clip_model(path, m);
  const auto back = load_clip_model<float, 1, SmallField>(path);
  CHECK(back.static_background);
  CHECK(back.deformation_enabled);
  ClipRenderBuffers<float, SmallField> b1, b2;
  render_clip_frame(m, 1, b1);
  render_clip_frame(back, 1, b2);
  CHECK(b1.merged.storage() == b2.merged.storage());
  // Without the flag the file differs in that one byte only (3 = deformed + static, 1 = deformed).
  const std::string with = read_file_bytes(path);
  m.static_background = false;
  save_clip_model(path, m);
  std::string without = read_file_bytes(path);
  REQUIRE(with.size() == without.size());
  std::size_t diffs = 0, at = 0;
  for (std::size_t i = 0; i < with.size(); ++i)
    if (with[i] != without[i]) ++diffs, at = i;
  REQUIRE(diffs == 1);
  CHECK(int(with[at]) == 3);
  CHECK(int(without[at]) == 1);
  without[at] = char(9);  // bit 3: unknown
  io::write_file_atomic(path, without);
  CHECK_THROWS_WITH_AS(((void)load_clip_model<float, 1, SmallField>(path)), doctest::Contains("[io.format]"), io_error);
  std::filesystem::remove(path);
}

TEST_CASE("clip model files: the stop rule is kept (flags bit 2) and every render uses it; the method's rule adds no byte") {
  auto m = arc_model();
  m.deformation_enabled = true;
  REQUIRE(m.reference_stop());
  const auto path = temp_file("stop_rule");
  save_clip_model(path, m);
  const std::string reference = read_file_bytes(path);
  ClipRenderBuffers<float, SmallField> ref, b1, b2;
  render_clip_frame(m, 1, ref);
  // A stop that binds on this scene (opacity 0.1 at the start: pixels stop behind two Gaussians).
  m.min_transmittance = 0.9f;
  m.blend_at_stop = true;
  render_clip_frame(m, 1, b1);
  CHECK(b1.merged.storage() != ref.merged.storage());
  {  // the graph takes the model's rule over its settings'
    RasterSettings<float, 3> s;
    s.min_transmittance = 1e-4f, s.blend_at_stop = false;
    ClipRenderBuffers<float, SmallField> b3;
    render_clip_frame(m, 1, b3, nullptr, s);
    CHECK(b3.merged.storage() == b1.merged.storage());
  }
  save_clip_model(path, m);
  std::string with = read_file_bytes(path);
  CHECK(with.size() == reference.size() + 9);  // f64 stop + u8 rule after the flags
  const auto back = load_clip_model<float, 1, SmallField>(path);
  CHECK(back.min_transmittance == 0.9f);
  CHECK(back.blend_at_stop);
  render_clip_frame(back, 1, b2);
  CHECK(b2.merged.storage() == b1.merged.storage());
  {  // records for older readers cannot hold it
    io::BinaryWriter w(kClipModelMagic, 2);
    CHECK_THROWS_AS(write_clip_model(w, m, 2), option_error);
  }
  // The compact file keeps it too.
  const auto cpath = temp_file("stop_rule_compact");
  (void)save_compact_clip_model(cpath, m, {});
  const auto cback = load_compact_clip_model<float, 1, SmallField>(cpath);
  CHECK(cback.min_transmittance == 0.9f);
  CHECK(cback.blend_at_stop);
  std::filesystem::remove(cpath);
  // Back to the method's rule: the reference's bytes.
  m.min_transmittance = Model::kReferenceStop, m.blend_at_stop = false;
  save_clip_model(path, m);
  CHECK(read_file_bytes(path) == reference);
  // A stored stop outside (0, 1) is refused: find the f64 0.9 after the flags byte and break it.
  const double stop = double(0.9f);
  std::string bits(sizeof stop, '\0');
  std::memcpy(bits.data(), &stop, sizeof stop);
  const std::size_t at = with.find(bits);
  REQUIRE(at != std::string::npos);
  const double bad = 2.0;
  std::memcpy(with.data() + at, &bad, sizeof bad);
  io::write_file_atomic(path, with);
  CHECK_THROWS_WITH_AS(((void)load_clip_model<float, 1, SmallField>(path)), doctest::Contains("[io.format]"), io_error);
  std::filesystem::remove(path);
}

TEST_CASE("clip model files: each set's grid size is kept (version 2); version-1 files are still read") {
  auto o = small_options();
  o.frg_grid = {6, 4};  // 64-entry tables, 4 of 16 levels over the same resolutions
  o.bkg_grid = {8, 0};
  auto m = arc_model(o);
  const auto& fg = m.frg_field->grid();
  const auto& bg = m.bkg_field->grid();
  CHECK(fg.table_size() == 64);
  CHECK(fg.active_levels() == 4);
  CHECK(bg.table_size() == 256);
  CHECK(bg.active_levels() == 16);
  // 4 levels span the 16 levels' resolutions: the coarsest and the finest cells are those of the full grid.
  const SmallField::grid_type full;
  CHECK(fg.resolution(0) == full.resolution(0));
  CHECK(fg.resolution(3) == full.resolution(15));
  CHECK(fg.param_count() < bg.param_count());
  for (auto* f : {m.frg_field.get(), m.bkg_field.get()})
    for (auto& s : f->segments())
      for (std::size_t i = 0; i < s.value.size(); ++i) s.value[i] += 1e-3f * float((i * 7919) % 13) - 6e-3f;
  m.deformation_enabled = true;
  const auto path = temp_file("grid_size");
  save_clip_model(path, m);
  auto back = load_clip_model<float, 1, SmallField>(path);
  CHECK(back.frg_field->grid().table_size() == 64);
  CHECK(back.frg_field->grid().active_levels() == 4);
  CHECK(back.bkg_field->grid().table_size() == 256);
  CHECK(back.frg_field->grid().options().per_level_scale == fg.options().per_level_scale);
  ClipRenderBuffers<float, SmallField> b1, b2;
  render_clip_frame(m, 1, b1);
  render_clip_frame(back, 1, b2);
  CHECK(b1.merged.storage() == b2.merged.storage());
  // A resized grid cannot be written as version 1.
  CHECK_THROWS_WITH_AS(save_clip_model(path, m, 1), doctest::Contains("[option.version]"), option_error);

  // Version 1 (default-sized grids without a time cap) loads into the same model.
  auto d = arc_model(uncapped(small_options()));
  for (auto& s : d.bkg_field->segments()) s.value[0] = 0.25f;
  save_clip_model(path, d, 1);
  const std::string v1 = read_file_bytes(path);
  save_clip_model(path, d);
  CHECK(read_file_bytes(path).size() == v1.size() + 2 * 8 + 2 * 16);  // two int32 (v2) and four uint32 (v3) per field
  io::write_file_atomic(path, v1);
  auto old = load_clip_model<float, 1, SmallField>(path);
  CHECK(old.bkg_field->grid().param_count() == d.bkg_field->grid().param_count());
  CHECK(old.bkg_field->segments()[0].value[0] == 0.25f);
  ClipRenderBuffers<float, SmallField> b3, b4;
  render_clip_frame(d, 2, b3);
  render_clip_frame(old, 2, b4);
  CHECK(b3.merged.storage() == b4.merged.storage());
  std::filesystem::remove(path);
}

TEST_CASE("clip model files: a grid's cells cap along time is kept (version 3); version 2 cannot store it and is still read") {
  auto o = small_options();
  o.frg_grid.time_cells = 2;
  o.bkg_grid.time_cells = 0;
  auto m = arc_model(o);
  CHECK(m.frg_field->grid().resolution(5, 3) == 2);
  CHECK(m.frg_field->grid().resolution(5, 0) > 2);
  CHECK(m.bkg_field->grid().resolution(5, 3) > 2);
  for (auto& s : m.frg_field->segments())
    for (std::size_t i = 0; i < s.value.size(); ++i) s.value[i] += 1e-3f * float((i * 7919) % 13) - 6e-3f;
  m.deformation_enabled = true;
  const auto path = temp_file("time_cells");
  save_clip_model(path, m);
  auto back = load_clip_model<float, 1, SmallField>(path);
  CHECK(back.frg_field->grid().options().max_cells == m.frg_field->grid().options().max_cells);
  ClipRenderBuffers<float, SmallField> b1, b2;
  render_clip_frame(m, 1, b1);
  render_clip_frame(back, 1, b2);
  CHECK(b1.merged.storage() == b2.merged.storage());
  CHECK(test::error_id([&] { save_clip_model(path, m, 2); }) == "option.version");
  // A version-2 file (no caps) loads into the same model as the version-3 one.
  auto d = arc_model(uncapped(small_options()));
  save_clip_model(path, d, 2);
  const std::string v2 = read_file_bytes(path);
  save_clip_model(path, d);
  CHECK(read_file_bytes(path).size() == v2.size() + 2 * 16);
  io::write_file_atomic(path, v2);
  auto old = load_clip_model<float, 1, SmallField>(path);
  ClipRenderBuffers<float, SmallField> b3, b4;
  render_clip_frame(d, 2, b3);
  render_clip_frame(old, 2, b4);
  CHECK(b3.merged.storage() == b4.merged.storage());
  std::filesystem::remove(path);
  // One cell per frame: n - 1 cells along time, so every frame sits on a vertex.
  o.frg_grid.time_cells = GridSize::kTimeCellsPerFrame;
  auto p = arc_model(o);
  CHECK(p.frg_field->grid().resolution(5, 3) == std::uint32_t(p.frame_count() - 1));
  o.frg_grid.time_cells = -2;
  CHECK(test::error_id([&] { (void)arc_model(o); }) == "option.deformation");
}

TEST_CASE("make_clip_model: one time cell per frame by default, so a clip of fewer frames never gets a larger field") {
  // 2^16 tables: the coarse levels are dense, (R_l + 1)^3 x n vertices for n frames, while the others
  // are hashed (2^16 entries whatever the clip): entries never shrink as frames are added.
  using Field = DeformationField<float, HashGrid4D<float, 16>>;
  const auto pts = grid_points(0.3);
  std::size_t previous = 0;
  for (int n = 1; n <= 14; ++n) {
    CAPTURE(n);
    const auto cams = arc_cameras(n);
    auto m = make_clip_model<float, 1, Field>(FrameRange{0, n - 1}, std::span<const Camera<float>>(cams),
                                              std::span<const SfmPoint<double>>(pts), small_options());
    const auto& g = m.frg_field->grid();
    CHECK(g.resolution(0, 3) == std::uint32_t(std::max(n - 1, 1)));
    CHECK(g.resolution(0, 0) == 16);
    CHECK(m.bkg_field->grid().entries() == g.entries());
    CHECK(g.entries() >= previous);
    if (n >= 2 && n <= 13) CHECK(g.dense(0));  // 17^3 x n <= 2^16
    previous = g.entries();
  }
  // Without the cap every level is hashed at this size (17^4 > 2^16): as many entries as the longest clip's.
  auto o = uncapped(small_options());
  const auto cams = arc_cameras(14);
  auto u = make_clip_model<float, 1, Field>(FrameRange{0, 13}, std::span<const Camera<float>>(cams),
                                            std::span<const SfmPoint<double>>(pts), o);
  CHECK(u.frg_field->grid().entries() == previous);
}

TEST_CASE("make_clip_model: a static background gets the smallest grid unless its size is given") {
  auto o = small_options();
  o.static_background = true;
  auto m = arc_model(o);
  CHECK(m.bkg_field->grid().active_levels() == 1);
  CHECK(m.bkg_field->grid().table_size() == 4);
  CHECK(m.frg_field->grid().active_levels() == 16);
  o.bkg_grid = {9, 0};
  auto n = arc_model(o);
  CHECK(n.bkg_field->grid().table_size() == 512);
  CHECK(n.bkg_field->grid().active_levels() == 16);
}

TEST_CASE("make_clip_model: a grid's finest level follows GridSize::finest; bad values are refused") {
  auto o = small_options();
  o.frg_grid = {0, 6, 153};  // 6 levels from 16 to 153 cells per axis
  auto m = arc_model(o);
  const auto& g = m.frg_field->grid();
  CHECK(g.active_levels() == 6);
  CHECK(g.resolution(0) == 16);
  CHECK(g.resolution(5) == 153);
  for (int l = 1; l < 6; ++l) CHECK(g.resolution(l) > g.resolution(l - 1));
  CHECK(m.bkg_field->grid().resolution(15) == 2006);  // the other set keeps the full grid
  o.frg_grid = {0, 16, 0};  // all levels, default range: the same grid as no size at all
  auto d = arc_model(o);
  CHECK(d.frg_field->grid().options().per_level_scale == DeformationOptions{}.grid.per_level_scale);
  for (double bad : {8.0, std::nan("")}) {
    o.frg_grid = {0, 4, bad};
    CHECK_THROWS_WITH_AS((arc_model(o)),
                         doctest::Contains("[option.deformation]"), option_error);
  }
}

TEST_CASE("export_ply writes the set deformed to the frame") {
  const auto cams = arc_cameras(2);
  const auto pts = grid_points(0.3);
  auto m = make_clip_model<float, 1, SmallField>(FrameRange{0, 1}, std::span<const Camera<float>>(cams),
                                                 std::span<const SfmPoint<double>>(pts), small_options());
  for (auto& s : m.frg_field->segments())
    for (std::size_t i = 0; i < s.value.size(); ++i) s.value[i] += 0.01f;
  m.deformation_enabled = true;
  const auto d = m.deformed_cloud(GaussianSet::foreground, 1);
  CHECK(d.mean != m.frg.mean);
  const auto path = temp_file("export.ply");
  export_ply(m, GaussianSet::foreground, 1, path);
  const auto ply = io::read_ply<float>(path);
  CHECK(ply.sh_degree == 1);
  REQUIRE(ply.mean.size() == d.mean.size());
  CHECK(ply.mean == d.mean);
  CHECK(ply.log_scale == d.log_scale);
  CHECK_THROWS_AS(export_ply(m, GaussianSet::foreground, 2, path), option_error);
  std::filesystem::remove(path);
}

TEST_CASE("frame_surface_points: one point per stride block, on its pixel's ray at the depth of the SfM points nearest in the image") {
  auto cam = Camera<float>::from_fov(40, 30, 1.0f);
  cam.look_at({0, 0, -5}, {0, 0, 0});
  using V3 = Eigen::Matrix<float, 3, 1>;
  // SfM points on two fronto-parallel planes: camera depth 5 left of column 20, 8 right of it.
  std::vector<V3> pts;
  for (int v = 1; v < 30; v += 3)
    for (int u = 1; u < 40; u += 3) pts.push_back(cam.pixel_to_world({float(u) + 0.3f, float(v) + 0.6f}, u < 20 ? 5.0f : 8.0f));
  Image<float, 3> frame(40, 30);
  for (int y = 0; y < 30; ++y)
    for (int x = 0; x < 40; ++x) frame(x, y, 0) = float(x) / 40.0f, frame(x, y, 1) = float(y) / 30.0f, frame(x, y, 2) = 0.5f;
  for (int s : {1, 3, 4}) {
    CAPTURE(s);
    const auto [p, rgb] = frame_surface_points<float>(cam, frame, pts, s);
    const int half = s / 2, nx = (40 - half + s - 1) / s, ny = (30 - half + s - 1) / s;
    REQUIRE(p.size() == std::size_t(nx * ny));
    REQUIRE(rgb.size() == p.size());
    for (int b = 0; b < ny; ++b)
      for (int a = 0; a < nx; ++a) {
        const std::size_t q = std::size_t(b * nx + a);
        const int i = half + s * a, j = half + s * b;
        REQUIRE(i < 40);
        REQUIRE(j < 30);
        const auto xc = cam.world_to_camera(p[q]);
        const auto uv = cam.camera_to_pixel(xc);
        CHECK(uv.x() == doctest::Approx(i + 0.5).epsilon(1e-4));
        CHECK(uv.y() == doctest::Approx(j + 0.5).epsilon(1e-4));
        // Away from the planes' seam the 8 nearest points all lie on one plane.
        if (i < 14) CHECK(xc.z() == doctest::Approx(5.0f).epsilon(1e-5));
        if (i > 26) CHECK(xc.z() == doctest::Approx(8.0f).epsilon(1e-5));
        CHECK(xc.z() >= 5.0f - 1e-4f);
        CHECK(xc.z() <= 8.0f + 1e-4f);
        CHECK(rgb[q][0] == frame(i, j, 0));
        CHECK(rgb[q][1] == frame(i, j, 1));
        CHECK(rgb[q][2] == 0.5f);
      }
  }
  // The same for any thread count.
  ThreadPool pool(2);
  CHECK(frame_surface_points<float>(cam, frame, pts, 2).first == frame_surface_points<float>(cam, frame, pts, 2, 8, &pool).first);
  // Fewer points than k: the median of those there are.
  const std::vector<V3> three{cam.pixel_to_world({5, 5}, 4.0f), cam.pixel_to_world({30, 20}, 6.0f), cam.pixel_to_world({10, 25}, 9.0f)};
  for (const auto& x : frame_surface_points<float>(cam, frame, three, 7).first) CHECK(cam.world_to_camera(x).z() == doctest::Approx(6.0f));
  // An even count: the lower of the two middle depths.
  const std::vector<V3> two{cam.pixel_to_world({5, 5}, 4.0f), cam.pixel_to_world({30, 20}, 6.0f)};
  for (const auto& x : frame_surface_points<float>(cam, frame, two, 7).first) CHECK(cam.world_to_camera(x).z() == doctest::Approx(4.0f));
  // Points behind the camera or outside the image are not read; none left: no points.
  const std::vector<V3> unseen{cam.center() * 2.0f, cam.pixel_to_world({-3, 5}, 5.0f), cam.pixel_to_world({45, 5}, 5.0f)};
  CHECK(frame_surface_points<float>(cam, frame, unseen, 4).first.empty());
  const auto refused = [](auto&& call, const char* field) { return refused_naming(call, field); };
  CHECK(refused([&] { return frame_surface_points<float>(cam, frame, pts, 0); }, "background_dense_stride"));
  CHECK(refused([&] { return frame_surface_points<float>(cam, Image<float, 3>(20, 15), pts, 4); }, "frame"));
}

TEST_CASE("make_clip_model: cull_unseen drops exactly the initial Gaussians no camera sees; the renders do not change") {
  const auto cams = arc_cameras(3);
  ClipModelOptions o = small_options();
  o.background.points_per_shell = 400;
  o.background.radius_factors = {1.0, 12.0};  // the outer shell reaches behind the cameras
  Model ref = arc_model(o);
  o.cull_unseen = true;
  o.cull_margin = 3;
  CHECK(o.departures_key() == "|cull_unseen=3");
  CHECK(recommended_model_options().cull_unseen);
  CHECK(recommended_model_options().cull_margin == 16);
  Model cut = arc_model(o);
  const auto span_c = std::span<const Camera<float>>(ref.cameras);
  std::size_t in_band = 0;  // seen only through the guard band
  for (GaussianSet s : {GaussianSet::foreground, GaussianSet::background}) {
    const auto& a = ref.cloud(s);
    const auto& b = cut.cloud(s);
    const auto seen = seen_by_any_camera<float, 1>(a, span_c, {}, nullptr, 3);
    const auto seen0 = seen_by_any_camera<float, 1>(a, span_c);
    std::size_t j = 0, culled = 0;
    RasterSettings<float, 3> rs;
    for (std::size_t i = 0; i < a.size(); ++i) {
      ProjectedGaussian<float> pg, pw;
      bool any = false, wide = false;
      for (const auto& c : ref.cameras) {
        const bool in = project_gaussian(c, rs, &a.mean[3 * i], &a.log_scale[3 * i], &a.rotation[4 * i], a.opacity_logit[i], pg);
        auto w = c;  // the frame with 3 more pixels on each side, a window around the camera's image
        w.width += 6, w.height += 6, w.cx += 3, w.cy += 3;
        RasterSettings<float, 3> rw;
        rw.clamp_frame_x = rw.clamp_frame_y = -3, rw.clamp_frame_width = c.width, rw.clamp_frame_height = c.height;
        const bool in_w = project_gaussian(w, rw, &a.mean[3 * i], &a.log_scale[3 * i], &a.rotation[4 * i], a.opacity_logit[i], pw);
        if (in && in_w) {  // the same Gaussian on the screen (Jacobian clamp included), 3 pixels further
          CHECK(pw.u == doctest::Approx(pg.u + 3).epsilon(1e-5));
          CHECK(pw.v == doctest::Approx(pg.v + 3).epsilon(1e-5));
          for (int q = 0; q < 3; ++q) CHECK(pw.conic[q] == doctest::Approx(pg.conic[q]).epsilon(1e-5));
        }
        any = any || in;
        wide = wide || in_w;
      }
      CHECK(bool(seen0[i]) == any);
      CHECK(bool(seen[i]) == wide);
      CHECK((!any || wide));
      in_band += wide && !any;
      if (!seen[i]) {
        ++culled;
        continue;
      }
      REQUIRE(j < b.size());
      const auto ga = a.get(i), gb = b.get(j++);  // the same values, in the same order
      CHECK(ga.mean == gb.mean);
      CHECK(ga.rotation == gb.rotation);
      CHECK(ga.log_scale == gb.log_scale);
      CHECK(ga.opacity_logit == gb.opacity_logit);
      CHECK(ga.sh == gb.sh);
    }
    CHECK(j == b.size());
    if (s == GaussianSet::background) CHECK(culled > 0);
  }
  CHECK(in_band > 0);  // the band keeps Gaussians just outside the frames
  const auto negative_margin = [&] { (void)seen_by_any_camera<float, 1>(ref.bkg, span_c, {}, nullptr, -1); };
  CHECK_THROWS_AS(negative_margin(), option_error);
  // The fields' boxes are the uncut sets'.
  CHECK(cut.bkg_box_min == ref.bkg_box_min);
  CHECK(cut.bkg_box_max == ref.bkg_box_max);
  CHECK(cut.frg_box_min == ref.frg_box_min);
  // Undeformed, every frame renders the same bits: the culled Gaussians never reached a pixel.
  ref.deformation_enabled = cut.deformation_enabled = false;
  ClipRenderBuffers<float, SmallField> br, bc;
  for (int i = 0; i < 3; ++i) {
    render_clip_frame(ref, i, br);
    render_clip_frame(cut, i, bc);
    CHECK(std::equal(br.merged.storage().begin(), br.merged.storage().end(), bc.merged.storage().begin()));
    CHECK(std::equal(br.bkg.image.storage().begin(), br.bkg.image.storage().end(), bc.bkg.image.storage().begin()));
  }
}

TEST_CASE("make_clip_model: a set no camera sees is kept whole by cull_unseen, with a warning") {
  auto cams = arc_cameras(2);
  for (auto& cam : cams) cam.look_at(cam.center(), {0, 0, -100});  // facing away from everything
  const auto pts = grid_points(0.3);
  ClipModelOptions o = small_options();
  const auto ref = make_clip_model<float, 1, SmallField>(FrameRange{0, 1}, std::span<const Camera<float>>(cams),
                                                         std::span<const SfmPoint<double>>(pts), o);
  o.cull_unseen = true;
  const auto cut = make_clip_model<float, 1, SmallField>(FrameRange{0, 1}, std::span<const Camera<float>>(cams),
                                                         std::span<const SfmPoint<double>>(pts), o);
  CHECK(cut.frg.size() == ref.frg.size());
  bool warned = false;
  for (const auto& w : cut.warnings) warned = warned || w.find("no clip camera sees any initial Gaussian of set frg") != std::string::npos;
  CHECK(warned);
}

TEST_CASE("make_clip_model: a dense background start adds the middle frame's surface points after the shells") {
  const auto cams = arc_cameras(3);
  const auto pts = grid_points(0.3);
  const auto frames = ramp_frames(3);
  const auto span_f = std::span<const Image<float, 3>>(frames);
  const auto make = arc_model_with_frames;
  ClipModelOptions o = small_options();
  o.background_colour = BackgroundColour::frames;
  const auto shells = make(o, span_f);
  o.background_dense_stride = 4;
  CHECK(o.departures_key() == "|bkg_colour=frames|bkg_dense=4");
  const auto dense = make(o, span_f);
  std::vector<Eigen::Matrix<float, 3, 1>> world;
  for (const auto& p : pts) world.push_back(p.xyz.cast<float>());
  const auto [dp, drgb] = frame_surface_points<float>(cams[1], frames[1], world, 4);
  REQUIRE(dp.size() == 10u * 7u);
  REQUIRE(dense.bkg.size() == shells.bkg.size() + dp.size());
  const std::size_t n0 = shells.bkg.size(), stride = std::size_t(3 * GaussianCloud<float, 1>::sh_coeffs);
  for (std::size_t i = 0; i < n0 * 3; ++i) CHECK(dense.bkg.mean[i] == shells.bkg.mean[i]);  // the shells first, in place (their scales follow their new neighbours)
  for (std::size_t q = 0; q < dp.size(); ++q)
    for (int c = 0; c < 3; ++c) {
      CHECK(dense.bkg.mean[3 * (n0 + q) + std::size_t(c)] == dp[q][c]);
      CHECK(dense.bkg.sh[stride * (n0 + q) + std::size_t(c)] == sh::rgb_to_dc(drgb[q][std::size_t(c)]));
    }
  CHECK(dense.frg.mean == shells.frg.mean);
  // Frames are needed; a negative stride is refused.
  auto refused = [&](const ClipModelOptions& b, std::span<const Image<float, 3>> fr) {
    return refused_naming([&] { return make(b, fr); }, "background_dense_stride");
  };
  ClipModelOptions no_frames = small_options();
  no_frames.background_dense_stride = 4;
  CHECK(refused(no_frames, {}));
  no_frames.background_dense_stride = -1;
  CHECK(refused(no_frames, span_f));
}
