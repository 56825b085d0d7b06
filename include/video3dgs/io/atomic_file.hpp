#pragma once
/// @file
/// Atomic file output: write everything to a temporary file in the target's directory, flush it to
/// the disk, then rename it over the target. A reader (or a crash) sees either the old file or the
/// complete new one, never a half-written file.
///
///     video3dgs::io::AtomicFile out;
///     out.open("model.ply") << header << body;   // writes "<dir>/.model.ply.tmp.<pid>.<n>"
///     out.commit();                               // flush + fsync + rename to "model.ply"
///     // leaving scope without commit() removes the temporary file
///
/// Errors: `io_error` with id `io.unwritable` (directory missing or read-only, disk full, rename
/// failed), naming the target file.

#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <string>
#include <string_view>
#include <system_error>

#if defined(__unix__) || defined(__APPLE__)
#include <fcntl.h>
#include <unistd.h>
#define VIDEO3DGS_HAVE_POSIX_FSYNC 1
#endif

#include "video3dgs/core/error.hpp"

namespace video3dgs::io {

namespace detail {

/// A fresh temporary name beside `target`: "<dir>/.<name>.tmp.<pid>.<counter>" (hidden, so folder
/// listings such as `list_frames` skip it).
inline std::filesystem::path temp_path_for(const std::filesystem::path& target) {
  static std::atomic<unsigned long long> counter{0};
  unsigned long long pid = 0;
#if defined(VIDEO3DGS_HAVE_POSIX_FSYNC)
  pid = static_cast<unsigned long long>(::getpid());
#endif
  std::string name(1, '.');
  name += target.filename().string();
  name += ".tmp.";
  name += std::to_string(pid);
  name += '.';
  name += std::to_string(counter.fetch_add(1));
  return target.parent_path() / name;
}

/// Flushes a closed file's data to the disk (best effort where POSIX fsync is unavailable).
/// @return false if the file could not be synced.
inline bool sync_file(const std::filesystem::path& p) {
#if defined(VIDEO3DGS_HAVE_POSIX_FSYNC)
  const int fd = ::open(p.c_str(), O_RDONLY);
  if (fd < 0) return false;
  const bool ok = ::fsync(fd) == 0;
  ::close(fd);
  return ok;
#else
  (void)p;
  return true;
#endif
}

/// Syncs a directory so that a rename inside it is durable (best effort, errors ignored).
inline void sync_directory(const std::filesystem::path& dir) {
#if defined(VIDEO3DGS_HAVE_POSIX_FSYNC)
  const int fd = ::open(dir.empty() ? "." : dir.c_str(), O_RDONLY);
  if (fd < 0) return;
  (void)::fsync(fd);
  ::close(fd);
#else
  (void)dir;
#endif
}

}  // namespace detail

/// One atomic output file. Not copyable; movable is not needed (keep it on the stack).
class AtomicFile {
 public:
  AtomicFile() = default;
  /// Same as `AtomicFile f; f.open(target);`.
  explicit AtomicFile(const std::filesystem::path& target) { open(target); }
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  /// Without `commit()`, removes the temporary file (the target is left untouched).
  ~AtomicFile() { discard(); }

  /// Starts writing `target` (binary mode). Discards a previous uncommitted file of this object.
  /// @return the stream to write to; valid until `commit()` or `discard()`.
  /// @throws io_error `io.unwritable` if the temporary file cannot be created.
  std::ostream& open(const std::filesystem::path& target) {
    discard();
    target_ = target;
    temp_ = detail::temp_path_for(target);
    stream_.open(temp_, std::ios::binary | std::ios::out | std::ios::trunc);
    if (!stream_.is_open()) {
      const std::string where = target_.string();
      temp_.clear();
      std::error_code ec;
      const auto dir = target_.parent_path();
      const bool dir_ok = dir.empty() || std::filesystem::is_directory(dir, ec);
      throw io_error("io.unwritable", where,
                     dir_ok ? "cannot create a file in its directory (permissions?)"
                            : "its directory does not exist");
    }
    return stream_;
  }

  /// True between `open()` and `commit()` / `discard()`.
  [[nodiscard]] bool is_open() const noexcept { return !temp_.empty(); }
  [[nodiscard]] const std::filesystem::path& target() const noexcept { return target_; }
  [[nodiscard]] const std::filesystem::path& temp_path() const noexcept { return temp_; }
  /// The stream of the open file (only valid while `is_open()`).
  [[nodiscard]] std::ostream& stream() noexcept { return stream_; }

  /// Flushes, syncs and renames the temporary file over the target.
  /// @throws io_error `io.unwritable` if any write failed (e.g. disk full) or the rename failed;
  ///         the temporary file is removed and the target left untouched.
  void commit() {
    if (temp_.empty()) throw io_error("io.unwritable", target_.string(), "commit() without open()");
    stream_.flush();
    const bool wrote = static_cast<bool>(stream_);
    stream_.close();
    if (!wrote || stream_.fail()) fail("writing failed (disk full?)");
    if (!detail::sync_file(temp_)) fail("cannot flush the file to the disk");
    std::error_code ec;
    std::filesystem::rename(temp_, target_, ec);
    if (ec) fail("cannot rename the temporary file into place: " + ec.message());
    temp_.clear();
    detail::sync_directory(target_.parent_path());
  }

  /// Abandons the file: closes and removes the temporary file. Never throws.
  void discard() noexcept {
    if (stream_.is_open()) stream_.close();
    if (!temp_.empty()) {
      std::error_code ec;
      std::filesystem::remove(temp_, ec);
      temp_.clear();
    }
  }

 private:
  [[noreturn]] void fail(const std::string& detail) {
    discard();
    throw io_error("io.unwritable", target_.string(), detail);
  }

  std::filesystem::path target_;
  std::filesystem::path temp_;
  std::ofstream stream_;
};

/// Writes `bytes` to `path` atomically (temporary file in the same directory + fsync + rename).
/// @throws io_error `io.unwritable`
inline void write_file_atomic(const std::filesystem::path& path, std::string_view bytes) {
  AtomicFile f;
  f.open(path).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  f.commit();
}

}  // namespace video3dgs::io
