#pragma once
/// @file
/// synthetic: seeded synthetic Gaussian scenes (benchmark scene, demo scene and camera path).
#include "video3dgs/synthetic/scene.hpp"
