// Inverse kinematics: analytic branches of the spherical-wrist arms, numerical IK of the UR5,
// branch continuity along a path.
#include "stiff/compensate/ik.hpp"

#include <gtest/gtest.h>

#include <random>

#include "stiff/io/robot_io.hpp"
#include "test_support.hpp"

namespace stiff {
namespace {

RobotModel robot(const std::string& name) {
  return load_robot(test::source_path("examples/robots/" + name));
}

Eigen::VectorXd random_q(const RobotModel& r, std::mt19937_64& rng, double fraction = 0.9) {
  Eigen::VectorXd q(r.dof());
  for (int j = 0; j < r.dof(); ++j) {
    const double lo = std::max(r.joints[j].lower, -3.0), hi = std::min(r.joints[j].upper, 3.0);
    const double mid = 0.5 * (lo + hi), half = 0.5 * (hi - lo) * fraction;
    q(j) = std::uniform_real_distribution<>(mid - half, mid + half)(rng);
  }
  return q;
}

double fk_error(const RobotModel& r, const Eigen::Matrix4d& target, const Eigen::VectorXd& q) {
  const auto e = pose_error(target, r.tool_pose(q));
  return e.head<3>().norm() + e.tail<3>().norm();
}

class AnalyticIk : public ::testing::TestWithParam<const char*> {};

TEST_P(AnalyticIk, EveryBranchReproducesThePose) {
  const RobotModel r = robot(GetParam());
  const InverseKinematics ik(r);
  ASSERT_TRUE(ik.analytic()) << ik.structure().reason;
  std::mt19937_64 rng(7);
  int total = 0, found_original = 0;
  double worst = 0;
  IkOptions no_limits;
  no_limits.respect_limits = false;
  const InverseKinematics ik_all(r, no_limits);
  int eight = 0;
  for (int k = 0; k < 500; ++k) {
    const Eigen::VectorXd q = random_q(r, rng);
    const Eigen::Matrix4d pose = r.tool_pose(q);
    const auto sols = ik.solve_all(pose, &q);
    ASSERT_FALSE(sols.empty()) << "pose " << k;
    bool has_q = false;
    for (const auto& s : sols) {
      const double e = fk_error(r, pose, s.q);
      worst = std::max(worst, e);
      EXPECT_LT(e, 1e-10) << "pose " << k << " branch " << s.branch;
      for (int j = 0; j < r.dof(); ++j) {
        EXPECT_GE(s.q(j), r.joints[j].lower);
        EXPECT_LE(s.q(j), r.joints[j].upper);
      }
      if ((s.q - q).cwiseAbs().maxCoeff() < 1e-7) has_q = true;
      ++total;
    }
    if (has_q) ++found_original;
    if (ik_all.solve_all(pose).size() == 8) ++eight;
  }
  // The generating q is one of the branches (except at a tangency or an exact singularity).
  EXPECT_GE(found_original, 495);
  // Without limits a generic pose has 8 solutions; near the edge of the workspace the
  // backward shoulder (rokae: a1 = 30 mm offset) is out of reach and only 4 remain.
  EXPECT_GE(eight, 300);
  std::printf("%s: %d solutions of 500 poses, %d poses with 8 branches, max FK error %.3g\n",
              GetParam(), total, eight, worst);
}

INSTANTIATE_TEST_SUITE_P(BuiltIn,
                         AnalyticIk,
                         ::testing::Values("rokae.yaml", "puma560.yaml", "abb_irb120.yaml"));

TEST(NumericalIk, Ur5HasNoSphericalWristAndConvergesFromNearbySeeds) {
  const RobotModel r = robot("ur5.urdf");
  const InverseKinematics ik(r);
  EXPECT_FALSE(ik.analytic());
  EXPECT_FALSE(ik.structure().spherical);
  std::mt19937_64 rng(3);
  double worst = 0;
  for (int k = 0; k < 100; ++k) {
    const Eigen::VectorXd q = random_q(r, rng, 0.5);
    const Eigen::Matrix4d pose = r.tool_pose(q);
    Eigen::VectorXd seed = q;
    for (int j = 0; j < r.dof(); ++j) seed(j) += 0.1 * std::sin(3.0 * j + k);
    IkSolution s;
    ASSERT_TRUE(ik.solve_nearest(pose, seed, &s)) << k;
    worst = std::max(worst, fk_error(r, pose, s.q));
  }
  EXPECT_LT(worst, 1e-10);
  // Several distinct solutions from random starts.
  const Eigen::VectorXd q = random_q(r, rng, 0.5);
  const auto all = ik.solve_all(r.tool_pose(q));
  EXPECT_GE(all.size(), 2u);
  for (const auto& s : all) EXPECT_LT(fk_error(r, r.tool_pose(q), s.q), 1e-10);
}

TEST(IkPath, KeepsTheBranchAndReportsUnreachablePoints) {
  const RobotModel r = robot("rokae.yaml");
  const InverseKinematics ik(r);
  Eigen::VectorXd q0(6);
  q0 << 0.1, 0.3, -0.4, 0.2, 0.8, 0.3;
  std::vector<Eigen::Matrix4d> poses;
  for (int i = 0; i < 50; ++i) {
    Eigen::Matrix4d t = r.tool_pose(q0);
    t(0, 3) += 0.002 * i;
    t(1, 3) += 0.001 * i;
    poses.push_back(t);
  }
  Eigen::Matrix4d far = poses.back();
  far(0, 3) = 5.0;  // out of reach
  poses.insert(poses.begin() + 25, far);
  const IkPath p = solve_path(ik, poses, q0);
  EXPECT_TRUE(p.status[25] & kPointUnreachable);
  EXPECT_TRUE(p.q.allFinite());
  for (size_t i = 0; i < poses.size(); ++i) {
    if (i == 25) continue;
    EXPECT_EQ(p.status[i] & (kPointBranchChange | kPointJump), 0) << i;
    EXPECT_LT(fk_error(r, poses[i], p.q.row(static_cast<Eigen::Index>(i)).transpose()), 1e-10);
  }
  EXPECT_EQ(p.branch[0], p.branch[49 + 1]);
}

TEST(IkPath, AWristFlipThroughTheSingularityIsReported) {
  // q5 crosses 0 (wrist singularity: axes 4 and 6 aligned): the nearest solution either
  // flips the wrist (q4, q6 jump by pi) or stays; a flip is reported, never silent.
  const RobotModel r = robot("rokae.yaml");
  const InverseKinematics ik(r);
  Eigen::VectorXd q(6);
  q << 0.2, 0.4, -0.3, 0.6, 0.3, -0.2;
  std::vector<Eigen::Matrix4d> poses;
  for (int i = 0; i <= 60; ++i) {
    Eigen::VectorXd qi = q;
    qi(4) = 0.3 - 0.01 * i;  // q5 from 0.3 to -0.3 rad
    poses.push_back(r.tool_pose(qi));
  }
  const IkPath p = solve_path(ik, poses, q);
  int flagged = 0;
  for (size_t i = 1; i < poses.size(); ++i) {
    const double step =
        (p.q.row(static_cast<Eigen::Index>(i)) - p.q.row(static_cast<Eigen::Index>(i - 1)))
            .cwiseAbs()
            .maxCoeff();
    const bool reported = p.status[i] & (kPointBranchChange | kPointJump | kPointSingular);
    if (step > 0.35) {
      EXPECT_TRUE(reported) << "silent jump at " << i;
    }
    if (reported) ++flagged;
    EXPECT_LT(fk_error(r, poses[i], p.q.row(static_cast<Eigen::Index>(i)).transpose()), 1e-10);
  }
  EXPECT_GE(flagged, 1);  // the pass through q5 = 0 is singular at least
}

}  // namespace
}  // namespace stiff
