#pragma once
/// @file
/// autodiff: array-level reverse mode (Arena, Tape, ops) and a forward-mode Dual for cross-checks.
#include "video3dgs/autodiff/arena.hpp"
#include "video3dgs/autodiff/dual.hpp"
#include "video3dgs/autodiff/ops.hpp"
#include "video3dgs/autodiff/param_segment.hpp"
#include "video3dgs/autodiff/tape.hpp"
