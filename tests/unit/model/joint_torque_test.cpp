// The statics of a revolute joint (joint_torque.hpp) against the transpose of the geometric
// Jacobian, tau = J(L)^T (F, M), computed by the kinematics from its own Jacobian code.
#include "stiff/kinematics/joint_torque.hpp"

#include <gtest/gtest.h>

#include "stiff/kinematics/robot_model.hpp"
#include "test_support.hpp"

namespace stiff {
namespace {

TEST(JointTorque, EqualsTheJacobianTransposeTimesTheWrench) {
  const RobotModel robot = test::rokae();
  Eigen::VectorXd q(6);
  q << 0.3, -0.2, 0.5, -1.1, 0.7, 2.0;
  const ChainState s = robot.chain(q);
  const Eigen::Vector3d load(0.41, -0.12, 0.33);  // any point, base frame [m]
  const Matrix6X<double> jac = robot.jacobian_at(s, load);
  Eigen::Matrix<double, 6, 1> wrench;
  wrench << 35, -15, 30, 2.5, -1.0, 0.4;
  const Eigen::VectorXd expected = jac.transpose() * wrench;
  for (int j = 0; j < robot.dof(); ++j) {
    const Eigen::Vector3d z = s.axis.col(j), o = s.origin.col(j);
    Eigen::Vector3d w;
    lever_arm(z, o, load, w);
    EXPECT_NEAR((w - jac.block<3, 1>(0, j)).norm(), 0.0, 1e-15);
    const double tau = joint_torque(w, z, wrench.head<3>(), wrench.tail<3>());
    // Rounding of a 6-term dot product of O(10) values.
    EXPECT_NEAR(tau, expected(j), 1e-13) << "joint " << j + 1;
    EXPECT_NEAR(force_torque(w, wrench.head<3>()), tau - z.dot(wrench.tail<3>()), 1e-13);
  }
}

TEST(JointTorque, LanesIndexStructureOfArrays) {
  double v[3][4] = {{1, 2, 3, 4}, {5, 6, 7, 8}, {9, 10, 11, 12}};
  const Lane<4> lane{v, 2};
  EXPECT_EQ(lane[0], 3);
  EXPECT_EQ(lane[1], 7);
  EXPECT_EQ(lane[2], 11);
  const double z[3] = {0, 0, 1}, f[3] = {1, 0, 0}, m[3] = {0, 0, 2};
  // Lever arm of (3, 7, 11) about the z axis through the origin: z x p = (-7, 3, 0).
  double w[3];
  const double o[3] = {0, 0, 0};
  lever_arm(z, o, lane, w);
  EXPECT_EQ(w[0], -7);
  EXPECT_EQ(w[1], 3);
  EXPECT_EQ(w[2], 0);
  EXPECT_EQ(joint_torque(w, z, f, m), -7 + 2);
}

}  // namespace
}  // namespace stiff
