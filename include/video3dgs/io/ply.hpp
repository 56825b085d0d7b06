#pragma once
/// @file
/// PLY I/O of Gaussian clouds in the standard 3DGS layout (readable by common 3DGS viewers):
///
///     element vertex N
///     property float x, y, z, nx, ny, nz            (normals written as 0)
///     property float f_dc_0 .. f_dc_2               SH band 0 per channel
///     property float f_rest_0 .. f_rest_{3(K-1)-1}  SH bands >= 1, channel-major: f_rest[c (K-1) + k - 1]
///     property float opacity                        logit opacity
///     property float scale_0 .. scale_2             log scale
///     property float rot_0 .. rot_3                 quaternion (w, x, y, z), unnormalised
///
/// Writing: binary little-endian float32, atomically (temp file + rename). Reading: ascii,
/// binary_little_endian and binary_big_endian; any scalar property type; properties in any order;
/// other properties ignored; other elements skipped when their size is known. The SH degree (0..3) is
/// deduced from the number of f_rest_* properties (0, 9, 24, 45).
///
/// Errors (`io_error`): `io.unreadable` (cannot open), `io.format` (bad header, unknown format or
/// type, f_rest count that is no SH degree, bad ascii value), `io.missing_property` (a required
/// property is absent; names it), `io.truncated` (fewer bytes or values than the header promises),
/// `io.unsupported` (a list property in an element that precedes the vertices in a binary file).

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/gaussian/cloud.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/sh/basis.hpp"

namespace video3dgs::io {

/// A cloud read from a PLY file, with the SH degree found in the file (runtime).
template <class Scalar>
struct PlyCloud {
  std::size_t count = 0;
  int sh_degree = 0;
  std::vector<Scalar> mean, log_scale, rotation, opacity_logit, sh;  ///< layouts as in GaussianCloud

  [[nodiscard]] GaussianParams<Scalar> params() const noexcept {
    return {count, sh_degree, mean, log_scale, rotation, opacity_logit, sh};
  }
  /// Converts to a cloud of compile-time degree D: missing bands are zero, bands above D are dropped.
  template <int D>
  [[nodiscard]] GaussianCloud<Scalar, D> to_cloud() const {
    GaussianCloud<Scalar, D> c(count);
    c.mean = mean, c.log_scale = log_scale, c.rotation = rotation, c.opacity_logit = opacity_logit;
    const int Kf = sh::coeff_count(sh_degree), Kd = sh::coeff_count(D), Kc = std::min(Kf, Kd);
    for (std::size_t i = 0; i < count; ++i)
      for (int k = 0; k < Kc; ++k)
        for (int ch = 0; ch < 3; ++ch) c.sh[(i * Kd + k) * 3 + ch] = sh[(i * Kf + k) * 3 + ch];
    return c;
  }
};

namespace detail {

enum class PlyFormat { ascii, binary_le, binary_be };

struct PlyProperty {
  std::string name;
  std::string type;       ///< scalar type (or the item type of a list)
  std::string count_type; ///< non-empty for list properties
  int size = 0;           ///< bytes of the scalar type
};
struct PlyElement {
  std::string name;
  std::size_t count = 0;
  std::vector<PlyProperty> props;
};
struct PlyHeader {
  PlyFormat format = PlyFormat::ascii;
  std::vector<PlyElement> elements;
  std::size_t body_offset = 0;
};

inline int ply_type_size(const std::string& t) {
  if (t == "char" || t == "uchar" || t == "int8" || t == "uint8") return 1;
  if (t == "short" || t == "ushort" || t == "int16" || t == "uint16") return 2;
  if (t == "int" || t == "uint" || t == "float" || t == "int32" || t == "uint32" || t == "float32") return 4;
  if (t == "double" || t == "float64") return 8;
  return 0;
}

inline PlyHeader parse_ply_header(std::string_view bytes, const std::string& where) {
  auto malformed = [&](const std::string& why) { throw io_error("io.format", where, why); };
  PlyHeader h;
  std::size_t pos = 0;
  auto next_line = [&](std::string& line) {
    const std::size_t nl = bytes.find('\n', pos);
    if (nl == std::string_view::npos) throw io_error("io.truncated", where, "header ends before end_header");
    line.assign(bytes.substr(pos, nl - pos));
    if (!line.empty() && line.back() == '\r') line.pop_back();
    pos = nl + 1;
  };
  std::string line;
  next_line(line);
  if (line != "ply") malformed("not a PLY file (first line is not 'ply')");
  bool have_format = false;
  for (;;) {
    next_line(line);
    std::istringstream ss(line);
    std::string kw;
    ss >> kw;
    if (kw.empty() || kw == "comment" || kw == "obj_info") continue;
    if (kw == "end_header") break;
    if (kw == "format") {
      std::string f, v;
      ss >> f >> v;
      if (f == "ascii") h.format = PlyFormat::ascii;
      else if (f == "binary_little_endian") h.format = PlyFormat::binary_le;
      else if (f == "binary_big_endian") h.format = PlyFormat::binary_be;
      else malformed("unknown format '" + f + "'");
      have_format = true;
    } else if (kw == "element") {
      PlyElement e;
      long long n = -1;
      ss >> e.name >> n;
      if (e.name.empty() || n < 0 || ss.fail()) malformed("bad element line '" + line + "'");
      e.count = static_cast<std::size_t>(n);
      h.elements.push_back(e);
    } else if (kw == "property") {
      if (h.elements.empty()) malformed("property before any element");
      PlyProperty p;
      std::string t;
      ss >> t;
      if (t == "list") {
        ss >> p.count_type >> p.type >> p.name;
        if (ply_type_size(p.count_type) == 0) malformed("unknown list count type in '" + line + "'");
      } else {
        p.type = t;
        ss >> p.name;
      }
      p.size = ply_type_size(p.type);
      if (p.size == 0 || p.name.empty()) malformed("bad property line '" + line + "'");
      h.elements.back().props.push_back(p);
    } else {
      malformed("unknown header keyword '" + kw + "'");
    }
  }
  if (!have_format) malformed("no format line");
  h.body_offset = pos;
  return h;
}

/// Reads one binary scalar of PLY type `t` (size `size`) at `p`, swapping bytes if needed.
inline double read_binary_scalar(const char* p, const std::string& t, int size, bool swap) {
  unsigned char b[8];
  std::memcpy(b, p, static_cast<std::size_t>(size));
  if (swap) std::reverse(b, b + size);
  auto get = [&](auto v) {
    std::memcpy(&v, b, sizeof(v));
    return static_cast<double>(v);
  };
  if (t == "char" || t == "int8") return get(std::int8_t{});
  if (t == "uchar" || t == "uint8") return get(std::uint8_t{});
  if (t == "short" || t == "int16") return get(std::int16_t{});
  if (t == "ushort" || t == "uint16") return get(std::uint16_t{});
  if (t == "int" || t == "int32") return get(std::int32_t{});
  if (t == "uint" || t == "uint32") return get(std::uint32_t{});
  if (t == "float" || t == "float32") return get(float{});
  return get(double{});
}

}  // namespace detail

/// Decodes the Gaussians of a 3DGS PLY file held in memory; `where` names it in errors (see the file
/// comment for the layout and errors).
template <class Scalar = float>
[[nodiscard]] PlyCloud<Scalar> decode_ply(std::string_view bytes, const std::string& where = "<memory>") {
  const detail::PlyHeader h = detail::parse_ply_header(bytes, where);
  const bool binary = h.format != detail::PlyFormat::ascii;
  const bool swap = (h.format == detail::PlyFormat::binary_be) != (std::endian::native == std::endian::big);
  std::size_t pos = h.body_offset;
  std::istringstream ascii;
  if (!binary) ascii.str(std::string(bytes.substr(pos)));
  auto truncated = [&](const std::string& why) { throw io_error("io.truncated", where, why); };

  // Counts in the header are checked against the bytes present before they drive a loop or an
  // allocation: a binary element needs count x its record size, an ascii value at least 2 bytes (one
  // character and a separator; the last value 1).
  const std::size_t ascii_values = binary ? 0 : (bytes.size() - pos + 1) / 2;
  auto list_count = [&](double v, const std::string& element) {
    if (!(v >= 0 && v <= static_cast<double>(ascii_values) && v == std::floor(v)))
      throw io_error("io.format", where, "element '" + element + "': bad list count " + std::to_string(v));
    return static_cast<std::size_t>(v);
  };

  // Skip elements that precede "vertex".
  const detail::PlyElement* vertex = nullptr;
  for (const auto& e : h.elements) {
    if (e.name == "vertex") {
      vertex = &e;
      break;
    }
    if (e.props.empty()) continue;
    if (binary) {
      std::size_t record = 0;
      for (const auto& p : e.props) {
        if (!p.count_type.empty())
          throw io_error("io.unsupported", where, "list property '" + p.name + "' in element '" + e.name + "' before the vertices");
        record += static_cast<std::size_t>(p.size);
      }
      if (e.count > (bytes.size() - pos) / record) truncated("element '" + e.name + "' is longer than the file");
      pos += e.count * record;
      continue;
    }
    if (e.count > ascii_values / e.props.size()) truncated("element '" + e.name + "' has fewer values than declared");
    for (std::size_t i = 0; i < e.count; ++i)
      for (const auto& p : e.props) {
        double v;
        if (!(ascii >> v)) truncated("element '" + e.name + "' has fewer values than declared");
        if (!p.count_type.empty())
          for (std::size_t j = list_count(v, e.name); j > 0; --j)
            if (!(ascii >> v)) truncated("element '" + e.name + "' has fewer values than declared");
      }
  }
  if (!vertex) throw io_error("io.missing_property", where, "no 'vertex' element");

  // Map the properties we need.
  const auto& props = vertex->props;
  auto find = [&](const std::string& name) -> int {
    for (std::size_t i = 0; i < props.size(); ++i)
      if (props[i].name == name) return static_cast<int>(i);
    return -1;
  };
  auto require = [&](const std::string& name) {
    const int i = find(name);
    if (i < 0) throw io_error("io.missing_property", where, "vertex property '" + name + "' is missing");
    if (!props[static_cast<std::size_t>(i)].count_type.empty())
      throw io_error("io.format", where, "vertex property '" + name + "' is a list");
    return i;
  };
  int n_rest = 0;
  while (find("f_rest_" + std::to_string(n_rest)) >= 0) ++n_rest;
  for (const auto& p : props)
    if (p.name.rfind("f_rest_", 0) == 0 && find("f_rest_" + std::to_string(n_rest)) < 0) {
      const std::string idx = p.name.substr(7);
      if (!idx.empty() && std::all_of(idx.begin(), idx.end(), [](char ch) { return ch >= '0' && ch <= '9'; }) &&
          (idx.size() > 9 || std::stoi(idx) >= n_rest))
        throw io_error("io.format", where, "f_rest_* properties are not numbered 0.." + std::to_string(n_rest - 1) + " ('" + p.name + "')");
    }
  int degree = -1;
  for (int d = 0; d <= sh::kMaxDegree; ++d)
    if (3 * (sh::coeff_count(d) - 1) == n_rest) degree = d;
  if (degree < 0)
    throw io_error("io.format", where, std::to_string(n_rest) + " f_rest_* properties: expected 0, 9, 24 or 45 (SH degree 0..3)");
  const int K = sh::coeff_count(degree);
  const char* names[] = {"x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
                         "rot_0", "rot_1", "rot_2", "rot_3"};
  int idx[14];
  for (int i = 0; i < 14; ++i) idx[i] = require(names[i]);
  std::vector<int> rest_idx(static_cast<std::size_t>(n_rest));
  for (int i = 0; i < n_rest; ++i) rest_idx[static_cast<std::size_t>(i)] = require("f_rest_" + std::to_string(i));

  const std::size_t n = vertex->count;
  std::vector<double> row(props.size());
  std::size_t stride = 0;
  bool has_list = false;
  for (const auto& p : props) {
    stride += static_cast<std::size_t>(p.size);
    has_list = has_list || !p.count_type.empty();
  }
  if (binary && has_list) throw io_error("io.unsupported", where, "list properties in the vertex element");
  if (binary && (bytes.size() - pos) / stride < n)
    truncated("vertex data: " + std::to_string(n) + " vertices of " + std::to_string(stride) + " bytes declared, " +
              std::to_string(bytes.size() - pos) + " bytes present");
  if (!binary && n > ascii_values / props.size())
    truncated(std::to_string(n) + " vertices of " + std::to_string(props.size()) + " values declared, the file is too short for them");
  PlyCloud<Scalar> out;
  out.count = n;
  out.sh_degree = degree;
  out.mean.resize(3 * n), out.log_scale.resize(3 * n), out.rotation.resize(4 * n), out.opacity_logit.resize(n);
  out.sh.resize(static_cast<std::size_t>(3 * K) * n);
  for (std::size_t i = 0; i < n; ++i) {
    if (binary) {
      for (std::size_t j = 0; j < props.size(); ++j) {
        row[j] = detail::read_binary_scalar(bytes.data() + pos, props[j].type, props[j].size, swap);
        pos += static_cast<std::size_t>(props[j].size);
      }
    } else {
      for (std::size_t j = 0; j < props.size(); ++j) {
        std::string tok;
        if (!(ascii >> tok)) truncated("vertex " + std::to_string(i) + " of " + std::to_string(n) + " is incomplete");
        try {
          std::size_t used = 0;
          row[j] = std::stod(tok, &used);
          if (used != tok.size()) throw std::invalid_argument(tok);
        } catch (const std::exception&) {
          throw io_error("io.format", where, "vertex " + std::to_string(i) + ": bad value '" + tok + "'");
        }
        if (!props[j].count_type.empty())
          for (std::size_t m = list_count(row[j], "vertex"); m > 0; --m)
            if (!(ascii >> tok)) truncated("vertex " + std::to_string(i) + " list is incomplete");
      }
    }
    auto v = [&](int k) { return static_cast<Scalar>(row[static_cast<std::size_t>(idx[k])]); };
    for (int k = 0; k < 3; ++k) out.mean[3 * i + k] = v(k);
    for (int k = 0; k < 3; ++k) out.sh[i * 3 * K + k] = v(3 + k);
    out.opacity_logit[i] = v(6);
    for (int k = 0; k < 3; ++k) out.log_scale[3 * i + k] = v(7 + k);
    for (int k = 0; k < 4; ++k) out.rotation[4 * i + k] = v(10 + k);
    for (int c = 0; c < 3; ++c)
      for (int k = 1; k < K; ++k)
        out.sh[(i * K + k) * 3 + c] = static_cast<Scalar>(row[static_cast<std::size_t>(rest_idx[static_cast<std::size_t>(c * (K - 1) + k - 1)])]);
  }
  return out;
}

/// Reads the Gaussians of a 3DGS PLY file (see the file comment for the layout and errors).
template <class Scalar = float>
[[nodiscard]] PlyCloud<Scalar> read_ply(const std::filesystem::path& path) {
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw io_error("io.unreadable", path.string(), "cannot open PLY file");
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  return decode_ply<Scalar>(bytes, path.string());
}

/// The PLY bytes (binary little-endian float32, standard 3DGS layout) of N Gaussians.
template <class Scalar>
[[nodiscard]] std::string ply_bytes(const GaussianParams<Scalar>& g) {
  g.validate("ply");
  const int K = g.sh_coeffs();
  std::string s = "ply\nformat binary_little_endian 1.0\ncomment video3dgs\nelement vertex " + std::to_string(g.count) + "\n";
  for (const char* p : {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"}) s += std::string("property float ") + p + "\n";
  for (int i = 0; i < 3 * (K - 1); ++i) s += "property float f_rest_" + std::to_string(i) + "\n";
  s += "property float opacity\n";
  for (const char* p : {"scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"}) s += std::string("property float ") + p + "\n";
  s += "end_header\n";
  const std::size_t floats = static_cast<std::size_t>(3 + 3 + 3 + 3 * (K - 1) + 1 + 3 + 4);
  std::vector<float> row(floats);
  const std::size_t header = s.size();
  s.resize(header + g.count * floats * sizeof(float));
  char* out = s.data() + header;
  for (std::size_t i = 0; i < g.count; ++i) {
    std::size_t j = 0;
    for (int k = 0; k < 3; ++k) row[j++] = static_cast<float>(g.mean[3 * i + k]);
    for (int k = 0; k < 3; ++k) row[j++] = 0.0f;
    for (int c = 0; c < 3; ++c) row[j++] = static_cast<float>(g.sh[i * 3 * K + c]);
    for (int c = 0; c < 3; ++c)
      for (int k = 1; k < K; ++k) row[j++] = static_cast<float>(g.sh[(i * K + k) * 3 + c]);
    row[j++] = static_cast<float>(g.opacity_logit[i]);
    for (int k = 0; k < 3; ++k) row[j++] = static_cast<float>(g.log_scale[3 * i + k]);
    for (int k = 0; k < 4; ++k) row[j++] = static_cast<float>(g.rotation[4 * i + k]);
    std::memcpy(out, row.data(), floats * sizeof(float));
    if constexpr (std::endian::native == std::endian::big)
      for (std::size_t f = 0; f < floats; ++f) std::reverse(out + 4 * f, out + 4 * f + 4);
    out += floats * sizeof(float);
  }
  return s;
}

/// Writes N Gaussians as a 3DGS PLY file, atomically. @throws io_error `io.unwritable`.
template <class Scalar>
void write_ply(const std::filesystem::path& path, const GaussianParams<Scalar>& g) {
  write_file_atomic(path, ply_bytes(g));
}
template <class Scalar, int D>
void write_ply(const std::filesystem::path& path, const GaussianCloud<Scalar, D>& cloud) {
  write_ply(path, cloud.params());
}

}  // namespace video3dgs::io
