#include "stiff/kinematics/robot_model.hpp"

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "stiff/error.hpp"
#include "stiff/io/robot_io.hpp"
#include "stiff/random.hpp"
#include "test_support.hpp"

namespace stiff {
namespace {

constexpr double kDeg = M_PI / 180.0;

Eigen::VectorXd random_q(const RobotModel& r, Rng& rng) {
  Eigen::VectorXd q(r.dof());
  for (int j = 0; j < r.dof(); ++j) {
    const double lo = std::max(r.joints[j].lower, -M_PI), hi = std::min(r.joints[j].upper, M_PI);
    q(j) = rng.uniform(lo, hi);
  }
  return q;
}

// Central differences of the tool position (linear part) and of the orientation (angular
// part, from R(q+h) R(q-h)^T) against the geometric Jacobian.
void expect_jacobian_matches_fd(const RobotModel& r, const Eigen::VectorXd& q) {
  const Matrix6X<double> jac = r.jacobian(q);
  const double h = 1e-6;
  for (int j = 0; j < r.dof(); ++j) {
    Eigen::VectorXd qp = q, qm = q;
    qp(j) += h;
    qm(j) -= h;
    const Eigen::Matrix4d tp = r.tool_pose(qp), tm = r.tool_pose(qm);
    const Eigen::Vector3d dp = (tp.block<3, 1>(0, 3) - tm.block<3, 1>(0, 3)) / (2 * h);
    const Eigen::Matrix3d dr = tp.block<3, 3>(0, 0) * tm.block<3, 3>(0, 0).transpose();
    const Eigen::Vector3d w =
        Eigen::Vector3d(dr(2, 1) - dr(1, 2), dr(0, 2) - dr(2, 0), dr(1, 0) - dr(0, 1)) / (4 * h);
    // Truncation error of central differences ~ h^2 * |p'''| ~ 1e-12 m; round-off ~ 1e-16/h.
    EXPECT_NEAR((jac.block<3, 1>(0, j) - dp).norm(), 0.0, 1e-8) << r.name << " joint " << j + 1;
    EXPECT_NEAR((jac.block<3, 1>(3, j) - w).norm(), 0.0, 1e-8) << r.name << " joint " << j + 1;
  }
}

TEST(RobotModel, JacobianMatchesCentralDifferencesOnEveryBuiltInRobot) {
  for (const char* name : {"rokae.yaml", "puma560.yaml", "abb_irb120.yaml", "ur5.urdf"}) {
    RobotModel r = load_robot(test::source_path(std::string("examples/robots/") + name));
    r.measured_point = Eigen::Vector3d(0.01, -0.02, 0.05);  // off the flange axis, too
    Rng rng(7);
    for (int k = 0; k < 50; ++k) expect_jacobian_matches_fd(r, random_q(r, rng));
  }
}

TEST(RobotModel, Puma560ForwardKinematicsAtPublishedPoses) {
  // Corke's Robotics Toolbox p560 (standard DH, m): fkine(qz) = [0.4521, -0.1500, 0.4318],
  // fkine(qr = [0 pi/2 -pi/2 0 0 0]) = [0.0203, -0.1500, 0.8636] (flange, no tool, no base
  // transform).
  const RobotModel r = load_robot(test::source_path("examples/robots/puma560.yaml"));
  Eigen::VectorXd qz = Eigen::VectorXd::Zero(6), qr(6);
  qr << 0, M_PI / 2, -M_PI / 2, 0, 0, 0;
  const Eigen::Vector3d pz = r.tool_pose(qz).block<3, 1>(0, 3);
  const Eigen::Vector3d pr = r.tool_pose(qr).block<3, 1>(0, 3);
  EXPECT_NEAR((pz - Eigen::Vector3d(0.4521, -0.1500, 0.4318)).norm(), 0.0, 1e-4);
  EXPECT_NEAR((pr - Eigen::Vector3d(0.0203, -0.1500, 0.8636)).norm(), 0.0, 1e-4);
}

TEST(RobotModel, RokaeZeroPoseFollowsTheDhTable) {
  // At q = 0 the links a1 + a2 + a3 = 30 + 340 + 35 mm lie along the base x axis; alpha1 =
  // alpha3 = -90 deg turn z4 (and with alpha4 = -alpha5 also z6) to the base -z axis, so
  // d4 + d6 = 345 + 87 mm hang downwards.
  const RobotModel r = test::rokae();
  const Eigen::Vector3d p = r.tool_pose(Eigen::VectorXd::Zero(6)).block<3, 1>(0, 3);
  EXPECT_NEAR(p.x(), 0.405, 1e-12);
  EXPECT_NEAR(p.y(), 0.0, 1e-12);
  EXPECT_NEAR(p.z(), -0.432, 1e-12);
}

TEST(RobotModel, CompilesAndAgreesWithCeresJet) {
  using J = ceres::Jet<double, 6>;
  const RobotModel r = test::rokae();
  const RobotModelTpl<J> rj = r.cast<J>();
  Eigen::VectorXd q(6);
  q << 0.1, 0.5, -0.3, 1.0, -0.7, 0.2;
  VectorX<J> qj(6);
  for (int i = 0; i < 6; ++i) qj(i) = J(q(i), i);
  const Matrix4<J> tj = rj.tool_pose(qj);
  const Matrix6X<double> jac = r.jacobian(q);
  // The derivative of the position by autodiff is the linear part of the geometric Jacobian.
  for (int i = 0; i < 6; ++i)
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(tj(k, 3).v(i), jac(k, i), 1e-12);
}

TEST(RobotModel, GravityTorquesBalanceTheWeightMoment) {
  // Virtual work: tau_g . dq = (sum m g) . dp for any motion -> compare with finite differences
  // of the potential energy V = -sum m g . c.
  const RobotModel r = test::rokae();
  Eigen::VectorXd q(6);
  q << 0.3, 0.4, -0.2, 0.8, 0.5, -0.1;
  auto potential = [&](const Eigen::VectorXd& qq) {
    const ChainState s = r.chain(qq);
    double v = 0;
    for (int i = 0; i < 6; ++i) {
      const auto& t = s.link[i];
      const Eigen::Vector3d c = t.block<3, 3>(0, 0) * r.joints[i].com + t.block<3, 1>(0, 3);
      v -= r.joints[i].mass * r.gravity.dot(c);
    }
    const Eigen::Vector3d c = s.flange.block<3, 3>(0, 0) * r.tool_com + s.flange.block<3, 1>(0, 3);
    return v - r.tool_mass * r.gravity.dot(c);
  };
  const Eigen::VectorXd tau = gravity_torques(r, r.chain(q));
  for (int j = 0; j < 6; ++j) {
    Eigen::VectorXd qp = q, qm = q;
    qp(j) += 1e-6;
    qm(j) -= 1e-6;
    EXPECT_NEAR(tau(j), -(potential(qp) - potential(qm)) / 2e-6, 1e-6) << "joint " << j + 1;
  }
}

TEST(RobotFile, BadInputsGiveTheirOwnErrorWithLocation) {
  struct Case {
    const char* text;
    const char* expect;
  };
  const Case cases[] = {
      {"name: x\nconvention: euler\njoints:\n  - {alpha: 0, a: 0, d: 0}\n", "unknown convention"},
      {"name: x\nconvention: modified_dh\njoints:\n  - {alpha: 0, a: 0, d: 0, limits: [10, -10]}\n",
       "lower must be less than upper"},
      {"name: x\nconvention: modified_dh\nunits: {length: furlong}\njoints:\n  - {alpha: 0, a: 0, "
       "d: 0}\n",
       "unknown length unit"},
      {"name: x\nconvention: modified_dh\njoints:\n  - {alpha: 0, a: zero, d: 0}\n",
       "must be a number"},
      {"name: x\nconvention: modified_dh\njoints:\n  - {alpha: 0, d: 0}\n", "missing 'a'"},
      {"name: x\nconvention: modified_dh\njoints: []\n", "non-empty list"},
      {"name: x\nconvention: modified_dh\njoint:\n  - {alpha: 0, a: 0, d: 0}\n",
       "unknown key 'joint'"},
      {"name: [x\n", "robot.yaml:"},
  };
  for (const auto& c : cases) {
    try {
      parse_robot_yaml(c.text, "robot.yaml");
      ADD_FAILURE() << "accepted: " << c.text;
    } catch (const ParseError& e) {
      EXPECT_NE(std::string(e.what()).find(c.expect), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("robot.yaml:"), std::string::npos) << e.what();
    }
  }
}

TEST(RobotFile, YamlRoundTripKeepsKinematics) {
  for (const char* name : {"rokae.yaml", "puma560.yaml", "ur5.urdf"}) {
    const RobotModel r = load_robot(test::source_path(std::string("examples/robots/") + name));
    const RobotModel back = parse_robot_yaml(robot_to_yaml(r), "roundtrip");
    Eigen::VectorXd q(r.dof());
    for (int i = 0; i < r.dof(); ++i) q(i) = 0.1 * (i + 1);
    EXPECT_NEAR((r.tool_pose(q) - back.tool_pose(q)).norm(), 0.0, 1e-12) << name;
    EXPECT_EQ(r.has_masses(), back.has_masses());
  }
}

}  // namespace
}  // namespace stiff

namespace stiff {
namespace {

// The FMU's start pose: inside the limits, and better conditioned for the compensation than a
// typical pose of the range (the median of random poses), on every built-in robot; the
// all-zero pose it replaces is singular on each of them.
TEST(RobotModel, HomePoseIsInsideTheLimitsAndAwayFromSingularities) {
  for (const char* name :
       {"rokae.yaml", "puma560.yaml", "abb_irb120.yaml", "ur10.yaml", "ur5.urdf"}) {
    const RobotModel r = load_robot(test::source_path(std::string("examples/robots/") + name));
    const Eigen::VectorXd home = home_pose(r);
    ASSERT_EQ(home.size(), r.dof());
    for (int j = 0; j < r.dof(); ++j) {
      const double mid = 0.5 * (r.joints[j].lower + r.joints[j].upper);
      const double half = std::min(0.5 * (r.joints[j].upper - r.joints[j].lower), M_PI);
      EXPECT_LE(std::fabs(home(j) - mid), 2.0 / 3.0 * half + 1e-12) << name << " joint " << j + 1;
    }
    Rng rng(11);
    std::vector<double> typical;
    for (int k = 0; k < 201; ++k) typical.push_back(compensation_dexterity(r, random_q(r, rng)));
    std::nth_element(typical.begin(), typical.begin() + 100, typical.end());
    const double at_home = compensation_dexterity(r, home);
    EXPECT_GT(at_home, typical[100]) << name;
    EXPECT_LT(compensation_dexterity(r, Eigen::VectorXd::Zero(r.dof())), 1e-6 * at_home) << name;
    EXPECT_EQ(home_pose(r), home) << name;  // deterministic
  }
}

}  // namespace
}  // namespace stiff
