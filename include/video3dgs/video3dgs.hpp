#pragma once
/// @file
/// Everything in video3dgs. Each module also has its own umbrella header (`video3dgs/core.hpp`, ...).
#include "video3dgs/autodiff.hpp"
#include "video3dgs/core.hpp"
#include "video3dgs/deformation.hpp"
#include "video3dgs/flow.hpp"
#include "video3dgs/gaussian.hpp"
#include "video3dgs/hash_grid.hpp"
#include "video3dgs/heads.hpp"
#include "video3dgs/io.hpp"
#include "video3dgs/loss.hpp"
#include "video3dgs/metrics.hpp"
#include "video3dgs/optim.hpp"
#include "video3dgs/rasterizer.hpp"
#include "video3dgs/scheduling.hpp"
#include "video3dgs/sh.hpp"
