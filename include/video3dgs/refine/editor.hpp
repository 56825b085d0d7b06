#pragma once
/// @file
/// Video editors for stage 2 (refine/refine.hpp): a video editor maps the frames of a video to
/// edited frames. Zero-shot diffusion editors (TokenFlow, RAVE, Text2Video-Zero, ...) are external
/// programs; the `Editor` concept lets the recursive refiner call any of them, and two editors come
/// with the library:
///
///   FlickerEditor   a deliberately flickering test editor: a fixed, idempotent style transform
///                   (colour toning, S(S(x)) = S(x)) plus a seeded per-frame, per-channel gain and
///                   offset jitter and a low-frequency per-frame shading wave, so that tests have a
///                   temporally inconsistent edit and the clean style S(source) as ground truth;
///   CommandEditor   runs an external program (posix_spawn through io::run_process, no shell) that
///                   reads a folder of PNG frames and writes the same number of edited frames.
///
/// An editor is called with the phase index of recursive refinement (`EditContext`): phase p of
/// `phases` edits the source (p = 0) or the previous phase's refined video (p > 0).

#include <algorithm>
#include <array>
#include <cmath>
#include <concepts>
#include <cstdio>
#include <cstdint>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/io/frame_folder.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/io/process.hpp"

namespace video3dgs {

/// What an editor is told about the call.
struct EditContext {
  int phase = 0;   ///< 0-based phase of recursive refinement
  int phases = 1;  ///< N_r
};

/// A video editor: `edit(frames, ctx)` returns as many frames as it gets, of the same size.
template <class E>
concept Editor = requires(E& e, const std::vector<Image<float, 3>>& frames, const EditContext& ctx) {
  { e.edit(frames, ctx) } -> std::convertible_to<std::vector<Image<float, 3>>>;
};

/// Checks an editor's output against its input. @throws external_error `external.editor`
inline void check_edited(const std::vector<Image<float, 3>>& in, const std::vector<Image<float, 3>>& out, const std::string& who) {
  if (out.size() != in.size())
    throw external_error("external.editor", who, "returned " + std::to_string(out.size()) + " frames for " + std::to_string(in.size()));
  for (std::size_t i = 0; i < out.size(); ++i) {
    if (out[i].width() != in[i].width() || out[i].height() != in[i].height())
      throw external_error("external.editor", who, "frame " + std::to_string(i) + " changed size");
    for (float v : out[i].storage())
      if (!std::isfinite(v)) throw external_error("external.editor", who, "frame " + std::to_string(i) + " holds a non-finite value");
  }
}

/// The deliberately flickering test editor (see the file comment).
///
///   S(x)      = clamp(l(x) tone, 0, 1),   l(x) = 0.299 r + 0.587 g + 0.114 b,   l(tone) = 1
///   E_t(x)_c  = clamp(g_tc S(x)_c + o_tc + w_t(x), 0, 1)
///   g_tc ~ 1 + U(-gain, gain),  o_tc ~ U(-offset, offset),
///   w_t(x)    = wave A_t sin(2 pi (x cos phi_t + y sin phi_t) / period + psi_t)
/// with every random draw seeded by (seed, phase, frame): the same call gives the same frames.
struct FlickerEditor {
  std::uint64_t seed = 1;
  double gain = 0.2;        ///< per-channel gain jitter amplitude
  double offset = 0.08;     ///< per-channel offset jitter amplitude
  double wave = 0.05;       ///< amplitude of the per-frame shading wave
  double period = 48;       ///< wavelength of the wave, pixels
  std::array<double, 3> tone{1.25, 1.0, 0.62};  ///< style colour (rescaled so that l(tone) = 1)

  /// The clean style transform S (no jitter): the ground truth a consistent edit should match.
  [[nodiscard]] Image<float, 3> style(const Image<float, 3>& in) const {
    const double lt = 0.299 * tone[0] + 0.587 * tone[1] + 0.114 * tone[2];
    Image<float, 3> out(in.width(), in.height());
    for (std::size_t p = 0; p < in.pixel_count(); ++p) {
      const float* s = in.data() + 3 * p;
      const double l = 0.299 * s[0] + 0.587 * s[1] + 0.114 * s[2];
      for (int c = 0; c < 3; ++c) out.data()[3 * p + std::size_t(c)] = float(std::clamp(l * tone[std::size_t(c)] / lt, 0.0, 1.0));
    }
    return out;
  }

  [[nodiscard]] std::vector<Image<float, 3>> edit(const std::vector<Image<float, 3>>& frames, const EditContext& ctx) const {
    std::vector<Image<float, 3>> out;
    out.reserve(frames.size());
    for (std::size_t t = 0; t < frames.size(); ++t) {
      std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ull ^ (std::uint64_t(ctx.phase) << 40) ^ std::uint64_t(t));
      std::uniform_real_distribution<double> u(-1.0, 1.0);
      double g[3], o[3];
      for (int c = 0; c < 3; ++c) g[c] = 1 + gain * u(rng), o[c] = offset * u(rng);
      const double amp = wave * u(rng), phi = 3.14159265358979 * u(rng), psi = 3.14159265358979 * u(rng);
      const double cx = std::cos(phi), sy = std::sin(phi);
      Image<float, 3> e = style(frames[t]);
      for (int y = 0; y < e.height(); ++y)
        for (int x = 0; x < e.width(); ++x) {
          const double wv = amp * std::sin(2 * 3.14159265358979 * (x * cx + y * sy) / period + psi);
          float* p = e.pixel(x, y);
          for (int c = 0; c < 3; ++c) p[c] = float(std::clamp(g[c] * p[c] + o[c] + wv, 0.0, 1.0));
        }
      out.push_back(std::move(e));
    }
    return out;
  }
};

/// An external editor program. `command` is an argument vector (no shell is involved, so paths and
/// prompts need no quoting); in each argument the placeholders
///
///   {input}  folder of the input frames (00000.png, 00001.png, ...)
///   {output} empty folder the program must fill with one edited image per input frame
///   {phase}  0-based phase index,   {phases}  number of phases
///
/// are replaced; if neither {input} nor {output} occurs, the two folders are appended. The output
/// frames are read back in natural order. Each call uses `work_dir/phase_<p>/` (created) and logs the
/// program's output to `work_dir/phase_<p>/editor.log`.
struct CommandEditor {
  std::vector<std::string> command;
  std::filesystem::path work_dir;
  double timeout_seconds = 0;  ///< 0 = none

  /// @throws external_error `external.missing`, `external.spawn`, `external.failed`, `external.editor`;
  ///         io_error from reading or writing the frames.
  [[nodiscard]] std::vector<Image<float, 3>> edit(const std::vector<Image<float, 3>>& frames, const EditContext& ctx) const {
    namespace fs = std::filesystem;
    if (command.empty()) throw option_error("option.editor", "command", "is empty");
    const fs::path dir = work_dir / ("phase_" + std::to_string(ctx.phase));
    const fs::path in = dir / "input", out = dir / "output";
    std::error_code ec;
    fs::remove_all(dir, ec);
    fs::create_directories(in, ec);
    fs::create_directories(out, ec);
    if (ec) throw io_error("io.unwritable", dir.string(), "cannot create folder: " + ec.message());
    for (std::size_t i = 0; i < frames.size(); ++i) {
      char name[32];
      std::snprintf(name, sizeof(name), "%05zu.png", i);
      io::write_png(in / name, frames[i]);
    }
    std::vector<std::string> argv;
    bool placed = false;
    for (const std::string& a : command) {
      std::string s = a;
      auto sub = [&](const std::string& key, const std::string& val) {
        for (std::size_t p = s.find(key); p != std::string::npos; p = s.find(key, p + val.size())) {
          s.replace(p, key.size(), val);
          if (key == "{input}" || key == "{output}") placed = true;
        }
      };
      sub("{input}", in.string());
      sub("{output}", out.string());
      sub("{phases}", std::to_string(ctx.phases));
      sub("{phase}", std::to_string(ctx.phase));
      argv.push_back(std::move(s));
    }
    if (!placed) {
      argv.push_back(in.string());
      argv.push_back(out.string());
    }
    const fs::path log = dir / "editor.log";
    const io::ProcessResult r = io::run_process(argv, log, timeout_seconds);
    if (!r.ok())
      throw external_error("external.failed", argv[0],
                           (r.timed_out ? std::string("timed out") : "exited with code " + std::to_string(r.exit_code)) +
                               "; log " + log.string() + ": " + io::log_tail(log));
    std::vector<Image<float, 3>> edited = io::read_frames(io::list_frames(out));
    check_edited(frames, edited, argv[0]);
    return edited;
  }
};

/// Splits a command line into words the way a POSIX shell splits plain words and quotes ('...',
/// "...", backslash escapes), with no expansion of any kind. @throws option_error `option.editor`
/// on an unterminated quote.
[[nodiscard]] inline std::vector<std::string> split_command_line(const std::string& line) {
  std::vector<std::string> words;
  std::string cur;
  bool in_word = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (c == '\'' || c == '"') {
      const std::size_t j = line.find(c, i + 1);
      if (j == std::string::npos) throw option_error("option.editor", line, "unterminated quote");
      cur += line.substr(i + 1, j - i - 1);
      in_word = true;
      i = j;
    } else if (c == '\\' && i + 1 < line.size()) {
      cur += line[++i];
      in_word = true;
    } else if (c == ' ' || c == '\t' || c == '\n') {
      if (in_word) words.push_back(cur), cur.clear(), in_word = false;
    } else {
      cur += c;
      in_word = true;
    }
  }
  if (in_word) words.push_back(cur);
  return words;
}

static_assert(Editor<FlickerEditor>, "FlickerEditor must model Editor");
static_assert(Editor<CommandEditor>, "CommandEditor must model Editor");

}  // namespace video3dgs
