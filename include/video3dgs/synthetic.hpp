#pragma once
/// @file
/// synthetic: seeded synthetic Gaussian scenes (benchmark scene, demo scene and camera path) and a
/// synthetic video clip with cameras, masks and noisy foreground points (`make_synthetic_clip`).
#include "video3dgs/synthetic/clip.hpp"
#include "video3dgs/synthetic/scene.hpp"
