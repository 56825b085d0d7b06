#pragma once
/// @file
/// io: atomic file output, versioned binary records, image files (stb), frame/mask folders, 3DGS PLY.
#include "video3dgs/io/atomic_file.hpp"
#include "video3dgs/io/binary_stream.hpp"
#include "video3dgs/io/frame_folder.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/io/ply.hpp"
