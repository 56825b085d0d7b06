// pipeline/reconstruct.hpp without COLMAP: a fake SfM back end that returns the synthetic video's exact
// cameras. Checks the outputs and report, --resume (no retraining, identical model), a stop request
// (checkpoint kept, [run.interrupted], then resumed to the same result), the quality floor (extension,
// resume inside it, key), --scale, and the input checks
// (`prepare_input`) with their ids, none of which writes anything.
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <thread>
#include <filesystem>
#include <optional>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>

#include <unistd.h>

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include "video3dgs/io/image_io.hpp"
#include "video3dgs/pipeline/reconstruct.hpp"
#include "video3dgs/synthetic/clip.hpp"
#include "../test_data.hpp"
#include "pipeline_fixture.hpp"

using namespace video3dgs;
namespace fs = std::filesystem;

using namespace test_pipeline;

TEST_CASE("reconstruct_video: outputs, report, resume without retraining") {
  const auto root = temp_dir("full");
  const Video v = write_video(root / "video");
  ThreadPool pool(2);
  auto o = options(v, root / "out");
  const auto in = pipeline::prepare_input(o, &pool);
  CHECK(in.frame_count() == 10);
  CHECK(in.list.masks.size() == 10);
  CHECK(in.masks({0, 9}).size() == 10);
  FakeSfm sfm{&v.clip};
  const auto rep = pipeline::reconstruct_video(o, in, sfm, {}, &pool);
  // 10 frames, k = 6: clips 0-5 and 4-9 (the tail extended back to 6 frames).
  REQUIRE(rep.clips.size() == 2);
  CHECK(rep.clips[0].first == 0);
  CHECK(rep.clips[1].last == 9);
  CHECK(rep.trained_clips == 2);
  CHECK(rep.frames == 10);
  CHECK(rep.psnr_per_frame.size() == 10);
  CHECK(std::isfinite(rep.psnr));
  CHECK(rep.psnr > rep.psnr_mean_colour + 2);  // 100 iterations clearly beat a flat image
  CHECK(rep.clips[0].iterations == 100);
  CHECK(rep.clips[0].model_bytes > 0);
  for (const char* f : {"report.json", "metrics.csv", "metrics.png", "model/manifest.txt", "model/clip_000.model", "model/clip_001.model",
                        "renders/00000.png", "renders/00009.png", "compare/00009.png", "ply/clip_000_frg.ply", "ply/clip_001_bkg.ply",
                        "train/clip_001.done"})
    CHECK_MESSAGE(fs::exists(o.out / f), f);
  CHECK(!fs::exists(o.out / "train/clip_000.ckpt"));
  const std::string report = slurp(o.out / "report.json");
  CHECK(report.find("\"clips\":[{\"first\":0,\"last\":5") != std::string::npos);
  // A back end without attempts() cannot say whether its SfM saw masked frames: null, not a guess.
  CHECK(!rep.clips[0].sfm_masked.has_value());
  CHECK(report.find("\"sfm_masked\":null") != std::string::npos);
  // Per clip: each set's PSNR alone, the merge weight inside / outside the masks, SfM's error.
  for (const auto& cr : rep.clips) {
    REQUIRE(cr.psnr_frg.has_value());
    REQUIRE(cr.psnr_bkg.has_value());
    CHECK(std::isfinite(*cr.psnr_frg));
    CHECK(std::isfinite(*cr.psnr_bkg));
    REQUIRE(cr.alpha_inside.has_value());
    REQUIRE(cr.alpha_outside.has_value());
    CHECK((*cr.alpha_inside > 0 && *cr.alpha_inside < 1 && *cr.alpha_outside > 0 && *cr.alpha_outside < 1));
    CHECK(*cr.alpha_inside != *cr.alpha_outside);  // trained, not the initial 0.5 everywhere
    REQUIRE(cr.sfm_reprojection_error.has_value());
    CHECK(*cr.sfm_reprojection_error >= 0);
    // Each set's hash grid as trained: the default 2^16 entries x 16 levels.
    CHECK(cr.log2_table_frg == 16);
    CHECK(cr.log2_table_bkg == 16);
    CHECK(cr.grid_levels_frg == 16);
    CHECK(cr.grid_levels_bkg == 16);
    // One time cell per frame (the default): the clip's frames - 1.
    CHECK(cr.time_cells_frg == cr.last - cr.first);
    CHECK(cr.time_cells_bkg == cr.last - cr.first);
  }
  CHECK(report.find("\"log2_table_frg\":16,\"log2_table_bkg\":16,\"grid_levels_frg\":16,\"grid_levels_bkg\":16") != std::string::npos);
  CHECK(report.find("\"psnr_frg\":") != std::string::npos);
  CHECK(report.find("\"alpha_inside\":") != std::string::npos);
  // What the clips were trained with: the default preset's settings at these iterations.
  CHECK(report.find("\"training\":{\"preset\":\"balanced\",\"iterations\":100,\"resolution_schedule\":[{\"from_iteration\":0,\"scale\":0.25},"
                    "{\"from_iteration\":33,\"scale\":0.5},{\"from_iteration\":67,\"scale\":1.0}],\"resolution_min_size\":200,"
                    "\"prune_weight\":0.0") != std::string::npos);
  CHECK(report.find("\"sparse_adam\":false,\"camera_lr\":[0.0,0.0],\"lr_deformation\":0.0008,\"lr_sh\":{\"dc\":0.0025,\"rest\":0.000125},\"lr_position_fine\":{\"factor\":1.0,\"from\":67},"
                    "\"lr_alpha_fine\":{\"factor\":3.0,\"from\":67},\"lr_sh_fine\":{\"factor\":8.0,\"from\":67},\"lr_anneal\":null,\"lambda_dssim\":0.2,\"lambda_dssim_fine\":{\"from\":67,\"value\":0.4},\"extend\":{\"below_psnr\":0.0,\"max_iterations\":2000,\"step\":500}}") !=
        std::string::npos);  // no camera refinement, no stepped position rate, the paper's colour rates, the preset's alpha rate x 3, colour rates x 8 and D-SSIM 0.4 at full size, no anneal, no floor by default
  // compare/ is source | render | heat map.
  CHECK(io::read_image_info(o.out / "compare/00000.png").width == 3 * 48 + 4);

  // Without resume/overwrite the folder is refused; with resume nothing is retrained.
  CHECK_THROWS_WITH_AS((void)pipeline::prepare_input(o, &pool), doctest::Contains("[io.output_exists]"), io_error);
  const std::string model0 = slurp(o.out / "model/clip_000.model");
  o.resume = true;
  FakeSfm sfm2{&v.clip};
  const auto rep2 = pipeline::reconstruct_video(o, pipeline::prepare_input(o, &pool), sfm2, {}, &pool);
  CHECK(rep2.trained_clips == 0);
  CHECK(rep2.clips[0].reused);
  CHECK(rep2.psnr == rep.psnr);
  // A reused clip reports the figures of the run that trained it (.done) or of its saved model.
  CHECK(rep2.clips[0].psnr_frg == rep.clips[0].psnr_frg);
  CHECK(rep2.clips[0].psnr_bkg == rep.clips[0].psnr_bkg);
  CHECK(rep2.clips[0].alpha_inside == rep.clips[0].alpha_inside);
  CHECK(rep2.clips[1].alpha_outside == rep.clips[1].alpha_outside);
  CHECK(rep2.clips[1].log2_table_bkg == 16);  // read from the saved model
  CHECK(slurp(o.out / "model/clip_000.model") == model0);
  CHECK(!rep2.clips[0].compact_bytes.has_value());
  CHECK(report.find("\"compact_bytes\":null") != std::string::npos);
  // compact on a resumed run: the clips are reused, each is also written compact, its bytes reported.
  {
    auto oc = o;
    oc.compact = CompactOptions{};
    FakeSfm sfmc{&v.clip};
    const auto repc = pipeline::reconstruct_video(oc, pipeline::prepare_input(oc, &pool), sfmc, {}, &pool);
    CHECK(repc.trained_clips == 0);
    REQUIRE(repc.clips[1].compact_bytes.has_value());
    CHECK(repc.clips[1].compact_bytes->total == fs::file_size(o.out / "model/clip_001.compact"));
    CHECK(repc.clips[1].compact_bytes->total < repc.clips[1].model_bytes);
    const auto back = load_compact_clip_model<float>(o.out / "model/clip_001.compact");
    CHECK(back.frg.size() == repc.clips[1].gaussians_frg);
    CHECK(slurp(o.out / "report.json").find("\"compact_bytes\":{\"gaussians\":") != std::string::npos);
    CHECK(slurp(o.out / "model/clip_000.model") == model0);
  }
  // clip_NNN.done is JSON under a stable key; a key=value file of version 0.1 (its key the std::hash
  // of the same settings text) is still recognised on resume.
  const auto done = nlohmann::json::parse(slurp(o.out / "train/clip_000.done"));
  CHECK(done.at("key").get<std::string>().size() == 16);
  CHECK(done.at("iterations") == 100);
  {
    const auto in2 = pipeline::prepare_input(o, &pool);
    FakeSfm s3{&v.clip};
    const auto stage1 = pipeline::sfm_stage(o, in2, s3);
    const auto key = pipeline::clip_key(o, in2, o.train_options(), stage1.clips[0]);
    CHECK(key.key == done.at("key").get<std::string>());
    CHECK(key.key == stable_key(key.text));
    // Any training setting enters the key, also one no option of the job sets (a preset's base rate,
    // as an upgrade may change it): such a clip is retrained, not reused.
    {
      TrainOptions other = o.train_options();
      other.lr_sh_dc *= 2;
      CHECK(pipeline::clip_key(o, in2, other, stage1.clips[0]).key != key.key);
      other.lr_sh_dc = o.train_options().lr_sh_dc;
      CHECK(pipeline::clip_key(o, in2, other, stage1.clips[0]).key == key.key);
    }
    // --join-tail reaches the scheduler: with k = 6 the first clip, 0-5, would leave 4 frames, and
    // with join_tail 4 it takes them in (the method's schedule is 0-5 and 4-9).
    {
      REQUIRE(stage1.clips.size() == 2);
      CHECK(stage1.clips[1].range == FrameRange{4, 9});
      auto oj = o;
      oj.join_tail = 4;
      FakeSfm sj{&v.clip};
      const auto joined = pipeline::sfm_stage(oj, in2, sj);
      REQUIRE(joined.clips.size() == 1);
      CHECK(joined.clips[0].range == FrameRange{0, 9});
      CHECK(sj.calls == 1);
      oj.join_tail = 5;  // above k - 2 (sfm_stage's overlap is 1): refused before any frame is read
      CHECK_THROWS_WITH_AS(oj.validate(), doctest::Contains("--join-tail"), option_error);
    }
    // The masks enter the key, each frame's by its path: the same run without masks, or with masks
    // found elsewhere, does not reuse these clips.
    REQUIRE(in2.has_masks());
    CHECK(key.text.find("|masks|" + fs::absolute(in2.list.masks[0]).string() + "|") != std::string::npos);
    auto in_unmasked = in2;
    in_unmasked.list.masks.clear();
    const auto kun = pipeline::clip_key(o, in_unmasked, o.train_options(), stage1.clips[0]);
    CHECK(kun.key != key.key);
    CHECK(kun.text.find("|masks") == std::string::npos);
    auto in_moved = in2;
    in_moved.list.masks[1] = in_moved.list.masks[1].parent_path() / "elsewhere" / in_moved.list.masks[1].filename();
    CHECK(pipeline::clip_key(o, in_moved, o.train_options(), stage1.clips[0]).key != key.key);
    // A resolution schedule is given for the preset's iterations, scales with --iterations, and
    // enters the key (only when set: the key above is unchanged).
    auto ores = o;
    ores.resolution_schedule = {{0, 0.25}, {1500, 1.0}};
    const TrainOptions tres = ores.train_options();  // 100 of the balanced preset's 3000 iterations
    REQUIRE(tres.resolution_schedule.size() == 2);
    CHECK(tres.resolution_schedule[1].from_iteration == 50);
    CHECK(tres.resolution_schedule[1].scale == 1.0);
    // balanced's fine phase moves with it: the alpha maps' step from the schedule's first full-size
    // iteration, x 3000 / 1500 = 2 (TrainOptions::with_resolution_schedule); --fine-alpha-lr still wins.
    CHECK(tres.lr_fine_from == 50);
    CHECK(tres.lr_alpha_fine == 2);
    auto ores_alpha = ores;
    ores_alpha.fine_alpha_lr = 5;
    CHECK(ores_alpha.train_options().lr_alpha_fine == 5);
    CHECK(ores_alpha.train_options().lr_fine_from == 50);
    CHECK(pipeline::clip_key(ores, in2, tres, stage1.clips[0]).key != key.key);
    // The default preset, balanced: its schedule scaled with --iterations (1000 and 2000 of 3000 ->
    // 33 and 67 of 100), no pruning by weight; --prune-weight and the reference preset override them.
    const TrainOptions tdef = o.train_options();
    REQUIRE(tdef.resolution_schedule.size() == 3);
    CHECK(tdef.resolution_schedule[1].from_iteration == 33);
    CHECK(tdef.resolution_schedule[2].from_iteration == 67);
    CHECK(tdef.prune_weight == 0);
    // balanced's one efficiency prune, 50 iterations after its last densification event (2050 of
    // 3000 -> 68 of 100).
    CHECK(tdef.prune_efficiency == 0.01);
    CHECK(tdef.prune_efficiency_at == 68);
    CHECK(key.text.find("|prune_eff=0.01@68") != std::string::npos);
    auto onp = o;
    onp.prune_weight = 0.25;
    CHECK(onp.train_options().prune_weight == 0.25);
    CHECK(pipeline::clip_key(onp, in2, onp.train_options(), stage1.clips[0]).key != key.key);
    auto ocrop = o;
    ocrop.crop = 0.5;
    CHECK(ocrop.train_options().crop == 0.5);
    CHECK(tdef.crop == 0);
    CHECK(pipeline::clip_key(ocrop, in2, ocrop.train_options(), stage1.clips[0]).key != key.key);
    // The periodic efficiency prune: its start scaled (1500 of 3000 -> 50, the scaled run's one event at
    // interval 50), no one-shot prune unless --prune-efficiency-at is given; both enter the key.
    auto ope = o;
    ope.prune_efficiency = 0.01;
    ope.prune_efficiency_from = 1500;
    const TrainOptions tpe = ope.train_options();
    CHECK(tpe.prune_efficiency_at == 0);
    CHECK(tpe.prune_efficiency_from == 50);
    CHECK(tpe.first_efficiency_event() == 50);
    CHECK_NOTHROW(tpe.validate());
    const auto kpe = pipeline::clip_key(ope, in2, tpe, stage1.clips[0]);
    CHECK(kpe.text.find("@0|prune_eff_from=50") != std::string::npos);
    ope.prune_efficiency_at = 2050;  // both: the one-shot prune kept, scaled
    CHECK(ope.train_options().prune_efficiency_at == 68);
    CHECK(pipeline::clip_key(ope, in2, ope.train_options(), stage1.clips[0]).key != kpe.key);
    ope.prune_efficiency_bkg = 0.03;  // the background's own threshold: passed on, in the key
    CHECK(ope.train_options().prune_efficiency_bkg == 0.03);
    CHECK(ope.train_options().prune_efficiency == 0.01);
    CHECK(pipeline::clip_key(ope, in2, ope.train_options(), stage1.clips[0]).text.find("|prune_eff_bkg=0.029999999999999999") != std::string::npos);
    ope.prune_efficiency = 0;  // off: its start and the background's threshold say nothing
    CHECK(ope.train_options().prune_efficiency == 0);
    CHECK(ope.train_options().prune_efficiency_at == 0);
    CHECK(ope.train_options().prune_efficiency_from == 0);
    CHECK(ope.train_options().prune_efficiency_bkg == 0);
    CHECK(ope.train_options().settings_text().find("prune_efficiency") == std::string::npos);
    // Unset: the preset's prune (balanced's E = 0.01), which the other flags adjust.
    ope.prune_efficiency.reset();
    CHECK(ope.train_options().prune_efficiency == 0.01);
    CHECK(ope.train_options().prune_efficiency_from == 50);
    CHECK(ope.train_options().prune_efficiency_bkg == 0.03);
    ope.prune_efficiency_from.reset(), ope.prune_efficiency_at.reset();
    CHECK(ope.train_options().prune_efficiency_at == 68);  // the preset's 2050, scaled
    auto oref = o;
    oref.preset = "reference";
    CHECK(oref.train_options().resolution_schedule.empty());
    CHECK(oref.train_options().prune_weight == 0);
    CHECK(oref.train_options().prune_efficiency == 0);
    CHECK(pipeline::clip_key(oref, in2, oref.train_options(), stage1.clips[0]).key != key.key);
    // Alpha maps from the masks: off by default (no text), on it enters the key with both values.
    CHECK(key.text.find("alpha_mask") == std::string::npos);
    auto oam = o;
    oam.model.alpha_mask = 0.9;
    const auto kam = pipeline::clip_key(oam, in2, oam.train_options(), stage1.clips[0]);
    CHECK(kam.key != key.key);
    CHECK(kam.text.find("|alpha_mask=0.90000000000000002,0.10000000000000001") != std::string::npos);
    // Background colours: from the frames by default ("|bkg_colour=frames"); the method's draw leaves no
    // text, as keys written before the option existed have none.
    CHECK(pipeline::ReconstructOptions{}.model.background_colour == BackgroundColour::frames);
    CHECK(recommended_model_options().departures_key() == "|bkg_colour=frames|cull_unseen=16");  // the departures the key names
    CHECK(ClipModelOptions{}.departures_key().empty());                              // the reference
    CHECK(key.text.find("|bkg_colour=frames") != std::string::npos);
    auto obc = o;
    obc.model.background_colour = BackgroundColour::random;
    const auto kbc = pipeline::clip_key(obc, in2, obc.train_options(), stage1.clips[0]);
    CHECK(kbc.key != key.key);
    CHECK(kbc.text.find("bkg_colour") == std::string::npos);
    // Unseen initial Gaussians: dropped by default ("|cull_unseen=16", the guard band); kept (--keep-unseen), no text.
    CHECK(key.text.find("|cull_unseen=16") != std::string::npos);
    auto oku = o;
    oku.model.cull_unseen = false;
    const auto kku = pipeline::clip_key(oku, in2, oku.train_options(), stage1.clips[0]);
    CHECK(kku.key != key.key);
    CHECK(kku.text.find("cull_unseen") == std::string::npos);
    // The grids' time cap: the default (one cell per frame) enters the key; no cap leaves the text as
    // it was before the cap existed (grids of the default size print nothing).
    auto onone = o;
    onone.model.frg_grid.time_cells = onone.model.bkg_grid.time_cells = 0;
    const auto knone = pipeline::clip_key(onone, in2, onone.train_options(), stage1.clips[0]);
    CHECK(knone.key != key.key);
    CHECK(key.text.find("|frg_grid_time=frames|bkg_grid_time=frames") != std::string::npos);
    CHECK(knone.text.find("|frg_grid") == std::string::npos);
    CHECK(knone.text.find("|bkg_grid") == std::string::npos);
    // Camera refinement: off in every preset (no text in the key); on, its rates enter the key.
    CHECK(!tdef.refines_cameras());
    CHECK(key.text.find("|cameras") == std::string::npos);
    auto ocam = o;
    ocam.camera_lr = std::array<double, 2>{1e-4, 2e-4};
    const TrainOptions tcam = ocam.train_options();
    CHECK(tcam.lr_camera_rotation == 1e-4);
    CHECK(tcam.lr_camera_translation == 2e-4);
    const auto kcam = pipeline::clip_key(ocam, in2, tcam, stage1.clips[0]);
    CHECK(kcam.key != key.key);
    CHECK(kcam.text.find("|cameras=0.0001,0.00020000000000000001") != std::string::npos);
    ocam.camera_lr = std::array<double, 2>{0, 0};
    CHECK(pipeline::clip_key(ocam, in2, ocam.train_options(), stage1.clips[0]).key == key.key);
    // The fields' rate and a fixed foreground share enter the key only when they differ from the
    // preset's / are set, so earlier runs' keys stay valid.
    CHECK(key.text.find("|lr_def") == std::string::npos);
    CHECK(key.text.find("|frg_share") == std::string::npos);
    auto olr = o;
    olr.deformation_lr = 1.6e-3;
    CHECK(olr.train_options().lr_deformation_init == 1.6e-3);
    CHECK(olr.train_options().lr_deformation_final == tdef.lr_deformation_final);
    const auto klr = pipeline::clip_key(olr, in2, olr.train_options(), stage1.clips[0]);
    CHECK(klr.key != key.key);
    CHECK(klr.text.find("|lr_def=0.0016") != std::string::npos);
    olr.deformation_lr = tdef.lr_deformation_init;
    CHECK(pipeline::clip_key(olr, in2, olr.train_options(), stage1.clips[0]).key == key.key);
    // The colours' rate for the whole run: the DC band's as given, the other bands' a twentieth; in the
    // key only where it departs from the preset's.
    CHECK(key.text.find("|lr_sh=") == std::string::npos);
    auto osh = o;
    osh.sh_lr = 4e-3;
    CHECK(osh.train_options().lr_sh_dc == 4e-3);
    CHECK(osh.train_options().lr_sh_rest == 4e-3 / 20);
    CHECK(osh.train_options().lr_sh_fine == tdef.lr_sh_fine);
    const auto ksh = pipeline::clip_key(osh, in2, osh.train_options(), stage1.clips[0]);
    CHECK(ksh.key != key.key);
    CHECK(ksh.text.find("|lr_sh=0.0040000000000000001,0.00020000000000000001") != std::string::npos);
    osh.sh_lr = tdef.lr_sh_dc;
    CHECK(pipeline::clip_key(osh, in2, osh.train_options(), stage1.clips[0]).key == key.key);
    osh.sh_lr = -1;
    CHECK(test::error_id([&] { (void)osh.train_options(); }) == "option.train");
    // A fine-phase rate step given by hand (ReconstructOptions::fine_*_lr) sets the TrainOptions field,
    // enters the key with its factor and first iteration, and a negative factor is refused.
    const std::string at = "@" + std::to_string(tdef.lr_fine_from);
    const auto check_step = [&](std::optional<double> pipeline::ReconstructOptions::*given, double TrainOptions::*field, double f,
                                const std::string& text) {
      auto os = o;
      os.*given = f;
      CHECK(os.train_options().*field == f);
      CHECK(os.train_options().lr_fine_from == tdef.lr_fine_from);
      const auto ks = pipeline::clip_key(os, in2, os.train_options(), stage1.clips[0]);
      CHECK(ks.key != key.key);
      CHECK(ks.text.find(text + at) != std::string::npos);
      os.*given = -1;
      CHECK(test::error_id([&] { (void)os.train_options(); }) == "option.train");
    };
    // No preset steps the position rate; the default preset's alpha (x 3) and colour (x 8) steps are
    // in its key.
    CHECK(key.text.find("|lr_pos_fine") == std::string::npos);
    CHECK(key.text.find("|lr_alpha_fine=3" + at) != std::string::npos);
    CHECK(key.text.find("|lr_sh_fine=8" + at) != std::string::npos);
    check_step(&pipeline::ReconstructOptions::fine_position_lr, &TrainOptions::lr_position_fine, 0.5, "|lr_pos_fine=0.5");
    check_step(&pipeline::ReconstructOptions::fine_alpha_lr, &TrainOptions::lr_alpha_fine, 5, "|lr_alpha_fine=5");
    check_step(&pipeline::ReconstructOptions::fine_sh_lr, &TrainOptions::lr_sh_fine, 4, "|lr_sh_fine=4");
    // A factor of 1 is no step: it leaves the key.
    auto oalpha = o;
    oalpha.fine_alpha_lr = 1;
    const auto kalpha = pipeline::clip_key(oalpha, in2, oalpha.train_options(), stage1.clips[0]);
    CHECK(kalpha.key != key.key);
    CHECK(kalpha.text.find("|lr_alpha_fine") == std::string::npos);
    // The fine phase's D-SSIM weight: the default preset's (0.4) is in the key with its first
    // iteration, another value changes it; the paper's presets have none.
    CHECK(key.text.find("|dssim_fine=0.4") != std::string::npos);
    CHECK(tdef.lambda_dssim_at(tdef.lr_fine_from) == 0.4);
    auto odssim = o;
    odssim.fine_dssim = 0.6;
    CHECK(odssim.train_options().lambda_dssim_fine == 0.6);
    const auto kdssim = pipeline::clip_key(odssim, in2, odssim.train_options(), stage1.clips[0]);
    CHECK(kdssim.key != key.key);
    CHECK(kdssim.text.find("|dssim_fine=0.59999999999999998@" + std::to_string(tdef.lr_fine_from)) != std::string::npos);
    auto oref3k = o;
    oref3k.preset = "3k";
    CHECK(pipeline::clip_key(oref3k, in2, oref3k.train_options(), stage1.clips[0]).text.find("|dssim_fine") == std::string::npos);
    odssim.fine_dssim = 1.5;
    CHECK(test::error_id([&] { (void)odssim.train_options(); }) == "option.train");
    // The anneal: --anneal-lr alone starts half way through the preset's fine phase (2500 of 3000 ->
    // 83 of 100), --anneal-from moves it (in the preset's iterations), both enter the key; 1 is none,
    // and a start without an anneal is refused with the field's name.
    CHECK(key.text.find("|anneal") == std::string::npos);
    CHECK(tdef.lr_anneal_from == 0);
    auto oanneal = o;
    oanneal.anneal_lr = 0.5;
    const TrainOptions tanneal = oanneal.train_options();
    CHECK(tanneal.lr_anneal_factor == 0.5);
    CHECK(tanneal.lr_anneal_from == 83);
    const auto kanneal = pipeline::clip_key(oanneal, in2, tanneal, stage1.clips[0]);
    CHECK(kanneal.key != key.key);
    CHECK(kanneal.text.find("|anneal=0.5@83") != std::string::npos);
    oanneal.anneal_from = 2700;
    CHECK(oanneal.train_options().lr_anneal_from == 90);
    CHECK(pipeline::clip_key(oanneal, in2, oanneal.train_options(), stage1.clips[0]).key != kanneal.key);
    oanneal.anneal_lr = 1;
    CHECK(test::error_id([&] { (void)oanneal.train_options(); }) == "option.train");
    oanneal.anneal_from.reset();
    CHECK(oanneal.train_options().lr_anneal_from == 0);
    CHECK(pipeline::clip_key(oanneal, in2, oanneal.train_options(), stage1.clips[0]).key == key.key);
    oanneal.anneal_lr = 0;
    CHECK(test::error_id([&] { (void)oanneal.train_options(); }) == "option.train");
    auto oshare = o;
    oshare.foreground_share = 1.0;
    CHECK(oshare.train_options().foreground_share == 1.0);
    CHECK(pipeline::clip_key(oshare, in2, oshare.train_options(), stage1.clips[0]).key == key.key);  // no budget reads it
    auto obudget = o;
    obudget.gaussians_per_pixel = 0.5;
    oshare.gaussians_per_pixel = 0.5;
    CHECK(pipeline::clip_key(oshare, in2, oshare.train_options(), stage1.clips[0]).key !=
          pipeline::clip_key(obudget, in2, obudget.train_options(), stage1.clips[0]).key);
    // A fixed share survives the clip's masks; without one the masks' coverage is the share.
    std::vector<Image<float, 1>> masks{Image<float, 1>(4, 2, 0.0f)};
    for (int x = 0; x < 2; ++x)
      for (int y = 0; y < 2; ++y) masks[0](x, y, 0) = 1.0f;
    CHECK(pipeline::detail::with_clip_share(oshare.train_options(), masks, true).foreground_share == 1.0);
    CHECK(pipeline::detail::with_clip_share(o.train_options(), masks).foreground_share == doctest::Approx(0.5));
    // --capacity auto: the clip's plan (training/capacity.hpp) sizes the grids, sets the budget with the
    // foreground's share fixed at 1, and caps the SH degree; sizes given explicitly win. Without it the
    // settings are the video's.
    {
      const auto& clip = stage1.clips[0];
      const auto plain = pipeline::detail::clip_settings(o, in2, o.train_options(), clip);
      CHECK(!plain.capacity.has_value());
      CHECK(pipeline::clip_key(plain.o, in2, plain.topt, clip).key == key.key);
      auto ocap = o;
      ocap.capacity = CapacityRules{};
      const auto cs = pipeline::detail::clip_settings(ocap, in2, ocap.train_options(), clip);
      REQUIRE(cs.capacity.has_value());
      const std::vector<Camera<float>> cams = pipeline::detail::clip_cameras(in2, clip);
      const ClipShape shape = clip_shape(in2.width, in2.height, std::span<const Camera<float>>(cams),
                                         std::span<const SfmPoint<double>>(clip.result.points));
      const CapacityPlan plan = plan_capacity(shape);
      CHECK(cs.capacity->plan == plan);
      CHECK(cs.capacity->view_spread == shape.view_spread);
      REQUIRE(plan.frg_grid.resized());  // a small clip: a small table, a budget
      CHECK(cs.o.model.frg_grid.log2_table_size == plan.log2_table);
      CHECK(cs.o.model.bkg_grid.levels == plan.bkg_grid.levels);
      CHECK(cs.o.model.frg_grid.time_cells == o.model.frg_grid.time_cells);
      CHECK(cs.topt.gaussians_per_pixel == plan.gaussians_per_pixel);
      CHECK(cs.topt.foreground_share == 1.0);
      CHECK(cs.o.foreground_share == 1.0);
      CHECK(cs.topt.max_sh_degree == plan.max_sh_degree);
      const auto kcap = pipeline::clip_key(cs.o, in2, cs.topt, clip);
      CHECK(kcap.key != key.key);
      CHECK(kcap.text.find("|frg_grid=" + std::to_string(plan.log2_table) + ":") != std::string::npos);
      CHECK(kcap.text.find("|budget=") != std::string::npos);
      // Explicit sizes win.
      auto oexp = ocap;
      oexp.model.frg_grid.log2_table_size = 15;
      oexp.gaussians_per_pixel = 0.7;
      oexp.foreground_share = 0.4;
      const auto ce = pipeline::detail::clip_settings(oexp, in2, oexp.train_options(), clip);
      CHECK(ce.o.model.frg_grid.log2_table_size == 15);
      CHECK(ce.o.model.bkg_grid.log2_table_size == plan.log2_table);
      CHECK(ce.topt.gaussians_per_pixel == 0.7);
      CHECK(ce.topt.foreground_share == 0.4);
      // An SH cap below 3 enters the key.
      auto tsh = cs.topt;
      tsh.max_sh_degree = 0;
      CHECK(pipeline::clip_key(cs.o, in2, tsh, clip).text.find("|sh_max=0") != std::string::npos);
      CHECK((kcap.text.find("|sh_max") != std::string::npos) == (plan.max_sh_degree < 3));
    }
    std::ofstream(o.out / "train/clip_000.done") << "key=" << key.legacy_key << "\nfirst=0\nlast=5\niterations=100\npsnr=30.5\nssim=0.9\ntrain_seconds=1.25\n";
    const auto legacy = pipeline::load_finished_clip(o, 0, key);
    REQUIRE(legacy.has_value());
    CHECK(legacy->second.psnr == 30.5);
    CHECK(legacy->second.train_seconds == 1.25);
    std::ofstream(o.out / "train/clip_000.done") << "key=12345\niterations=100\n";
    CHECK(!pipeline::load_finished_clip(o, 0, key).has_value());
    // Stage 3 alone, from the saved model: the renders the whole job wrote.
    auto o3 = o;
    o3.out = root / "render_only";
    const auto r3 = pipeline::render_stage(o3, in2, load_video_model<float>(o.out / "model"), {}, &pool);
    CHECK(r3.psnr == rep.psnr);
    CHECK(slurp(o3.out / "renders/00007.png") == slurp(o.out / "renders/00007.png"));
  }

  // The saved model renders what the job rendered.
  const auto vm = load_video_model<float>(o.out / "model");
  VideoRenderBuffers<float> buf;
  const auto& img = vm.render_frame(5, buf, &pool);
  CHECK(io::encode_png<float, 3>(img) == slurp(o.out / "renders/00005.png"));
  fs::remove_all(root);
}

TEST_CASE("reconstruct_video: no pool and 3 threads give byte-identical models, renders and report") {
  const auto root = temp_dir("threads");
  const Video v = write_video(root / "video");
  ThreadPool pool(3);
  auto oa = options(v, root / "serial");
  oa.iterations = 60;
  oa.write_ply = false;
  oa.write_compare = false;
  auto ob = oa;
  ob.out = root / "threaded";
  FakeSfm sfm{&v.clip};
  const auto ra = pipeline::reconstruct_video(oa, pipeline::prepare_input(oa, nullptr), sfm, {}, nullptr);
  const auto rb = pipeline::reconstruct_video(ob, pipeline::prepare_input(ob, &pool), sfm, {}, &pool);
  REQUIRE(ra.clips.size() == 2);
  CHECK(ra.psnr == rb.psnr);
  for (const char* f : {"model/manifest.txt", "model/clip_000.model", "model/clip_001.model", "renders/00000.png", "renders/00007.png",
                        "metrics.csv"}) {
    INFO(f);
    const std::string a = slurp(oa.out / f), b = slurp(ob.out / f);
    CHECK(!a.empty());
    CHECK((a == b));
  }
  // The report without its wall times (every "...seconds..." figure and the "seconds" object).
  auto strip = [](std::string r) {
    r = std::regex_replace(r, std::regex(R"re("seconds":\{[^}]*\})re"), "");
    return std::regex_replace(r, std::regex(R"re("[a-z_]*seconds[a-z_]*":[^,}\]]*)re"), "");
  };
  const std::string rep_a = strip(slurp(oa.out / "report.json")), rep_b = strip(slurp(ob.out / "report.json"));
  CHECK(rep_a.find("psnr") != std::string::npos);
  CHECK(rep_a.find("seconds") == std::string::npos);
  CHECK((rep_a == rep_b));
  fs::remove_all(root);
}

TEST_CASE("reconstruct_video: a stop request keeps a checkpoint; resuming finishes the same model") {
  const auto root = temp_dir("stop");
  const Video v = write_video(root / "video", 6);
  ThreadPool pool(2);
  auto o = one_clip_options(v, root / "a");
  std::atomic<bool> stop{false};
  pipeline::ReconstructHooks hooks;
  hooks.stop = &stop;
  int seen = 0;
  hooks.progress = [&](const pipeline::ProgressEvent& e) {
    if (e.stage == pipeline::ProgressEvent::Stage::train && ++seen == 10) stop = true;
  };
  FakeSfm sfm{&v.clip};
  CHECK_THROWS_WITH_AS((void)pipeline::reconstruct_video(o, pipeline::prepare_input(o, &pool), sfm, hooks, &pool),
                       doctest::Contains("[run.interrupted]"), error);
  CHECK(fs::exists(o.out / "train/clip_000.ckpt"));
  CHECK(!fs::exists(o.out / "report.json"));
  o.resume = true;
  stop = false;
  hooks.progress = {};
  const auto resumed = pipeline::reconstruct_video(o, pipeline::prepare_input(o, &pool), sfm, hooks, &pool);
  CHECK(resumed.trained_clips == 1);
  CHECK(resumed.clips[0].iterations == 24);
  // Same as an uninterrupted run.
  auto ob = one_clip_options(v, root / "b");
  const auto straight = pipeline::reconstruct_video(ob, pipeline::prepare_input(ob, &pool), sfm, {}, &pool);
  CHECK(straight.psnr == resumed.psnr);
  CHECK(slurp(o.out / "model/clip_000.model") == slurp(ob.out / "model/clip_000.model"));
  fs::remove_all(root);
}

TEST_CASE("reconstruct_video: a quality floor extends a clip below it; a stop inside the extension resumes to the same model") {
  const auto root = temp_dir("extend");
  const Video v = write_video(root / "video", 6);
  ThreadPool pool(2);
  auto o = one_clip_options(v, root / "a");
  o.extend = {.below_psnr = 150, .max_iterations = 16, .step = 8};  // a floor no clip reaches: 24 + 8 + 8
  std::atomic<bool> stop{false};
  pipeline::ReconstructHooks hooks;
  hooks.stop = &stop;
  int lengthened = 0;
  hooks.progress = [&](const pipeline::ProgressEvent& e) {
    if (e.stage != pipeline::ProgressEvent::Stage::train) return;
    lengthened = std::max(lengthened, e.iterations);
    if (e.iteration == 29) stop = true;  // inside the first extension step (24..32)
  };
  FakeSfm sfm{&v.clip};
  CHECK_THROWS_WITH_AS((void)pipeline::reconstruct_video(o, pipeline::prepare_input(o, &pool), sfm, hooks, &pool),
                       doctest::Contains("[run.interrupted]"), error);
  CHECK(lengthened == 32);  // the progress events give the lengthened run
  CHECK(fs::exists(o.out / "train/clip_000.ckpt"));
  o.resume = true;
  stop = false;
  hooks.progress = {};
  const auto resumed = pipeline::reconstruct_video(o, pipeline::prepare_input(o, &pool), sfm, hooks, &pool);
  REQUIRE(resumed.clips.size() == 1);
  CHECK(resumed.clips[0].iterations == 40);
  const std::string report = slurp(o.out / "report.json");
  CHECK(report.find("\"extend\":{\"below_psnr\":150.0,\"max_iterations\":16,\"step\":8}") != std::string::npos);
  auto ob = one_clip_options(v, root / "b");
  ob.extend = o.extend;
  const auto straight = pipeline::reconstruct_video(ob, pipeline::prepare_input(ob, &pool), sfm, {}, &pool);
  CHECK(straight.clips[0].iterations == 40);
  CHECK(straight.psnr == resumed.psnr);
  CHECK(slurp(o.out / "model/clip_000.model") == slurp(ob.out / "model/clip_000.model"));
  // The floor is part of the clip's key: without it the clip is trained again (24 iterations), not reused.
  ob.extend = {};
  ob.resume = true;
  const auto plain = pipeline::reconstruct_video(ob, pipeline::prepare_input(ob, &pool), sfm, {}, &pool);
  CHECK(plain.trained_clips == 1);
  CHECK(plain.clips[0].iterations == 24);
  // A floor the clip clears after its preset: no extension.
  auto oc = one_clip_options(v, root / "c");
  oc.extend = {.below_psnr = plain.clips[0].psnr - 1, .max_iterations = 16, .step = 8};
  const auto cleared = pipeline::reconstruct_video(oc, pipeline::prepare_input(oc, &pool), sfm, {}, &pool);
  CHECK(cleared.clips[0].iterations == 24);
  CHECK(slurp(oc.out / "model/clip_000.model") == slurp(ob.out / "model/clip_000.model"));
  fs::remove_all(root);
}

TEST_CASE("reconstruct_video: --scale trains and renders at the reduced size") {
  const auto root = temp_dir("scale");
  const Video v = write_video(root / "video", 6);
  ThreadPool pool(2);
  auto o = options(v, root / "out");
  o.scale = 0.5;
  // Background colours read from the frames (the default) at the training size, the masks at the
  // source size (make_clip_model refuses frames or masks it cannot match to the cameras).
  REQUIRE(o.model.background_colour == BackgroundColour::frames);
  o.write_ply = false;
  o.write_compare = false;
  FakeSfm sfm{&v.clip};
  const auto rep = pipeline::reconstruct_video(o, pipeline::prepare_input(o, &pool), sfm, {}, &pool);
  CHECK(rep.width == 24);
  CHECK(rep.height == 18);
  CHECK(io::read_image_info(o.out / "renders/00000.png").width == 24);
  CHECK(rep.psnr > rep.psnr_mean_colour);
  CHECK(!fs::exists(o.out / "compare"));
  fs::remove_all(root);
}

TEST_CASE("prepare_input: every bad input fails with its id and writes nothing") {
  const auto root = temp_dir("bad");
  const Video v = write_video(root / "video", 4);
  ThreadPool pool(2);
  auto expect = [&](pipeline::ReconstructOptions o, const char* id) {
    CAPTURE(id);
    const std::string tag = std::string("[") + id + "]";
    CHECK_THROWS_WITH((void)pipeline::prepare_input(o, &pool), doctest::Contains(tag.c_str()));
    if (!fs::is_regular_file(o.out)) CHECK(!fs::exists(o.out));
  };
  auto o = options(v, root / "out");
  fs::create_directories(root / "empty");
  auto e = o;
  e.frames_dir = root / "empty";
  expect(e, "io.empty");
  fs::copy(v.dir / "masks", root / "some_masks");
  fs::remove(root / "some_masks" / "00002.png");
  e = o;
  e.masks_dir = root / "some_masks";
  expect(e, "io.mask_missing");
  fs::copy(v.dir / "frames", root / "mixed");
  io::write_png(root / "mixed" / "00002.png", Image<float, 3>(30, 20, 0.5f));
  e = o;
  e.frames_dir = root / "mixed";
  e.masks_dir.clear();
  expect(e, "io.size_mismatch");
  fs::copy(v.dir / "frames", root / "corrupt");
  {
    const std::string png = slurp(root / "corrupt" / "00001.png");
    std::ofstream(root / "corrupt" / "00001.png", std::ios::binary) << png.substr(0, png.size() / 2);
  }
  e = o;
  e.frames_dir = root / "corrupt";
  e.masks_dir.clear();
  expect(e, "io.truncated");
  std::ofstream(root / "a_file") << "keep";
  e = o;
  e.out = root / "a_file";
  expect(e, "io.not_a_folder");
  CHECK(slurp(root / "a_file") == "keep");
  e = o;
  e.scale = 0;
  expect(e, "option.range");
  e = o;
  e.preset = "7k";
  expect(e, "option.train");
  fs::remove_all(root);
}

namespace {

/// FakeSfm whose attempts after the first clip wait (up to `max_wait_ms`) until `go` is set, and that fails
/// hard on clips starting at or after `fail_from` (-1: never).
struct GatedSfm {
  FakeSfm inner;
  std::atomic<bool>* go = nullptr;
  int fail_from = -1;
  int max_wait_ms = 20000;
  bool waited_for_go = false;  ///< an attempt found `go` set (after waiting if needed)
  int calls = 0;
  SfmResult<double> operator()(FrameRange r) {
    ++calls;
    if (go && r.first > 0) {
      for (int i = 0; i < max_wait_ms / 10 && !go->load(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
      waited_for_go = waited_for_go || go->load();
    }
    if (fail_from >= 0 && r.first >= fail_from) {
      SfmResult<double> s;
      s.status = SfmStatus::hard_error;
      s.range = r;
      s.message = "scripted failure";
      return s;
    }
    return inner(r);
  }
};

}  // namespace

TEST_CASE("train_during_sfm: clips train while SfM works on later ones, with the outputs of the stages in turn") {
  const auto root = temp_dir("overlap");
  const Video v = write_video(root / "video", 16);  // k = 6: clips 0-5, 5-10, 10-15
  ThreadPool pool(2);
  auto oa = options(v, root / "sequential");
  oa.iterations = 40;
  oa.write_compare = false;
  oa.train_during_sfm = false;
  auto ob = oa;
  ob.out = root / "overlapped";
  ob.train_during_sfm = true;

  FakeSfm plain{&v.clip};
  const auto ra = pipeline::reconstruct_video(oa, pipeline::prepare_input(oa, &pool), plain, {}, &pool);
  // Overlapped: SfM of the second clip waits until clip 0 has started training, so the two stages
  // provably run at once; progress events arrive from both threads, one at a time.
  std::atomic<bool> clip0_training{false};
  GatedSfm gated{FakeSfm{&v.clip}, &clip0_training};
  int in_hook = 0, overlapping_calls = 0, sfm_events_after_training = 0;
  bool training_seen = false;
  std::optional<pipeline::ProgressEvent> first_train;
  pipeline::ReconstructHooks hooks;
  hooks.progress = [&](const pipeline::ProgressEvent& e) {
    overlapping_calls += ++in_hook > 1 ? 1 : 0;
    if (e.stage == pipeline::ProgressEvent::Stage::train && !first_train) first_train = e;
    if (e.stage == pipeline::ProgressEvent::Stage::train && e.clip == 0) training_seen = true, clip0_training = true;
    if (e.stage == pipeline::ProgressEvent::Stage::sfm && training_seen) ++sfm_events_after_training;
    --in_hook;
  };
  const auto rb = pipeline::reconstruct_video(ob, pipeline::prepare_input(ob, &pool), gated, hooks, &pool);
  CHECK(gated.waited_for_go);
  CHECK(sfm_events_after_training >= 2);  // clips 1 and 2 were scheduled while clip 0 trained
  CHECK(overlapping_calls == 0);
  REQUIRE(first_train);  // sent while clip 1's SfM waited: one clip known, more to come
  CHECK(first_train->clips == 1);
  CHECK(!first_train->clips_final);
  REQUIRE(ra.clips.size() == 3);
  REQUIRE(rb.clips.size() == 3);
  CHECK(ra.psnr == rb.psnr);
  for (std::size_t c = 0; c < 3; ++c) {
    CHECK(ra.clips[c].first == rb.clips[c].first);
    CHECK(ra.clips[c].psnr == rb.clips[c].psnr);
    CHECK(ra.clips[c].sfm_points == rb.clips[c].sfm_points);
  }
  for (const char* f : {"model/manifest.txt", "model/clip_000.model", "model/clip_001.model", "model/clip_002.model", "renders/00000.png",
                        "renders/00015.png", "metrics.csv"}) {
    INFO(f);
    const std::string a = slurp(oa.out / f), b = slurp(ob.out / f);
    CHECK(!a.empty());
    CHECK((a == b));
  }

  // An SfM failure on the third clip: the clips already final are trained and kept, then the error
  // comes out with its id; a resumed run (stages in turn) reuses them.
  auto oc = ob;
  oc.out = root / "failing";
  GatedSfm failing{FakeSfm{&v.clip}, nullptr, 10};
  CHECK_THROWS_WITH_AS((void)pipeline::reconstruct_video(oc, pipeline::prepare_input(oc, &pool), failing, {}, &pool),
                       doctest::Contains("[sfm.hard_error]"), error);
  CHECK(fs::exists(oc.out / "train/clip_000.done"));
  CHECK(fs::exists(oc.out / "train/clip_001.done"));
  CHECK(!fs::exists(oc.out / "report.json"));
  oc.resume = true;
  oc.train_during_sfm = false;
  FakeSfm again{&v.clip};
  const auto rc = pipeline::reconstruct_video(oc, pipeline::prepare_input(oc, &pool), again, {}, &pool);
  CHECK(rc.trained_clips == 1);
  CHECK(rc.psnr == ra.psnr);

  // A stop request while SfM works on later clips: the training thread stops SfM too, which
  // finishes the attempt under way (clip 1's) and starts no other.
  auto od = ob;
  od.out = root / "stopped";
  std::atomic<bool> stop{false}, never{false};
  GatedSfm slow{FakeSfm{&v.clip}, &never, -1, 5000};  // each later attempt waits 5 s for a flag never set
  pipeline::ReconstructHooks stopping;
  stopping.stop = &stop;
  stopping.progress = [&](const pipeline::ProgressEvent& e) {
    if (e.stage == pipeline::ProgressEvent::Stage::train && e.iteration == 10) stop = true;
  };
  const auto t0 = std::chrono::steady_clock::now();
  CHECK_THROWS_WITH_AS((void)pipeline::reconstruct_video(od, pipeline::prepare_input(od, &pool), slow, stopping, &pool),
                       doctest::Contains("[run.interrupted]"), error);
  CHECK(fs::exists(od.out / "train/clip_000.ckpt"));
  CHECK(slow.calls == 2);  // clip 0's attempt and the one under way; clip 2's never started
  CHECK(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < 60);
  fs::remove_all(root);
}
