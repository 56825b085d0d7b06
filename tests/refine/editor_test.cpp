// Tests of include/video3dgs/refine/editor.hpp: the flickering test editor, command-line
// splitting, and the command editor (external program, no shell) with its errors.
#include <cstdio>
#include <filesystem>
#include <vector>

#include <doctest/doctest.h>

#include "video3dgs/refine/editor.hpp"

using namespace video3dgs;

namespace {
std::vector<Image<float, 3>> gradient_frames(int n) {
  std::vector<Image<float, 3>> v;
  for (int t = 0; t < n; ++t) {
    Image<float, 3> f(16, 12);
    for (int y = 0; y < 12; ++y)
      for (int x = 0; x < 16; ++x)
        for (int c = 0; c < 3; ++c) f(x, y, c) = float((x + 2 * y + 3 * c + t) % 17) / 16.f;
    v.push_back(f);
  }
  return v;
}
std::string id_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const error& e) {
    return e.id();
  }
  return "none";
}
}  // namespace

TEST_CASE("FlickerEditor: style is idempotent, edits are seeded, in range, and flicker") {
  FlickerEditor ed;
  const auto frames = gradient_frames(4);
  Image<float, 3> dim = frames[0];
  for (float& v : dim.storage()) v *= 0.5f;  // no channel clips: S(S(x)) = S(x) exactly
  const auto s = ed.style(dim);
  const auto ss = ed.style(s);
  for (std::size_t i = 0; i < s.size(); ++i) CHECK(ss.data()[i] == doctest::Approx(s.data()[i]).epsilon(1e-5));
  const auto a = ed.edit(frames, {0, 2});
  const auto b = ed.edit(frames, {0, 2});
  const auto c = ed.edit(frames, {1, 2});
  REQUIRE(a.size() == 4);
  CHECK(a[1].storage() == b[1].storage());
  CHECK(a[1].storage() != c[1].storage());
  for (const auto& f : a)
    for (float v : f.storage()) CHECK((v >= 0.f && v <= 1.f));
  // same input frame, different time -> different output (flicker)
  const std::vector<Image<float, 3>> still(3, frames[0]);
  const auto e = ed.edit(still, {});
  CHECK(e[0].storage() != e[1].storage());
}

TEST_CASE("split_command_line: quotes and escapes, no expansion") {
  CHECK(split_command_line("a b  c") == std::vector<std::string>{"a", "b", "c"});
  CHECK(split_command_line("edit --prompt 'a watercolor painting' \"x y\"") ==
        std::vector<std::string>{"edit", "--prompt", "a watercolor painting", "x y"});
  CHECK(split_command_line("a\\ b $HOME;rm") == std::vector<std::string>{"a b", "$HOME;rm"});
  CHECK(split_command_line("").empty());
  CHECK(id_of([] { (void)split_command_line("a 'b"); }) == "option.editor");
}

TEST_CASE("CommandEditor: runs a program on frame folders (placeholders, appended folders) and reports failures") {
  namespace fs = std::filesystem;
  const fs::path work = fs::temp_directory_path() / "video3dgs_editor_test dir with spaces";
  fs::remove_all(work);
  const auto frames = gradient_frames(3);
  CommandEditor ed;
  ed.work_dir = work;
  // /bin/sh receives the folders as positional parameters: no string is ever parsed by a shell.
  ed.command = {"/bin/sh", "-c", "cp \"$0\"/*.png \"$1\"/ && test \"$2\" = 1", "{input}", "{output}", "{phase}"};
  const auto out = ed.edit(frames, {1, 2});
  REQUIRE(out.size() == 3);
  for (std::size_t i = 0; i < 3; ++i)
    for (std::size_t k = 0; k < out[i].size(); ++k) CHECK(out[i].data()[k] == doctest::Approx(frames[i].data()[k]).epsilon(0.003));
  CHECK(fs::exists(work / "phase_1" / "editor.log"));
  // folders appended when no placeholder is used
  ed.command = {"/bin/sh", "-c", "cp \"$0\"/*.png \"$1\"/"};
  CHECK(ed.edit(frames, {0, 1}).size() == 3);
  // failures
  ed.command = {"/bin/sh", "-c", "exit 3"};
  CHECK(id_of([&] { (void)ed.edit(frames, {0, 1}); }) == "external.failed");
  ed.command = {"/nonexistent/editor"};
  CHECK(id_of([&] { (void)ed.edit(frames, {0, 1}); }) == "external.missing");
  ed.command = {"/bin/sh", "-c", "cp \"$0\"/00000.png \"$1\"/"};
  CHECK(id_of([&] { (void)ed.edit(frames, {0, 1}); }) == "external.editor");
  ed.command = {};
  CHECK(id_of([&] { (void)ed.edit(frames, {0, 1}); }) == "option.editor");
  fs::remove_all(work);
}
