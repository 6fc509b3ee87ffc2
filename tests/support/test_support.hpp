// Shared helpers of the C++ tests: paths of built-in files, the paper's robot and designs.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "stiff/io/dataset.hpp"
#include "stiff/io/robot_io.hpp"

namespace stiff::test {

inline std::string source_path(const std::string& rel) {
  return std::string(STIFF_SOURCE_DIR) + "/" + rel;
}

inline RobotModel rokae() { return load_robot(source_path("examples/robots/rokae.yaml")); }

/// The paper's identified stiffness (Jiang & Fang 2023), N*m/rad; joint 6 assumed 4000 (not
/// identified).
inline Eigen::VectorXd paper_stiffness() {
  Eigen::VectorXd k(6);
  k << 5.0914e4, 1.6382e4, 3.1311e4, 7.7911e3, 5.6136e3, 4.0e3;
  return k;
}

/// The paper's kappa_F^-1(A) design: 10 poses (deg) and loads (N, base frame).
inline Dataset paper_design_a() {
  return read_measurements_csv(source_path("examples/paper/design_kappa_a.csv"), 6);
}
inline Dataset paper_design_j() {
  return read_measurements_csv(source_path("examples/paper/design_kappa_j.csv"), 6);
}

/// The transform a joint's kinematic errors (du, dv [m], ru, rv [rad]) put after its `pre`
/// frame, independently of the effect's code: a translation du u + dv v and a rotation by
/// ru u + rv v, with u the frame axis least aligned with the joint axis a, made orthogonal,
/// and v = a x u (docs/effects.md, kinematic).
inline Eigen::Matrix4d axis_error_transform(const Eigen::Vector3d& a, const Eigen::Vector4d& e) {
  int least = 0;
  a.cwiseAbs().minCoeff(&least);
  const Eigen::Vector3d x = Eigen::Vector3d::Unit(least);
  const Eigen::Vector3d u = (x - x.dot(a) * a).normalized(), v = a.cross(u);
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  const Eigen::Vector3d w = e(2) * u + e(3) * v;
  if (w.norm() > 0) t.topLeftCorner<3, 3>() = Eigen::AngleAxisd(w.norm(), w.normalized()).matrix();
  t.topRightCorner<3, 1>() = e(0) * u + e(1) * v;
  return t;
}

}  // namespace stiff::test
