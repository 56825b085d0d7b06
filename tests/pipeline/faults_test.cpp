// Faults of the output folder (issue 19, item 4): deleted while the job runs, a full disk, a read-only
// folder. Each is an io error with its id and the file or folder at fault, never a crash, and what an
// earlier run wrote stays intact.
#include <csignal>
#include <filesystem>
#include <string>
#include <vector>

#include <sys/mount.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "pipeline_fixture.hpp"

using namespace video3dgs;
namespace fs = std::filesystem;
using namespace test_pipeline;

namespace {

/// The error a call throws (id and place), or {"<no error>", ""}.
template <class F>
std::pair<std::string, std::string> fault_of(F&& f) {
  try {
    f();
  } catch (const video3dgs::error& e) {
    return {e.id(), e.where()};
  }
  return {"<no error>", ""};
}

/// Hidden temporaries of atomic writes left anywhere below `dir`.
std::vector<fs::path> leftover_temporaries(const fs::path& dir) {
  std::vector<fs::path> left;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
    if (it->path().filename().string().find(".tmp.") != std::string::npos) left.push_back(it->path());
  return left;
}

/// The file-size limit (RLIMIT_FSIZE) set to `bytes` for the scope: a write beyond it fails with EFBIG
/// as on a full disk (SIGXFSZ ignored meanwhile).
class FileSizeLimit {
 public:
  explicit FileSizeLimit(rlim_t bytes) {
    ::getrlimit(RLIMIT_FSIZE, &old_);
    old_handler_ = std::signal(SIGXFSZ, SIG_IGN);
    rlimit l = old_;
    l.rlim_cur = bytes;
    ok_ = ::setrlimit(RLIMIT_FSIZE, &l) == 0;
  }
  ~FileSizeLimit() {
    ::setrlimit(RLIMIT_FSIZE, &old_);
    std::signal(SIGXFSZ, old_handler_);
  }
  FileSizeLimit(const FileSizeLimit&) = delete;
  FileSizeLimit& operator=(const FileSizeLimit&) = delete;
  [[nodiscard]] bool ok() const noexcept { return ok_; }

 private:
  rlimit old_{};
  void (*old_handler_)(int) = SIG_DFL;
  bool ok_ = false;
};

/// A small job of each fault test: the written video, 30 iterations per clip, its input prepared.
struct FaultJob {
  Video v;
  pipeline::ReconstructOptions o;
  pipeline::PreparedInput in;
  FakeSfm sfm;
  explicit FaultJob(const fs::path& root) : v(write_video(root / "video")), o(options(v, root / "out")) {
    o.iterations = 30;
    in = pipeline::prepare_input(o);
    sfm = FakeSfm{&v.clip};
  }
  FaultJob(const FaultJob&) = delete;  // sfm points into v
  FaultJob& operator=(const FaultJob&) = delete;
};

}  // namespace

TEST_CASE("faults: the output folder deleted while frames render is an io error naming a path in it") {
  const auto root = temp_dir("fault_deleted");
  FaultJob job(root);
  auto& [v, o, in, sfm] = job;
  pipeline::ReconstructHooks hooks;
  hooks.progress = [&](const pipeline::ProgressEvent& e) {
    if (e.stage == pipeline::ProgressEvent::Stage::render && e.frame == 2) fs::remove_all(o.out);
  };
  const auto [id, where] = fault_of([&] { (void)pipeline::reconstruct_video(o, in, sfm, hooks); });
  INFO(id << " at " << where);
  CHECK((id == "io.unwritable" || id == "io.missing"));
  CHECK(where.rfind(o.out.string(), 0) == 0);
  CHECK_FALSE(fs::exists(o.out / "report.json"));
  fs::remove_all(root);
}

TEST_CASE("faults: a full disk fails the write that does not fit with io.unwritable; earlier outputs stay intact") {
  const auto root = temp_dir("fault_full");
  FaultJob job(root);
  auto& [v, o, in, sfm] = job;
  (void)pipeline::reconstruct_video(o, in, sfm);
  const std::string model_before = slurp(o.out / "model" / "clip_000.model"), report_before = slurp(o.out / "report.json");
  REQUIRE(model_before.size() > 64 * 1024);

  o.overwrite = true;
  o.seed = 11;  // a different model, so an overwrite would show
  std::pair<std::string, std::string> fault;
  {
    const FileSizeLimit limit(16 * 1024);  // smaller than a clip model, larger than any state file
    REQUIRE(limit.ok());
    fault = fault_of([&] { (void)pipeline::reconstruct_video(o, in, sfm); });
  }
  INFO(fault.first << " at " << fault.second);
  CHECK(fault.first == "io.unwritable");
  CHECK(fault.second == (o.out / "model" / "clip_000.model").string());
  CHECK(slurp(o.out / "model" / "clip_000.model") == model_before);
  CHECK(slurp(o.out / "report.json") == report_before);
  CHECK(leftover_temporaries(o.out).empty());
  // With room again, the same job finishes.
  const auto rep = pipeline::reconstruct_video(o, in, sfm);
  CHECK(rep.clips.size() == 2);
  CHECK(slurp(o.out / "model" / "clip_000.model") != model_before);
  fs::remove_all(root);
}

TEST_CASE("faults: a read-only output folder is io.unwritable naming the file; nothing in it changes" * doctest::test_suite("needs_program")) {
  const auto root = temp_dir("fault_readonly");
  FaultJob job(root);
  auto& [v, o, in, sfm] = job;
  (void)pipeline::reconstruct_video(o, in, sfm);
  const std::string model_before = slurp(o.out / "model" / "clip_000.model");
  // Permission bits do not stop root: there the folder becomes a read-only bind mount of itself.
  bool mounted = false;
  if (::geteuid() == 0) {
    if (::mount(o.out.c_str(), o.out.c_str(), nullptr, MS_BIND | MS_REC, nullptr) != 0) {
      test::skip("a read-only folder for root needs mount(2) (CAP_SYS_ADMIN)");
      fs::remove_all(root);
      return;
    }
    mounted = true;
    REQUIRE(::mount(nullptr, o.out.c_str(), nullptr, MS_REMOUNT | MS_BIND | MS_RDONLY, nullptr) == 0);
  } else {
    for (const auto& d : {o.out, o.out / "model", o.out / "train"}) fs::permissions(d, fs::perms::owner_read | fs::perms::owner_exec);
  }
  o.overwrite = true;
  o.seed = 11;
  const auto [id, where] = fault_of([&] { (void)pipeline::reconstruct_video(o, in, sfm); });
  if (mounted) ::umount(o.out.c_str());
  else
    for (const auto& d : {o.out, o.out / "model", o.out / "train"}) fs::permissions(d, fs::perms::owner_all);
  INFO(id << " at " << where);
  CHECK(id == "io.unwritable");
  CHECK(where.rfind(o.out.string(), 0) == 0);
  CHECK(slurp(o.out / "model" / "clip_000.model") == model_before);
  fs::remove_all(root);
}
