#pragma once
// The flags that choose how a clip's model starts (ClipModelOptions), shared by the commands that
// train clips: `reconstruct` and `trade`.
#include <cstdint>
#include <string>

#include <CLI/CLI.hpp>

#include "video3dgs/model/clip_model.hpp"

namespace video3dgs::cli {

/// --static-background, --alpha-mask A, --bkg-colour random|frames, --keep-unseen into `m`.
inline void add_model_start_options(CLI::App* sub, ClipModelOptions& m) {
  sub->add_flag("--static-background", m.static_background,
                "the background set is not deformed (its field is neither evaluated nor trained; for scenes whose background is still)");
  sub->add_option("--alpha-mask", m.alpha_mask, "alpha maps start from the masks: A inside, 0.1 outside (0 = the method's uniform 0.5)")
      ->check(CLI::Range(0.0, 0.999));
  sub->add_option_function<std::string>(
         "--bkg-colour", [&m](const std::string& c) { m.background_colour = c == "frames" ? BackgroundColour::frames : BackgroundColour::random; },
         "background set's first colours: frames (the default: what the frames show where each point projects, outside "
         "the masks) or random (the method's, drawn with the seed)")
      ->check(CLI::IsMember({"random", "frames"}));
  sub->add_flag_function(
      "--keep-unseen", [&m](std::int64_t) { m.cull_unseen = false; },
      "keep the initial Gaussians that no clip camera sees (the method's start; by default they are dropped: they never "
      "receive a gradient and only cost deformation and optimiser work)");
}

}  // namespace video3dgs::cli
