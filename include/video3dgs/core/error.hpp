#pragma once
/// @file
/// The exception hierarchy. Every error raised at a boundary (files, user options, external programs)
/// derives from `video3dgs::error`. Its message starts with a stable id in brackets, then names the
/// file, field or frame at fault:
///
///     [io.unreadable] frames/00012.jpg: cannot decode image (corrupt JPEG data)
///
/// Programs may match on `id()` (stable across versions; extend, never rename). Ids are
/// `<area>.<what>`: `io.*` for files, `option.*` for user options, `colmap.*` / `external.*` for other
/// programs, `numeric.*` for non-finite values caught at a boundary.

#include <stdexcept>
#include <string>
#include <utility>

namespace video3dgs {

class error : public std::runtime_error {
 public:
  /// @param id     stable id, e.g. "io.unreadable"
  /// @param where  the file, field or frame at fault (may be empty)
  /// @param detail what went wrong, for a person
  error(std::string id, std::string where, const std::string& detail)
      : std::runtime_error(format(id, where, detail)), id_(std::move(id)), where_(std::move(where)) {}

  [[nodiscard]] const std::string& id() const noexcept { return id_; }
  [[nodiscard]] const std::string& where() const noexcept { return where_; }

 private:
  static std::string format(const std::string& id, const std::string& where, const std::string& detail) {
    std::string s = "[" + id + "] ";
    if (!where.empty()) s += where + ": ";
    return s + detail;
  }
  std::string id_;
  std::string where_;
};

/// A file is missing, unreadable, truncated or malformed (`io.*`).
class io_error : public error {
  using error::error;
};
/// A user option or argument is invalid (`option.*`).
class option_error : public error {
  using error::error;
};
/// An external program failed or is missing (`colmap.*`, `external.*`).
class external_error : public error {
  using error::error;
};
/// A non-finite or out-of-range value was caught at a boundary (`numeric.*`).
class numeric_error : public error {
  using error::error;
};

}  // namespace video3dgs
