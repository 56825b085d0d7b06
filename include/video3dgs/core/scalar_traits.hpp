#pragma once
/// @file
/// One traits hub per scalar type: epsilons and test tolerances live here, nowhere else.

#include <concepts>
#include <limits>

namespace video3dgs {

/// Specialise for a new scalar type. `epsilon` guards divisions; `test_tolerance` is the relative
/// tolerance a forward test may expect after a few hundred operations.
template <class Scalar>
struct scalar_traits {
  static_assert(std::floating_point<Scalar>,
                "video3dgs: scalar_traits<Scalar> is defined for float and double; specialise "
                "video3dgs::scalar_traits for your scalar type (epsilon, test_tolerance, name)");
};

template <>
struct scalar_traits<float> {
  static constexpr float epsilon = 1e-7f;
  static constexpr float test_tolerance = 1e-4f;
  static constexpr const char* name = "float";
};

template <>
struct scalar_traits<double> {
  static constexpr double epsilon = 1e-15;
  static constexpr double test_tolerance = 1e-10;
  static constexpr const char* name = "double";
};

/// The scalar types the library is written for (float for speed, double for checks).
template <class T>
concept Real = std::floating_point<T>;

}  // namespace video3dgs
