#pragma once
/// @file
/// Running an external program without a shell: posix_spawn with an argument vector (no quoting
/// issues with paths), stdin from /dev/null, stdout + stderr appended to a log file, an optional
/// wall-clock timeout after which the program's whole process group gets SIGTERM, then SIGKILL.
/// POSIX only (this header is not part of the `video3dgs/io.hpp` umbrella; include it where needed).
///
/// Used by the COLMAP adapter (re-exported as `video3dgs::colmap::run_process`) and by the command
/// editor of stage 2 (refine/editor.hpp).

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include "video3dgs/core/error.hpp"

extern char** environ;  // NOLINT: POSIX

namespace video3dgs::io {

struct ProcessResult {
  int exit_code = -1;      ///< exit status if the program exited normally, else -1
  int signal = 0;          ///< terminating signal, 0 if none
  bool timed_out = false;  ///< killed because the timeout passed
  double seconds = 0;      ///< wall time
  [[nodiscard]] bool ok() const noexcept { return exit_code == 0 && !timed_out; }
};

/// Resolves a program name the way execvp would: a name containing '/' is taken as is, otherwise
/// each PATH entry is tried. Returns an empty path if no executable file is found.
[[nodiscard]] inline std::filesystem::path find_executable(const std::filesystem::path& program) {
  const std::string s = program.string();
  if (s.empty()) return {};
  auto executable = [](const std::filesystem::path& p) {
    std::error_code ec;
    return std::filesystem::is_regular_file(p, ec) && ::access(p.c_str(), X_OK) == 0;
  };
  if (s.find('/') != std::string::npos) return executable(program) ? program : std::filesystem::path{};
  const char* path = std::getenv("PATH");
  std::string dirs = path ? path : "/usr/local/bin:/usr/bin:/bin";
  std::size_t i = 0;
  while (i <= dirs.size()) {
    std::size_t j = dirs.find(':', i);
    if (j == std::string::npos) j = dirs.size();
    const std::filesystem::path cand = std::filesystem::path(j > i ? dirs.substr(i, j - i) : ".") / program;
    if (executable(cand)) return cand;
    i = j + 1;
  }
  return {};
}

/// Runs `argv` (argv[0] = program, resolved with `find_executable`), appending its output to `log`.
/// @param timeout_seconds 0 = no timeout
/// @param env_overrides   "NAME=value" entries added to (or replacing in) the current environment
/// @throws external_error `external.missing` (program not found), `external.spawn` (spawn failed),
///         io_error `io.unwritable` (log file cannot be opened)
inline ProcessResult run_process(const std::vector<std::string>& argv, const std::filesystem::path& log,
                                 double timeout_seconds = 0, const std::vector<std::string>& env_overrides = {}) {
  if (argv.empty()) throw external_error("external.spawn", "", "empty command");
  const std::filesystem::path exe = find_executable(argv[0]);
  if (exe.empty()) throw external_error("external.missing", argv[0], "program not found (not on PATH or not executable)");

  const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd < 0) throw io_error("io.unwritable", log.string(), std::string("cannot open log file: ") + std::strerror(errno));
  {  // Record the command line in the log (arguments separated by spaces, as a person reads them).
    std::string line = "$";
    for (const auto& a : argv) line += " " + a;
    line += "\n";
    [[maybe_unused]] const auto n = ::write(fd, line.data(), line.size());
  }

  // Environment: current entries, minus overridden names, plus the overrides.
  std::vector<std::string> env_store;
  for (char** e = environ; e && *e; ++e) {
    const std::string entry = *e;
    const std::string name = entry.substr(0, entry.find('='));
    bool overridden = false;
    for (const auto& o : env_overrides) overridden = overridden || o.substr(0, o.find('=')) == name;
    if (!overridden) env_store.push_back(entry);
  }
  for (const auto& o : env_overrides) env_store.push_back(o);
  std::vector<char*> envp;
  for (auto& s : env_store) envp.push_back(s.data());
  envp.push_back(nullptr);
  std::vector<std::string> args = argv;
  std::vector<char*> argp;
  for (auto& a : args) argp.push_back(a.data());
  argp.push_back(nullptr);

  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_adddup2(&actions, fd, 1);
  posix_spawn_file_actions_adddup2(&actions, fd, 2);
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  posix_spawnattr_setpgroup(&attr, 0);  // own process group, so a timeout kills its children too
  posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETPGROUP);

  const auto t0 = std::chrono::steady_clock::now();
  pid_t pid = -1;
  const int rc = ::posix_spawn(&pid, exe.c_str(), &actions, &attr, argp.data(), envp.data());
  posix_spawn_file_actions_destroy(&actions);
  posix_spawnattr_destroy(&attr);
  ::close(fd);
  if (rc != 0) throw external_error("external.spawn", exe.string(), std::string("cannot start: ") + std::strerror(rc));

  ProcessResult result;
  int status = 0;
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  auto sleep_ms = std::chrono::milliseconds(2);
  for (;;) {
    const pid_t w = ::waitpid(pid, &status, WNOHANG);
    if (w == pid) break;
    if (w < 0 && errno != EINTR) break;
    if (timeout_seconds > 0 && elapsed() > timeout_seconds) {
      result.timed_out = true;
      ::kill(-pid, SIGTERM);
      for (int i = 0; i < 100 && ::waitpid(pid, &status, WNOHANG) == 0; ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      ::kill(-pid, SIGKILL);
      while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
      }
      break;
    }
    std::this_thread::sleep_for(sleep_ms);
    if (sleep_ms < std::chrono::milliseconds(50)) sleep_ms *= 2;
  }
  result.seconds = elapsed();
  if (WIFEXITED(status)) result.exit_code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) result.signal = WTERMSIG(status);
  if (result.timed_out) result.exit_code = -1;
  return result;
}

/// The last `max_bytes` of a log file (for error messages), empty if unreadable.
[[nodiscard]] inline std::string log_tail(const std::filesystem::path& log, std::size_t max_bytes = 600) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(log, ec);
  if (ec) return {};
  const int fd = ::open(log.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return {};
  const auto start = size > max_bytes ? size - max_bytes : 0;
  std::string buf(static_cast<std::size_t>(size - start), '\0');
  const auto n = ::pread(fd, buf.data(), buf.size(), static_cast<off_t>(start));
  ::close(fd);
  buf.resize(n > 0 ? static_cast<std::size_t>(n) : 0);
  return buf;
}

}  // namespace video3dgs::io
