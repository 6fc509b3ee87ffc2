/// \file effects/common.hpp
/// What an effect source file includes. Generic code rules (style.md 3.3): literals as T(x),
/// never cast T to double, maths functions unqualified after `using std::sin;`.
#pragma once

#include <ceres/rotation.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "stiff/effect.hpp"
#include "stiff/error.hpp"

namespace stiff::effects {

/// A parameter spec in one line: name, SI unit, one line of physics, bounds, typical
/// magnitude, null value (effect off) and start value of a fit.
inline ParameterSpec parameter(std::string name,
                               std::string unit,
                               std::string meaning,
                               double lower,
                               double upper,
                               double typical,
                               double null_value,
                               double start) {
  ParameterSpec p;
  p.name = std::move(name);
  p.unit = std::move(unit);
  p.meaning = std::move(meaning);
  p.lower = lower;
  p.upper = upper;
  p.typical = typical;
  p.null_value = null_value;
  p.start = start;
  return p;
}

/// True when v carries no derivative (always for double): a pass of automatic
/// differentiation that does not move it.
inline bool constant(const Vector3<double>&) { return true; }
inline bool constant(const Vector3<Jet>& v) {
  return v(0).v.isZero(0.0) && v(1).v.isZero(0.0) && v(2).v.isZero(0.0);
}
/// The values of v.
inline Eigen::Vector3d value(const Vector3<double>& v) { return v; }
inline Eigen::Vector3d value(const Vector3<Jet>& v) { return {v(0).a, v(1).a, v(2).a}; }

/// Flange rotation R_06 (flange frame -> base frame) of the measurement's configuration.
template <typename T>
Matrix3<T> flange_rotation(const EvalState<T>& s) {
  return s.context->chain.flange.template block<3, 3>(0, 0).template cast<T>();
}

/// Rotation matrix of the rotation vector w (axis * angle) [rad]; exact, and differentiable at
/// w = 0 (Ceres uses the Taylor expansion there).
template <typename T>
Matrix3<T> rotation_matrix(const T* w) {
  Matrix3<T> r;  // column-major, as AngleAxisToRotationMatrix writes by default
  ceres::AngleAxisToRotationMatrix(w, r.data());
  return r;
}

}  // namespace stiff::effects
