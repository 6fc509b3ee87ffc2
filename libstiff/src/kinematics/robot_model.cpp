#include "stiff/kinematics/robot_model.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

#include "stiff/error.hpp"
#include "stiff/kinematics/joint_torque.hpp"

namespace stiff {

template class RobotModelTpl<double>;

const char* to_string(Convention c) {
  switch (c) {
    case Convention::modified_dh:
      return "modified_dh";
    case Convention::standard_dh:
      return "standard_dh";
    case Convention::urdf:
      return "urdf";
  }
  return "unknown";
}

Joint modified_dh_joint(double alpha, double a, double d, double theta_offset) {
  // Craig: T = RotX(alpha) TransX(a) RotZ(theta) TransZ(d); TransZ commutes with RotZ.
  Joint j;
  j.pre = rot_x(alpha) * translation(a, 0.0, 0.0) * translation(0.0, 0.0, d) * rot_z(theta_offset);
  j.dh[0] = alpha;
  j.dh[1] = a;
  j.dh[2] = d;
  j.dh[3] = theta_offset;
  return j;
}

Joint standard_dh_joint(double alpha, double a, double d, double theta_offset) {
  // Denavit-Hartenberg: T = RotZ(theta) TransZ(d) TransX(a) RotX(alpha).
  Joint j;
  j.post = rot_z(theta_offset) * translation(0.0, 0.0, d) * translation(a, 0.0, 0.0) * rot_x(alpha);
  j.dh[0] = alpha;
  j.dh[1] = a;
  j.dh[2] = d;
  j.dh[3] = theta_offset;
  return j;
}

Eigen::MatrixXd gravity_torques_by_link(const RobotModel& robot,
                                        const ChainState& s,
                                        Eigen::MatrixXd* quadrature) {
  const int n = robot.dof();
  Eigen::MatrixXd tau = Eigen::MatrixXd::Zero(n, n);
  if (quadrature) quadrature->setZero(n, n);
  auto add_weight = [&](int link, double mass, const Eigen::Vector3d& com_local) {
    if (mass <= 0.0) return;
    const Eigen::Matrix4d& t = s.link[link];
    const Eigen::Vector3d c = t.block<3, 3>(0, 0) * com_local + t.block<3, 1>(0, 3);
    const Eigen::Vector3d w = mass * robot.gravity;
    // Only joints up to and including `link` carry the weight of that link.
    for (int j = 0; j <= link; ++j) {
      Eigen::Vector3d lever;
      lever_arm(s.axis.col(j), s.origin.col(j), c, lever);
      tau(j, link) += force_torque(lever, w);
      if (quadrature) (*quadrature)(j, link) += s.axis.col(j).dot(lever.cross(w));
    }
  };
  for (int i = 0; i < n; ++i) add_weight(i, robot.joints[i].mass, robot.joints[i].com);
  if (n > 0) add_weight(n - 1, robot.tool_mass, robot.tool_com);
  return tau;
}

Eigen::VectorXd gravity_torques(const RobotModel& robot,
                                const ChainState& s,
                                Eigen::VectorXd* quadrature) {
  Eigen::MatrixXd q;
  const Eigen::VectorXd tau =
      gravity_torques_by_link(robot, s, quadrature ? &q : nullptr).rowwise().sum();
  if (quadrature) *quadrature = q.rowwise().sum();
  return tau;
}

JacobianConditioning translational_conditioning(const RobotModel& robot, const Eigen::VectorXd& q) {
  const Eigen::Matrix<double, 3, Eigen::Dynamic> jt = robot.jacobian(q).topRows<3>();
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(jt);
  const auto& sv = svd.singularValues();
  const double smin = sv(sv.size() - 1);
  return {smin, smin > 0 ? sv(0) / smin : INFINITY};
}

namespace {

// Singular values of the compensation's Jacobian at q divided by the largest, ascending.
Eigen::VectorXd relative_singular_values(const RobotModel& robot, const Eigen::VectorXd& q) {
  const Matrix6X<double> j = robot.jacobian(q);
  Eigen::MatrixXd a;
  if (robot.dof() >= 6) {
    double length = robot.measured_point.norm();
    for (const auto& joint : robot.joints)
      length += joint.pre.block<3, 1>(0, 3).norm() + joint.post.block<3, 1>(0, 3).norm();
    a = j;
    if (length > 0) a.topRows<3>() /= length;
  } else {
    a = j.topRows<3>();
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(a);
  Eigen::VectorXd s = svd.singularValues().reverse();
  if (s.size() == 0 || !(s(s.size() - 1) > 0)) return Eigen::VectorXd::Zero(s.size());
  return s / s(s.size() - 1);
}

// a better than b: compared from the smallest value up, so that where two directions are
// singular (the all-zero pose of many arms) lifting one of them already counts.
bool more_dexterous(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  for (Eigen::Index i = 0; i < a.size(); ++i) {
    if (a(i) > b(i) + 1e-9) return true;
    if (a(i) < b(i) - 1e-9) return false;
  }
  return false;
}

}  // namespace

double compensation_dexterity(const RobotModel& robot, const Eigen::VectorXd& q) {
  const Eigen::VectorXd s = relative_singular_values(robot, q);
  return s.size() == 0 ? 0.0 : s(0);
}

Eigen::VectorXd home_pose(const RobotModel& robot) {
  constexpr double kPi = 3.141592653589793238462643383279502884;
  const int n = robot.dof();
  Eigen::VectorXd mid(n), half(n);
  for (int i = 0; i < n; ++i) {
    const Joint& j = robot.joints[static_cast<size_t>(i)];
    mid(i) = 0.5 * (j.lower + j.upper);
    // Beyond +-pi about the middle a revolute joint only repeats angles.
    half(i) = std::min(0.5 * (j.upper - j.lower), kPi);
  }
  Eigen::VectorXd q = mid;
  Eigen::VectorXd best = relative_singular_values(robot, q);
  for (int sweep = 0; sweep < 8; ++sweep) {
    bool moved = false;
    for (int i = 0; i < n; ++i) {
      Eigen::VectorXd trial = q;
      double value = q(i);
      for (double f : {0.0, -2.0 / 3.0, -1.0 / 3.0, 1.0 / 3.0, 2.0 / 3.0}) {
        trial(i) = mid(i) + f * half(i);
        const Eigen::VectorXd s = relative_singular_values(robot, trial);
        // Strictly better only: a joint the Jacobian does not see stays where it is.
        if (more_dexterous(s, best)) {
          best = s;
          value = trial(i);
        }
      }
      if (value != q(i)) {
        q(i) = value;
        moved = true;
      }
    }
    if (!moved) break;
  }
  return q;
}

void check_joint_vector(const RobotModel& robot,
                        const Eigen::VectorXd& q,
                        const std::string& where) {
  if (q.size() != robot.dof())
    throw InvalidArgument(where + ": " + std::to_string(q.size()) + " joint values for a " +
                          std::to_string(robot.dof()) + "-joint robot");
  for (int i = 0; i < q.size(); ++i)
    if (!std::isfinite(q(i)))
      throw InvalidArgument(where + ": joint q" + std::to_string(i + 1) + " is not finite");
}

}  // namespace stiff
