#pragma once
/// @file
/// refine: stage 2 (refine_clip / refine_video / refine_recursive with ClipRefiner, the Editor
/// concept, FlickerEditor, CommandEditor).
#include "video3dgs/refine/editor.hpp"
#include "video3dgs/refine/refine.hpp"
