#pragma once
/// @file
/// The COLMAP adapter (target `video3dgs::colmap`): sparse model I/O (.txt / .bin), conversion to
/// `Camera` / `SfmResult`, undistortion through `colmap image_undistorter`, running external programs,
/// reading COLMAP databases and matching their SIFT features exactly (reproducible SfM), and
/// `ColmapSfm`, the SfM back end of MC-COLMAP for `video3dgs::schedule_clips`.
#include "video3dgs/colmap/clip_input.hpp"
#include "video3dgs/colmap/convert.hpp"
#include "video3dgs/colmap/database.hpp"
#include "video3dgs/colmap/matcher.hpp"
#include "video3dgs/colmap/model.hpp"
#include "video3dgs/colmap/model_io.hpp"
#include "video3dgs/colmap/process.hpp"
#include "video3dgs/colmap/sfm.hpp"
#include "video3dgs/colmap/undistort.hpp"
