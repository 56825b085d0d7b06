#pragma once
/// @file
/// loss: photometric losses with their backward passes, templated on Scalar and Channels.
///
/// One API for every loss: `<name>_forward(render, target, ctx, pool)` returns the loss value and
/// saves what the backward needs in `ctx` (a reusable workspace: no heap allocation once it has seen
/// the image size); `<name>_backward(ctx, dL_dvalue, dL_drender, pool)` ADDS the gradient with respect
/// to the first image (the render) into `dL_drender`. `pool` may be null (serial); results are
/// bit-identical for any thread count.
///   - L1 (optionally weighted per pixel):          l1.hpp
///   - SSIM and D-SSIM = 1 - SSIM:                    ssim.hpp
///     (`SsimTarget`: a target's statistics, filled once and shared by several renders' forwards)
///   - (1 - lambda) L1_w + lambda D-SSIM:             l1_dssim.hpp
#include "video3dgs/loss/alpha_merge.hpp"
#include "video3dgs/loss/l1.hpp"
#include "video3dgs/loss/l1_dssim.hpp"
#include "video3dgs/loss/ssim.hpp"
