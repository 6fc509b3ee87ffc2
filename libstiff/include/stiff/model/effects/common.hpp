/// \file effects/common.hpp
/// What an effect source file includes. Generic code rules: literals as T(x),
/// never cast T to double, maths functions unqualified after `using std::sin;`.
#pragma once

#include <ceres/rotation.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "stiff/error.hpp"
#include "stiff/model/effect.hpp"

namespace stiff::effects {

/// Experiments that separate effects (Effect::experiment_hints), shared by the effects that
/// the same experiment tells apart.
inline constexpr const char* kHintLoadReversal =
    "load reversal: measure +F and -F at every pose (a linear-elastic response is odd in F; "
    "backlash, preload nonlinearity and drift show in the even part)";
inline constexpr const char* kHintLoadLevel =
    "a second load level at a subset of poses (nonlinear and second-order stiffness depend on "
    "the level, backlash and drift do not)";
inline constexpr const char* kHintGravityVariety =
    "more gravity variety: poses over the whole q2/q3 range (gravity preload differs)";

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
  // Exact zeros (a NaN is not one), as isZero(0.0) but without its per-element abs.
  return (v(0).v.array() == 0.0).all() && (v(1).v.array() == 0.0).all() &&
         (v(2).v.array() == 0.0).all();
}
/// The values of v.
inline Eigen::Vector3d value(const Vector3<double>& v) { return v; }
inline Eigen::Vector3d value(const Vector3<Jet>& v) { return {v(0).a, v(1).a, v(2).a}; }

/// a . b for a constant vector b, and y += x b: one pass over a Jet's derivative part instead
/// of a Jet temporary per product and sum.
inline double dot(const Vector3<double>& a, const Eigen::Vector3d& b) { return a.dot(b); }
inline Jet dot(const Vector3<Jet>& a, const Eigen::Vector3d& b) {
  return Jet(a(0).a * b(0) + a(1).a * b(1) + a(2).a * b(2),
             a(0).v * b(0) + a(1).v * b(1) + a(2).v * b(2));
}
inline void add_scaled(Vector3<double>& y, double x, const Eigen::Vector3d& b) { y += x * b; }
inline void add_scaled(Vector3<Jet>& y, const Jet& x, const Eigen::Vector3d& b) {
  for (int r = 0; r < 3; ++r) {
    y(r).a += x.a * b(r);
    y(r).v += x.v * b(r);
  }
}

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

/// Right Jacobian of SO(3) at the rotation vector w: Exp(w + dw) = Exp(w) Exp(J_r(w) dw) to
/// first order, J_r = I - (1 - cos t) / t^2 [w]x + (t - sin t) / t^3 [w]x^2 with t = |w|
/// (series below 1e-4 rad, where the closed form cancels; Sola, Deray & Atchuthan, A micro
/// Lie theory for state estimation in robotics, 2018).
inline Eigen::Matrix3d right_jacobian(const Eigen::Vector3d& w) {
  Eigen::Matrix3d k;
  k << 0, -w(2), w(1), w(2), 0, -w(0), -w(1), w(0), 0;
  const double th = w.norm();
  const double c1 = th < 1e-4 ? 0.5 - th * th / 24 : (1 - std::cos(th)) / (th * th);
  const double c2 = th < 1e-4 ? 1.0 / 6 - th * th / 120 : (th - std::sin(th)) / (th * th * th);
  return Eigen::Matrix3d::Identity() - c1 * k + c2 * k * k;
}

/// First alignment of absolute data with the nominal robot: per session the rigid motion
/// (instrument <- base) and one offset of the measured point (flange frame) that best map the
/// nominal forward kinematics onto the measured positions (least squares, alternating the
/// rotations by the SVD method of Arun, Huang & Blostein 1987 with a joint linear solve of the
/// point offset and the translations), and the mean rotation of a 6-D probe on the flange.
/// Start values of `registration`, `tool` and `tool_orientation`.
struct Alignment {
  std::vector<std::string> sessions;      ///< labels, in the model's session order
  std::vector<Eigen::Matrix3d> rotation;  ///< per session: instrument <- base
  std::vector<Eigen::Vector3d> translation;
  Eigen::Vector3d point_offset = Eigen::Vector3d::Zero();  ///< flange frame [m]
  /// Rows with orientation: rotation vector of the probe frame in the flange frame [rad].
  Eigen::Vector3d probe = Eigen::Vector3d::Zero();
  double rms = 0.0;  ///< residual RMS after alignment [m]
};
/// Throws InvalidArgument naming a session whose target positions are (nearly) collinear.
Alignment alignment(const RobotModel& robot, const Dataset& data);

}  // namespace stiff::effects
