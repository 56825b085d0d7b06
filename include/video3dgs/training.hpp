#pragma once
/// @file
/// training: stage 1 per clip (ClipTrainer, TrainOptions presets, capacity plans, densification, detail
/// weights, the policy bundle). Stage 2 lives in video3dgs/refine.hpp, included here for older code.
#include "video3dgs/refine.hpp"
#include "video3dgs/training/capacity.hpp"
#include "video3dgs/training/clip_trainer.hpp"
#include "video3dgs/training/densify.hpp"
#include "video3dgs/training/detail_weight.hpp"
#include "video3dgs/training/extend.hpp"
#include "video3dgs/training/policy.hpp"
#include "video3dgs/training/split_adam.hpp"
#include "video3dgs/training/train_options.hpp"
