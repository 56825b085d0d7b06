// Compact model files (model/compact_io.hpp): the codes' bounds (half floats, smallest-three
// rotations, k-means), a round trip within the documented per-attribute bounds, renders close to the
// original's, the same bytes for any thread count, and corrupt, truncated or foreign files refused
// with their ids.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <random>
#include <string>

#include <unistd.h>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "../tiny_clip.hpp"
#include "video3dgs/io/ply.hpp"
#include "video3dgs/metrics/psnr.hpp"
#include "video3dgs/model/compact_io.hpp"
#include "video3dgs/model/render_clip.hpp"
#include "video3dgs/sh/basis.hpp"

using namespace video3dgs;

namespace {

using test::TinyField;
using test::TinyModel;

std::filesystem::path compact_temp(const char* name) {
  return std::filesystem::temp_directory_path() / (std::string("video3dgs_compact_") + name + "_" + std::to_string(::getpid()));
}

/// The tiny clip's initial model with every attribute spread out (random rotations, anisotropic
/// scales, opacities, SH rest bands, field values, alpha maps), deformation on: nothing quantises
/// trivially.
TinyModel spread_model(std::uint64_t seed) {
  auto m = test::make_tiny_clip(true, false, seed).model;
  auto rng = test::seeded_rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (auto* c : {&m.frg, &m.bkg}) {
    for (auto& v : c->log_scale) v += 0.5 * normal(rng);
    for (auto& v : c->rotation) v = normal(rng);
    for (auto& v : c->opacity_logit) v = logit(0.05 + 0.9 * unit(rng));
    for (std::size_t i = 0; i < c->size(); ++i)
      for (std::size_t j = 3; j < 48; ++j) c->sh[48 * i + j] = 0.1 * normal(rng);
  }
  for (auto* f : {m.frg_field.get(), m.bkg_field.get()})
    for (auto& s : f->segments())
      for (auto& v : s.value) v += 0.02 * normal(rng);
  for (auto& a : m.alpha_logit)
    for (int y = 0; y < a.height(); ++y)
      for (int x = 0; x < a.width(); ++x) a(x, y) = 3 * std::sin(0.3 * x + 0.2 * y) + 0.5 * normal(rng);
  m.deformation_enabled = true;
  return m;
}

/// max over Gaussians of |a - b| for value j of k per Gaussian, and the documented bound
/// step(bits, min, max) / 2 of that value's code.
struct AxisError {
  double error = 0, bound = 0;
};
AxisError axis_error(const std::vector<double>& a, const std::vector<double>& b, std::size_t k, std::size_t j, int bits) {
  AxisError e;
  double mn = 1e300, mx = -1e300;
  for (std::size_t i = j; i < a.size(); i += k) {
    mn = std::min(mn, a[i]), mx = std::max(mx, a[i]);
    e.error = std::max(e.error, std::abs(a[i] - b[i]));
  }
  e.bound = (mx - mn) / double((1 << bits) - 1) / 2;
  return e;
}

/// The DC of `a` with the rest bands' error (decoded `b` minus original `a`) at the clip's view
/// directions fed back: dc - mean_f sum_{k>=1} B_k(d_f) (b_k - a_k) / C0 (compact_io.hpp's contract).
template <class Cloud>
std::vector<double> fed_back_dc(const TinyModel& m, const Cloud& a, const Cloud& b) {
  std::vector<double> dc(3 * a.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    const Eigen::Vector3d mu(a.mean[3 * i], a.mean[3 * i + 1], a.mean[3 * i + 2]);
    for (std::size_t c = 0; c < 3; ++c) {
      double err = 0;
      for (const auto& cam : m.cameras) {
        const Eigen::Vector3d d = (mu - cam.center()).normalized();
        double B[16];
        sh::basis<double>(3, d.x(), d.y(), d.z(), B);
        for (std::size_t k = 1; k < 16; ++k) err += B[k] * (b.sh[48 * i + 3 * k + c] - a.sh[48 * i + 3 * k + c]);
      }
      dc[3 * i + c] = a.sh[48 * i + c] - err / double(m.cameras.size()) / sh::kC0;
    }
  }
  return dc;
}

/// Set `s` of `m` in the order a compact file stores it (Morton order of its position codes): the
/// loaded set's Gaussian k is this set's Gaussian k.
auto in_file_order(const TinyModel& m, GaussianSet s, const CompactOptions& o) {
  const auto& c = m.cloud(s);
  return detail::permuted(c, detail::compact_order(c, s == GaussianSet::foreground ? o.frg_position_bits : o.position_bits));
}

template <class F>
std::string failing_id(F&& f) {
  return test::error_id(std::forward<F>(f));
}

}  // namespace

TEST_CASE("compact codes: half floats, smallest-three rotations, zigzag") {
  // Every finite half reads back to itself; rounding a float is within 2^-11 relative (2^-25 absolute
  // below 2^-14).
  for (std::uint32_t h = 0; h < 0x10000u; ++h) {
    if (((h >> 10) & 0x1f) == 31) continue;
    CHECK(detail::float_to_half(detail::half_to_float(std::uint16_t(h))) == h);
  }
  auto rng = test::seeded_rng(7);
  std::uniform_real_distribution<double> e(-20, 15);
  for (int k = 0; k < 20000; ++k) {
    const float x = float((k % 2 ? -1 : 1) * std::exp2(e(rng)));
    const float y = detail::half_to_float(detail::float_to_half(x));
    CHECK(std::abs(double(y) - double(x)) <= std::max(std::ldexp(std::abs(double(x)), -11), 0x1.0p-25));
  }
  CHECK(detail::half_to_float(detail::float_to_half(1e6f)) == 65504.0f);

  // Rotations: u = q/|q| WITH its sign (the deformation adds to u, so -u deforms differently); the
  // stored three within delta, the largest within 6 delta (1 + delta).
  std::normal_distribution<double> normal;
  const double delta = std::sqrt(2.0) / 1022;
  double worst_small = 0, worst_large = 0;
  for (int k = 0; k < 20000; ++k) {
    std::array<double, 4> q{normal(rng), normal(rng), normal(rng), normal(rng)};
    if (k % 5 == 0) q[std::size_t(k % 4)] = 0;  // components at 0 and ties
    const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    const auto d = detail::decode_rotation(detail::encode_rotation(q));
    std::size_t m = 0;
    for (std::size_t c = 1; c < 4; ++c)
      if (std::abs(q[c]) > std::abs(q[m])) m = c;
    for (std::size_t c = 0; c < 4; ++c) {
      const double err = std::abs(q[c] / n - d[c]);
      (c == m ? worst_large : worst_small) = std::max(c == m ? worst_large : worst_small, err);
    }
    CHECK(std::abs(d[0] * d[0] + d[1] * d[1] + d[2] * d[2] + d[3] * d[3] - 1) < 1e-12);
  }
  CHECK(worst_small <= delta * (1 + 1e-9));
  CHECK(worst_large <= 6 * delta * (1 + delta));
  // q and -q keep their own codes.
  CHECK(detail::decode_rotation(detail::encode_rotation({-0.9, 0.1, -0.3, 0.2}))[0] < 0);
  CHECK(detail::decode_rotation(detail::encode_rotation({0.9, -0.1, 0.3, -0.2}))[0] > 0);
  // Version-1 codes (10 bits per value, no sign bit): m = 1, v = (w, y, z) at code 0, 1023, 511.5 - 0.5.
  {
    const std::uint32_t v1 = 1u | (0u << 2) | (1023u << 12) | (511u << 22);
    const auto d = detail::decode_rotation_v1(v1);
    const double a = std::sqrt(0.5), b = -a + 511 * std::sqrt(2.0) / 1023;
    const double n = std::sqrt(a * a + a * a + b * b + std::max(0.0, 1 - a * a - a * a - b * b));
    CHECK(d[0] == doctest::Approx(-a / n).epsilon(1e-12));
    CHECK(d[2] == doctest::Approx(a / n).epsilon(1e-12));
    CHECK(d[3] == doctest::Approx(b / n).epsilon(1e-12));
    CHECK(d[1] >= 0);
  }
  // Any 32 bits decode to a unit quaternion (corrupt files render).
  for (std::uint32_t v : {0u, 0xffffffffu, 0xfffffffcu, 0x12345678u}) {
    const auto d = detail::decode_rotation(v);
    CHECK(std::abs(d[0] * d[0] + d[1] * d[1] + d[2] * d[2] + d[3] * d[3] - 1) < 1e-12);
  }
  for (std::int32_t v : {0, 1, -1, 127, -127, 32767, -32767}) CHECK(detail::unzigzag(detail::zigzag(v)) == v);
  CHECK(detail::zigzag(-1) == 1u);
}

TEST_CASE("compact codes: delta codes are exact and fit their bits; Morton order") {
  auto rng = test::seeded_rng(11);
  for (int bits : {8, 16, 24}) {
    CAPTURE(bits);
    const std::uint32_t max = (std::uint32_t(1) << bits) - 1;
    std::uniform_int_distribution<std::uint32_t> any(0, max);
    std::vector<std::uint32_t> q = {0, max, 0, max, max, 1, 0};  // the widest steps, both ways
    for (int k = 0; k < 2000; ++k) q.push_back(any(rng));
    auto d = q;
    detail::delta_codes(d, bits);
    for (auto v : d) CHECK(v <= max);
    detail::undelta_codes(d, bits);
    CHECK(d == q);
    // Small steps give small codes: a walk of +-3 codes at most 6 (zigzag).
    std::vector<std::uint32_t> walk = {max / 2};
    std::uniform_int_distribution<int> step(-3, 3);
    for (int k = 0; k < 500; ++k) walk.push_back(std::uint32_t(int(walk.back()) + step(rng)));
    auto dw = walk;
    detail::delta_codes(dw, bits);
    for (std::size_t k = 1; k < dw.size(); ++k) CHECK(dw[k] <= 6);
    detail::undelta_codes(dw, bits);
    CHECK(dw == walk);
  }
  // Keys interleave x, y, z (x lowest): (1,0,0) -> 1, (0,1,0) -> 2, (0,0,1) -> 4, (1,1,1) -> 7; a tie
  // keeps the index order.
  const std::vector<std::uint32_t> planes = {1, 0, 1, 0, 1,   // x of points 0..4
                                             1, 0, 0, 1, 0,   // y
                                             1, 1, 0, 0, 0};  // z
  CHECK(detail::morton_order(planes, 5, 2) == std::vector<std::uint32_t>{2, 4, 3, 1, 0});
  // Above 21 bits only the top 21 enter the key: points that differ below them keep the index order.
  const std::vector<std::uint32_t> wide = {7, 0, 1u << 23, 0, 0, 0, 0, 0, 0};
  CHECK(detail::morton_order(wide, 3, 24) == std::vector<std::uint32_t>{0, 1, 2});
}

TEST_CASE("compact codes: k-means is deterministic, codewords are nearest, small sets are kept") {
  const std::size_t n = 3000, dim = 9;
  std::vector<float> x(n * dim);
  auto rng = test::seeded_rng(11);
  std::normal_distribution<float> normal;
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t d = 0; d < dim; ++d) x[i * dim + d] = float(i % 7) + 0.1f * normal(rng);
  const detail::VectorQuantizerOptions o{64, 5, 1000};
  ThreadPool one(1), two(2);
  const auto a = detail::fit_vector_codebook(x, n, int(dim), o, &one);
  const auto b = detail::fit_vector_codebook(x, n, int(dim), o, &two);
  const auto c = detail::fit_vector_codebook(x, n, int(dim), o, nullptr);
  REQUIRE(a.size() == 64);
  CHECK(a.codewords == b.codewords);
  CHECK(a.index == b.index);
  CHECK(a.codewords == c.codewords);
  CHECK(a.index == c.index);
  double worst = 0;
  for (std::size_t i = 0; i < n; ++i) {
    auto dist = [&](std::size_t k) {
      double s = 0;
      for (std::size_t d = 0; d < dim; ++d) s += std::pow(double(x[i * dim + d]) - a.codewords[k * dim + d], 2);
      return s;
    };
    double best = 1e300;
    for (std::size_t k = 0; k < a.size(); ++k) best = std::min(best, dist(k));
    CHECK(dist(a.index[i]) <= best * (1 + 1e-4) + 1e-6);
    worst = std::max(worst, dist(a.index[i]));
  }
  CHECK(worst < 0.5);  // 7 clusters of spread 0.1 x sqrt(9) among 64 codewords
  // n <= K: the points themselves, rounded to half floats.
  const auto small = detail::fit_vector_codebook(x, 50, int(dim), {64, 5, 1000}, nullptr);
  REQUIRE(small.size() == 50);
  for (std::size_t i = 0; i < 50; ++i) {
    CHECK(small.index[i] == i);
    for (std::size_t d = 0; d < dim; ++d) CHECK(small.codewords[i * dim + d] == detail::half_to_float(detail::float_to_half(x[i * dim + d])));
  }
}

TEST_CASE("compact model: round trip within the documented bounds; renders close; PLY export") {
  auto m = spread_model(3);
  const auto path = compact_temp("roundtrip");
  CompactOptions o;
  o.alpha_tolerance = 0;  // nearest alpha codes (the tolerance's bound has its own test below)
  const CompactSizes sizes = save_compact_clip_model(path, m, o);
  CHECK(sizes.total == std::filesystem::file_size(path));
  CHECK(sizes.total == sizes.gaussians + sizes.fields + sizes.alpha + sizes.other);
  CHECK(sizes.gaussians > 0);
  CHECK(sizes.fields > 0);
  CHECK(sizes.alpha > 0);
  const auto back = load_compact_clip_model<double, 3, TinyField>(path);

  // Exact parts.
  CHECK(back.range == m.range);
  REQUIRE(back.cameras.size() == m.cameras.size());
  for (std::size_t i = 0; i < m.cameras.size(); ++i) {
    CHECK(back.cameras[i].R == m.cameras[i].R);
    CHECK(back.cameras[i].t == m.cameras[i].t);
    CHECK(back.cameras[i].fx == m.cameras[i].fx);
  }
  CHECK(back.scene_radius == m.scene_radius);
  CHECK(back.deformation_enabled);
  CHECK(back.has_foreground);
  CHECK(back.frg_box_min == m.frg_box_min);
  CHECK(back.bkg_box_max == m.bkg_box_max);
  CHECK(back.frg_field->box_lo() == m.frg_field->box_lo());
  CHECK(back.warnings == m.warnings);

  for (auto s : {GaussianSet::foreground, GaussianSet::background}) {
    const auto a = in_file_order(m, s, o);
    const auto& b = back.cloud(s);
    CAPTURE(to_string(s));
    REQUIRE(b.size() == a.size());
    REQUIRE(a.size() < std::size_t(o.sh_codebook));
    for (std::size_t j = 0; j < 3; ++j) {
      const auto pe = axis_error(a.mean, b.mean, 3, j, s == GaussianSet::foreground ? o.frg_position_bits : o.position_bits);
      CHECK(pe.error <= pe.bound * (1 + 1e-9) + 1e-15);
      const auto se = axis_error(a.log_scale, b.log_scale, 3, j, o.scale_bits);
      CHECK(se.error <= se.bound * (1 + 1e-9) + 1e-15);
      CHECK(se.error > 0);  // actually quantised
    }
    // DC: within its code's bound of the DC with the rest bands' error fed back (compact_io.hpp).
    const auto fed = fed_back_dc(m, a, b);
    std::vector<double> dc_a, dc_b;
    for (std::size_t i = 0; i < a.size(); ++i)
      for (std::size_t c = 0; c < 3; ++c) dc_a.push_back(fed[3 * i + c]), dc_b.push_back(b.sh[48 * i + c]);
    for (std::size_t c = 0; c < 3; ++c) {
      const auto de = axis_error(dc_a, dc_b, 3, c, o.dc_bits);
      CHECK(de.error <= de.bound * (1 + 1e-9) + 1e-15);
    }
    const double delta = std::sqrt(2.0) / 1022;
    for (std::size_t i = 0; i < a.size(); ++i) {
      CHECK(std::abs(sigmoid(a.opacity_logit[i]) - sigmoid(b.opacity_logit[i])) <= 1.0 / 510 + 1e-12);
      // Rotation: unit, and u = q/|q| with its own sign within the bounds (the field adds to u).
      const double* q = a.rotation.data() + 4 * i;
      const double* r = b.rotation.data() + 4 * i;
      const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
      for (int c = 0; c < 4; ++c) CHECK(std::abs(q[c] / n - r[c]) <= 6 * delta * (1 + delta));
      // Rest bands: the set is smaller than the codebook, so only half-float rounding.
      for (std::size_t j = 3; j < 48; ++j) {
        const double x = a.sh[48 * i + j];
        CHECK(std::abs(x - b.sh[48 * i + j]) <= std::max(std::ldexp(std::abs(x), -11), 0x1.0p-25));
      }
    }
  }
  // Fields: table values within max|block| / (2 * 127), heads to float precision.
  for (auto s : {GaussianSet::foreground, GaussianSet::background}) {
    auto sa = m.field(s).segments();
    auto sb = const_cast<TinyModel&>(back).field(s).segments();
    REQUIRE(sa.size() == sb.size());
    for (std::size_t k = 0; k < sa.size(); ++k) {
      const std::size_t block = k == 0 ? 4096 : sa[k].value.size();
      for (std::size_t lo = 0; lo < sa[k].value.size(); lo += block) {
        const std::size_t hi = std::min(sa[k].value.size(), lo + block);
        double mx = 0, err = 0;
        for (std::size_t i = lo; i < hi; ++i) {
          mx = std::max(mx, std::abs(sa[k].value[i]));
          err = std::max(err, std::abs(sa[k].value[i] - sb[k].value[i]));
        }
        CHECK(err <= (k == 0 ? mx / 254 * (1 + 1e-6) : mx * 0x1.0p-24));
      }
    }
  }
  // Alpha: |A' - A| <= 1/510 at full resolution.
  double alpha_err = 0;
  for (std::size_t f = 0; f < m.alpha_logit.size(); ++f)
    for (std::size_t i = 0; i < m.alpha_logit[f].size(); ++i)
      alpha_err = std::max(alpha_err, std::abs(sigmoid(m.alpha_logit[f].data()[i]) - sigmoid(back.alpha_logit[f].data()[i])));
  CHECK(alpha_err <= 1.0 / 510 + 1e-12);
  CHECK(alpha_err > 0);

  // Renders. Floor: the colour codes alone move a pixel by at most ~1/510 of the colour range (DC) and
  // 1/510 in the merge (alpha), i.e. >= ~48 dB; positions, scales and rotations move edges by a small
  // fraction of a pixel at 32x24. 35 dB leaves room for that and still fails any decoding slip (a
  // swapped axis, a wrong codeword or sign drops the render below 20 dB).
  ClipRenderBuffers<double, TinyField> b1, b2;
  for (int i = 0; i < m.frame_count(); ++i) {
    render_clip_frame(m, i, b1);
    render_clip_frame(back, i, b2);
    const double p = metrics::psnr<double, 3>(b1.merged, b2.merged);
    MESSAGE("frame " << i << ": PSNR original vs compact " << p << " dB");
    CHECK(p > 35.0);
  }
  // The loaded model exports PLY like any other.
  const auto ply = compact_temp("export.ply");
  export_ply(back, GaussianSet::foreground, 1, ply);
  CHECK(io::read_ply<double>(ply).count == back.frg.size());
  std::filesystem::remove(ply);
  std::filesystem::remove(path);
}

TEST_CASE("compact model: Gaussians in Morton order store smaller; version-2 parts are still read") {
  auto m = spread_model(4);
  CompactOptions o;
  o.alpha_tolerance = 0;
  const auto back = read_compact_clip_model<double, 3, TinyField>(write_compact_clip_model(m, o), "mem");
  // A version-2 part, written the way version 2 did (file order, positions as codes, rotations as
  // 32-bit words), decodes to the same Gaussians in the saved order.
  io::BinaryWriter w("ccm.gaus", 2);
  for (auto s : {GaussianSet::foreground, GaussianSet::background}) {
    const auto& c = m.cloud(s);
    const std::size_t n = c.size();
    w.put<std::uint64_t>(n);
    detail::put_uniform_planes<double>(w, c.mean, 3, s == GaussianSet::foreground ? o.frg_position_bits : o.position_bits);
    detail::put_uniform_planes<double>(w, c.log_scale, 3, o.scale_bits);
    std::vector<std::uint32_t> rot(n);
    std::vector<std::uint8_t> opacity(n);
    std::vector<double> dc(3 * n);
    std::vector<std::uint16_t> halves;
    std::vector<std::uint32_t> index(n);
    for (std::size_t i = 0; i < n; ++i) {
      const double* q = c.rotation.data() + 4 * i;
      rot[i] = detail::encode_rotation({q[0], q[1], q[2], q[3]});
      opacity[i] = detail::encode_unit(sigmoid(c.opacity_logit[i]));
      for (std::size_t ch = 0; ch < 3; ++ch) dc[3 * i + ch] = c.sh[48 * i + ch];
      for (std::size_t j = 3; j < 48; ++j) halves.push_back(detail::float_to_half(float(c.sh[48 * i + j])));
      index[i] = std::uint32_t(i);  // one codeword per Gaussian
    }
    w.put_vector(rot);
    w.put_vector(opacity);
    detail::put_uniform_planes<double>(w, dc, 3, o.dc_bits);
    w.put<std::uint32_t>(std::uint32_t(n));
    w.put_vector(halves);
    w.put_vector(detail::to_planes(index, n <= 256 ? 1 : 2));
  }
  auto v2 = read_compact_clip_model<double, 3, TinyField>(write_compact_clip_model(m, o), "mem");
  detail::read_compact_gaussians(v2, w.bytes(), "v2.compact", {m.frg.size(), m.bkg.size()});
  for (auto s : {GaussianSet::foreground, GaussianSet::background}) {
    CAPTURE(to_string(s));
    const auto& a = m.cloud(s);
    const auto order = detail::compact_order(a, s == GaussianSet::foreground ? o.frg_position_bits : o.position_bits);
    // The stored order is a permutation, and not the identity here (the test would be empty).
    auto sorted = order;
    std::sort(sorted.begin(), sorted.end());
    for (std::size_t k = 0; k < sorted.size(); ++k) CHECK(sorted[k] == k);
    CHECK(order != sorted);
    // Version 3 gives the version-2 file's decoded Gaussians, permuted (the same codes either way).
    const auto& b3 = back.cloud(s);
    const auto& b2 = v2.cloud(s);
    REQUIRE(b3.size() == b2.size());
    for (std::size_t k = 0; k < b3.size(); ++k) {
      const std::size_t i = order[k];
      for (int j = 0; j < 3; ++j) {
        CHECK(b3.mean[3 * k + std::size_t(j)] == b2.mean[3 * i + std::size_t(j)]);
        CHECK(b3.log_scale[3 * k + std::size_t(j)] == b2.log_scale[3 * i + std::size_t(j)]);
      }
      for (int j = 0; j < 4; ++j) CHECK(b3.rotation[4 * k + std::size_t(j)] == b2.rotation[4 * i + std::size_t(j)]);
      CHECK(b3.opacity_logit[k] == b2.opacity_logit[i]);
    }
  }
  // Spatially coherent Gaussians (positions on a smooth surface, listed at random) store their
  // positions in Morton order, delta-coded, at least 15 % smaller than the same codes in file order.
  auto rng = test::seeded_rng(12);
  std::uniform_real_distribution<double> u(-1, 1);
  GaussianCloud<double, 3> surface(20000);
  for (std::size_t i = 0; i < surface.size(); ++i) {
    const double x = u(rng), y = u(rng);
    surface.mean[3 * i] = x, surface.mean[3 * i + 1] = y, surface.mean[3 * i + 2] = 0.3 * std::sin(3 * x) * std::cos(2 * y);
  }
  io::BinaryWriter file_order("test", 1), morton("test", 1);
  auto planes = detail::quantise_planes<double>(surface.mean, 3, 16);
  detail::put_planes(file_order, planes, 16);
  const auto order = detail::morton_order(planes.q, surface.size(), 16);
  auto sorted = planes;
  for (std::size_t j = 0; j < 3; ++j)
    for (std::size_t k = 0; k < surface.size(); ++k) sorted.q[j * surface.size() + k] = planes.q[j * surface.size() + order[k]];
  detail::put_planes(morton, sorted, 16, true);
  const auto before = io::detail::deflate_bytes(file_order.bytes(), 9, "test").size();
  const auto after = io::detail::deflate_bytes(morton.bytes(), 9, "test").size();
  MESSAGE("20k surface positions, 16 bits: " << before << " bytes in file order, " << after << " in Morton order, delta-coded");
  CHECK(double(after) < 0.85 * double(before));  // 0.76 x when written
}

TEST_CASE("compact model: sets larger than the codebook use their nearest codeword; alpha at a lower resolution") {
  auto m = spread_model(5);
  CompactOptions o;
  o.sh_codebook = 16;
  o.alpha_downscale = 4;
  // Constant alpha on frame 0: the block means and the bilinear upsampling keep it (within 1/510).
  m.alpha_logit[0].fill(0.7);
  const auto bytes = write_compact_clip_model(m, o);
  const auto back = read_compact_clip_model<double, 3, TinyField>(bytes, "mem");
  for (const auto* set : {&back.frg, &back.bkg}) {
    const auto a = in_file_order(m, set == &back.frg ? GaussianSet::foreground : GaussianSet::background, o);
    // The codebook is the set of distinct decoded rest vectors.
    std::vector<std::vector<double>> codewords;
    for (std::size_t i = 0; i < set->size(); ++i) {
      std::vector<double> v(set->sh.begin() + std::ptrdiff_t(48 * i + 3), set->sh.begin() + std::ptrdiff_t(48 * i + 48));
      if (std::find(codewords.begin(), codewords.end(), v) == codewords.end()) codewords.push_back(v);
    }
    CHECK(codewords.size() <= 16);
    for (std::size_t i = 0; i < a.size(); ++i) {
      auto dist = [&](const double* c) {
        double s = 0;
        for (std::size_t j = 0; j < 45; ++j) s += std::pow(a.sh[48 * i + 3 + j] - c[j], 2);
        return s;
      };
      double best = 1e300;
      for (const auto& c : codewords) best = std::min(best, dist(c.data()));
      CHECK(dist(set->sh.data() + 48 * i + 3) <= best * (1 + 1e-4) + 1e-9);
    }
  }
  REQUIRE(back.alpha_logit[0].width() == m.width());
  for (std::size_t i = 0; i < back.alpha_logit[0].size(); ++i)
    CHECK(std::abs(sigmoid(back.alpha_logit[0].data()[i]) - sigmoid(0.7)) <= 1.0 / 510 + 1e-12);
}

TEST_CASE("compact model: hash-table codes of 2..7 bits keep their bound, shrink the file, and refuse codes out of range") {
  auto m = spread_model(3);
  CompactOptions o;
  const std::size_t fields8 = [&] {
    CompactSizes s;
    (void)write_compact_clip_model(m, o, nullptr, &s);
    return s.fields;
  }();
  for (int bits : {2, 4, 6, 7}) {
    CAPTURE(bits);
    o.field_bits = bits;
    CompactSizes sizes;
    const auto back = read_compact_clip_model<double, 3, TinyField>(write_compact_clip_model(m, o, nullptr, &sizes), "mem");
    CHECK(sizes.fields < fields8);
    const double qmax = double((1 << (bits - 1)) - 1);
    for (auto s : {GaussianSet::foreground, GaussianSet::background}) {
      const auto a = m.field(s).segments()[0].value;
      const auto b = const_cast<TinyModel&>(back).field(s).segments()[0].value;
      REQUIRE(a.size() == b.size());
      double worst = 0;  // the error relative to its bound, max|block| / (2 qmax)
      for (std::size_t lo = 0; lo < a.size(); lo += 4096) {
        const std::size_t hi = std::min(a.size(), lo + 4096);
        double mx = 0;
        for (std::size_t i = lo; i < hi; ++i) mx = std::max(mx, std::abs(a[i]));
        for (std::size_t i = lo; i < hi; ++i) worst = std::max(worst, std::abs(a[i] - b[i]) / (mx / (2 * qmax)));
      }
      CHECK(worst <= 1 + 1e-6);
      CHECK(worst > 0.5);  // actually quantised that coarsely
    }
  }
  // An 8-bit record relabelled as 4 bits holds codes above 2 qmax = 14: refused, naming the field.
  o.field_bits = 8;
  const std::string r8 = detail::compact_fields(m, o);
  o.field_bits = 4;
  const std::string r4 = detail::compact_fields(m, o);
  REQUIRE(r8.size() == r4.size());  // one byte per code either way
  std::size_t at = 0;
  while (at < r8.size() && r8[at] == r4[at]) ++at;  // the first difference: the frg table's bits
  REQUIRE(at < r8.size());
  REQUIRE(r8[at] == char(8));
  std::string bad = r8;
  bad[at] = char(4);
  auto target = read_compact_clip_model<double, 3, TinyField>(write_compact_clip_model(m, {}), "mem");
  CHECK_NOTHROW(detail::read_compact_fields(target, r8, "f.compact"));
  CHECK(test::error_id([&] { detail::read_compact_fields(target, bad, "f.compact"); }) == "io.format");
  bad[at] = char(9);  // 9..15 bits are not a format
  CHECK(test::error_id([&] { detail::read_compact_fields(target, bad, "f.compact"); }) == "io.format");
  o.field_bits = 9;
  CHECK(test::error_id([&] { o.validate(); }) == "option.compact");
}

TEST_CASE("compact model: rest bands coarser than the set keep their mean colour at the clip's views (DC feedback)") {
  auto m = spread_model(6);
  CompactOptions o;
  o.sh_codebook = 8;  // far fewer codewords than Gaussians: large rest-band errors
  o.dc_bits = 16;
  const auto back = read_compact_clip_model<double, 3, TinyField>(write_compact_clip_model(m, o), "mem");
  for (auto s : {GaussianSet::foreground, GaussianSet::background}) {
    const auto a = in_file_order(m, s, o);
    const auto& b = back.cloud(s);
    CAPTURE(to_string(s));
    // Per Gaussian and channel, the colour error (before the clamp) averaged over the clip's frames is
    // only the DC code's rounding, while the rest bands alone are off by much more.
    double mn = 1e300, mx = -1e300, worst_mean = 0, worst_rest = 0;
    for (const double v : fed_back_dc(m, a, b)) mn = std::min(mn, v), mx = std::max(mx, v);
    const double dc_step = (mx - mn) / 65535;  // >= every channel's step
    for (std::size_t i = 0; i < a.size(); ++i) {
      const Eigen::Vector3d mu(a.mean[3 * i], a.mean[3 * i + 1], a.mean[3 * i + 2]);
      for (std::size_t c = 0; c < 3; ++c) {
        double mean_err = 0, rest_err = 0;
        for (const auto& cam : m.cameras) {
          const Eigen::Vector3d d = (mu - cam.center()).normalized();
          double B[16];
          sh::basis<double>(3, d.x(), d.y(), d.z(), B);
          double rest = 0;
          for (std::size_t k = 1; k < 16; ++k) rest += B[k] * (b.sh[48 * i + 3 * k + c] - a.sh[48 * i + 3 * k + c]);
          mean_err += rest + B[0] * (b.sh[48 * i + c] - a.sh[48 * i + c]);
          rest_err += rest;
        }
        worst_mean = std::max(worst_mean, std::abs(mean_err) / double(m.cameras.size()));
        worst_rest = std::max(worst_rest, std::abs(rest_err) / double(m.cameras.size()));
      }
    }
    CHECK(worst_mean <= sh::kC0 * dc_step / 2 * (1 + 1e-6) + 1e-12);
    CHECK(worst_rest > 100 * worst_mean);
  }
}

TEST_CASE("compact model: an alpha tolerance moves the merged render by at most tau and stores smaller") {
  auto m = spread_model(8);
  CompactOptions exact;
  exact.alpha_tolerance = 0;
  CompactOptions loose;
  loose.alpha_tolerance = 0.02;
  CompactSizes se, sl;
  const auto be = write_compact_clip_model(m, exact, nullptr, &se);
  const auto bl = write_compact_clip_model(m, loose, nullptr, &sl);
  CHECK(sl.alpha < se.alpha);
  CHECK(sl.gaussians == se.gaussians);
  const auto back = read_compact_clip_model<double, 3, TinyField>(bl, "mem");
  ClipRenderBuffers<double, TinyField> buf;
  std::size_t moved = 0;
  for (int f = 0; f < m.frame_count(); ++f) {
    render_clip_frame(m, f, buf);
    for (int y = 0; y < m.height(); ++y)
      for (int x = 0; x < m.width(); ++x) {
        const double A = sigmoid(m.alpha_logit[std::size_t(f)](x, y)), A2 = sigmoid(back.alpha_logit[std::size_t(f)](x, y));
        double delta = 0;
        for (int c = 0; c < 3; ++c) delta = std::max(delta, std::abs(buf.frg.image(x, y, c) - buf.bkg.image(x, y, c)));
        // |I' - I| = |A' - A| |I_f - I_b| <= max(tau, Delta / 510) per channel.
        CHECK(std::abs(A2 - A) * delta <= std::max(loose.alpha_tolerance, delta / 510) * (1 + 1e-9) + 1e-12);
        moved += std::abs(A2 - A) > 1.0 / 510 + 1e-9;
      }
  }
  CHECK(moved > 0);  // the tolerance was used
  // Without foreground renders to compare (d > 1) the tolerance is not used: the same bytes as tau = 0.
  exact.alpha_downscale = loose.alpha_downscale = 2;
  CHECK(write_compact_clip_model(m, exact) == write_compact_clip_model(m, loose));
}

TEST_CASE("compact model: the same bytes for any thread count") {
  auto m = spread_model(9);
  CompactOptions o;
  o.sh_codebook = 32;  // the k-means path
  ThreadPool one(1), two(2);
  const auto a = write_compact_clip_model(m, o, &one);
  const auto b = write_compact_clip_model(m, o, &two);
  const auto c = write_compact_clip_model(m, o, nullptr);
  CHECK(a == b);
  CHECK(a == c);
}

TEST_CASE("compact presets: every named preset is valid; small is default with smaller codes; unknown names refused") {
  for (const char* name : CompactOptions::preset_names()) CHECK_NOTHROW(CompactOptions::preset(name).validate());
  const CompactOptions d = CompactOptions::preset("default"), s = CompactOptions::preset("small"), plain;
  CHECK(d.field_bits == plain.field_bits);
  CHECK(d.sh_codebook == plain.sh_codebook);
  CHECK(d.frg_position_bits == plain.frg_position_bits);
  CHECK(s.field_bits == 5);
  CHECK(s.sh_codebook == 16);
  CHECK(s.frg_position_bits == 16);
  CHECK(s.position_bits == plain.position_bits);
  CHECK(s.alpha_downscale == plain.alpha_downscale);
  // On a model, small writes fewer bytes in the parts it changes.
  auto m = spread_model(2);
  CompactSizes sd, ss;
  (void)write_compact_clip_model(m, d, nullptr, &sd);
  (void)write_compact_clip_model(m, s, nullptr, &ss);
  CHECK(ss.fields < sd.fields);
  CHECK(ss.gaussians < sd.gaussians);
  CHECK(ss.alpha == sd.alpha);
  try {
    (void)CompactOptions::preset("tiny");
    FAIL("no exception");
  } catch (const option_error& e) {
    CHECK(e.id() == "option.compact");
    CHECK(e.where() == "preset");
    CHECK(std::string(e.what()).find("small") != std::string::npos);
  }
}

TEST_CASE("compact model: options, non-finite values and wrong template arguments are refused with their ids") {
  auto m = spread_model(4);
  auto bad_option = [&](auto set, const char* field) {
    CompactOptions o;
    set(o);
    try {
      (void)write_compact_clip_model(m, o);
      FAIL("no exception for " << field);
    } catch (const option_error& e) {
      CHECK(e.id() == "option.compact");
      CHECK(e.where() == field);
    }
  };
  bad_option([](CompactOptions& o) { o.sh_codebook = 0; }, "sh_codebook");
  bad_option([](CompactOptions& o) { o.sh_codebook = 65537; }, "sh_codebook");
  bad_option([](CompactOptions& o) { o.position_bits = 12; }, "position_bits");
  bad_option([](CompactOptions& o) { o.frg_position_bits = 32; }, "frg_position_bits");
  bad_option([](CompactOptions& o) { o.scale_bits = 24; }, "scale_bits");
  bad_option([](CompactOptions& o) { o.alpha_tolerance = -0.1; }, "alpha_tolerance");
  bad_option([](CompactOptions& o) { o.alpha_tolerance = std::nan(""); }, "alpha_tolerance");
  bad_option([](CompactOptions& o) { o.dc_bits = 32; }, "dc_bits");
  bad_option([](CompactOptions& o) { o.field_bits = 0; }, "field_bits");
  bad_option([](CompactOptions& o) { o.alpha_downscale = 0; }, "alpha_downscale");
  bad_option([](CompactOptions& o) { o.alpha_downscale = 17; }, "alpha_downscale");
  bad_option([](CompactOptions& o) { o.zlib_level = 10; }, "zlib_level");
  bad_option([](CompactOptions& o) { o.kmeans_iterations = -1; }, "kmeans_iterations");
  bad_option([](CompactOptions& o) { o.kmeans_sample = 0; }, "kmeans_sample");

  m.bkg.mean[7] = std::nan("");
  try {
    (void)write_compact_clip_model(m, {});
    FAIL("no exception");
  } catch (const numeric_error& e) {
    CHECK(e.id() == "numeric.non_finite");
    CHECK(e.where() == "bkg.mean[7]");
  }
  m.bkg.mean[7] = 0;
  m.alpha_logit[1](2, 3) = INFINITY;
  CHECK(failing_id([&] { (void)write_compact_clip_model(m, {}); }) == "numeric.non_finite");
  m.alpha_logit[1](2, 3) = 0;

  const auto path = compact_temp("mismatch");
  (void)save_compact_clip_model(path, m);
  CHECK(failing_id([&] { (void)load_compact_clip_model<double, 2, TinyField>(path); }) == "io.mismatch");
  using OtherField = DeformationField<double, HashGrid<double, 4, 4, 2, 11>, 8>;
  CHECK(failing_id([&] { (void)load_compact_clip_model<double, 3, OtherField>(path); }) == "io.mismatch");
  CHECK(failing_id([&] { (void)load_compact_clip_model<double, 3, TinyField>(path.string() + ".missing"); }) == "io.unreadable");
  // A float model of the same layout reads the same file (the format does not depend on Scalar).
  using FloatField = DeformationField<float, HashGrid<float, 4, 4, 2, 10>, 8>;
  CHECK(failing_id([&] { (void)load_compact_clip_model<float, 3, FloatField>(path); }) == "<no error>");
  std::filesystem::remove(path);
}

TEST_CASE("compact model: truncated, corrupt and foreign files are refused with their ids, naming the file") {
  auto m = spread_model(6);
  CompactOptions o;
  o.alpha_downscale = 2;
  const std::string bytes = write_compact_clip_model(m, o);
  const std::string file = "clip_x.compact";
  auto id_of = [&](const std::string& b) {
    try {
      (void)read_compact_clip_model<double, 3, TinyField>(b, file);
    } catch (const io_error& e) {
      CHECK(std::string(e.what()).find(file) != std::string::npos);
      return e.id();
    }
    return std::string("<no error>");
  };
  REQUIRE(id_of(bytes) == "<no error>");

  // Every prefix shorter than the header is not a compact file; every longer one is truncated.
  std::size_t prefixes = 0;
  for (std::size_t n = 0; n < bytes.size(); n += (n < 400 ? 1 : 37), ++prefixes) {
    CAPTURE(n);
    CHECK(id_of(bytes.substr(0, n)) == (n < 12 ? "io.format" : "io.truncated"));
  }
  MESSAGE(prefixes << " prefixes of a " << bytes.size() << "-byte file refused");
  CHECK(id_of(bytes + "x") == "io.format");  // trailing bytes

  // Magic and version.
  std::string b = bytes;
  b[3] = 'X';
  CHECK(id_of(b) == "io.format");
  b = bytes;
  b[8] = char(kCompactModelVersion + 1);
  CHECK(id_of(b) == "io.version");
  CHECK(id_of(std::string("V3DGSCLM") + bytes.substr(8)) == "io.format");  // a full model's magic

  // The part sizes: a raw size beyond what the stream can hold, or a wrong one, is io.format; a
  // packed length beyond the file io.truncated.
  const std::size_t meta_raw = 12, meta_len = 20;
  b = bytes;
  b[meta_raw + 7] = char(0x40);  // raw size ~2^62
  CHECK(id_of(b) == "io.format");
  b = bytes;
  b[meta_raw] = char(b[meta_raw] + 1);
  CHECK(id_of(b) == "io.format");
  b = bytes;
  b[meta_len + 5] = char(0x01);
  CHECK(id_of(b) == "io.truncated");

  // Any flipped byte after the header: the zlib checks (Adler-32, stream structure) or the length
  // checks refuse it; never a crash, never another exception. The one exception is a flip confined to
  // the padding bits after a deflate stream's last code, which inflate skips: that file decodes to
  // exactly the original model.
  const auto original = read_compact_clip_model<double, 3, TinyField>(bytes, file);
  auto same_model = [&](const auto& x) {
    bool same = x.frg.mean == original.frg.mean && x.frg.sh == original.frg.sh && x.bkg.mean == original.bkg.mean &&
                x.bkg.rotation == original.bkg.rotation && x.bkg.opacity_logit == original.bkg.opacity_logit &&
                x.alpha_logit.size() == original.alpha_logit.size();
    for (std::size_t f = 0; same && f < x.alpha_logit.size(); ++f) same = x.alpha_logit[f].storage() == original.alpha_logit[f].storage();
    for (GaussianSet set : {GaussianSet::foreground, GaussianSet::background}) {
      auto a = const_cast<std::remove_cvref_t<decltype(x)>&>(x).field(set).segments();
      auto c = const_cast<std::remove_cvref_t<decltype(original)>&>(original).field(set).segments();
      for (std::size_t k = 0; same && k < a.size(); ++k) same = std::equal(a[k].value.begin(), a[k].value.end(), c[k].value.begin(), c[k].value.end());
    }
    return same;
  };
  std::size_t flips = 0, padding = 0;
  for (std::size_t i = 12; i < bytes.size(); i += 7, ++flips) {
    b = bytes;
    b[i] = char(b[i] ^ 0x5a);
    CAPTURE(i);
    const auto id = id_of(b);
    if (id == "<no error>") {
      ++padding;
      CHECK(same_model(read_compact_clip_model<double, 3, TinyField>(b, file)));
      continue;
    }
    CHECK_MESSAGE((id == "io.format" || id == "io.truncated"), id);
  }
  CHECK(padding <= 4);  // at most one per part (four parts)
  MESSAGE(flips << " corrupted files: " << flips - padding << " refused, " << padding << " decode to the original model");

  // Version 1 (no CRC after each part) is still read: the same file without the four CRCs.
  std::string v1 = bytes.substr(0, 12);
  v1[8] = char(1);
  for (std::size_t at = 12; at < bytes.size();) {
    std::uint64_t n = 0;
    std::memcpy(&n, bytes.data() + at + 8, 8);
    v1 += bytes.substr(at, 16 + std::size_t(n));
    at += 16 + std::size_t(n) + 4;
  }
  CHECK(v1.size() + 16 == bytes.size());
  CHECK(same_model(read_compact_clip_model<double, 3, TinyField>(v1, file)));
  // A part whose content disagrees with its CRC (the zlib stream itself intact) is refused.
  b = bytes;
  b[b.size() - 1] = char(b[b.size() - 1] ^ 1);  // the alpha part's CRC
  CHECK_THROWS_WITH_AS(((void)read_compact_clip_model<double, 3, TinyField>(b, file)), doctest::Contains("CRC-32"), io_error);
}
