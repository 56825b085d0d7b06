#pragma once
/// @file
/// Binary records of a `ClipModel` (versioned, bounds-checked, atomic on disk) and 3DGS PLY export.
///
///     io::write_file_atomic(path, ...)  via  save_clip_model(path, model)
///     auto m = load_clip_model<float>(path);                 // same template arguments as saved
///     export_ply(model, GaussianSet::foreground, frame, "frg.ply");   // deformed to that frame
///
/// Record (after the `V3DGSCLM` header, version 3): scalar size, SH degree, the foreground field's
/// parameter count; range; cameras; scene radius, flags (and the stop rule when it is not the
/// method's: `detail::put_flags`); both clouds; both field boxes, options and
/// parameters; the alpha logit maps. Version 2 adds each grid's table size and level count to its
/// options (HashGridOptions::log2_table_size, levels: the two fields may differ), version 3 its cells
/// cap per axis (HashGridOptions::max_cells of x, y, z, t); version-1 records (both fields the Field
/// type's default size) and version-2 records (no caps) are still read. A trainer checkpoint
/// (training/clip_trainer.hpp) embeds the same record.
/// Errors: `io.format` / `io.version` / `io.truncated` from the reader, `io.mismatch` when the file
/// was written with other template arguments (scalar type, SH degree, field layout).

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/io/binary_stream.hpp"
#include "video3dgs/io/ply.hpp"
#include "video3dgs/model/clip_model.hpp"

namespace video3dgs {

inline constexpr const char* kClipModelMagic = "V3DGSCLM";
inline constexpr std::uint32_t kClipModelVersion = 3;

namespace detail {

template <class Scalar, int D>
void put_cloud(io::BinaryWriter& w, const GaussianCloud<Scalar, D>& c) {
  w.put_vector(c.mean);
  w.put_vector(c.log_scale);
  w.put_vector(c.rotation);
  w.put_vector(c.opacity_logit);
  w.put_vector(c.sh);
}

template <class Scalar, int D>
void get_cloud(io::BinaryReader& r, GaussianCloud<Scalar, D>& c, const char* name) {
  const std::string n(name);
  c.mean = r.get_vector<Scalar>(n + ".mean");
  c.log_scale = r.get_vector<Scalar>(n + ".log_scale");
  c.rotation = r.get_vector<Scalar>(n + ".rotation");
  c.opacity_logit = r.get_vector<Scalar>(n + ".opacity_logit");
  c.sh = r.get_vector<Scalar>(n + ".sh");
  const std::size_t N = c.opacity_logit.size();
  if (c.mean.size() != 3 * N || c.log_scale.size() != 3 * N || c.rotation.size() != 4 * N ||
      c.sh.size() != std::size_t(3 * sh::coeff_count(D)) * N)
    throw io_error("io.format", r.file(), n + ": arrays disagree on the number of Gaussians");
}

/// `version` >= 2 adds the grid's log2_table_size and levels, >= 3 its max_cells of the 4 axes.
inline void put_deformation_options(io::BinaryWriter& w, const DeformationOptions& o, std::uint32_t version) {
  w.put<double>(o.grid.base_resolution);
  w.put<double>(o.grid.per_level_scale);
  w.put<std::int32_t>(static_cast<std::int32_t>(o.grid.interpolation));
  w.put<std::uint64_t>(o.grid.seed);
  w.put<double>(o.grid.init_range);
  w.put<std::int32_t>(static_cast<std::int32_t>(o.mode));
  w.put<double>(o.box_margin);
  w.put<std::uint8_t>(o.grid_input_gradient ? 1 : 0);
  w.put<double>(o.min_scale);
  if (version >= 2) {
    w.put<std::int32_t>(o.grid.log2_table_size);
    w.put<std::int32_t>(o.grid.levels);
  }
  if (version >= 3)
    for (int d = 0; d < 4; ++d) w.put<std::uint32_t>(o.grid.max_cells[std::size_t(d)]);
}

inline DeformationOptions get_deformation_options(io::BinaryReader& r, std::uint32_t version) {
  DeformationOptions o;
  o.grid.base_resolution = r.get<double>("deformation.base_resolution");
  o.grid.per_level_scale = r.get<double>("deformation.per_level_scale");
  o.grid.interpolation = static_cast<GridInterpolation>(r.get<std::int32_t>("deformation.interpolation"));
  o.grid.seed = r.get<std::uint64_t>("deformation.seed");
  o.grid.init_range = r.get<double>("deformation.init_range");
  o.mode = static_cast<DeformationMode>(r.get<std::int32_t>("deformation.mode"));
  o.box_margin = r.get<double>("deformation.box_margin");
  o.grid_input_gradient = r.get<std::uint8_t>("deformation.grid_input_gradient") != 0;
  o.min_scale = r.get<double>("deformation.min_scale");
  if (version >= 2) {
    o.grid.log2_table_size = r.get<std::int32_t>("deformation.log2_table_size");
    o.grid.levels = r.get<std::int32_t>("deformation.levels");
  }
  if (version >= 3)
    for (int d = 0; d < 4; ++d) o.grid.max_cells[std::size_t(d)] = r.get<std::uint32_t>("deformation.max_cells");
  return o;
}

template <class Field>
std::size_t field_param_count(Field& f) {
  std::size_t n = 0;
  for (const auto& s : f.segments()) n += s.value.size();
  return n;
}

/// The flags byte of a record and what follows it: bit 0 deformation_enabled, bit 1 static_background,
/// bit 2 a stop rule other than the method's (ClipModel::min_transmittance, blend_at_stop), then
/// stored as f64 min_transmittance and u8 blend_at_stop. Models with the method's rule give the bytes
/// of the records before the rule was stored; older readers refuse bit 2 (unknown flags).
template <class Scalar, int D, class Field>
void put_flags(io::BinaryWriter& w, const ClipModel<Scalar, D, Field>& m) {
  const bool rule = !m.reference_stop();
  w.put<std::uint8_t>(std::uint8_t((m.deformation_enabled ? 1 : 0) | (m.static_background ? 2 : 0) | (rule ? 4 : 0)));
  if (rule) {
    w.put<double>(double(m.min_transmittance));
    w.put<std::uint8_t>(m.blend_at_stop ? 1 : 0);
  }
}
/// Reads what `put_flags` wrote (`name`: the flags' field name in messages).
/// @throws io_error `io.format` on unknown flags or a stop outside (0, 1).
template <class Scalar, int D, class Field>
void get_flags(io::BinaryReader& r, ClipModel<Scalar, D, Field>& m, const std::string& name) {
  const auto flags = r.get<std::uint8_t>(name);
  if (flags > 7) throw io_error("io.format", r.file(), "unknown " + name + " " + std::to_string(int(flags)));
  m.deformation_enabled = (flags & 1) != 0;
  m.static_background = (flags & 2) != 0;
  m.min_transmittance = ClipModel<Scalar, D, Field>::kReferenceStop;
  m.blend_at_stop = false;
  if (flags & 4) {
    const double t = r.get<double>("min_transmittance");
    if (!(t > 0 && t < 1)) throw io_error("io.format", r.file(), "min_transmittance " + std::to_string(t) + " is not in (0, 1)");
    const auto b = r.get<std::uint8_t>("blend_at_stop");
    if (b > 1) throw io_error("io.format", r.file(), "blend_at_stop is " + std::to_string(int(b)) + ", not 0 or 1");
    m.min_transmittance = static_cast<Scalar>(t);
    m.blend_at_stop = b != 0;
  }
}

}  // namespace detail

/// Appends the model's record of `version` to `w` (the fields are read through `segments()`, hence
/// non-const). Version 1 (for readers that know no other) needs both grids at their default size,
/// version 2 grids without a cells cap.
/// @throws option_error `option.version` on another version, or an older one that cannot hold the grids.
template <class Scalar, int D, class Field>
void write_clip_model(io::BinaryWriter& w, ClipModel<Scalar, D, Field>& m, std::uint32_t version = kClipModelVersion) {
  if (version < 1 || version > kClipModelVersion)
    throw option_error("option.version", "clip model record", "version " + std::to_string(version) + " is not 1, 2 or 3");
  for (const Field* f : {m.frg_field.get(), m.bkg_field.get()}) {
    if (version < 2 && (f->options().grid.log2_table_size != 0 || f->options().grid.levels != 0))
      throw option_error("option.version", "clip model record", "version 1 cannot store a resized hash grid");
    if (version < 3 && f->options().grid.max_cells != decltype(f->options().grid.max_cells){})
      throw option_error("option.version", "clip model record", "versions 1-2 cannot store a hash grid's cells cap");
  }
  if (version < 3 && !m.reference_stop())
    throw option_error("option.version", "clip model record", "versions 1-2 cannot store a stop rule other than the method's");
  w.put<std::uint32_t>(sizeof(Scalar));
  w.put<std::int32_t>(D);
  w.put<std::uint64_t>(detail::field_param_count(*m.frg_field));
  w.put<std::int32_t>(m.range.first);
  w.put<std::int32_t>(m.range.last);
  w.put<std::uint64_t>(m.cameras.size());
  for (const auto& c : m.cameras) {
    w.put<std::int32_t>(c.width);
    w.put<std::int32_t>(c.height);
    for (Scalar v : {c.fx, c.fy, c.cx, c.cy}) w.put<Scalar>(v);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) w.put<Scalar>(c.R(i, j));
    for (int i = 0; i < 3; ++i) w.put<Scalar>(c.t(i));
  }
  w.put<Scalar>(m.scene_radius);
  w.put<std::uint8_t>(m.has_foreground ? 1 : 0);
  // One byte of flags: bit 0 deformation_enabled, bit 1 static_background, bit 2 a stop rule follows
  // (files without a static background and with the method's stop are byte-identical to those of
  // versions that knew only bit 0).
  detail::put_flags(w, m);
  detail::put_cloud(w, m.frg);
  detail::put_cloud(w, m.bkg);
  for (auto* box : {&m.frg_box_min, &m.frg_box_max, &m.bkg_box_min, &m.bkg_box_max})
    for (Scalar v : *box) w.put<Scalar>(v);
  for (Field* f : {m.frg_field.get(), m.bkg_field.get()}) {
    detail::put_deformation_options(w, f->options(), version);
    for (const auto& s : f->segments()) w.put_array(std::span<const Scalar>(s.value.data(), s.value.size()));
  }
  w.put<std::uint64_t>(m.alpha_logit.size());
  for (const auto& a : m.alpha_logit) w.put_vector(a.storage());
  w.put<std::uint64_t>(m.warnings.size());
  for (const auto& s : m.warnings) w.put_string(s);
}

/// Reads a record of `version` (1 to 3) written by `write_clip_model` with the same template arguments.
template <class Scalar, int D = 3, class Field = DefaultDeformationField<Scalar>>
[[nodiscard]] ClipModel<Scalar, D, Field> read_clip_model(io::BinaryReader& r, std::uint32_t version = kClipModelVersion) {
  using Model = ClipModel<Scalar, D, Field>;
  auto mismatch = [&](const std::string& what) { throw io_error("io.mismatch", r.file(), what); };
  if (r.get<std::uint32_t>("scalar_size") != sizeof(Scalar)) mismatch("written with another scalar type");
  if (r.get<std::int32_t>("sh_degree") != D) mismatch("written with another SH degree");
  const auto field_params = r.get<std::uint64_t>("field_params");
  Model m;
  m.range.first = r.get<std::int32_t>("range.first");
  m.range.last = r.get<std::int32_t>("range.last");
  if (m.range.first < 0 || m.range.last < m.range.first)
    throw io_error("io.format", r.file(), "bad frame range " + std::to_string(m.range.first) + "-" + std::to_string(m.range.last));
  const auto ncam = r.get<std::uint64_t>("cameras");
  if (ncam > r.remaining() / (8 + 16 * sizeof(Scalar))) throw io_error("io.truncated", r.file(), "camera count exceeds the file");
  if (std::int64_t(m.range.last) - m.range.first + 1 != static_cast<std::int64_t>(ncam))
    throw io_error("io.format", r.file(), "range and camera count disagree");
  for (std::uint64_t k = 0; k < ncam; ++k) {
    Camera<Scalar> c;
    c.width = r.get<std::int32_t>("camera.width");
    c.height = r.get<std::int32_t>("camera.height");
    c.fx = r.get<Scalar>("camera.fx");
    c.fy = r.get<Scalar>("camera.fy");
    c.cx = r.get<Scalar>("camera.cx");
    c.cy = r.get<Scalar>("camera.cy");
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) c.R(i, j) = r.get<Scalar>("camera.R");
    for (int i = 0; i < 3; ++i) c.t(i) = r.get<Scalar>("camera.t");
    try {
      c.validate(("camera " + std::to_string(k)).c_str());
    } catch (const option_error& e) {
      throw io_error("io.format", r.file(), e.what());
    }
    if (k > 0 && (c.width != m.cameras.front().width || c.height != m.cameras.front().height))
      throw io_error("io.format", r.file(), "camera " + std::to_string(k) + ": image size differs from camera 0's");
    m.cameras.push_back(c);
  }
  m.scene_radius = r.get<Scalar>("scene_radius");
  m.has_foreground = r.get<std::uint8_t>("has_foreground") != 0;
  detail::get_flags(r, m, "deformation flags");
  detail::get_cloud(r, m.frg, "frg");
  detail::get_cloud(r, m.bkg, "bkg");
  for (auto* box : {&m.frg_box_min, &m.frg_box_max, &m.bkg_box_min, &m.bkg_box_max})
    for (Scalar& v : *box) v = r.get<Scalar>("field.box");
  for (GaussianSet s : {GaussianSet::foreground, GaussianSet::background}) {
    const DeformationOptions o = detail::get_deformation_options(r, version);
    try {
      m.build_field(s, o);
    } catch (const option_error& e) {
      throw io_error("io.format", r.file(), std::string("deformation field: ") + e.what());
    }
    // Version 1: both fields have the header's count; version 2: the foreground's (each segment's size
    // is checked below).
    if ((version < 2 || s == GaussianSet::foreground) && detail::field_param_count(m.field(s)) != field_params)
      mismatch("written with another deformation field layout");
    for (const auto& seg : m.field(s).segments()) {
      const auto v = r.get_vector<Scalar>("field.params");
      if (v.size() != seg.value.size()) mismatch("deformation field segment sizes differ");
      std::copy(v.begin(), v.end(), seg.value.begin());
    }
  }
  const auto na = r.get<std::uint64_t>("alpha_maps");
  if (na != m.cameras.size()) throw io_error("io.format", r.file(), "alpha map count differs from the frame count");
  m.alpha_logit.resize(na);
  for (std::size_t f = 0; f < na; ++f) {
    auto v = r.get_vector<Scalar>("alpha_logit");
    if (v.size() != std::size_t(m.width()) * std::size_t(m.height())) throw io_error("io.format", r.file(), "alpha map size");
    m.alpha_logit[f].resize(m.width(), m.height());
    m.alpha_logit[f].storage() = std::move(v);
  }
  const auto nw = r.get<std::uint64_t>("warnings");
  for (std::uint64_t k = 0; k < nw; ++k) m.warnings.push_back(r.get_string("warning"));
  return m;
}

/// Reads a whole file into memory. @throws io_error `io.unreadable`.
inline std::string read_file_bytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw io_error("io.unreadable", path.string(), "cannot open file");
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw io_error("io.unreadable", path.string(), "read error");
  return ss.str();
}

/// Writes a model file (of `version`, see write_clip_model) atomically. @throws io_error `io.unwritable`.
template <class Scalar, int D, class Field>
void save_clip_model(const std::filesystem::path& path, ClipModel<Scalar, D, Field>& m, std::uint32_t version = kClipModelVersion) {
  io::BinaryWriter w(kClipModelMagic, version);
  write_clip_model(w, m, version);
  io::write_file_atomic(path, w.bytes());
}

/// Reads a model file written by `save_clip_model` with the same template arguments.
template <class Scalar, int D = 3, class Field = DefaultDeformationField<Scalar>>
[[nodiscard]] ClipModel<Scalar, D, Field> load_clip_model(const std::filesystem::path& path) {
  const std::string bytes = read_file_bytes(path);
  io::BinaryReader r(bytes, path.string(), kClipModelMagic, kClipModelVersion);
  auto m = read_clip_model<Scalar, D, Field>(r, r.version());
  r.expect_end();
  return m;
}

/// Writes one set deformed to clip frame i as a standard 3DGS PLY (atomic).
template <class Scalar, int D, class Field>
void export_ply(const ClipModel<Scalar, D, Field>& m, GaussianSet s, int i, const std::filesystem::path& path,
                ThreadPool* pool = nullptr) {
  if (i < 0 || i >= m.frame_count()) throw option_error("option.frame", "frame index " + std::to_string(i), "outside the clip");
  io::write_ply(path, m.deformed_cloud(s, i, pool));
}

}  // namespace video3dgs
