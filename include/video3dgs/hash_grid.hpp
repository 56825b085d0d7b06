#pragma once
/// @file
/// hash_grid: multiresolution hash encoding (dense levels where they fit, spatial hash otherwise).
#include "video3dgs/hash_grid/hash_grid.hpp"
