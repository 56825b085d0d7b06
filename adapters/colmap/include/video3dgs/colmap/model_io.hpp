#pragma once
/// @file
/// Reading and writing COLMAP sparse models (cameras, images, points3D) in COLMAP's text (.txt) and
/// binary (.bin, little-endian) formats.
///
///     auto model = video3dgs::colmap::read_model("sparse/0");          // .bin if present, else .txt
///     video3dgs::colmap::write_model("out/0", model, Format::text);     // atomic per file
///
/// Binary layout (COLMAP 3.x): cameras.bin = u64 count, then per camera i32 id, i32 model, u64 width,
/// u64 height, f64 params[n(model)]; images.bin = u64 count, then per image u32 id, f64 q[4], f64 t[3],
/// u32 camera id, NUL-terminated name, u64 n2d, n2d x (f64 x, f64 y, u64 point3D id or 2^64-1);
/// points3D.bin = u64 count, then per point u64 id, f64 xyz[3], u8 rgb[3], f64 error, u64 track length,
/// track x (u32 image id, u32 point2D index).
/// Text: COLMAP's documented line formats (comments start with '#'; an image takes two lines, the
/// second one, possibly empty, holds its 2D points). Written numbers use the shortest representation
/// that reads back to the same double, so text round-trips are exact too.
///
/// Errors (`io_error`, message names the file and the record): `colmap.missing` (file or folder
/// absent), `colmap.truncated` (file ends inside a record), `colmap.malformed` (unparsable field,
/// wrong parameter count, unknown camera model, trailing bytes, dangling ids), `io.unwritable`.

#include <bit>
#include <charconv>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <vector>

#include "video3dgs/colmap/model.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/io/atomic_file.hpp"

namespace video3dgs::colmap {

enum class Format { automatic, text, binary };

namespace detail {

static_assert(std::endian::native == std::endian::little,
              "video3dgs::colmap: the binary model reader assumes a little-endian host (as COLMAP's files are)");

inline std::string read_whole_file(const std::filesystem::path& file) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec)) throw io_error("colmap.missing", file.string(), "no such file");
  std::ifstream in(file, std::ios::binary);
  if (!in) throw io_error("colmap.missing", file.string(), "cannot open for reading");
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw io_error("colmap.malformed", file.string(), "read error");
  return bytes;
}

/// Bounds-checked little-endian cursor over a whole binary file.
class BinaryReader {
 public:
  explicit BinaryReader(const std::filesystem::path& file) : file_(file.string()), bytes_(read_whole_file(file)) {}

  template <class T>
  T read(const std::string& record, const char* field) {
    static_assert(std::is_trivially_copyable_v<T>);
    need(sizeof(T), record, field);
    T v;
    std::memcpy(&v, bytes_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  std::string read_cstring(const std::string& record, const char* field) {
    const std::size_t end = bytes_.find('\0', pos_);
    if (end == std::string::npos) truncated(record, field);
    std::string s = bytes_.substr(pos_, end - pos_);
    pos_ = end + 1;
    return s;
  }
  /// A count of items of `item_bytes` each that must still fit in the file.
  std::uint64_t read_count(const std::string& record, const char* field, std::size_t item_bytes) {
    const auto n = read<std::uint64_t>(record, field);
    if (item_bytes > 0 && n > remaining() / item_bytes)
      throw io_error("colmap.truncated", file_,
                     record + ": " + field + " = " + std::to_string(n) + " needs " + std::to_string(item_bytes) +
                         " bytes each, but only " + std::to_string(remaining()) + " bytes remain");
    return n;
  }
  [[nodiscard]] std::size_t remaining() const noexcept { return bytes_.size() - pos_; }
  void expect_end() const {
    if (pos_ != bytes_.size())
      throw io_error("colmap.malformed", file_,
                     std::to_string(bytes_.size() - pos_) + " unexpected bytes after the last record");
  }
  [[noreturn]] void malformed(const std::string& record, const std::string& what) const {
    throw io_error("colmap.malformed", file_, record + ": " + what);
  }
  [[nodiscard]] const std::string& file() const noexcept { return file_; }

 private:
  void need(std::size_t n, const std::string& record, const char* field) const {
    if (n > bytes_.size() - pos_) truncated(record, field);
  }
  [[noreturn]] void truncated(const std::string& record, const char* field) const {
    throw io_error("colmap.truncated", file_,
                   record + ": file ends inside " + field + " (at byte " + std::to_string(pos_) + " of " +
                       std::to_string(bytes_.size()) + ")");
  }
  std::string file_;
  std::string bytes_;
  std::size_t pos_ = 0;
};

/// Line-oriented tokenizer for COLMAP's text files.
class TextReader {
 public:
  explicit TextReader(const std::filesystem::path& file) : file_(file.string()), text_(read_whole_file(file)) {}

  /// Next line that is neither empty nor a comment; false at the end of the file.
  bool next_record(std::string_view& line) {
    while (next_raw(line)) {
      const std::string_view t = trim(line);
      if (t.empty() || t.front() == '#') continue;
      line = t;
      return true;
    }
    return false;
  }
  /// Next raw line (may be empty); false at the end of the file.
  bool next_raw(std::string_view& line) {
    if (pos_ >= text_.size()) return false;
    std::size_t end = text_.find('\n', pos_);
    if (end == std::string::npos) end = text_.size();
    line = std::string_view(text_).substr(pos_, end - pos_);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    pos_ = end + 1;
    ++line_no_;
    return true;
  }
  [[nodiscard]] int line_no() const noexcept { return line_no_; }
  [[nodiscard]] const std::string& file() const noexcept { return file_; }
  [[noreturn]] void fail(const char* id, const std::string& what) const {
    throw io_error(id, file_, "line " + std::to_string(line_no_) + ": " + what);
  }

  static std::string_view trim(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t' || s.front() == '\r')) s.remove_prefix(1);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
    return s;
  }
  static std::vector<std::string_view> split(std::string_view s) {
    std::vector<std::string_view> out;
    std::size_t i = 0;
    while (i < s.size()) {
      while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
      std::size_t j = i;
      while (j < s.size() && s[j] != ' ' && s[j] != '\t') ++j;
      if (j > i) out.push_back(s.substr(i, j - i));
      i = j;
    }
    return out;
  }
  template <class T>
  T parse(std::string_view tok, const std::string& record, const char* field) const {
    T v{};
    const auto [p, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), v);
    if (ec != std::errc{} || p != tok.data() + tok.size())
      fail("colmap.malformed", record + ": cannot parse " + field + " from '" + std::string(tok) + "'");
    return v;
  }

 private:
  std::string file_;
  std::string text_;
  std::size_t pos_ = 0;
  int line_no_ = 0;
};

inline std::string fmt(double v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, r.ptr);
}

/// Appends ' ' then `token` (no temporary strings).
inline void field(std::string& out, std::string_view token) {
  out.push_back(' ');
  out.append(token);
}

template <class T>
void put(std::string& out, const T& v) {
  static_assert(std::is_trivially_copyable_v<T>);
  const auto* p = reinterpret_cast<const char*>(&v);
  out.append(p, sizeof(T));
}

inline const CameraModelInfo& model_or_throw(int id, const std::string& file, const std::string& record) {
  const CameraModelInfo* m = find_camera_model(id);
  if (!m) throw io_error("colmap.malformed", file, record + ": unknown camera model id " + std::to_string(id));
  return *m;
}

inline std::string record_name(const char* what, std::size_t index, std::uint64_t id) {
  return std::string(what) + " #" + std::to_string(index) + " (id " + std::to_string(id) + ")";
}

}  // namespace detail

// ---------------------------------------------------------------------------------------- binary

[[nodiscard]] inline std::map<std::uint32_t, CameraRecord> read_cameras_binary(const std::filesystem::path& file) {
  detail::BinaryReader r(file);
  std::map<std::uint32_t, CameraRecord> out;
  const auto n = r.read_count("header", "camera count", 24 + 8 * 3);
  for (std::uint64_t i = 0; i < n; ++i) {
    std::string rec = "camera #" + std::to_string(i);
    CameraRecord c;
    c.id = static_cast<std::uint32_t>(r.read<std::int32_t>(rec, "camera id"));
    rec = detail::record_name("camera", i, c.id);
    c.model_id = r.read<std::int32_t>(rec, "model id");
    const auto& m = detail::model_or_throw(c.model_id, r.file(), rec);
    c.width = r.read<std::uint64_t>(rec, "width");
    c.height = r.read<std::uint64_t>(rec, "height");
    c.params.resize(static_cast<std::size_t>(m.num_params));
    for (auto& p : c.params) p = r.read<double>(rec, "params");
    if (!out.emplace(c.id, std::move(c)).second) r.malformed(rec, "duplicate camera id");
  }
  r.expect_end();
  return out;
}

[[nodiscard]] inline std::map<std::uint32_t, ImageRecord> read_images_binary(const std::filesystem::path& file) {
  detail::BinaryReader r(file);
  std::map<std::uint32_t, ImageRecord> out;
  const auto n = r.read_count("header", "image count", 4 + 8 * 7 + 4 + 1 + 8);
  for (std::uint64_t i = 0; i < n; ++i) {
    std::string rec = "image #" + std::to_string(i);
    ImageRecord im;
    im.id = r.read<std::uint32_t>(rec, "image id");
    rec = detail::record_name("image", i, im.id);
    for (auto& q : im.qvec) q = r.read<double>(rec, "qvec");
    for (auto& t : im.tvec) t = r.read<double>(rec, "tvec");
    im.camera_id = r.read<std::uint32_t>(rec, "camera id");
    im.name = r.read_cstring(rec, "name");
    rec += " '" + im.name + "'";
    const auto n2 = r.read_count(rec, "point2D count", 24);
    im.points2D.resize(n2);
    im.point3D_ids.resize(n2);
    for (std::uint64_t j = 0; j < n2; ++j) {
      im.points2D[j][0] = r.read<double>(rec, "points2D");
      im.points2D[j][1] = r.read<double>(rec, "points2D");
      const auto pid = r.read<std::uint64_t>(rec, "point3D ids");
      im.point3D_ids[j] = pid == std::numeric_limits<std::uint64_t>::max() ? kNoPoint3D : static_cast<std::int64_t>(pid);
    }
    if (!out.emplace(im.id, std::move(im)).second) r.malformed(rec, "duplicate image id");
  }
  r.expect_end();
  return out;
}

[[nodiscard]] inline std::map<std::uint64_t, Point3DRecord> read_points3D_binary(const std::filesystem::path& file) {
  detail::BinaryReader r(file);
  std::map<std::uint64_t, Point3DRecord> out;
  const auto n = r.read_count("header", "point count", 8 + 24 + 3 + 8 + 8);
  for (std::uint64_t i = 0; i < n; ++i) {
    std::string rec = "point3D #" + std::to_string(i);
    Point3DRecord p;
    p.id = r.read<std::uint64_t>(rec, "point3D id");
    rec = detail::record_name("point3D", i, p.id);
    for (auto& x : p.xyz) x = r.read<double>(rec, "xyz");
    for (auto& c : p.rgb) c = r.read<std::uint8_t>(rec, "rgb");
    p.error = r.read<double>(rec, "error");
    const auto nt = r.read_count(rec, "track length", 8);
    p.track.resize(nt);
    for (auto& t : p.track) {
      t.image_id = r.read<std::uint32_t>(rec, "track");
      t.point2D_idx = r.read<std::uint32_t>(rec, "track");
    }
    if (!out.emplace(p.id, std::move(p)).second) r.malformed(rec, "duplicate point3D id");
  }
  r.expect_end();
  return out;
}

inline void write_cameras_binary(const std::filesystem::path& file, const std::map<std::uint32_t, CameraRecord>& cameras) {
  std::string out;
  detail::put(out, static_cast<std::uint64_t>(cameras.size()));
  for (const auto& [id, c] : cameras) {
    const auto& m = detail::model_or_throw(c.model_id, file.string(), "camera " + std::to_string(id));
    if (c.params.size() != static_cast<std::size_t>(m.num_params))
      throw io_error("colmap.malformed", file.string(),
                     "camera " + std::to_string(id) + ": " + m.name + " needs " + std::to_string(m.num_params) +
                         " params, has " + std::to_string(c.params.size()));
    detail::put(out, static_cast<std::int32_t>(id));
    detail::put(out, static_cast<std::int32_t>(c.model_id));
    detail::put(out, c.width);
    detail::put(out, c.height);
    for (double p : c.params) detail::put(out, p);
  }
  io::write_file_atomic(file, out);
}

inline void write_images_binary(const std::filesystem::path& file, const std::map<std::uint32_t, ImageRecord>& images) {
  std::string out;
  detail::put(out, static_cast<std::uint64_t>(images.size()));
  for (const auto& [id, im] : images) {
    if (im.points2D.size() != im.point3D_ids.size())
      throw io_error("colmap.malformed", file.string(), "image " + std::to_string(id) + ": points2D and point3D_ids differ in size");
    detail::put(out, id);
    for (double q : im.qvec) detail::put(out, q);
    for (double t : im.tvec) detail::put(out, t);
    detail::put(out, im.camera_id);
    out.append(im.name);
    out.push_back('\0');
    detail::put(out, static_cast<std::uint64_t>(im.points2D.size()));
    for (std::size_t j = 0; j < im.points2D.size(); ++j) {
      detail::put(out, im.points2D[j][0]);
      detail::put(out, im.points2D[j][1]);
      const std::int64_t pid = im.point3D_ids[j];
      detail::put(out, pid < 0 ? std::numeric_limits<std::uint64_t>::max() : static_cast<std::uint64_t>(pid));
    }
  }
  io::write_file_atomic(file, out);
}

inline void write_points3D_binary(const std::filesystem::path& file, const std::map<std::uint64_t, Point3DRecord>& points) {
  std::string out;
  detail::put(out, static_cast<std::uint64_t>(points.size()));
  for (const auto& [id, p] : points) {
    detail::put(out, id);
    for (double x : p.xyz) detail::put(out, x);
    for (auto c : p.rgb) detail::put(out, c);
    detail::put(out, p.error);
    detail::put(out, static_cast<std::uint64_t>(p.track.size()));
    for (const auto& t : p.track) {
      detail::put(out, t.image_id);
      detail::put(out, t.point2D_idx);
    }
  }
  io::write_file_atomic(file, out);
}

// ------------------------------------------------------------------------------------------ text

[[nodiscard]] inline std::map<std::uint32_t, CameraRecord> read_cameras_text(const std::filesystem::path& file) {
  detail::TextReader r(file);
  std::map<std::uint32_t, CameraRecord> out;
  std::string_view line;
  while (r.next_record(line)) {
    const auto tok = detail::TextReader::split(line);
    std::string rec = "camera";
    if (tok.size() < 4) r.fail("colmap.malformed", "camera: expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]");
    CameraRecord c;
    c.id = r.parse<std::uint32_t>(tok[0], rec, "CAMERA_ID");
    rec = "camera " + std::to_string(c.id);
    const CameraModelInfo* m = find_camera_model(tok[1]);
    if (!m) r.fail("colmap.malformed", rec + ": unknown camera model '" + std::string(tok[1]) + "'");
    c.model_id = m->id;
    c.width = r.parse<std::uint64_t>(tok[2], rec, "WIDTH");
    c.height = r.parse<std::uint64_t>(tok[3], rec, "HEIGHT");
    if (tok.size() - 4 != static_cast<std::size_t>(m->num_params))
      r.fail("colmap.malformed", rec + ": " + m->name + " needs " + std::to_string(m->num_params) + " params (" +
                                     m->params + "), got " + std::to_string(tok.size() - 4));
    for (std::size_t j = 4; j < tok.size(); ++j) c.params.push_back(r.parse<double>(tok[j], rec, "PARAMS"));
    if (!out.emplace(c.id, std::move(c)).second) r.fail("colmap.malformed", rec + ": duplicate camera id");
  }
  return out;
}

[[nodiscard]] inline std::map<std::uint32_t, ImageRecord> read_images_text(const std::filesystem::path& file) {
  detail::TextReader r(file);
  std::map<std::uint32_t, ImageRecord> out;
  std::string_view line;
  while (r.next_record(line)) {
    const auto tok = detail::TextReader::split(line);
    std::string rec = "image";
    if (tok.size() < 10) r.fail("colmap.malformed", "image: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME");
    ImageRecord im;
    im.id = r.parse<std::uint32_t>(tok[0], rec, "IMAGE_ID");
    rec = "image " + std::to_string(im.id);
    for (int j = 0; j < 4; ++j) im.qvec[static_cast<std::size_t>(j)] = r.parse<double>(tok[static_cast<std::size_t>(1 + j)], rec, "QVEC");
    for (int j = 0; j < 3; ++j) im.tvec[static_cast<std::size_t>(j)] = r.parse<double>(tok[static_cast<std::size_t>(5 + j)], rec, "TVEC");
    im.camera_id = r.parse<std::uint32_t>(tok[8], rec, "CAMERA_ID");
    // The name is the rest of the line (so names with spaces survive).
    im.name = std::string(detail::TextReader::trim(line.substr(static_cast<std::size_t>(tok[9].data() - line.data()))));
    rec += " '" + im.name + "'";
    std::string_view pts;
    if (!r.next_raw(pts)) r.fail("colmap.truncated", rec + ": file ends before the POINTS2D line");
    const auto pt = detail::TextReader::split(detail::TextReader::trim(pts));
    if (pt.size() % 3 != 0)
      r.fail("colmap.malformed", rec + ": POINTS2D needs triples (X Y POINT3D_ID), got " + std::to_string(pt.size()) + " values");
    im.points2D.resize(pt.size() / 3);
    im.point3D_ids.resize(pt.size() / 3);
    for (std::size_t j = 0; j < pt.size() / 3; ++j) {
      im.points2D[j][0] = r.parse<double>(pt[3 * j], rec, "POINTS2D.X");
      im.points2D[j][1] = r.parse<double>(pt[3 * j + 1], rec, "POINTS2D.Y");
      const auto pid = r.parse<std::int64_t>(pt[3 * j + 2], rec, "POINT3D_ID");
      im.point3D_ids[j] = pid < 0 ? kNoPoint3D : pid;
    }
    if (!out.emplace(im.id, std::move(im)).second) r.fail("colmap.malformed", rec + ": duplicate image id");
  }
  return out;
}

[[nodiscard]] inline std::map<std::uint64_t, Point3DRecord> read_points3D_text(const std::filesystem::path& file) {
  detail::TextReader r(file);
  std::map<std::uint64_t, Point3DRecord> out;
  std::string_view line;
  while (r.next_record(line)) {
    const auto tok = detail::TextReader::split(line);
    std::string rec = "point3D";
    if (tok.size() < 8) r.fail("colmap.malformed", "point3D: expected POINT3D_ID X Y Z R G B ERROR TRACK[]");
    Point3DRecord p;
    p.id = r.parse<std::uint64_t>(tok[0], rec, "POINT3D_ID");
    rec = "point3D " + std::to_string(p.id);
    for (std::size_t j = 0; j < 3; ++j) p.xyz[j] = r.parse<double>(tok[1 + j], rec, "XYZ");
    for (std::size_t j = 0; j < 3; ++j) {
      const int c = r.parse<int>(tok[4 + j], rec, "RGB");
      if (c < 0 || c > 255) r.fail("colmap.malformed", rec + ": colour value " + std::to_string(c) + " outside 0..255");
      p.rgb[j] = static_cast<std::uint8_t>(c);
    }
    p.error = r.parse<double>(tok[7], rec, "ERROR");
    if ((tok.size() - 8) % 2 != 0) r.fail("colmap.malformed", rec + ": TRACK needs pairs (IMAGE_ID POINT2D_IDX)");
    for (std::size_t j = 8; j < tok.size(); j += 2)
      p.track.push_back({r.parse<std::uint32_t>(tok[j], rec, "TRACK.IMAGE_ID"), r.parse<std::uint32_t>(tok[j + 1], rec, "TRACK.POINT2D_IDX")});
    if (!out.emplace(p.id, std::move(p)).second) r.fail("colmap.malformed", rec + ": duplicate point3D id");
  }
  return out;
}

inline void write_cameras_text(const std::filesystem::path& file, const std::map<std::uint32_t, CameraRecord>& cameras) {
  std::string out = "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n";
  out += "# Number of cameras: " + std::to_string(cameras.size()) + "\n";
  for (const auto& [id, c] : cameras) {
    const auto& m = detail::model_or_throw(c.model_id, file.string(), "camera " + std::to_string(id));
    if (c.params.size() != static_cast<std::size_t>(m.num_params))
      throw io_error("colmap.malformed", file.string(),
                     "camera " + std::to_string(id) + ": " + m.name + " needs " + std::to_string(m.num_params) + " params");
    out += std::to_string(id);
    detail::field(out, m.name);
    detail::field(out, std::to_string(c.width));
    detail::field(out, std::to_string(c.height));
    for (double p : c.params) detail::field(out, detail::fmt(p));
    out += "\n";
  }
  io::write_file_atomic(file, out);
}

inline void write_images_text(const std::filesystem::path& file, const std::map<std::uint32_t, ImageRecord>& images) {
  std::size_t obs = 0;
  for (const auto& [id, im] : images)
    for (auto pid : im.point3D_ids) obs += pid >= 0 ? 1 : 0;
  std::string out =
      "# Image list with two lines of data per image:\n#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
      "#   POINTS2D[] as (X, Y, POINT3D_ID)\n";
  out += "# Number of images: " + std::to_string(images.size()) + ", mean observations per image: " +
         detail::fmt(images.empty() ? 0.0 : double(obs) / double(images.size())) + "\n";
  for (const auto& [id, im] : images) {
    if (im.points2D.size() != im.point3D_ids.size())
      throw io_error("colmap.malformed", file.string(), "image " + std::to_string(id) + ": points2D and point3D_ids differ in size");
    out += std::to_string(id);
    for (double q : im.qvec) detail::field(out, detail::fmt(q));
    for (double t : im.tvec) detail::field(out, detail::fmt(t));
    detail::field(out, std::to_string(im.camera_id));
    detail::field(out, im.name);
    out.push_back('\n');
    for (std::size_t j = 0; j < im.points2D.size(); ++j) {
      if (j) out.push_back(' ');
      out += detail::fmt(im.points2D[j][0]);
      detail::field(out, detail::fmt(im.points2D[j][1]));
      detail::field(out, std::to_string(im.point3D_ids[j] < 0 ? std::int64_t{-1} : im.point3D_ids[j]));
    }
    out += "\n";
  }
  io::write_file_atomic(file, out);
}

inline void write_points3D_text(const std::filesystem::path& file, const std::map<std::uint64_t, Point3DRecord>& points) {
  std::size_t obs = 0;
  for (const auto& [id, p] : points) obs += p.track.size();
  std::string out =
      "# 3D point list with one line of data per point:\n#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as "
      "(IMAGE_ID, POINT2D_IDX)\n";
  out += "# Number of points: " + std::to_string(points.size()) + ", mean track length: " +
         detail::fmt(points.empty() ? 0.0 : double(obs) / double(points.size())) + "\n";
  for (const auto& [id, p] : points) {
    out += std::to_string(id);
    for (double x : p.xyz) detail::field(out, detail::fmt(x));
    for (auto c : p.rgb) detail::field(out, std::to_string(static_cast<int>(c)));
    detail::field(out, detail::fmt(p.error));
    for (const auto& t : p.track) {
      detail::field(out, std::to_string(t.image_id));
      detail::field(out, std::to_string(t.point2D_idx));
    }
    out += "\n";
  }
  io::write_file_atomic(file, out);
}

// ------------------------------------------------------------------------------------- whole model

/// The format found in `dir`: binary if cameras.bin exists, else text if cameras.txt exists.
/// @throws io_error `colmap.missing` if neither exists
[[nodiscard]] inline Format detect_format(const std::filesystem::path& dir) {
  std::error_code ec;
  if (std::filesystem::exists(dir / "cameras.bin", ec)) return Format::binary;
  if (std::filesystem::exists(dir / "cameras.txt", ec)) return Format::text;
  throw io_error("colmap.missing", dir.string(), "no COLMAP model here (neither cameras.bin nor cameras.txt)");
}

/// Checks cross-references: every image's camera exists, every track element names an existing image
/// and 2D point, and every 2D point's 3D id exists.
/// @throws io_error `colmap.malformed` naming the model folder and the record
inline void validate(const Model& m, const std::string& where) {
  for (const auto& [id, im] : m.images) {
    if (!m.cameras.count(im.camera_id))
      throw io_error("colmap.malformed", where, "image " + std::to_string(id) + " '" + im.name + "': camera " +
                                                    std::to_string(im.camera_id) + " does not exist");
    for (std::size_t j = 0; j < im.point3D_ids.size(); ++j)
      if (im.point3D_ids[j] >= 0 && !m.points.count(static_cast<std::uint64_t>(im.point3D_ids[j])))
        throw io_error("colmap.malformed", where, "image " + std::to_string(id) + " '" + im.name + "': point2D " +
                                                      std::to_string(j) + " refers to missing point3D " +
                                                      std::to_string(im.point3D_ids[j]));
  }
  for (const auto& [id, p] : m.points)
    for (const auto& t : p.track) {
      auto it = m.images.find(t.image_id);
      if (it == m.images.end())
        throw io_error("colmap.malformed", where, "point3D " + std::to_string(id) + ": track names missing image " +
                                                      std::to_string(t.image_id));
      if (t.point2D_idx >= it->second.points2D.size())
        throw io_error("colmap.malformed", where, "point3D " + std::to_string(id) + ": track names point2D " +
                                                      std::to_string(t.point2D_idx) + " of image " +
                                                      std::to_string(t.image_id) + ", which has " +
                                                      std::to_string(it->second.points2D.size()));
    }
}

/// Reads cameras, images and points3D from `dir` and validates their cross-references.
/// @throws io_error `colmap.missing`, `colmap.truncated`, `colmap.malformed`
[[nodiscard]] inline Model read_model(const std::filesystem::path& dir, Format format = Format::automatic) {
  if (format == Format::automatic) format = detect_format(dir);
  Model m;
  if (format == Format::binary) {
    m.cameras = read_cameras_binary(dir / "cameras.bin");
    m.images = read_images_binary(dir / "images.bin");
    m.points = read_points3D_binary(dir / "points3D.bin");
  } else {
    m.cameras = read_cameras_text(dir / "cameras.txt");
    m.images = read_images_text(dir / "images.txt");
    m.points = read_points3D_text(dir / "points3D.txt");
  }
  validate(m, dir.string());
  return m;
}

/// Writes the model's three files into `dir` (created if missing), each atomically.
/// @throws io_error `io.unwritable`, `colmap.malformed` (wrong parameter count, unknown model)
inline void write_model(const std::filesystem::path& dir, const Model& m, Format format = Format::binary) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw io_error("io.unwritable", dir.string(), "cannot create folder: " + ec.message());
  if (format == Format::text) {
    write_cameras_text(dir / "cameras.txt", m.cameras);
    write_images_text(dir / "images.txt", m.images);
    write_points3D_text(dir / "points3D.txt", m.points);
  } else {
    write_cameras_binary(dir / "cameras.bin", m.cameras);
    write_images_binary(dir / "images.bin", m.images);
    write_points3D_binary(dir / "points3D.bin", m.points);
  }
}

}  // namespace video3dgs::colmap
