#pragma once
/// @file
/// deformation: DeformationField = HashGrid(x, y, z, t) + heads -> (dxyz, drot, dscale) per Gaussian.
#include "video3dgs/deformation/deformation_field.hpp"
