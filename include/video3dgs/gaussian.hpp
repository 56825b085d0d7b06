#pragma once
/// @file
/// gaussian: one Gaussian, the SoA cloud and its views, activations, covariance forward/backward.
#include "video3dgs/gaussian/activations.hpp"
#include "video3dgs/gaussian/cloud.hpp"
#include "video3dgs/gaussian/covariance.hpp"
