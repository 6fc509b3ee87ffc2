// Compensation: identify on simulated data -> compensate a contour -> evaluate the loaded tool
// on the true model (the virtual robot).
#include "stiff/compensate/compensate.hpp"

#include <gtest/gtest.h>

#include <cstdio>

#include "stiff/error.hpp"
#include "stiff/identify/identify.hpp"
#include "stiff/io/path_io.hpp"
#include "stiff/sim/simulate.hpp"
#include "test_support.hpp"

namespace stiff {
namespace {

/// A rectangular contour (200 x 150 mm) 150 mm below the shoulder in front of the rokae arm,
/// tool pointing down, about 1 mm between points.
std::vector<Eigen::Matrix4d> contour() {
  std::vector<Eigen::Matrix4d> poses;
  const double x0 = 0.35, x1 = 0.55, y0 = -0.075, y1 = 0.075, z = -0.15;
  const Eigen::Vector3d corners[5] = {
      {x0, y0, z}, {x1, y0, z}, {x1, y1, z}, {x0, y1, z}, {x0, y0, z}};
  PathOptions o;
  for (int e = 0; e < 4; ++e) {
    const int n = static_cast<int>((corners[e + 1] - corners[e]).norm() / 1e-3);
    for (int k = 0; k < n; ++k) {
      Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
      t.block<3, 3>(0, 0) = o.tool_orientation;
      t.block<3, 1>(0, 3) = corners[e] + (corners[e + 1] - corners[e]) * (double(k) / n);
      poses.push_back(t);
    }
  }
  return poses;
}

Eigen::MatrixXd milling_wrench() {
  Eigen::MatrixXd w(1, 6);
  w << -60.0, 40.0, -120.0, 0.0, 0.0, 0.0;  // cutting and feed forces [N], base frame
  return w;
}

Dataset design(uint64_t seed) {
  RandomDesignOptions o;
  o.count = 60;
  o.seed = seed;
  return random_design(test::rokae(), o);
}

struct Outcome {
  double max_before = 0, max_after = 0, worst_ratio = 0;
  Eigen::VectorXd after;  // per point compensated position deviation [m]
  Eigen::MatrixXd q_cmd;
};

/// Compensate the contour with (model, theta) and evaluate on the truth.
Outcome evaluate(const RobotModel& robot,
                 const DeflectionModel& model,
                 const Eigen::VectorXd& theta,
                 const Truth& truth) {
  const auto poses = contour();
  const Eigen::MatrixXd w = milling_wrench();
  const PathCompensation pc = compensate_path(model, theta, poses, w, Eigen::VectorXd());
  const DeflectionModel true_model(robot, truth.effects);
  const Eigen::MatrixXd before = loaded_deviation(true_model, truth.theta, poses, pc.nominal.q, w);
  const Eigen::MatrixXd after = loaded_deviation(true_model, truth.theta, poses, pc.q_cmd, w);
  Outcome o;
  o.after.resize(after.rows());
  o.q_cmd = pc.q_cmd;
  for (Eigen::Index i = 0; i < before.rows(); ++i) {
    EXPECT_EQ(pc.status[static_cast<size_t>(i)] & (kPointUnreachable | kPointNotConverged), 0)
        << "point " << i;
    const double b = before.row(i).head<3>().norm(), a = after.row(i).head<3>().norm();
    o.max_before = std::max(o.max_before, b);
    o.max_after = std::max(o.max_after, a);
    o.worst_ratio = std::max(o.worst_ratio, a / b);
    o.after(i) = a;
  }
  return o;
}

TEST(Compensation, ExactJointModelReachesTheNominalPath) {
  const RobotModel robot = test::rokae();
  const Truth truth = joint_truth(test::paper_stiffness());
  NoiseModel noise;
  noise.tracker_sigma_m = 0;
  const Dataset data = simulate(robot, truth, design(1), noise);
  const FitResult fit = identify_joint_linear(robot, data);
  const DeflectionModel model(robot, fit.model);
  const Outcome o = evaluate(robot, model, fit.theta(), truth);
  std::printf(
      "joint truth, exact joint fit: max deviation %.1f um before, %.3g um after, "
      "worst ratio %.3g\n",
      o.max_before * 1e6, o.max_after * 1e6, o.worst_ratio);
  EXPECT_GT(o.max_before, 50e-6);
  EXPECT_LT(o.worst_ratio, 0.01);
}

TEST(Compensation, TheMissingEffectMattersAndItsModelCompensatesIt) {
  const RobotModel robot = test::rokae();
  const Truth truth = read_truth(test::source_path("examples/truths/rokae_backlash.yaml"), robot);
  NoiseModel noise;
  noise.tracker_sigma_m = 0;
  const Dataset data = simulate(robot, truth, design(2), noise);
  const FitResult joint_only = identify_joint_linear(robot, data);
  const FitResult full = identify(robot, data, truth.effects);
  const Outcome a =
      evaluate(robot, DeflectionModel(robot, joint_only.model), joint_only.theta(), truth);
  const Outcome b = evaluate(robot, DeflectionModel(robot, full.model), full.theta(), truth);
  std::printf(
      "backlash truth: before %.1f um; joint-only fit: after %.2f um (ratio %.3g); "
      "joint+backlash fit: after %.3g um (ratio %.3g)\n",
      a.max_before * 1e6, a.max_after * 1e6, a.worst_ratio, b.max_after * 1e6, b.worst_ratio);
  EXPECT_LT(b.worst_ratio, 0.01);
  EXPECT_GT(a.max_after, 5 * b.max_after);
}

TEST(Compensation, WithNoiseTheResidualIsWithinTheIdentificationUncertainty) {
  const RobotModel robot = test::rokae();
  const Truth truth = joint_truth(test::paper_stiffness());
  NoiseModel noise;
  noise.tracker_sigma_m = 10e-6;
  noise.seed = 11;
  const Dataset data = simulate(robot, truth, design(3), noise);
  const FitResult fit = identify_joint_linear(robot, data);
  const DeflectionModel model(robot, fit.model);
  const Outcome o = evaluate(robot, model, fit.theta(), truth);
  // Predicted standard deviation of the model's deflection at the commanded joints:
  // d = A(q) c, cov(d) = A cov(c) A^T (unidentified c6 moves no point on axis 6).
  Eigen::MatrixXd cov = fit.covariance;
  for (Eigen::Index i = 0; i < cov.size(); ++i)
    if (!std::isfinite(cov.data()[i])) cov.data()[i] = 0;
  const auto poses = contour();
  const Eigen::MatrixXd w = milling_wrench();
  int outside = 0;
  double worst_z = 0;
  for (Eigen::Index i = 0; i < o.q_cmd.rows(); ++i) {
    const Eigen::VectorXd q = o.q_cmd.row(i).transpose();
    const ChainState s = robot.chain(q);
    const auto jac = robot.jacobian_at(s, robot.point_position(s, robot.measured_point));
    const auto jl = robot.jacobian_at(s, robot.point_position(s, robot.load_point));
    const Eigen::Matrix<double, 3, Eigen::Dynamic> a =
        observation_block(jac, jl, w.row(0).transpose());
    const double sd = std::sqrt((a * cov * a.transpose()).trace());
    worst_z = std::max(worst_z, o.after(i) / sd);
    if (o.after(i) > 3 * sd) ++outside;
  }
  std::printf(
      "noise 10 um: max deviation %.1f um before, %.2f um after; worst residual / "
      "predicted sd %.2f; %d of %ld points beyond 3 sd\n",
      o.max_before * 1e6, o.max_after * 1e6, worst_z, outside, long(o.q_cmd.rows()));
  EXPECT_EQ(outside, 0);
  EXPECT_LT(o.max_after, 0.2 * o.max_before);
}

TEST(Compensation, PoseSolvesTheSixDimensionalEquationOnTheModel) {
  const RobotModel robot = test::rokae();
  const Truth truth = joint_truth(test::paper_stiffness());
  const DeflectionModel model(robot, truth.effects);
  Eigen::VectorXd q(6);
  q << 0.1, 0.4, -0.5, 0.3, 0.9, -0.4;
  const Eigen::Matrix4d target = robot.tool_pose(q);
  Vector6d w;
  w << 80, -50, -150, 3, -2, 1;
  const PoseCompensation c = compensate_pose(model, truth.theta, target, q, w);
  ASSERT_TRUE(c.converged);
  EXPECT_LE(c.iterations, 6);
  const Vector6d d = predict_deflection(model, truth.theta, c.q_cmd, w);
  const Vector6d e = pose_error(target, loaded_pose(robot.tool_pose(c.q_cmd), d));
  // One solver for the core, the C ABI and the FMU: Broyden updates take it to the default
  // tolerance of 1e-12 (m and rad), where a fixed Jacobian stopped at 1e-10.
  EXPECT_LE(c.residual, 1e-12);
  EXPECT_LT(e.head<3>().norm(), 1e-12);
  EXPECT_LT(e.tail<3>().norm(), 1e-12);
  // The uncompensated deflection is far larger.
  EXPECT_GT(predict_deflection(model, truth.theta, q, w).head<3>().norm(), 1e-4);
  // Position only leaves the orientation error but still reaches the position.
  CompensationOptions po;
  po.orientation = false;
  const PoseCompensation cp = compensate_pose(model, truth.theta, target, q, w, po);
  const Vector6d ep = pose_error(
      target,
      loaded_pose(robot.tool_pose(cp.q_cmd), predict_deflection(model, truth.theta, cp.q_cmd, w)));
  EXPECT_LT(ep.head<3>().norm(), 1e-10);
}

// The solver on a non-smooth model: backlash switches sign with the joint torque, so the loaded
// pose is not differentiable where a torque crosses zero; step halving keeps the residual
// falling and the point converges where the torques keep their sign.
TEST(Compensation, SolverConvergesWithBacklash) {
  const RobotModel robot = test::rokae();
  const DeflectionModel model(robot, {"joint", "backlash"});
  Eigen::VectorXd theta = model.null_parameters();
  theta.head(6) = test::paper_stiffness().cwiseInverse();
  for (int j = 0; j < 5; ++j) theta(6 + j) = 0.5 * M_PI / (180.0 * 60.0);  // 0.5 arcmin
  Eigen::VectorXd q(6);
  q << -0.2, 0.6, -0.4, 0.2, 0.8, 0.3;
  Vector6d w;
  w << 60, -40, -120, 0, 0, 0;
  const Eigen::Matrix4d target = robot.tool_pose(q);
  const PoseCompensation c = compensate_pose(model, theta, target, q, w);
  ASSERT_TRUE(c.converged) << c.residual;
  const Vector6d e = pose_error(
      target, loaded_pose(robot.tool_pose(c.q_cmd), predict_deflection(model, theta, c.q_cmd, w)));
  EXPECT_LT(std::max(e.head<3>().norm(), e.tail<3>().norm()), 1e-12);
}

TEST(Compensation, BadInputIsRejected) {
  const RobotModel robot = test::rokae();
  const Truth truth = joint_truth(test::paper_stiffness());
  const DeflectionModel model(robot, truth.effects);
  const auto poses = contour();
  EXPECT_THROW(
      compensate_path(model, truth.theta, poses, Eigen::MatrixXd::Zero(3, 6), Eigen::VectorXd()),
      InvalidArgument);
  EXPECT_THROW(
      compensate_path(model, truth.theta, poses, Eigen::MatrixXd::Zero(1, 3), Eigen::VectorXd()),
      InvalidArgument);
  Eigen::MatrixXd nan = Eigen::MatrixXd::Zero(1, 6);
  nan(0, 2) = NAN;
  EXPECT_THROW(compensate_path(model, truth.theta, poses, nan, Eigen::VectorXd()), InvalidArgument);
}

}  // namespace
}  // namespace stiff
