// Compensation with a model of absolute accuracy (geometry, tool, registration, joint
// compliance with the robot's weight): the command must bring the tool of the CALIBRATED
// robot to the nominal target. The truth is evaluated independently of the model's corrected
// kinematics: a robot whose joint transforms are moved (RobotModel::chain), deflected by
// dtheta = C (J(L)^T W + tau_g) of that robot, through its forward kinematics.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

#include "stiff/compensate/compensate.hpp"
#include "stiff/error.hpp"
#include "stiff/io/robot_io.hpp"
#include "test_support.hpp"

namespace stiff {
namespace {

struct Geometry {
  Eigen::VectorXd dq;    ///< joint offsets [rad]
  Eigen::MatrixXd axis;  ///< 4 x n: du, dv [m], ru, rv [rad] per joint (kinematic effect)
  Eigen::Vector3d tool;  ///< target offset, flange frame [m]
};

/// The real robot: joint transforms moved by the axis errors, the offsets turned into the
/// joints' origins, the target moved on the flange, the load point where it was.
RobotModel real_robot(const RobotModel& nominal, const Geometry& g) {
  RobotModel r = nominal;
  for (int j = 0; j < r.dof(); ++j) {
    const Eigen::Matrix4d e = test::axis_error_transform(r.joints[j].axis, g.axis.col(j));
    Eigen::Matrix4d z = Eigen::Matrix4d::Identity();
    z.topLeftCorner<3, 3>() = Eigen::AngleAxisd(g.dq(j), r.joints[j].axis).matrix();
    r.joints[j].pre = r.joints[j].pre * e * z;
  }
  // The tool effect moves the measured target; the process force acts where the robot file
  // (or --load-point) says.
  r.measured_point += g.tool;
  return r;
}

/// Tool pose of the real robot at command q under wrench W at the tool point, with joint
/// compliances c (none: rigid): its own Jacobian and gravity torques, its own kinematics.
Eigen::Matrix4d real_pose(const RobotModel& real,
                          const Eigen::VectorXd& q,
                          const Vector6d& w,
                          const Eigen::VectorXd& c) {
  if (c.size() == 0) return real.tool_pose(q);
  const ChainState s = real.chain(q);
  const Eigen::VectorXd tau =
      real.jacobian_at(s, real.point_position(s, real.load_point)).transpose() * w +
      gravity_torques(real, s);
  return real.tool_pose(q + c.cwiseProduct(tau));
}

/// The model's parameters for the geometry g (registration: an instrument 2 m away, turned),
/// compliances c.
Eigen::VectorXd theta_for(const DeflectionModel& m, const Geometry& g, const Eigen::VectorXd& c) {
  Eigen::VectorXd t = m.null_parameters();
  const int n = m.robot().dof();
  const double registration[6] = {0.1, -0.2, 2.1, 2.0, -1.0, 0.4};
  for (int k = 0; k < 6; ++k) t(m.offset(m.find("registration")) + k) = registration[k];
  t.segment<3>(m.offset(m.find("tool"))) = g.tool;
  t.segment(m.offset(m.find("joint_offset")), n) = g.dq;
  for (int j = 0; j < n; ++j) t.segment<4>(m.offset(m.find("kinematic")) + 4 * j) = g.axis.col(j);
  if (c.size()) t.segment(m.offset(m.find("joint")), n) = c;
  return t;
}

Geometry random_geometry(int n, std::mt19937_64& rng) {
  std::normal_distribution<double> z(0.0, 1.0);
  Geometry g;
  g.dq = Eigen::VectorXd::NullaryExpr(n, [&] { return 1e-3 * z(rng); });
  g.axis.resize(4, n);
  for (int j = 0; j < n; ++j)
    g.axis.col(j) << 3e-4 * z(rng), 3e-4 * z(rng), 1e-3 * z(rng), 1e-3 * z(rng);
  g.tool = Eigen::Vector3d(0.01 * z(rng), 0.01 * z(rng), 0.05 + 0.01 * z(rng));
  return g;
}

double distance(const Eigen::Matrix4d& a, const Eigen::Matrix4d& b) {
  return (a.col(3) - b.col(3)).norm();
}

double rotation_angle(const Eigen::Matrix4d& a, const Eigen::Matrix4d& b) {
  return Eigen::AngleAxisd(a.topLeftCorner<3, 3>() * b.topLeftCorner<3, 3>().transpose()).angle();
}

const std::vector<std::string> kGeometric = {"registration", "tool", "joint_offset", "kinematic"};

TEST(GeometricCompensation, TheCalibratedToolReachesTheNominalTarget) {
  // Geometry only: the real robot at the command is at the target to the solver's tolerance
  // (the model's corrected chain and RobotModel::chain of the moved robot agree to rounding).
  const RobotModel robot = load_robot(test::source_path("examples/robots/ur5.urdf"));
  std::mt19937_64 rng(3);
  const Geometry g = random_geometry(robot.dof(), rng);
  const RobotModel real = real_robot(robot, g);
  const DeflectionModel model(robot, kGeometric, nullptr, {"S0"});
  const Eigen::VectorXd theta = theta_for(model, g, {});
  std::uniform_real_distribution<double> u(-2.5, 2.5);
  double worst_nominal = 0.0;
  for (int trial = 0; trial < 10; ++trial) {
    const Eigen::VectorXd q = Eigen::VectorXd::NullaryExpr(6, [&] { return u(rng); });
    if (compensation_dexterity(robot, q) < 0.05) continue;  // away from singular poses
    const Eigen::Matrix4d target = robot.tool_pose(q);
    const PoseCompensation c = compensate_pose(model, theta, target, q, Vector6d::Zero());
    ASSERT_TRUE(c.converged) << c.residual;
    const Eigen::Matrix4d reached = real.tool_pose(c.q_cmd);
    EXPECT_LT(distance(reached, target), 1e-9) << trial;
    EXPECT_LT(rotation_angle(reached, target), 1e-9) << trial;
    worst_nominal = std::max(worst_nominal, distance(real.tool_pose(q), target));
  }
  // The geometry matters: the nominal command misses by millimetres (tool offset ~5 cm).
  EXPECT_GT(worst_nominal, 1e-3);
}

TEST(GeometricCompensation, GeometryDeflectionAndWeightTogether) {
  // With joint compliance the model deflects the corrected pose by J dtheta on the nominal
  // chain; the real robot turns its own joints. They differ by second-order terms: the
  // rotations' products, |dtheta|_1^2 (times the reach, ~1 m, for the position), and the
  // deflection times the angle by which the real axes are turned from the nominal ones (at
  // most the sum of the tilts and offsets). The solver's own residual is at 1e-12.
  const RobotModel robot = load_robot(test::source_path("examples/robots/ur5.urdf"));
  ASSERT_TRUE(robot.has_masses());
  std::mt19937_64 rng(4);
  const Geometry g = random_geometry(robot.dof(), rng);
  const RobotModel real = real_robot(robot, g);
  const double tilt = g.axis.bottomRows<2>().cwiseAbs().sum() + g.dq.cwiseAbs().sum();
  std::vector<std::string> effects = kGeometric;
  effects.push_back("joint");
  const DeflectionModel model(robot, effects, nullptr, {"S0"});
  Eigen::VectorXd c(6);
  c << 2e-6, 1.5e-6, 2e-6, 4e-6, 5e-6, 5e-6;  // rad/(N*m)
  const Eigen::VectorXd theta = theta_for(model, g, c);
  Vector6d w;
  w << 80.0, -50.0, -120.0, 0.0, 0.0, 0.0;
  std::uniform_real_distribution<double> u(-2.5, 2.5);
  int tried = 0;
  while (tried < 8) {
    const Eigen::VectorXd q = Eigen::VectorXd::NullaryExpr(6, [&] { return u(rng); });
    if (compensation_dexterity(robot, q) < 0.05) continue;
    ++tried;
    const Eigen::Matrix4d target = robot.tool_pose(q);
    const PoseCompensation cmd = compensate_pose(model, theta, target, q, w);
    ASSERT_TRUE(cmd.converged) << cmd.residual;
    EXPECT_LE(cmd.residual, 1e-12);
    const Eigen::Matrix4d reached = real_pose(real, cmd.q_cmd, w, c);
    const ChainState s = real.chain(cmd.q_cmd);
    const Eigen::VectorXd tau =
        real.jacobian_at(s, real.point_position(s, real.load_point)).transpose() * w +
        gravity_torques(real, s);
    const double dtheta = c.cwiseProduct(tau).lpNorm<1>();
    const double bound = dtheta * dtheta + dtheta * tilt;
    EXPECT_LT(distance(reached, target), bound) << tried << " |dtheta|_1 = " << dtheta;
    EXPECT_LT(rotation_angle(reached, target), bound) << tried << " |dtheta|_1 = " << dtheta;
    // Without the deflection (geometry alone) the real robot misses by the deflection.
    const PoseCompensation rigid = compensate_pose(
        DeflectionModel(robot, kGeometric, nullptr, {"S0"}),
        theta_for(DeflectionModel(robot, kGeometric, nullptr, {"S0"}), g, {}), target, q, w);
    EXPECT_GT(distance(real_pose(real, rigid.q_cmd, w, c), target), 1e-5);
  }
}

TEST(GeometricCompensation, PathReportsTheCalibratedDeviation) {
  // compensate_path's `predicted` is where the calibrated model puts the tool at the nominal
  // joints, relative to the nominal pose: the real robot's miss.
  const RobotModel robot = load_robot(test::source_path("examples/robots/ur5.urdf"));
  std::mt19937_64 rng(5);
  const Geometry g = random_geometry(robot.dof(), rng);
  const RobotModel real = real_robot(robot, g);
  const DeflectionModel model(robot, kGeometric, nullptr, {"S0"});
  const Eigen::VectorXd theta = theta_for(model, g, {});
  std::vector<Eigen::Matrix4d> poses;
  Eigen::VectorXd q0(6);
  q0 << 0.3, -1.2, 1.4, -1.6, -1.5, 0.2;
  for (int k = 0; k < 5; ++k) {
    Eigen::Matrix4d t = robot.tool_pose(q0);
    t(0, 3) += 0.01 * k;
    poses.push_back(t);
  }
  const PathCompensation p = compensate_path(model, theta, poses, Eigen::MatrixXd::Zero(1, 6), q0);
  for (size_t i = 0; i < poses.size(); ++i) {
    ASSERT_EQ(p.status[i] & kPointNotConverged, 0) << i;
    const Eigen::VectorXd qn = p.nominal.q.row(static_cast<Eigen::Index>(i)).transpose();
    const Eigen::Vector3d miss =
        real.tool_pose(qn).topRightCorner<3, 1>() - robot.tool_pose(qn).topRightCorner<3, 1>();
    EXPECT_LT((p.predicted.row(static_cast<Eigen::Index>(i)).head<3>().transpose() - miss).norm(),
              1e-9);
    const Eigen::VectorXd qc = p.q_cmd.row(static_cast<Eigen::Index>(i)).transpose();
    EXPECT_LT(distance(real.tool_pose(qc), poses[i]), 1e-9);
  }
}

}  // namespace
}  // namespace stiff
