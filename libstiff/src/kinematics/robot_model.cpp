#include "stiff/kinematics/robot_model.hpp"

#include <Eigen/SVD>
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

Eigen::VectorXd gravity_torques(const RobotModel& robot, const ChainState& s) {
  const int n = robot.dof();
  Eigen::VectorXd tau = Eigen::VectorXd::Zero(n);
  auto add_weight = [&](int link, double mass, const Eigen::Vector3d& com_local) {
    if (mass <= 0.0) return;
    const Eigen::Matrix4d& t = s.link[link];
    const Eigen::Vector3d c = t.block<3, 3>(0, 0) * com_local + t.block<3, 1>(0, 3);
    const Eigen::Vector3d w = mass * robot.gravity;
    // Only joints up to and including `link` carry the weight of that link.
    for (int j = 0; j <= link; ++j) {
      Eigen::Vector3d lever;
      lever_arm(s.axis.col(j), s.origin.col(j), c, lever);
      tau(j) += force_torque(lever, w);
    }
  };
  for (int i = 0; i < n; ++i) add_weight(i, robot.joints[i].mass, robot.joints[i].com);
  if (n > 0) add_weight(n - 1, robot.tool_mass, robot.tool_com);
  return tau;
}

JacobianConditioning translational_conditioning(const RobotModel& robot, const Eigen::VectorXd& q) {
  const Eigen::Matrix<double, 3, Eigen::Dynamic> jt = robot.jacobian(q).topRows<3>();
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(jt);
  const auto& sv = svd.singularValues();
  const double smin = sv(sv.size() - 1);
  return {smin, smin > 0 ? sv(0) / smin : INFINITY};
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
