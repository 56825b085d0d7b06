#pragma once
/// @file
/// flow: dense optical-flow fields, bilinear warping, the forward-backward occlusion check, endpoint
/// error, Middlebury .flo files, and a built-in coarse-to-fine Horn-Schunck estimator.
#include "video3dgs/flow/flo_io.hpp"
#include "video3dgs/flow/horn_schunck.hpp"
#include "video3dgs/flow/warp.hpp"
