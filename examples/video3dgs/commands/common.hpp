#pragma once
// Shared plumbing of the CLI's subcommands: each add_<name>_command registers its options and a
// callback with `on_run`; main() parses and then calls `run_selected`, so library errors surface
// in one place with their ids.
#include <functional>
#include <map>
#include <string>

#include <CLI/CLI.hpp>

namespace video3dgs::cli {

inline std::map<const CLI::App*, std::function<void()>>& handlers() {
  static std::map<const CLI::App*, std::function<void()>> h;
  return h;
}

/// Registers `fn` to run when subcommand `sub` was selected.
inline void on_run(CLI::App* sub, std::function<void()> fn) { handlers()[sub] = std::move(fn); }

inline void run_selected(const CLI::App& app) {
  for (const CLI::App* sub : app.get_subcommands()) {
    auto it = handlers().find(sub);
    if (it != handlers().end()) it->second();
  }
}

}  // namespace video3dgs::cli
