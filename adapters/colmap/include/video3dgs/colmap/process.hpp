#pragma once
/// @file
/// The process runner moved to core I/O (video3dgs/io/process.hpp) so that other external programs
/// (e.g. the stage-2 command editor) share it; these names keep the adapter's spelling working.

#include "video3dgs/io/process.hpp"

namespace video3dgs::colmap {

using io::find_executable;
using io::log_tail;
using io::ProcessResult;
using io::run_process;

}  // namespace video3dgs::colmap
