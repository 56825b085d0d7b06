#pragma once
/// @file
/// pipeline: the jobs of the command-line tool as library calls, each split into stages a user can
/// call alone. reconstruct.hpp: a video's reconstruction (input checks, MC-COLMAP over any SfM back
/// end, per-clip training with resumable checkpoints, blended rendering, metrics, report);
/// refine.hpp: stage 2 on an edited video (ensemble or recursive, with its report); outputs.hpp: the
/// image products (area resize, error heat map, side-by-side, metrics plot, compare header);
/// report_html.hpp: report.html, the page a person reads a reconstruction from.
#include "video3dgs/pipeline/outputs.hpp"
#include "video3dgs/pipeline/reconstruct.hpp"
#include "video3dgs/pipeline/refine.hpp"
#include "video3dgs/pipeline/report_html.hpp"
