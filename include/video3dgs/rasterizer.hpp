#pragma once
/// @file
/// rasterizer: EWA projection, depth sort + tile binning, front-to-back compositing and its exact
/// backward pass; `Rasterizer<Scalar, TileSize, Channels>` ties them together.
#include "video3dgs/rasterizer/backward.hpp"
#include "video3dgs/rasterizer/binning.hpp"
#include "video3dgs/rasterizer/context.hpp"
#include "video3dgs/rasterizer/forward.hpp"
#include "video3dgs/rasterizer/project.hpp"
#include "video3dgs/rasterizer/rasterizer.hpp"
#include "video3dgs/rasterizer/settings.hpp"
