#include <gtest/gtest.h>

#include <cmath>

#include "stiff/error.hpp"
#include "stiff/identify.hpp"
#include "stiff/simulate.hpp"
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
  EXPECT_THROW(fit_from_json("{\"format\": \"other\"}", "x.json"), ParseError);
  EXPECT_THROW(fit_from_json("{not json", "x.json"), ParseError);
}

}  // namespace
}  // namespace stiff
