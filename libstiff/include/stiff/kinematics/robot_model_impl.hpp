/// \file robot_model_impl.hpp
/// Template bodies of robot_model.hpp; visible so that ceres::Jet instantiations compile.
#pragma once

#include <cmath>

namespace stiff {

template <typename Scalar>
Matrix4<Scalar> rot_x(Scalar angle) {
  using std::cos;
  using std::sin;
  Matrix4<Scalar> t = Matrix4<Scalar>::Identity();
  t(1, 1) = cos(angle);
  t(1, 2) = -sin(angle);
  t(2, 1) = sin(angle);
  t(2, 2) = cos(angle);
  return t;
}

template <typename Scalar>
Matrix4<Scalar> rot_z(Scalar angle) {
  using std::cos;
  using std::sin;
  Matrix4<Scalar> t = Matrix4<Scalar>::Identity();
  t(0, 0) = cos(angle);
  t(0, 1) = -sin(angle);
  t(1, 0) = sin(angle);
  t(1, 1) = cos(angle);
  return t;
}

template <typename Scalar>
Matrix4<Scalar> translation(Scalar x, Scalar y, Scalar z) {
  Matrix4<Scalar> t = Matrix4<Scalar>::Identity();
  t(0, 3) = x;
  t(1, 3) = y;
  t(2, 3) = z;
  return t;
}

namespace detail {
// Rotation about a unit axis by angle (Rodrigues), as a homogeneous transform.
template <typename Scalar>
Matrix4<Scalar> rot_axis(const Vector3<Scalar>& u, const Scalar& angle) {
  using std::cos;
  using std::sin;
  const Scalar c = cos(angle), s = sin(angle), v = Scalar(1) - c;
  Matrix4<Scalar> t = Matrix4<Scalar>::Identity();
  t(0, 0) = u.x() * u.x() * v + c;
  t(0, 1) = u.x() * u.y() * v - u.z() * s;
  t(0, 2) = u.x() * u.z() * v + u.y() * s;
  t(1, 0) = u.y() * u.x() * v + u.z() * s;
  t(1, 1) = u.y() * u.y() * v + c;
  t(1, 2) = u.y() * u.z() * v - u.x() * s;
  t(2, 0) = u.z() * u.x() * v - u.y() * s;
  t(2, 1) = u.z() * u.y() * v + u.x() * s;
  t(2, 2) = u.z() * u.z() * v + c;
  return t;
}
}  // namespace detail

template <typename Scalar>
bool RobotModelTpl<Scalar>::has_masses() const {
  if (tool_mass > 0.0) return true;
  for (const auto& j : joints)
    if (j.mass > 0.0) return true;
  return false;
}

template <typename Scalar>
ChainStateTpl<Scalar> RobotModelTpl<Scalar>::chain(const VectorX<Scalar>& q) const {
  const int n = dof();
  ChainStateTpl<Scalar> s;
  s.link.resize(n);
  s.axis.resize(3, n);
  s.origin.resize(3, n);
  Matrix4<Scalar> t = Matrix4<Scalar>::Identity();
  for (int i = 0; i < n; ++i) {
    const auto& j = joints[i];
    t = t * j.pre;
    // The rotation acts about the axis through the origin of the frame after `pre`.
    s.axis.col(i) = t.template block<3, 3>(0, 0) * j.axis;
    s.origin.col(i) = t.template block<3, 1>(0, 3);
    t = t * detail::rot_axis<Scalar>(j.axis, q(i)) * j.post;
    s.link[i] = t;
  }
  s.flange = t;
  return s;
}

template <typename Scalar>
Vector3<Scalar> RobotModelTpl<Scalar>::point_position(const ChainStateTpl<Scalar>& s,
                                                      const Vector3<Scalar>& p_flange) const {
  return s.flange.template block<3, 3>(0, 0) * p_flange + s.flange.template block<3, 1>(0, 3);
}

template <typename Scalar>
Matrix4<Scalar> RobotModelTpl<Scalar>::tool_pose(const VectorX<Scalar>& q) const {
  const auto s = chain(q);
  Matrix4<Scalar> t = s.flange;
  t.template block<3, 1>(0, 3) = point_position(s, measured_point);
  return t;
}

template <typename Scalar>
Matrix6X<Scalar> RobotModelTpl<Scalar>::jacobian_at(const ChainStateTpl<Scalar>& s,
                                                    const Vector3<Scalar>& p) const {
  const int n = dof();
  Matrix6X<Scalar> jac(6, n);
  for (int i = 0; i < n; ++i) {
    const Vector3<Scalar> z = s.axis.col(i);
    const Vector3<Scalar> r = p - s.origin.col(i);
    jac.template block<3, 1>(0, i) = z.cross(r);
    jac.template block<3, 1>(3, i) = z;
  }
  return jac;
}

template <typename Scalar>
Matrix6X<Scalar> RobotModelTpl<Scalar>::jacobian(const VectorX<Scalar>& q) const {
  const auto s = chain(q);
  return jacobian_at(s, point_position(s, measured_point));
}

}  // namespace stiff
