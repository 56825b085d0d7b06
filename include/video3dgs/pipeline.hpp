#pragma once
/// @file
/// pipeline: the whole reconstruction job of a video (input checks, MC-COLMAP over any SfM back end,
/// per-clip training with resumable checkpoints, blended rendering, metrics, report) and its image
/// products (area resize, error heat map, side-by-side, metrics plot).
#include "video3dgs/pipeline/outputs.hpp"
#include "video3dgs/pipeline/reconstruct.hpp"
