#pragma once
/// @file
/// The per-clip computation as one forward / backward pair on the autodiff tape (`ClipGraph`).
#include "video3dgs/graph/clip_graph.hpp"
