// pipeline/refine.hpp: the stage-2 job on a reconstruction of the synthetic video and a flickering
// edit of it: input checks with their ids (nothing written), then outputs and report.json.
#include <cmath>
#include <filesystem>
#include <string>

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include "pipeline_fixture.hpp"
#include "video3dgs/pipeline/refine.hpp"

using namespace video3dgs;
using namespace test_pipeline;

TEST_CASE("refine_edited_video: checks every input first, then writes the refined video, model and report") {
  const auto root = temp_dir("refine_job");
  const Video v = write_video(root / "video", 6);
  ThreadPool pool(2);
  auto ro = options(v, root / "recon");
  ro.iterations = 60;
  ro.write_ply = false;
  FakeSfm sfm{&v.clip};
  (void)pipeline::reconstruct_video(ro, pipeline::prepare_input(ro, &pool), sfm, {}, &pool);
  // The edit: every other frame brighter (a flicker the refinement should smooth), and a short copy.
  fs::create_directories(root / "edit");
  fs::create_directories(root / "short");
  for (int f = 0; f < 6; ++f) {
    Image<float, 3> e = v.clip.frames[std::size_t(f)];
    for (float& x : e.storage()) x = std::min(1.0f, x * (f % 2 ? 1.25f : 1.0f));
    io::write_png(root / "edit" / (std::to_string(f) + ".png"), e);
    if (f < 5) io::write_png(root / "short" / (std::to_string(f) + ".png"), e);
  }
  pipeline::RefineJobOptions o;
  o.model = root / "recon";
  o.source = v.dir / "frames";
  o.out = root / "refined";
  o.refine.iterations = 30;
  auto id_of = [&](const pipeline::RefineJobOptions& bad) {
    try {
      (void)pipeline::prepare_refine_input(bad, &pool);
    } catch (const error& e) {
      return e.id();
    }
    return std::string("none");
  };
  CHECK(id_of(o) == "option.refine");  // neither --edited nor an editor
  o.edited = {root / "short"};
  CHECK(id_of(o) == "io.count_mismatch");
  o.edited = {root / "edit"};
  auto flows = o;
  flows.flow_forward = root;
  CHECK(id_of(flows) == "option.warp_ssim");
  CHECK(!fs::exists(o.out));  // nothing written by a failed check

  auto in = pipeline::prepare_refine_input(o, &pool);
  CHECK(in.source.size() == 6);
  const auto rep = pipeline::refine_edited_video(o, in, &pool);
  CHECK(rep.frames == 6);
  CHECK(rep.width == 48);
  REQUIRE(rep.edits.size() == 1);
  CHECK(rep.stats.clips.size() == 1);
  CHECK(rep.stats.clips[0].iterations == 30);
  CHECK(std::isfinite(rep.warp_ssim_refined));
  CHECK(rep.psnr_refined_vs_edited > 15);
  for (const char* f : {"refined/00000.png", "refined/00005.png", "compare/00005.png", "model/manifest.txt", "report.json"})
    CHECK_MESSAGE(fs::exists(o.out / f), f);
  const auto j = nlohmann::json::parse(slurp(o.out / "report.json"));
  CHECK(j.at("frames") == 6);
  CHECK(j.at("iterations") == 30);
  CHECK(j.at("edits").at(0).at("dir") == (root / "edit").string());
  CHECK(j.at("warp_ssim_refined").get<double>() == doctest::Approx(rep.warp_ssim_refined));
  CHECK(j.at("seconds").get<double>() > 0);
  CHECK(!j.contains("phases"));
  fs::remove_all(root);
}
