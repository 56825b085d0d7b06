#pragma once
/// @file
/// metrics: PSNR / MSE, SSIM (the loss's definition, in double), and both on image files and frame
/// folders (via io), WarpSSIM (temporal consistency through the source's optical flow).
#include "video3dgs/metrics/files.hpp"
#include "video3dgs/metrics/psnr.hpp"
#include "video3dgs/metrics/ssim.hpp"
#include "video3dgs/metrics/warp_ssim.hpp"
