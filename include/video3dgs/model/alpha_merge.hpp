#pragma once
/// @file
/// Moved to video3dgs/loss/alpha_merge.hpp (the differentiable image operations live next to the
/// losses); this header keeps old includes working.
#include "video3dgs/loss/alpha_merge.hpp"
