#pragma once
/// @file
/// sh: real spherical-harmonic colour of degree 0..3 (3DGS convention), forward and backward.
#include "video3dgs/sh/basis.hpp"
