#pragma once
/// @file
/// optim: Optimizer<Scalar, Policy> (Adam, Sgd) with named groups, lr schedules, freeze and row edits.
#include "video3dgs/optim/optimizer.hpp"
#include "video3dgs/optim/policies.hpp"
#include "video3dgs/optim/schedule.hpp"
