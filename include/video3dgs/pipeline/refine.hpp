#pragma once
/// @file
/// The stage-2 job, as library code (the `video3dgs refine` command only parses flags and prints the
/// report): refine an edited video with the reconstruction of its source (refine/refine.hpp).
///
///     pipeline::RefineJobOptions o;
///     o.model = "out";  o.source = "video/frames";  o.edited = {"edit/frames"};  o.out = "refined";
///     ThreadPool pool;
///     auto input = pipeline::prepare_refine_input(o, &pool);     // every check, no writes
///     auto report = pipeline::refine_edited_video(o, input, &pool);
///
/// `prepare_refine_input` reads the model (a `video3dgs reconstruct` output folder or its model/
/// folder), the source and every edited folder (paired with the model's frames in natural order and
/// resampled, area-weighted, to the model's render size; frame counts must match: `io.count_mismatch`),
/// and the source's optical flow (built-in estimator, or .flo folders) before anything is written.
/// Several edited folders form an ensemble (loss summed). With an editor command the refinement is
/// recursive (`refine_recursive` with a `CommandEditor`): phase 0 edits the source, each later phase
/// the previous refined video; edited folders are then ignored.
///
/// `refine_edited_video` writes OUT/refined/00000.png..., OUT/compare/00000.png (source | edited |
/// refined), OUT/model/ (the refined model) and, last, OUT/report.json (`RefineJobReport::json`).
/// warp_ssim_* use the source's flow; for an ensemble, warp_ssim_edited and psnr_refined_vs_edited are
/// means over the edits (each edit's values are under "edits"); for recursive refinement they refer to
/// phase 0's edit.

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include <nlohmann/json.hpp>

#include "video3dgs/core/error.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/io/frame_folder.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/metrics/psnr.hpp"
#include "video3dgs/metrics/warp_ssim.hpp"
#include "video3dgs/model/video_model.hpp"
#include "video3dgs/pipeline/outputs.hpp"
#include "video3dgs/refine/editor.hpp"
#include "video3dgs/refine/refine.hpp"

namespace video3dgs::pipeline {

struct RefineJobOptions {
  std::filesystem::path model;                 ///< required: reconstruction folder (or its model/ folder)
  std::filesystem::path source;                ///< required: frames of the source video
  std::vector<std::filesystem::path> edited;   ///< frames of each edit (several = ensemble)
  std::filesystem::path out;                   ///< required: output folder
  RefineOptions refine{};                      ///< per clip (and per phase)
  std::vector<std::string> editor_command;     ///< non-empty: recursive refinement with this editor
  int phases = 2;                              ///< N_r of recursive refinement
  double editor_timeout = 0;                   ///< seconds per editor call (0 = none)
  std::filesystem::path flow_forward, flow_backward;  ///< .flo folders (both or neither; default: estimated)

  /// @throws option_error `option.refine` (naming the flag), `option.warp_ssim`
  void validate() const {
    if (edited.empty() && editor_command.empty())
      throw option_error("option.refine", "--edited", "give at least one --edited folder or an --editor-cmd");
    if (flow_forward.empty() != flow_backward.empty())
      throw option_error("option.warp_ssim", "--flow-forward", "give both --flow-forward and --flow-backward, or neither");
    if (!editor_command.empty() && phases < 1) throw option_error("option.refine", "--phases", "must be >= 1");
    refine.validate();
  }
};

/// The checked input of the job (see the file comment).
struct RefineInput {
  VideoModel<float> model;
  std::vector<Image<float, 3>> source;              ///< at the model's render size
  std::vector<std::vector<Image<float, 3>>> edits;  ///< one video per edited folder (empty with an editor)
  std::vector<std::string> edit_names;
  metrics::VideoFlows flows;                        ///< of the source
  double warp_ssim_source = 0;
  double seconds = 0;                               ///< spent reading and checking
};

struct RefineEditReport {
  std::string dir;
  double warp_ssim = 0, psnr_refined_vs_edited = 0;
};

struct RefinePhaseReport {
  int phase = 0;
  double warp_ssim_edited = 0, warp_ssim_refined = 0;
};

struct RefineJobReport {
  double warp_ssim_edited = 0, warp_ssim_refined = 0, psnr_refined_vs_edited = 0;  ///< means over the edits
  double warp_ssim_source = 0;
  double warp_ssim_gain_percent = 0;  ///< 100 (refined - edited) / edited
  double seconds = 0;  ///< the whole job: reading the input and refining
  int frames = 0, width = 0, height = 0;
  RefineOptions options;
  std::vector<RefineEditReport> edits;
  RefineStats stats;                      ///< of the (last) refinement
  std::vector<RefinePhaseReport> phases;  ///< recursive refinement only

  /// The report.json text (one object; see `to_json` below).
  [[nodiscard]] std::string json(int indent = -1) const;
};

/// One serialiser per report type (nlohmann/json writes numbers that are not finite as null).
inline void to_json(nlohmann::ordered_json& j, const RefineJobReport& r) {
  const RefineOptions& o = r.options;
  j = {{"warp_ssim_edited", r.warp_ssim_edited}, {"warp_ssim_refined", r.warp_ssim_refined},
       {"psnr_refined_vs_edited", r.psnr_refined_vs_edited}, {"seconds", r.seconds}, {"warp_ssim_source", r.warp_ssim_source},
       {"warp_ssim_gain_percent", r.warp_ssim_gain_percent}, {"frames", r.frames}, {"width", r.width}, {"height", r.height},
       {"iterations", o.iterations},
       {"options", {{"train_alpha", o.train_alpha}, {"train_opacity", o.train_opacity}, {"lr_sh_dc", o.lr_sh_dc}, {"lr_sh_rest", o.lr_sh_rest},
                    {"lr_opacity", o.lr_opacity}, {"lr_alpha", o.lr_alpha}, {"lambda_dssim", o.lambda_dssim}, {"overlap_anchor", o.overlap_anchor}}}};
  j["edits"] = nlohmann::ordered_json::array();
  for (const auto& e : r.edits) j["edits"].push_back({{"dir", e.dir}, {"warp_ssim", e.warp_ssim}, {"psnr_refined_vs_edited", e.psnr_refined_vs_edited}});
  j["clips"] = nlohmann::ordered_json::array();
  for (const auto& c : r.stats.clips)
    j["clips"].push_back({{"iterations", c.iterations}, {"skipped_steps", c.skipped_steps}, {"first_loss", c.first_loss},
                          {"last_loss", c.last_loss}, {"seconds", c.seconds}});
  if (!r.phases.empty()) {
    j["phases"] = nlohmann::ordered_json::array();
    for (const auto& p : r.phases)
      j["phases"].push_back({{"phase", p.phase}, {"warp_ssim_edited", p.warp_ssim_edited}, {"warp_ssim_refined", p.warp_ssim_refined}});
  }
}

inline std::string RefineJobReport::json(int indent) const { return nlohmann::ordered_json(*this).dump(indent); }

namespace detail {

/// Frames of a folder resampled to w x h; exactly `expect` of them. @throws io_error `io.count_mismatch`
inline std::vector<Image<float, 3>> read_video_at(const std::filesystem::path& dir, int w, int h, int expect, ThreadPool* pool) {
  auto frames = io::read_frames(io::list_frames(dir), pool);
  if (int(frames.size()) != expect)
    throw io_error("io.count_mismatch", dir.string(),
                   "holds " + std::to_string(frames.size()) + " frames but the model has " + std::to_string(expect));
  for (auto& f : frames) f = resize_area(f, w, h);
  return frames;
}

inline double mean_psnr(const std::vector<Image<float, 3>>& a, const std::vector<Image<float, 3>>& b) {
  double s = 0;
  for (std::size_t i = 0; i < a.size(); ++i) s += metrics::psnr<float, 3>(a[i], b[i]);
  return a.empty() ? 0.0 : s / double(a.size());
}

}  // namespace detail

/// Reads and checks every input (see the file comment); writes nothing.
/// @throws option_error, io_error (`io.count_mismatch`, `io.not_a_folder`, the readers' ids)
[[nodiscard]] inline RefineInput prepare_refine_input(const RefineJobOptions& o, ThreadPool* pool = nullptr) {
  namespace fs = std::filesystem;
  const auto t0 = std::chrono::steady_clock::now();
  o.validate();
  std::error_code ec;
  fs::path model_dir = o.model;
  if (!fs::exists(model_dir / kVideoModelManifest, ec) && fs::exists(model_dir / "model" / kVideoModelManifest, ec)) model_dir /= "model";
  RefineInput in;
  in.model = load_video_model<float>(model_dir);
  const int n = in.model.frame_count, w = in.model.width, h = in.model.height;
  in.source = detail::read_video_at(o.source, w, h, n, pool);
  if (o.editor_command.empty())
    for (const auto& d : o.edited) {
      in.edits.push_back(detail::read_video_at(d, w, h, n, pool));
      in.edit_names.push_back(d.string());
    }
  if (fs::exists(o.out, ec) && !fs::is_directory(o.out, ec)) throw io_error("io.not_a_folder", o.out.string(), "--out must be a folder");
  in.flows = o.flow_forward.empty() ? metrics::estimate_video_flows(in.source, {}, pool) : metrics::read_video_flows(o.flow_forward, o.flow_backward);
  in.warp_ssim_source = metrics::warp_ssim(in.source, in.flows, {}, pool).value;  // also checks the flows' count and size
  in.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return in;
}

/// Runs the refinement (ensemble or recursive) and writes OUT (see the file comment). `in.edits`
/// gains phase 0's edit when the refinement is recursive.
/// @throws option_error, io_error `io.unwritable`, whatever the editor throws
inline RefineJobReport refine_edited_video(const RefineJobOptions& o, RefineInput& in, ThreadPool* pool = nullptr) {
  namespace fs = std::filesystem;
  const auto t0 = std::chrono::steady_clock::now();
  RefineJobReport rep;
  std::error_code ec;
  fs::create_directories(o.out / "refined", ec);
  fs::create_directories(o.out / "compare", ec);
  if (ec) throw io_error("io.unwritable", o.out.string(), "cannot create folder: " + ec.message());
  VideoModel<float> refined;
  if (!o.editor_command.empty()) {
    CommandEditor editor;
    editor.command = o.editor_command;
    editor.work_dir = o.out / "editor";
    editor.timeout_seconds = o.editor_timeout;
    auto r = refine_recursive(in.model, in.source, editor, RecursiveRefineOptions{o.phases, o.refine}, pool);
    for (int p = 0; p < o.phases; ++p)
      rep.phases.push_back({p, metrics::warp_ssim(r.edited[std::size_t(p)], in.flows, {}, pool).value,
                            metrics::warp_ssim(r.refined[std::size_t(p)], in.flows, {}, pool).value});
    in.edits.push_back(std::move(r.edited.front()));
    in.edit_names.push_back((editor.work_dir / "phase_0" / "output").string());
    refined = std::move(r.model);
    rep.stats = std::move(r.stats.back());
  } else {
    refined = refine_video(in.model, in.edits, o.refine, pool, &rep.stats);
  }
  const auto frames = render_video(refined, pool);
  for (std::size_t f = 0; f < frames.size(); ++f) {
    char name[32];
    std::snprintf(name, sizeof(name), "%05zu.png", f);
    io::write_png(o.out / "refined" / name, frames[f]);
    io::write_png(o.out / "compare" / name, side_by_side({&in.source[f], &in.edits.front()[f], &frames[f]}));
  }
  save_video_model(o.out / "model", refined);
  rep.warp_ssim_refined = metrics::warp_ssim(frames, in.flows, {}, pool).value;
  for (std::size_t e = 0; e < in.edits.size(); ++e) {
    const RefineEditReport er{in.edit_names[e], metrics::warp_ssim(in.edits[e], in.flows, {}, pool).value, detail::mean_psnr(frames, in.edits[e])};
    rep.warp_ssim_edited += er.warp_ssim / double(in.edits.size());
    rep.psnr_refined_vs_edited += er.psnr_refined_vs_edited / double(in.edits.size());
    rep.edits.push_back(er);
  }
  rep.warp_ssim_source = in.warp_ssim_source;
  rep.warp_ssim_gain_percent = 100.0 * (rep.warp_ssim_refined - rep.warp_ssim_edited) / rep.warp_ssim_edited;
  rep.frames = refined.frame_count, rep.width = refined.width, rep.height = refined.height;
  rep.options = o.refine;
  rep.seconds = in.seconds + std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  io::write_file_atomic(o.out / "report.json", rep.json(1) + "\n");
  return rep;
}

}  // namespace video3dgs::pipeline
