// The kinematics templated on the scalar: RobotModelTpl<ceres::Jet> differentiates the forward
// kinematics exactly, so its derivatives with respect to the joints must equal the geometric
// Jacobian that the double instantiation builds from the joint axes (two independent routes to
// the same matrix: automatic differentiation of FK, and z_j x (p - o_j)).
#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "stiff/io/robot_io.hpp"
#include "stiff/kinematics/robot_model.hpp"
#include "stiff/kinematics/robot_model_impl.hpp"
#include "test_support.hpp"

namespace stiff {
namespace {

using Jet6 = ceres::Jet<double, 6>;

void expect_autodiff_equals_jacobian(const RobotModel& robot, const Eigen::VectorXd& q) {
  ASSERT_EQ(robot.dof(), 6);
  const RobotModelTpl<Jet6> jet_robot = robot.cast<Jet6>();
  VectorX<Jet6> qj(6);
  for (int i = 0; i < 6; ++i) qj(i) = Jet6(q(i), i);
  const Matrix4<Jet6> pose = jet_robot.tool_pose(qj);
  const Matrix6X<double> jac = robot.jacobian(q);
  const Eigen::Matrix4d pose_d = robot.tool_pose(q);
  for (int r = 0; r < 3; ++r) {
    EXPECT_NEAR(pose(r, 3).a, pose_d(r, 3), 1e-15);
    for (int i = 0; i < 6; ++i) EXPECT_NEAR(pose(r, 3).v(i), jac(r, i), 1e-14) << r << "," << i;
  }
  // Angular rows: dR/dq_i R^T = [z_i]x, the skew matrix of the joint axis.
  for (int i = 0; i < 6; ++i) {
    Eigen::Matrix3d dr, rot;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        dr(a, b) = pose(a, b).v(i);
        rot(a, b) = pose(a, b).a;
      }
    const Eigen::Matrix3d w = dr * rot.transpose();
    const Eigen::Vector3d axis(w(2, 1), w(0, 2), w(1, 0));
    EXPECT_NEAR((axis - jac.block<3, 1>(3, i)).norm(), 0.0, 1e-14) << "joint " << i + 1;
  }
}

TEST(RobotModelJet, AutodiffOfForwardKinematicsIsTheGeometricJacobian) {
  Eigen::VectorXd q(6);
  q << 0.3, -0.7, 0.9, -1.4, 0.6, 2.1;
  expect_autodiff_equals_jacobian(test::rokae(), q);  // modified DH
  expect_autodiff_equals_jacobian(
      load_robot(std::string(STIFF_SOURCE_DIR) + "/examples/robots/puma560.yaml"), q);
  expect_autodiff_equals_jacobian(
      load_robot(std::string(STIFF_SOURCE_DIR) + "/examples/robots/ur5.urdf"), q);  // URDF
}

}  // namespace
}  // namespace stiff
