#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "kinematics/fast_chain.hpp"
#include "stiff/error.hpp"
#include "stiff/identify/identify.hpp"
#include "stiff/sim/simulate.hpp"
#include "test_support.hpp"

namespace stiff {
namespace {

TEST(IdentifyLinear, NoiseFreeSimulationIsRecoveredTo1e9) {
  const RobotModel robot = test::rokae();
  const Eigen::VectorXd k = test::paper_stiffness();
  NoiseModel noise;
  noise.tracker_sigma_m = 0.0;
  for (const Dataset& design : {test::paper_design_a(), test::paper_design_j()}) {
    const Dataset data = simulate(robot, joint_truth(k), design, noise);
    const FitResult f = identify_joint_linear(robot, data);
    for (int j = 0; j < 5; ++j)
      EXPECT_NEAR(f.parameters[j].value * k(j), 1.0, 1e-9) << "joint " << j + 1;
  }
}

TEST(IdentifyLinear, PaperSetupReportsJoint6Unidentifiable) {
  const RobotModel robot = test::rokae();
  NoiseModel noise;
  const Dataset data =
      simulate(robot, joint_truth(test::paper_stiffness()), test::paper_design_a(), noise);
  const FitResult f = identify_joint_linear(robot, data);
  const auto ident = f.joint_identified();
  for (int j = 0; j < 5; ++j) EXPECT_TRUE(ident[j]);
  EXPECT_FALSE(ident[5]);
  EXPECT_EQ(f.rank, 5);
  bool named = false;
  for (const auto& w : f.warnings)
    named |= w.find("joint 6 is not identifiable") != std::string::npos;
  EXPECT_TRUE(named);
}

TEST(IdentifyLinear, StandardErrorsAreCalibratedOver200Seeds) {
  // With noise, each identified compliance lies within 3 reported standard errors in at least
  // 95 % of seeded runs (t with 25 degrees of freedom: 99.4 % expected).
  const RobotModel robot = test::rokae();
  const Eigen::VectorXd k = test::paper_stiffness();
  const Dataset design = test::paper_design_a();
  int inside = 0, total = 0;
  for (uint64_t seed = 1; seed <= 200; ++seed) {
    NoiseModel noise;
    noise.tracker_sigma_m = 10e-6;
    noise.seed = seed;
    const FitResult f =
        identify_joint_linear(robot, simulate(robot, joint_truth(k), design, noise));
    for (int j = 0; j < 5; ++j) {
      ++total;
      inside += std::abs(f.parameters[j].value - 1.0 / k(j)) <= 3 * f.parameters[j].standard_error;
    }
  }
  EXPECT_GE(inside, 0.95 * total) << inside << " of " << total;
}

TEST(IdentifyLinear, ANegativeComplianceIsHeldAtItsBoundAsTheBoundedFitDoes) {
  // Joint 4 nearly rigid: its least-squares compliance falls below 0 in about half the seeds.
  // The fit then holds it at 0 and fits the rest again, which is the solution the bounded
  // nonlinear identification (Ceres, lower bound 0) finds; and a model can be built from it.
  const RobotModel robot = test::rokae();
  Eigen::VectorXd k = test::paper_stiffness();
  k(3) = 1e9;
  const DeflectionModel model(robot, {"joint"});
  int held = 0;
  for (uint64_t seed = 1; seed <= 12; ++seed) {
    NoiseModel noise;
    noise.tracker_sigma_m = 20e-6;
    noise.seed = seed;
    const Dataset data = simulate(robot, joint_truth(k), test::paper_design_a(), noise);
    const FitResult lin = identify_joint_linear(robot, data);
    for (int j = 0; j < 6; ++j) EXPECT_GE(lin.parameters[j].value, 0.0) << "seed " << seed;
    EXPECT_NO_THROW(fit_for_model(lin, robot, model, "")) << "seed " << seed;
    // Joint 6 (no lever arm on the flange axis) is held for want of data, never at the bound.
    EXPECT_EQ(lin.parameters[5].held, "undetermined") << "seed " << seed;
    if (lin.parameters[3].identified) {
      EXPECT_EQ(lin.parameters[3].held, "") << "seed " << seed;
      continue;
    }
    ++held;
    EXPECT_EQ(lin.parameters[3].value, 0.0);
    EXPECT_EQ(lin.parameters[3].held, "bound") << "seed " << seed;
    // A fit file says so, and reads back the same.
    EXPECT_EQ(fit_from_json(fit_to_json(lin), "fit.json").parameters[3].held, "bound");
    EXPECT_TRUE(std::any_of(lin.warnings.begin(), lin.warnings.end(), [](const std::string& w) {
      return w.find("joint 4") != std::string::npos && w.find("below 0") != std::string::npos;
    }));
    const FitResult bounded = identify(robot, data, {"joint"});
    EXPECT_LT(bounded.parameters[3].value, 1e-3 * lin.parameters[4].standard_error);
    for (int j : {0, 1, 2, 4})
      EXPECT_NEAR(bounded.parameters[j].value, lin.parameters[j].value,
                  1e-3 * lin.parameters[j].standard_error)
          << "seed " << seed << " joint " << j + 1;
  }
  EXPECT_GE(held, 3);
}

TEST(IdentifyLinear, ResidualMatchesTheNoiseLevel) {
  const RobotModel robot = test::rokae();
  RandomDesignOptions o;
  o.count = 200;
  NoiseModel noise;
  noise.tracker_sigma_m = 10e-6;
  const FitResult f = identify_joint_linear(
      robot, simulate(robot, joint_truth(test::paper_stiffness()), random_design(robot, o), noise));
  // sigma_hat estimates sigma with relative sd 1/sqrt(2 * 595) ~ 3 %.
  EXPECT_NEAR(f.sigma_hat_m / 10e-6, 1.0, 0.12);
  EXPECT_DOUBLE_EQ(f.noise_floor_m, 10e-6);
}

TEST(IdentifyLinear, TooFewMeasurementsIsAClearError) {
  const RobotModel robot = test::rokae();
  Dataset d =
      simulate(robot, joint_truth(test::paper_stiffness()), test::paper_design_a(), NoiseModel{});
  d.rows.resize(1);
  EXPECT_THROW(identify_joint_linear(robot, d), InvalidArgument);
  Dataset plan = test::paper_design_a();
  EXPECT_THROW(identify_joint_linear(robot, plan), InvalidArgument);  // no displacements
}

TEST(FitJson, RoundTripKeepsEveryParameter) {
  const RobotModel robot = test::rokae();
  const FitResult f = identify_joint_linear(
      robot,
      simulate(robot, joint_truth(test::paper_stiffness()), test::paper_design_a(), NoiseModel{}));
  const FitResult g = fit_from_json(fit_to_json(f), "fit.json");
  ASSERT_EQ(g.parameters.size(), f.parameters.size());
  for (size_t k = 0; k < f.parameters.size(); ++k) {
    EXPECT_EQ(g.parameters[k].value, f.parameters[k].value);
    EXPECT_EQ(g.parameters[k].identified, f.parameters[k].identified);
  }
  // Why a parameter is held: kept through the file; an unknown reason is refused, naming it.
  EXPECT_EQ(g.parameters[5].held, "undetermined");
  std::string text = fit_to_json(f);
  const std::string said = "\"held\": \"undetermined\"";
  ASSERT_NE(text.find(said), std::string::npos);
  text.replace(text.find(said), said.size(), "\"held\": \"unknown\"");
  try {
    fit_from_json(text, "fit.json");
    ADD_FAILURE() << "an unknown held reason was read";
  } catch (const ParseError& e) {
    EXPECT_NE(std::string(e.what()).find("joint.c6"), std::string::npos) << e.what();
  }
  EXPECT_THROW(fit_from_json("{\"format\": \"other\"}", "x.json"), ParseError);
  EXPECT_THROW(fit_from_json("{not json", "x.json"), ParseError);
}

// The identification's kinematics (libstiff/src/kinematics/fast_chain.hpp): the polynomial sincos
// within 2 ulp-ish of libm, and the specialised chain equal to RobotModel::chain to round-off for
// modified-DH (ROKAE, PUMA 560) and URDF (UR5) joints.
TEST(IdentifyLinear, FastKinematicsEqualTheReference) {
  double worst = 0;
  for (int i = -200000; i <= 200000; ++i) {
    const double x = i * 1.7e-4 + (i % 7) * 1e-9;
    double s, c;
    detail::sincos_fast(x, &s, &c);
    worst = std::max({worst, std::abs(s - std::sin(x)), std::abs(c - std::cos(x))});
  }
  EXPECT_LT(worst, 4.5e-16);
  for (const char* file :
       {"examples/robots/rokae.yaml", "examples/robots/puma560.yaml", "examples/robots/ur5.urdf"}) {
    const RobotModel robot = load_robot(test::source_path(file));
    const detail::FastChain fk(robot);
    const int n = robot.dof();
    Eigen::Matrix3Xd z(3, n), o(3, n);
    Eigen::Matrix3d r;
    Eigen::Vector3d p;
    std::vector<Eigen::Matrix4d> links(n);
    for (int trial = 0; trial < 20; ++trial) {
      Eigen::VectorXd q(n);
      for (int j = 0; j < n; ++j) q(j) = std::sin(1.3 * trial + 0.7 * j) * 2.5;
      const ChainState ref = robot.chain(q);
      fk(q, z, o, r, p, links.data());
      EXPECT_LT((z - ref.axis).cwiseAbs().maxCoeff(), 1e-14) << file;
      EXPECT_LT((o - ref.origin).cwiseAbs().maxCoeff(), 1e-14) << file;
      EXPECT_LT((r - ref.flange.topLeftCorner<3, 3>()).cwiseAbs().maxCoeff(), 1e-14) << file;
      EXPECT_LT((p - ref.flange.topRightCorner<3, 1>()).cwiseAbs().maxCoeff(), 1e-14) << file;
      for (int j = 0; j < n; ++j)
        EXPECT_LT((links[j] - ref.link[j]).cwiseAbs().maxCoeff(), 1e-14) << file << " link " << j;
    }
  }
}

}  // namespace
}  // namespace stiff
