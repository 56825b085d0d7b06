#pragma once
/// @file
/// core: scalar traits, errors, debug assertions, images, cameras, the thread pool.
#include "video3dgs/core/assert.hpp"
#include "video3dgs/core/camera.hpp"
#include "video3dgs/core/error.hpp"
#include "video3dgs/core/hash.hpp"
#include "video3dgs/core/image.hpp"
#include "video3dgs/core/isa.hpp"
#include "video3dgs/core/parallel.hpp"
#include "video3dgs/core/scalar_traits.hpp"
#include "video3dgs/core/stopwatch.hpp"
