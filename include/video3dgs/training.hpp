#pragma once
/// @file
/// training: stage 1 per clip (ClipTrainer, TrainOptions presets, densification, detail weights) and
/// stage 2 (refine_video / refine_recursive, the Editor concept, FlickerEditor, CommandEditor).
#include "video3dgs/training/clip_trainer.hpp"
#include "video3dgs/training/densify.hpp"
#include "video3dgs/training/detail_weight.hpp"
#include "video3dgs/training/editor.hpp"
#include "video3dgs/training/policy.hpp"
#include "video3dgs/training/refine.hpp"
#include "video3dgs/training/split_adam.hpp"
#include "video3dgs/training/train_options.hpp"
