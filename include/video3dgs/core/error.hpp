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
/// programs, `numeric.*` for non-finite values caught at a boundary. Each id has one spelling; the
/// two that had two in version 0.1 are still matched by `is()` under their old spelling
/// (`kErrorIdAliases`).

#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>

namespace video3dgs {

/// Old spelling -> current spelling of an error id (version 0.1 raised both spellings).
inline constexpr std::pair<std::string_view, std::string_view> kErrorIdAliases[] = {
    {"numeric.nonfinite", "numeric.non_finite"},
    {"io.malformed", "io.format"},
};

class error : public std::runtime_error {
 public:
  /// @param id     stable id, e.g. "io.unreadable"
  /// @param where  the file, field or frame at fault (may be empty)
  /// @param detail what went wrong, for a person
  error(std::string id, std::string where, const std::string& detail)
      : std::runtime_error(format(id, where, detail)), id_(std::move(id)), where_(std::move(where)) {}

  [[nodiscard]] const std::string& id() const noexcept { return id_; }
  [[nodiscard]] const std::string& where() const noexcept { return where_; }
  /// True if this error's id is `id`, or `id` is an old spelling of it (kErrorIdAliases).
  [[nodiscard]] bool is(std::string_view id) const noexcept {
    if (id == id_) return true;
    for (const auto& [old_id, current] : kErrorIdAliases)
      if (id == old_id && current == id_) return true;
    return false;
  }

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
