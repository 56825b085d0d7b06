#pragma once
/// @file
/// Moved to video3dgs/refine/refine.hpp (stage 2 has its own folder); this header keeps old includes
/// working.
#include "video3dgs/refine/refine.hpp"
