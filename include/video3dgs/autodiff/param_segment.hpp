#pragma once
/// @file
/// `ParamSegment<Scalar>`: a parameter buffer and its gradient accumulator, the unit a trainable
/// module exposes and an optimizer group binds to.

#include <span>

namespace video3dgs {

template <class Scalar>
struct ParamSegment {
  std::span<Scalar> value;  ///< parameters
  std::span<Scalar> grad;   ///< dL/dparameters, same size
};

}  // namespace video3dgs
