#pragma once
/// @file
/// model: a clip's two deformable Gaussian sets + alpha maps (ClipModel), their initialisation
/// (background shells, kNN scales), the alpha merge, model files (exact and compact) and PLY export.
#include "video3dgs/loss/alpha_merge.hpp"
#include "video3dgs/model/clip_model.hpp"
#include "video3dgs/model/clip_model_io.hpp"
#include "video3dgs/model/compact_io.hpp"
#include "video3dgs/model/point_init.hpp"
#include "video3dgs/model/render_clip.hpp"
#include "video3dgs/model/video_model.hpp"
