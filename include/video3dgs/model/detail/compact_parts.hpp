#pragma once
/// @file
/// The four parts of a compact model file (model/compact_io.hpp describes the layout and the error
/// bounds): writers return a part's uncompressed record, readers check it and fill the model.
/// Readers check every count against the bytes that hold it before allocating from it.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/gaussian/activations.hpp"
#include "video3dgs/io/binary_stream.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/model/clip_model_io.hpp"
#include "video3dgs/model/compact_options.hpp"
#include "video3dgs/model/detail/compact_codec.hpp"
#include "video3dgs/model/detail/vector_quantizer.hpp"
#include "video3dgs/model/render_clip.hpp"
#include "video3dgs/sh/basis.hpp"

namespace video3dgs::detail {

inline constexpr std::uint64_t kCompactFieldBlock = 4096;

/// Gaussians per set announced by the meta part (the Gaussian part must agree).
struct CompactCounts {
  std::uint64_t frg = 0, bkg = 0;
};

template <class Scalar>
void require_finite(std::span<const Scalar> v, const std::string& what) {
  for (std::size_t i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i])) throw numeric_error("numeric.non_finite", what + "[" + std::to_string(i) + "]", "cannot be quantised");
}

/// io.format naming the file.
[[noreturn]] inline void compact_bad(const io::BinaryReader& r, const std::string& why) { throw io_error("io.format", r.file(), why); }

// ---- meta ------------------------------------------------------------------------------------------

template <class Scalar, int D, class Field>
[[nodiscard]] std::string compact_meta(ClipModel<Scalar, D, Field>& m) {
  // Version 2: each field's options carry its table size and level count (clip_model_io.hpp), version
  // 3 also its cells cap per axis; the segment sizes are the foreground field's (the background's
  // follow from its options and are checked by the fields part).
  io::BinaryWriter w("ccm.meta", 3);
  w.put<std::int32_t>(D);
  const auto segments = m.frg_field->segments();
  w.put<std::uint64_t>(segments.size());
  for (const auto& s : segments) w.put<std::uint64_t>(s.value.size());
  w.put<std::int32_t>(m.range.first);
  w.put<std::int32_t>(m.range.last);
  w.put<std::uint64_t>(m.cameras.size());
  for (const auto& c : m.cameras) {
    w.put<std::int32_t>(c.width);
    w.put<std::int32_t>(c.height);
    for (Scalar v : {c.fx, c.fy, c.cx, c.cy}) w.put<double>(double(v));
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) w.put<double>(double(c.R(i, j)));
    for (int i = 0; i < 3; ++i) w.put<double>(double(c.t(i)));
  }
  w.put<double>(double(m.scene_radius));
  w.put<std::uint8_t>(m.has_foreground ? 1 : 0);
  put_flags(w, m);  // with the stop rule when it is not the method's (clip_model_io.hpp)
  for (auto* box : {&m.frg_box_min, &m.frg_box_max, &m.bkg_box_min, &m.bkg_box_max})
    for (Scalar v : *box) w.put<double>(double(v));
  put_deformation_options(w, m.frg_field->options(), 3);
  put_deformation_options(w, m.bkg_field->options(), 3);
  w.put<std::uint64_t>(m.frg.size());
  w.put<std::uint64_t>(m.bkg.size());
  w.put<std::uint64_t>(m.warnings.size());
  for (const auto& s : m.warnings) w.put_string(s);
  return w.bytes();
}

template <class Scalar, int D, class Field>
CompactCounts read_compact_meta(ClipModel<Scalar, D, Field>& m, std::string_view bytes, const std::string& file) {
  io::BinaryReader r(bytes, file, "ccm.meta", 3);
  if (r.get<std::int32_t>("sh_degree") != D) throw io_error("io.mismatch", file, "written with another SH degree");
  const auto nseg = r.get<std::uint64_t>("field_segments");
  if (nseg > r.remaining() / 8) throw io_error("io.truncated", file, "field segment count exceeds the meta part");
  std::vector<std::uint64_t> seg_sizes(static_cast<std::size_t>(nseg));
  for (auto& s : seg_sizes) s = r.get<std::uint64_t>("field_segment_size");
  m.range.first = r.get<std::int32_t>("range.first");
  m.range.last = r.get<std::int32_t>("range.last");
  if (m.range.first < 0 || m.range.last < m.range.first)
    compact_bad(r, "bad frame range " + std::to_string(m.range.first) + "-" + std::to_string(m.range.last));
  const auto ncam = r.get<std::uint64_t>("cameras");
  if (ncam > r.remaining() / (8 + 16 * 8)) throw io_error("io.truncated", file, "camera count exceeds the meta part");
  if (std::int64_t(m.range.last) - m.range.first + 1 != static_cast<std::int64_t>(ncam)) compact_bad(r, "range and camera count disagree");
  for (std::uint64_t k = 0; k < ncam; ++k) {
    Camera<Scalar> c;
    c.width = r.get<std::int32_t>("camera.width");
    c.height = r.get<std::int32_t>("camera.height");
    for (Scalar* v : {&c.fx, &c.fy, &c.cx, &c.cy}) *v = Scalar(r.get<double>("camera.intrinsics"));
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) c.R(i, j) = Scalar(r.get<double>("camera.R"));
    for (int i = 0; i < 3; ++i) c.t(i) = Scalar(r.get<double>("camera.t"));
    try {
      c.validate(("camera " + std::to_string(k)).c_str());
    } catch (const option_error& e) {
      compact_bad(r, e.what());
    }
    if (k > 0 && (c.width != m.cameras.front().width || c.height != m.cameras.front().height))
      compact_bad(r, "camera " + std::to_string(k) + ": image size differs from camera 0's");
    m.cameras.push_back(c);
  }
  m.scene_radius = Scalar(r.get<double>("scene_radius"));
  m.has_foreground = r.get<std::uint8_t>("has_foreground") != 0;
  get_flags(r, m, "flags");
  for (auto* box : {&m.frg_box_min, &m.frg_box_max, &m.bkg_box_min, &m.bkg_box_max})
    for (Scalar& v : *box) v = Scalar(r.get<double>("field.box"));
  for (GaussianSet s : {GaussianSet::foreground, GaussianSet::background}) {
    const DeformationOptions o = get_deformation_options(r, r.version());
    try {
      m.build_field(s, o);
    } catch (const error& e) {
      compact_bad(r, std::string("deformation field: ") + e.what());
    }
    const auto segments = m.field(s).segments();
    bool same = segments.size() == seg_sizes.size();
    const bool sized = r.version() < 2 || s == GaussianSet::foreground;
    for (std::size_t k = 0; same && sized && k < segments.size(); ++k) same = segments[k].value.size() == seg_sizes[k];
    if (!same) throw io_error("io.mismatch", file, "written with another deformation field layout");
  }
  CompactCounts n;
  n.frg = r.get<std::uint64_t>("frg.count");
  n.bkg = r.get<std::uint64_t>("bkg.count");
  const auto nw = r.get<std::uint64_t>("warnings");
  for (std::uint64_t k = 0; k < nw; ++k) m.warnings.push_back(r.get_string("warning"));
  r.expect_end();
  return n;
}

// ---- Gaussians -------------------------------------------------------------------------------------

/// k uniform codes per item (value j of item i at v[k i + j]), each over its own [min, max]: the codes
/// (plane j at q[j n + i]) and their ranges.
struct QuantisedPlanes {
  std::vector<UniformCode> codes;
  std::vector<std::uint32_t> q;
};
template <class Scalar>
[[nodiscard]] QuantisedPlanes quantise_planes(std::span<const Scalar> v, std::size_t k, int bits) {
  const std::size_t n = v.size() / k;
  QuantisedPlanes p;
  p.q.resize(v.size());
  for (std::size_t j = 0; j < k; ++j) {
    double mn = 0, mx = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const double x = double(v[k * i + j]);
      mn = i == 0 ? x : std::min(mn, x);
      mx = i == 0 ? x : std::max(mx, x);
    }
    p.codes.push_back(UniformCode::fit(mn, mx, bits));
    for (std::size_t i = 0; i < n; ++i) p.q[j * n + i] = p.codes[j].encode(double(v[k * i + j]));
  }
  return p;
}

/// k x (lo, step) f64, i32 bits, then the codes' byte planes (item-major inside each of the k planes);
/// `delta`: each plane delta-coded first (`delta_codes`).
inline void put_planes(io::BinaryWriter& w, QuantisedPlanes p, int bits, bool delta = false) {
  const std::size_t k = p.codes.size(), n = k ? p.q.size() / k : 0;
  for (const UniformCode& c : p.codes) {
    w.put<double>(c.lo);
    w.put<double>(c.step);
  }
  if (delta)
    for (std::size_t j = 0; j < k; ++j) delta_codes(std::span<std::uint32_t>(p.q).subspan(j * n, n), bits);
  w.put<std::int32_t>(bits);
  w.put_vector(to_planes(p.q, bits / 8));
}

template <class Scalar>
void put_uniform_planes(io::BinaryWriter& w, std::span<const Scalar> v, std::size_t k, int bits) {
  put_planes(w, quantise_planes<Scalar>(v, k, bits), bits);
}

/// What `put_planes` wrote, checked; `decode` writes the values.
struct UniformPlanes {
  std::vector<UniformCode> codes;
  int bytes = 1;
  std::vector<std::uint8_t> planes;
  bool delta = false;

  static UniformPlanes read(io::BinaryReader& r, std::size_t k, const std::string& what, bool delta = false) {
    UniformPlanes p;
    p.delta = delta;
    for (std::size_t j = 0; j < k; ++j) {
      UniformCode c;
      c.lo = r.get<double>(what + ".lo");
      c.step = r.get<double>(what + ".step");
      if (!std::isfinite(c.lo) || !std::isfinite(c.step) || c.step < 0) compact_bad(r, what + ": bad code range");
      p.codes.push_back(c);
    }
    const auto bits = r.get<std::int32_t>(what + ".bits");
    if (bits != 8 && bits != 16 && bits != 24) compact_bad(r, what + ": " + std::to_string(bits) + " bits per code (8, 16 or 24)");
    for (auto& c : p.codes) c.bits = bits;
    p.bytes = bits / 8;
    p.planes = r.get_vector<std::uint8_t>(what);
    return p;
  }
  [[nodiscard]] bool holds(std::size_t n) const noexcept { return planes.size() == n * codes.size() * std::size_t(bytes); }
  template <class Scalar>
  void decode(std::span<Scalar> v) const {
    const std::size_t k = codes.size(), n = v.size() / k;
    std::vector<std::uint32_t> q(n);
    for (std::size_t j = 0; j < k; ++j) {
      for (std::size_t i = 0; i < n; ++i) q[i] = from_planes(planes, n * k, j * n + i, bytes);
      if (delta) undelta_codes(q, 8 * bytes);
      for (std::size_t i = 0; i < n; ++i) v[k * i + j] = Scalar(codes[j].decode(q[i]));
    }
  }
};

/// Gaussian i of `c` moved to place k where order[k] = i.
template <class Scalar, int D>
[[nodiscard]] GaussianCloud<Scalar, D> permuted(const GaussianCloud<Scalar, D>& c, std::span<const std::uint32_t> order) {
  GaussianCloud<Scalar, D> out(order.size());
  for (std::size_t k = 0; k < order.size(); ++k) out.set(k, c.get(order[k]));
  return out;
}

/// The order in which a set of Gaussians is stored (part version 3: Morton order of the position codes
/// of `bits` bits; see compact_codec.hpp): a loaded set's Gaussian k is the saved set's order[k].
template <class Scalar, int D>
[[nodiscard]] std::vector<std::uint32_t> compact_order(const GaussianCloud<Scalar, D>& c, int bits) {
  return morton_order(quantise_planes<Scalar>(c.mean, 3, bits).q, c.size(), bits);
}

template <class Scalar, int D>
void put_compact_cloud(io::BinaryWriter& w, const GaussianCloud<Scalar, D>& original, const CompactOptions& o, const std::string& name,
                       const std::vector<Camera<Scalar>>& cameras, ThreadPool* pool) {
  const std::size_t n = original.size();
  w.put<std::uint64_t>(n);
  if (n == 0) return;
  require_finite<Scalar>(original.mean, name + ".mean");
  require_finite<Scalar>(original.log_scale, name + ".log_scale");
  require_finite<Scalar>(original.rotation, name + ".rotation");
  require_finite<Scalar>(original.opacity_logit, name + ".opacity_logit");
  require_finite<Scalar>(original.sh, name + ".sh");
  // Stored in Morton order of the position codes, positions as differences (the codes of a
  // permuted set are the permuted codes: the ranges are the same).
  const int position_bits = name == "frg" ? o.frg_position_bits : o.position_bits;
  const GaussianCloud<Scalar, D> c = permuted(original, compact_order(original, position_bits));
  put_planes(w, quantise_planes<Scalar>(c.mean, 3, position_bits), position_bits, true);
  put_uniform_planes<Scalar>(w, c.log_scale, 3, o.scale_bits);
  std::vector<std::uint32_t> rot(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Scalar* q = c.rotation.data() + 4 * i;
    rot[i] = encode_rotation({double(q[0]), double(q[1]), double(q[2]), double(q[3])});
  }
  w.put_vector(to_planes(rot, 4));
  std::vector<std::uint8_t> opacity(n);
  for (std::size_t i = 0; i < n; ++i) opacity[i] = encode_unit(sigmoid(double(c.opacity_logit[i])));
  w.put_vector(opacity);
  constexpr std::size_t B = std::size_t(sh::coeff_count(D)), R = 3 * (B - 1);
  std::vector<double> dc(3 * n);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t ch = 0; ch < 3; ++ch) dc[3 * i + ch] = double(c.sh[3 * B * i + ch]);
  if constexpr (R > 0) {
    std::vector<float> rest(n * R);
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = 0; j < R; ++j) rest[R * i + j] = float(c.sh[3 * B * i + 3 + j]);
    const VectorCodebook cb = fit_vector_codebook(rest, n, int(R), {o.sh_codebook, o.kmeans_iterations, o.kmeans_sample}, pool);
    // DC error feedback (compact_io.hpp): the rest bands' error at the clip's view directions of the
    // (canonical) Gaussian, averaged over the frames, moves into the DC, which renders at any direction.
    std::vector<Eigen::Vector3d> centres;
    for (const auto& cam : cameras) centres.push_back(cam.center().template cast<double>());
    if (!centres.empty())
      parallel_for(pool, n, [&](std::size_t i) {
        const float* code = cb.codewords.data() + std::size_t(cb.index[i]) * R;
        const Eigen::Vector3d mu(double(c.mean[3 * i]), double(c.mean[3 * i + 1]), double(c.mean[3 * i + 2]));
        double err[3] = {0, 0, 0};
        for (const auto& centre : centres) {
          double inv = 0;
          const Eigen::Vector3d dir = sh::view_direction<double>(mu, centre, inv);
          double basis[16];
          sh::basis<double>(D, dir.x(), dir.y(), dir.z(), basis);
          for (std::size_t k = 1; k < B; ++k)
            for (std::size_t ch = 0; ch < 3; ++ch) err[ch] += basis[k] * (double(code[3 * (k - 1) + ch]) - double(rest[R * i + 3 * (k - 1) + ch]));
        }
        for (std::size_t ch = 0; ch < 3; ++ch) dc[3 * i + ch] -= err[ch] / double(centres.size()) / sh::kC0;
      }, 1024);
    put_uniform_planes<double>(w, dc, 3, o.dc_bits);
    w.put<std::uint32_t>(std::uint32_t(cb.size()));
    std::vector<std::uint16_t> halves(cb.codewords.size());
    for (std::size_t k = 0; k < halves.size(); ++k) halves[k] = float_to_half(cb.codewords[k]);
    w.put_vector(halves);
    w.put_vector(to_planes(cb.index, cb.size() <= 256 ? 1 : 2));
  } else {
    put_uniform_planes<double>(w, dc, 3, o.dc_bits);
  }
}

template <class Scalar, int D>
void read_compact_cloud(io::BinaryReader& r, GaussianCloud<Scalar, D>& c, std::uint64_t expected, const std::string& name) {
  const auto n64 = r.get<std::uint64_t>(name + ".count");
  if (n64 != expected) compact_bad(r, name + ": " + std::to_string(n64) + " Gaussians, the meta part says " + std::to_string(expected));
  if (n64 == 0) return;
  // Version 3: Morton order, positions delta-coded, rotations in byte planes (compact_codec.hpp).
  const bool v3 = r.version() >= 3;
  const auto mean = UniformPlanes::read(r, 3, name + ".mean", v3);
  const auto scale = UniformPlanes::read(r, 3, name + ".log_scale");
  std::vector<std::uint32_t> rot;
  if (v3) {
    const auto planes = r.get_vector<std::uint8_t>(name + ".rotation");
    if (planes.size() % 4 != 0) compact_bad(r, name + ".rotation: " + std::to_string(planes.size()) + " bytes, not 4 per Gaussian");
    rot.resize(planes.size() / 4);
    for (std::size_t i = 0; i < rot.size(); ++i) rot[i] = from_planes(planes, rot.size(), i, 4);
  } else {
    rot = r.get_vector<std::uint32_t>(name + ".rotation");
  }
  // The rotation codes bound n by the bytes that hold them: every later size check is against n.
  const std::size_t n = rot.size();
  auto size_bad = [&](const char* what) { compact_bad(r, name + "." + what + ": size disagrees with the Gaussian count"); };
  if (n64 != n) size_bad("rotation");
  if (!mean.holds(n)) size_bad("mean");
  if (!scale.holds(n)) size_bad("log_scale");
  const auto opacity = r.get_vector<std::uint8_t>(name + ".opacity");
  if (opacity.size() != n) size_bad("opacity");
  const auto dc = UniformPlanes::read(r, 3, name + ".sh_dc");
  if (!dc.holds(n)) size_bad("sh_dc");
  constexpr std::size_t B = std::size_t(sh::coeff_count(D)), R = 3 * (B - 1);
  std::vector<std::uint16_t> halves;
  std::vector<std::uint8_t> index;
  std::size_t K = 0;
  if constexpr (R > 0) {
    K = r.get<std::uint32_t>(name + ".codebook_size");
    if (K < 1 || K > 65536) compact_bad(r, name + ": codebook of " + std::to_string(K) + " vectors (1..65536)");
    halves = r.get_vector<std::uint16_t>(name + ".codebook");
    if (halves.size() != K * R) size_bad("codebook");
    index = r.get_vector<std::uint8_t>(name + ".sh_index");
    if (index.size() != n * (K <= 256 ? 1 : 2)) size_bad("sh_index");
  }
  c.resize(n);
  mean.decode<Scalar>(c.mean);
  scale.decode<Scalar>(c.log_scale);
  for (std::size_t i = 0; i < n; ++i) {
    const auto q = r.version() >= 2 ? decode_rotation(rot[i]) : decode_rotation_v1(rot[i]);
    for (int k = 0; k < 4; ++k) c.rotation[4 * i + std::size_t(k)] = Scalar(q[std::size_t(k)]);
    c.opacity_logit[i] = Scalar(unit_logit(double(opacity[i]) / 255.0));
  }
  std::vector<Scalar> dcv(3 * n);
  dc.decode<Scalar>(dcv);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t ch = 0; ch < 3; ++ch) c.sh[3 * B * i + ch] = dcv[3 * i + ch];
  if constexpr (R > 0) {
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t k = from_planes(index, n, i, K <= 256 ? 1 : 2);
      if (k >= K) compact_bad(r, name + ".sh_index: codeword " + std::to_string(k) + " of " + std::to_string(K));
      for (std::size_t j = 0; j < R; ++j) c.sh[3 * B * i + 3 + j] = Scalar(half_to_float(halves[R * k + j]));
    }
  }
}

template <class Scalar, int D, class Field>
[[nodiscard]] std::string compact_gaussians(ClipModel<Scalar, D, Field>& m, const CompactOptions& o, ThreadPool* pool) {
  io::BinaryWriter w("ccm.gaus", kCompactGaussiansVersion);
  put_compact_cloud(w, m.frg, o, "frg", m.cameras, pool);
  put_compact_cloud(w, m.bkg, o, "bkg", m.cameras, pool);
  return w.bytes();
}

template <class Scalar, int D, class Field>
void read_compact_gaussians(ClipModel<Scalar, D, Field>& m, std::string_view bytes, const std::string& file, const CompactCounts& n) {
  io::BinaryReader r(bytes, file, "ccm.gaus", kCompactGaussiansVersion);
  read_compact_cloud(r, m.frg, n.frg, "frg");
  read_compact_cloud(r, m.bkg, n.bkg, "bkg");
  r.expect_end();
}

// ---- fields ----------------------------------------------------------------------------------------

template <class Scalar, int D, class Field>
[[nodiscard]] std::string compact_fields(ClipModel<Scalar, D, Field>& m, const CompactOptions& o) {
  io::BinaryWriter w("ccm.flds", 1);
  const std::int32_t qmax = (std::int32_t(1) << (o.field_bits - 1)) - 1;
  for (GaussianSet s : {GaussianSet::foreground, GaussianSet::background}) {
    const auto segments = m.field(s).segments();
    for (std::size_t k = 0; k < segments.size(); ++k) {
      const std::span<const Scalar> v(segments[k].value.data(), segments[k].value.size());
      const std::string name = std::string(to_string(s)) + "_field.segment" + std::to_string(k);
      require_finite<Scalar>(v, name);
      if (k > 0) {
        std::vector<float> f(v.size());
        for (std::size_t i = 0; i < v.size(); ++i) f[i] = float(v[i]);
        w.put_vector(f);
        continue;
      }
      const std::size_t blocks = (v.size() + kCompactFieldBlock - 1) / kCompactFieldBlock;
      std::vector<float> scales(blocks);
      std::vector<std::uint32_t> q(v.size());
      for (std::size_t b = 0; b < blocks; ++b) {
        const std::size_t lo = b * kCompactFieldBlock, hi = std::min(v.size(), lo + kCompactFieldBlock);
        double mx = 0;
        for (std::size_t i = lo; i < hi; ++i) mx = std::max(mx, std::fabs(double(v[i])));
        scales[b] = float(mx / qmax);
        const double sc = double(scales[b]);
        for (std::size_t i = lo; i < hi; ++i) {
          const double t = sc > 0 ? std::round(double(v[i]) / sc) : 0.0;
          q[i] = zigzag(std::int32_t(std::clamp(t, double(-qmax), double(qmax))));
        }
      }
      w.put<std::int32_t>(o.field_bits);
      w.put<std::uint64_t>(kCompactFieldBlock);
      w.put_vector(scales);
      w.put_vector(to_planes(q, o.field_bits > 8 ? 2 : 1));
    }
  }
  return w.bytes();
}

template <class Scalar, int D, class Field>
void read_compact_fields(ClipModel<Scalar, D, Field>& m, std::string_view bytes, const std::string& file) {
  io::BinaryReader r(bytes, file, "ccm.flds", 1);
  for (GaussianSet s : {GaussianSet::foreground, GaussianSet::background}) {
    const auto segments = m.field(s).segments();
    for (std::size_t k = 0; k < segments.size(); ++k) {
      const std::span<Scalar> v = segments[k].value;
      const std::string name = std::string(to_string(s)) + "_field.segment" + std::to_string(k);
      if (k > 0) {
        const auto f = r.get_vector<float>(name);
        if (f.size() != v.size()) compact_bad(r, name + ": " + std::to_string(f.size()) + " values, the field has " + std::to_string(v.size()));
        for (std::size_t i = 0; i < v.size(); ++i) v[i] = Scalar(f[i]);
        continue;
      }
      const auto bits = r.get<std::int32_t>(name + ".bits");
      if (!(bits >= 2 && bits <= 8) && bits != 16) compact_bad(r, name + ": " + std::to_string(bits) + " bits per code (2..8 or 16)");
      const auto block = r.get<std::uint64_t>(name + ".block");
      if (block < 1 || block > (std::uint64_t(1) << 32)) compact_bad(r, name + ": bad block size " + std::to_string(block));
      const auto scales = r.get_vector<float>(name + ".scales");
      const auto planes = r.get_vector<std::uint8_t>(name + ".codes");
      const std::size_t bytes_per = bits > 8 ? 2 : 1;
      const std::uint32_t qmax = (std::uint32_t(1) << (bits - 1)) - 1;
      if (scales.size() != (v.size() + block - 1) / block || planes.size() != v.size() * bytes_per)
        compact_bad(r, name + ": size disagrees with the field's table");
      for (float sc : scales)
        if (!std::isfinite(sc) || sc < 0) compact_bad(r, name + ": bad block scale");
      for (std::size_t i = 0; i < v.size(); ++i) {
        const std::uint32_t z = from_planes(planes, v.size(), i, int(bytes_per));
        if (z > 2 * qmax) compact_bad(r, name + ": code " + std::to_string(z) + " out of range for " + std::to_string(bits) + " bits");
        v[i] = Scalar(double(unzigzag(z)) * double(scales[i / block]));
      }
    }
  }
  r.expect_end();
}

// ---- alpha maps ------------------------------------------------------------------------------------

template <class Scalar, int D, class Field>
[[nodiscard]] std::string compact_alpha(const ClipModel<Scalar, D, Field>& m, const CompactOptions& o, ThreadPool* pool) {
  const std::size_t d = std::size_t(o.alpha_downscale), W = std::size_t(m.width()), H = std::size_t(m.height());
  const std::size_t w = (W + d - 1) / d, h = (H + d - 1) / d;
  for (std::size_t f = 0; f < m.alpha_logit.size(); ++f) {
    const auto& a = m.alpha_logit[f].storage();
    require_finite<Scalar>(std::span<const Scalar>(a), "alpha_logit[" + std::to_string(f) + "]");
  }
  std::vector<std::uint8_t> codes(m.alpha_logit.size() * w * h);
  if (o.alpha_tolerance > 0 && d == 1 && m.has_foreground) {
    // Codes chosen for deflate within the merge's tolerance (see the file comment of compact_io.hpp):
    // at pixel p, I = A I_f + (1 - A) I_b moves by |A' - A| Delta_p, Delta_p = max_c |I_f - I_b|, so any
    // code in [A - tau / Delta_p, A + tau / Delta_p] (and always the nearest one) keeps |I' - I| <= max(tau,
    // Delta_p / 510); the one closest to the left neighbour's code (the row's first: the code above)
    // makes the Sub-filtered stream mostly zeros. Sequential over frames: renders use the pool.
    ClipRenderBuffers<Scalar, Field> buf;
    for (std::size_t f = 0; f < m.alpha_logit.size(); ++f) {
      render_clip_frame(m, int(f), buf, pool);
      const auto& a = m.alpha_logit[f];
      std::uint8_t* out = codes.data() + f * w * h;
      for (std::size_t y = 0; y < H; ++y)
        for (std::size_t x = 0; x < W; ++x) {
          const double A = sigmoid(double(a(int(x), int(y))));
          const std::uint8_t nearest = encode_unit(A);
          double delta = 0;
          for (int c = 0; c < 3; ++c)
            delta = std::max(delta, std::abs(double(buf.frg.image(int(x), int(y), c)) - double(buf.bkg.image(int(x), int(y), c))));
          const double reach = delta > 0 ? o.alpha_tolerance / delta : 2.0;
          const int lo = int(std::ceil(255.0 * std::max(0.0, A - reach))), hi = int(std::floor(255.0 * std::min(1.0, A + reach)));
          const int want = x > 0 ? out[y * w + x - 1] : y > 0 ? out[(y - 1) * w] : nearest;
          out[y * w + x] = lo > hi ? nearest : std::uint8_t(std::clamp(want, std::min<int>(lo, nearest), std::max<int>(hi, nearest)));
        }
      sub_filter(std::span<std::uint8_t>(out, w * h), w);
    }
  } else {
    parallel_for(pool, m.alpha_logit.size(), [&](std::size_t f) {
      const auto& a = m.alpha_logit[f];
      std::uint8_t* out = codes.data() + f * w * h;
      for (std::size_t Y = 0; Y < h; ++Y)
        for (std::size_t X = 0; X < w; ++X) {
          double sum = 0;
          std::size_t cnt = 0;
          for (std::size_t y = Y * d; y < std::min(H, Y * d + d); ++y)
            for (std::size_t x = X * d; x < std::min(W, X * d + d); ++x, ++cnt) sum += sigmoid(double(a(int(x), int(y))));
          out[Y * w + X] = encode_unit(sum / double(cnt));
        }
      sub_filter(std::span<std::uint8_t>(out, w * h), w);
    }, 1);
  }
  io::BinaryWriter wr("ccm.alph", 1);
  wr.put<std::int32_t>(o.alpha_downscale);
  wr.put<std::uint64_t>(m.alpha_logit.size());
  wr.put_vector(codes);
  return wr.bytes();
}

template <class Scalar, int D, class Field>
void read_compact_alpha(ClipModel<Scalar, D, Field>& m, std::string_view bytes, const std::string& file) {
  io::BinaryReader r(bytes, file, "ccm.alph", 1);
  const auto ds = r.get<std::int32_t>("alpha.downscale");
  if (ds < 1 || ds > kMaxAlphaDownscale) compact_bad(r, "alpha downscale " + std::to_string(ds) + " (1..16)");
  if (r.get<std::uint64_t>("alpha.frames") != m.cameras.size()) compact_bad(r, "alpha map count differs from the frame count");
  auto codes = r.get_vector<std::uint8_t>("alpha.maps");
  r.expect_end();
  const std::size_t d = std::size_t(ds), W = std::size_t(m.width()), H = std::size_t(m.height());
  const std::size_t w = (W + d - 1) / d, h = (H + d - 1) / d;
  if (codes.size() != m.cameras.size() * w * h) compact_bad(r, "alpha maps: size disagrees with the frames' size");
  m.alpha_logit.resize(m.cameras.size());
  for (std::size_t f = 0; f < m.cameras.size(); ++f) {
    std::uint8_t* in = codes.data() + f * w * h;
    sub_unfilter(std::span<std::uint8_t>(in, w * h), w);
    auto& a = m.alpha_logit[f];
    a.resize(int(W), int(H));
    for (std::size_t y = 0; y < H; ++y)
      for (std::size_t x = 0; x < W; ++x) {
        if (d == 1) {
          a(int(x), int(y)) = Scalar(unit_logit(double(in[y * w + x]) / 255.0));
          continue;
        }
        // Bilinear between stored pixel centres: source coordinate (x + 1/2) / d - 1/2, clamped.
        const double u = std::clamp((double(x) + 0.5) / double(d) - 0.5, 0.0, double(w - 1));
        const double v = std::clamp((double(y) + 0.5) / double(d) - 0.5, 0.0, double(h - 1));
        const std::size_t x0 = std::size_t(u), y0 = std::size_t(v);
        const std::size_t x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
        const double fx = u - double(x0), fy = v - double(y0);
        const double top = (1 - fx) * in[y0 * w + x0] + fx * in[y0 * w + x1];
        const double bottom = (1 - fx) * in[y1 * w + x0] + fx * in[y1 * w + x1];
        a(int(x), int(y)) = Scalar(unit_logit(((1 - fy) * top + fy * bottom) / 255.0));
      }
  }
}

}  // namespace video3dgs::detail
