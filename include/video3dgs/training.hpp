#pragma once
/// @file
/// training: stage 1 per clip (ClipTrainer, TrainOptions presets, densification, detail weights).
#include "video3dgs/training/clip_trainer.hpp"
#include "video3dgs/training/densify.hpp"
#include "video3dgs/training/detail_weight.hpp"
#include "video3dgs/training/split_adam.hpp"
#include "video3dgs/training/train_options.hpp"
