#pragma once
/// @file
/// scheduling: the MC-COLMAP clip scheduler, generic over any structure-from-motion back end
/// (`schedule_clips`, the `SfmBackend` concept and the `SfmResult` a back end returns).
#include "video3dgs/scheduling/schedule_clips.hpp"
#include "video3dgs/scheduling/sfm_result.hpp"
