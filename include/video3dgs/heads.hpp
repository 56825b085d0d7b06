#pragma once
/// @file
/// heads: Linear<Scalar, In, Out> and Mlp<...> (activation policy), Eigen-backed, forward/backward.
#include "video3dgs/heads/linear.hpp"
#include "video3dgs/heads/mlp.hpp"
