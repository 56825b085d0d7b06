#pragma once
/// @file
/// `Dual<Scalar>`: a forward-mode dual number a + b e (e^2 = 0), for cross-checking reverse-mode
/// gradients along one direction: f(x + v e) = f(x) + (J v) e.
///
///     (a + b e)(c + d e) = ac + (ad + bc) e        g(a + b e) = g(a) + g'(a) b e

#include <cmath>
#include <ostream>
#include <type_traits>

namespace video3dgs::autodiff {

template <class Scalar>
struct Dual {
  static_assert(std::is_floating_point_v<Scalar>, "video3dgs: Dual<Scalar> needs a floating-point Scalar");
  Scalar v = 0;  ///< value
  Scalar d = 0;  ///< directional derivative

  constexpr Dual() = default;
  constexpr Dual(Scalar value, Scalar derivative = 0) : v(value), d(derivative) {}  // NOLINT

  constexpr Dual& operator+=(const Dual& o) { v += o.v; d += o.d; return *this; }
  constexpr Dual& operator-=(const Dual& o) { v -= o.v; d -= o.d; return *this; }
  constexpr Dual& operator*=(const Dual& o) { d = d * o.v + v * o.d; v *= o.v; return *this; }
  constexpr Dual& operator/=(const Dual& o) { d = (d * o.v - v * o.d) / (o.v * o.v); v /= o.v; return *this; }

  friend constexpr Dual operator+(Dual a, const Dual& b) { return a += b; }
  friend constexpr Dual operator-(Dual a, const Dual& b) { return a -= b; }
  friend constexpr Dual operator*(Dual a, const Dual& b) { return a *= b; }
  friend constexpr Dual operator/(Dual a, const Dual& b) { return a /= b; }
  friend constexpr Dual operator-(const Dual& a) { return {-a.v, -a.d}; }
  friend constexpr bool operator<(const Dual& a, const Dual& b) { return a.v < b.v; }
  friend constexpr bool operator>(const Dual& a, const Dual& b) { return a.v > b.v; }
  friend constexpr bool operator<=(const Dual& a, const Dual& b) { return a.v <= b.v; }
  friend constexpr bool operator>=(const Dual& a, const Dual& b) { return a.v >= b.v; }
  friend std::ostream& operator<<(std::ostream& os, const Dual& a) { return os << a.v << "+" << a.d << "e"; }
};

template <class S> Dual<S> exp(const Dual<S>& a) { const S e = std::exp(a.v); return {e, e * a.d}; }
template <class S> Dual<S> log(const Dual<S>& a) { return {std::log(a.v), a.d / a.v}; }
template <class S> Dual<S> sqrt(const Dual<S>& a) { const S s = std::sqrt(a.v); return {s, a.d / (S(2) * s)}; }
template <class S> Dual<S> sin(const Dual<S>& a) { return {std::sin(a.v), std::cos(a.v) * a.d}; }
template <class S> Dual<S> cos(const Dual<S>& a) { return {std::cos(a.v), -std::sin(a.v) * a.d}; }
template <class S> Dual<S> abs(const Dual<S>& a) { return a.v < 0 ? -a : a; }
template <class S> Dual<S> sigmoid(const Dual<S>& a) {
  const S y = a.v >= 0 ? S(1) / (S(1) + std::exp(-a.v)) : std::exp(a.v) / (S(1) + std::exp(a.v));
  return {y, y * (S(1) - y) * a.d};
}

using DualF = Dual<float>;
using DualD = Dual<double>;

}  // namespace video3dgs::autodiff
