// Numerical robustness (docs/reliability.md): near-singular poses, rank-deficient data,
// huge and tiny loads, degenerate plans, effects the data cannot identify. Each gives a warning
// or an error that says what to do; never a NaN in a result that claims success, never a
// silently wrong result.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include "stiff/error.hpp"
#include "stiff/identify/fit.hpp"
#include "stiff/identify/identify.hpp"
#include "stiff/io/robot_io.hpp"
#include "stiff/plan/plan.hpp"
#include "stiff/sim/simulate.hpp"
#include "stiff/stiff.h"
#include "test_support.hpp"

namespace stiff {
namespace {

using test::paper_design_a;
using test::paper_stiffness;
using test::rokae;

Dataset simulated(const Dataset& design, double sigma = 10e-6, uint64_t seed = 7) {
  NoiseModel noise;
  noise.tracker_sigma_m = sigma;
  noise.seed = seed;
  return simulate(rokae(), joint_truth(paper_stiffness()), design, noise);
}

Dataset random_poses(int count, uint64_t seed = 3) {
  RandomDesignOptions o;
  o.count = count;
  o.seed = seed;
  return random_design(rokae(), o);
}

std::string joined(const std::vector<std::string>& w) {
  std::string s;
  for (const auto& x : w) s += x + "\n";
  return s;
}

/// A fit that claims success: finite parameters and statistics; NaN only in the standard
/// errors of parameters it marks unidentified (and then with a warning).
void expect_sound(const FitResult& fit) {
  bool any_unidentified = false;
  for (const auto& p : fit.parameters) {
    EXPECT_TRUE(std::isfinite(p.value)) << p.effect << "." << p.name;
    if (p.identified)
      EXPECT_TRUE(std::isfinite(p.standard_error)) << p.effect << "." << p.name;
    else
      any_unidentified = true;
  }
  EXPECT_TRUE(fit.residuals.allFinite());
  EXPECT_TRUE(std::isfinite(fit.rms_m));
  EXPECT_TRUE(std::isfinite(fit.sigma_hat_m));
  EXPECT_TRUE(std::isfinite(fit.condition_number) || fit.rank == 0);
  if (any_unidentified) {
    EXPECT_FALSE(fit.warnings.empty());
  }
}

// ---------------------------------------------------------------- near-singular poses
TEST(Robustness, WristSingularPosesAreFlaggedNotNaN) {
  Dataset design = random_poses(20);
  for (auto& m : design.rows) m.q(4) = 1e-9;  // q5 = 0: axes 4 and 6 aligned
  const Dataset data = simulated(design);
  const FitResult fit = identify_joint_linear(rokae(), data);
  expect_sound(fit);
  EXPECT_LT(fit.rank, 6);
  EXPECT_FALSE(fit.warnings.empty()) << "a rank-deficient fit must say which joints it lost";
  // Each lost joint is named with the reason (zero column: no torque or no motion; dependent
  // column: "add poses or loads that move it").
  for (int j = 0; j < 6; ++j)
    if (!fit.joint_identified()[j]) {
      EXPECT_NE(
          joined(fit.warnings).find("joint " + std::to_string(j + 1) + " is not identifiable"),
          std::string::npos)
          << joined(fit.warnings);
    }
}

TEST(Robustness, JacobianAndPredictionAtExactSingularityAreFinite) {
  const RobotModel r = rokae();
  Eigen::VectorXd q = Eigen::VectorXd::Zero(6);  // stretched-out, wrist singular
  EXPECT_TRUE(r.jacobian(q).allFinite());
  EXPECT_TRUE(r.tool_pose(q).allFinite());
}

// ---------------------------------------------------------------- rank-deficient data
TEST(Robustness, IdenticalRowsDoNotIdentifyAllJoints) {
  Dataset design = paper_design_a();
  for (auto& m : design.rows) {
    m.q = design.rows[0].q;
    m.force = design.rows[0].force;
  }
  const Dataset data = simulated(design);
  try {
    const FitResult fit = identify_joint_linear(rokae(), data);
    expect_sound(fit);
    EXPECT_LE(fit.rank, 3) << "one pose and one load give 3 independent equations";
    EXPECT_FALSE(fit.warnings.empty());
  } catch (const NumericalError& e) {
    EXPECT_NE(std::string(e.what()).find("identif"), std::string::npos) << e.what();
  }
}

TEST(Robustness, ZeroLoadsAreANumericalErrorThatNamesTheCause) {
  Dataset data = simulated(paper_design_a());
  for (auto& m : data.rows) m.force.setZero();
  try {
    identify_joint_linear(rokae(), data);
    FAIL() << "zero loads identified something";
  } catch (const NumericalError& e) {
    EXPECT_NE(std::string(e.what()).find("load"), std::string::npos) << e.what();
  }
  EXPECT_THROW(identify(rokae(), data, {"joint", "link"}), NumericalError);
}

TEST(Robustness, UnidentifiedJointHasNaNStiffnessAndAWarning) {
  // The paper's setup: the measured point lies on axis 6, so c6 is not identifiable.
  const FitResult fit = identify_joint_linear(rokae(), simulated(paper_design_a()));
  expect_sound(fit);
  const std::vector<bool> ok = fit.joint_identified();
  EXPECT_FALSE(ok[5]);
  // The core reports k = 1/c = inf for the held c6 = 0; the C ABI reports NaN (stiff.h).
  EXPECT_FALSE(std::isfinite(fit.joint_stiffness()(5)));
  EXPECT_TRUE(std::isnan(fit.parameters[5].standard_error));
  EXPECT_NE(joined(fit.warnings).find("joint 6"), std::string::npos);
}

// ---------------------------------------------------------------- huge and tiny loads
TEST(Robustness, HugeLoadsGiveTheSameStiffness) {
  Dataset design = paper_design_a();
  for (auto& m : design.rows) m.force *= 1e5;  // MN: deflections of metres, still linear
  const FitResult fit = identify_joint_linear(rokae(), simulated(design, 10e-6 * 1e5));
  expect_sound(fit);
  const Eigen::VectorXd k = fit.joint_stiffness();
  for (int j = 0; j < 5; ++j)
    EXPECT_NEAR(k(j) / paper_stiffness()(j), 1.0, 0.5) << "joint " << j + 1;
}

TEST(Robustness, TinyLoadsBelowTheNoiseAreNotReportedAsIdentified) {
  Dataset design = paper_design_a();
  for (auto& m : design.rows) m.force *= 1e-6;  // micro-newtons: deflection << 10 um noise
  FitResult fit;
  try {
    fit = identify_joint_linear(rokae(), simulated(design));
  } catch (const NumericalError& e) {
    // Nothing determined is an error that says so.
    EXPECT_NE(std::string(e.what()).find("no joint compliance is determined"), std::string::npos)
        << e.what();
    return;
  }
  expect_sound(fit);
  // Either the joints are marked unidentified, or the fit warns that its values are not
  // significant; silently reporting a precise-looking stiffness would be wrong.
  bool significant = false;
  const Eigen::VectorXd k = fit.joint_stiffness(), se = fit.joint_stiffness_se();
  for (int j = 0; j < 5; ++j)
    if (fit.joint_identified()[j] && std::isfinite(k(j)) && k(j) > 0 && se(j) < 0.5 * k(j))
      significant = true;
  EXPECT_TRUE(!significant || !fit.warnings.empty()) << joined(fit.warnings);
  EXPECT_FALSE(fit.warnings.empty()) << "no warning for loads whose deflection is below noise";
}

TEST(Robustness, DenormalAndZeroValuesAreAcceptedAndFinite) {
  Dataset data = simulated(paper_design_a());
  data.rows[0].moment = Eigen::Vector3d(4.9e-324, -4.9e-324, 0.0);
  data.rows[1].q(5) = 2.2e-310;
  data.has_moment = true;
  const FitResult fit = identify_joint_linear(rokae(), data);
  expect_sound(fit);
}

TEST(Robustness, NonFiniteDataIsRejectedNamingTheRow) {
  Dataset data = simulated(paper_design_a());
  data.rows[3].displacement(1) = std::numeric_limits<double>::quiet_NaN();
  try {
    identify_joint_linear(rokae(), data);
    FAIL();
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find(data.rows[3].id), std::string::npos) << e.what();
  }
  data.rows[3].displacement(1) = 0;
  data.rows[2].force(0) = std::numeric_limits<double>::infinity();
  EXPECT_THROW(identify(rokae(), data, {"joint"}), InvalidArgument);
}

TEST(Robustness, PredictionOverflowIsAnErrorNotInf) {
  stiff_robot* robot = nullptr;
  ASSERT_EQ(stiff_robot_load(&robot, test::source_path("examples/robots/rokae.yaml").c_str()),
            STIFF_OK);
  stiff_dataset* design = nullptr;
  ASSERT_EQ(stiff_dataset_read_csv(&design, robot,
                                   test::source_path("examples/paper/design_kappa_a.csv").c_str()),
            STIFF_OK);
  const Eigen::VectorXd k = paper_stiffness();
  stiff_dataset* data = nullptr;
  ASSERT_EQ(stiff_simulate(&data, robot, design, nullptr, k.data(), 6, nullptr), STIFF_OK);
  stiff_result* fit = nullptr;
  ASSERT_EQ(stiff_identify(&fit, robot, data, nullptr), STIFF_OK);
  stiff_model* model = nullptr;
  ASSERT_EQ(stiff_model_create(&model, robot, fit), STIFF_OK);
  const double q[6] = {0.1, 1.2, 0.5, -1.0, 1.3, 0.0};
  double d[6];
  const double huge[6] = {1e308, -1e308, 1e308, 0, 0, 0};
  const stiff_status s = stiff_predict(d, model, q, 6, huge);
  if (s == STIFF_OK) {
    for (double v : d) EXPECT_TRUE(std::isfinite(v));
  } else {
    EXPECT_EQ(s, STIFF_E_NUMERICAL) << stiff_last_error();
    EXPECT_NE(std::string(stiff_last_error()).find("not finite"), std::string::npos);
  }
  const double tiny[6] = {4.9e-324, 0, -4.9e-324, 0, 0, 0};
  ASSERT_EQ(stiff_predict(d, model, q, 6, tiny), STIFF_OK);
  for (double v : d) EXPECT_TRUE(std::isfinite(v));
  stiff_model_destroy(model);
  stiff_result_destroy(fit);
  stiff_dataset_destroy(data);
  stiff_dataset_destroy(design);
  stiff_robot_destroy(robot);
}

// ---------------------------------------------------------------- effects the data cannot identify
TEST(Robustness, EffectTheDataCannotSeeIsHeldWithAWarning) {
  // Without measured rotations, a tool-compliance or tracker-frame parameter set may not be
  // separable from the joints with 10 poses: whatever is not identifiable is named.
  const Dataset data = simulated(paper_design_a());
  IdentifyOptions o;
  o.max_iterations = 50;
  const FitResult fit = identify(rokae(), data, {"joint", "tracker_frame"}, o);
  expect_sound(fit);
  int unidentified = 0;
  for (const auto& p : fit.parameters)
    if (!p.identified) {
      ++unidentified;
      EXPECT_NE(joined(fit.warnings).find(p.name), std::string::npos)
          << p.name << " held without being named:\n"
          << joined(fit.warnings);
    }
  EXPECT_GT(unidentified, 0) << "10 measurements cannot identify 5 joints and a 6-DOF frame";
}

// ---------------------------------------------------------------- degenerate plans and designs
TEST(Robustness, DegenerateRandomDesignsAreRejected) {
  RandomDesignOptions o;
  o.count = 0;
  EXPECT_THROW(random_design(rokae(), o), InvalidArgument);
  o.count = 5;
  o.load_min_N = 40;
  o.load_max_N = 10;
  EXPECT_THROW(random_design(rokae(), o), InvalidArgument);
  o.load_min_N = 15;
  o.load_max_N = 35;
  o.range_fraction = 0.0;
  EXPECT_THROW(random_design(rokae(), o), InvalidArgument);
  o.range_fraction = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(random_design(rokae(), o), InvalidArgument);
}

TEST(Robustness, PlanThatCannotBeMetSaysWhy) {
  PoolOptions pool;
  pool.pose_count = 50;
  PlanOptions o;
  o.count = 1;  // 3 equations for 5 identifiable compliances
  try {
    plan_measurements(rokae(), pool, o);
    FAIL() << "a plan with 3N < m was accepted";
  } catch (const InvalidArgument& e) {
    EXPECT_FALSE(std::string(e.what()).empty());
  }
  pool.min_sigma_m = 50.0;  // no pose of a 1 m arm has sigma_min(J) = 50 m
  pool.pose_count = 2;      // (the pool gives up after a bounded number of draws)
  o.count = 10;
  try {
    plan_measurements(rokae(), pool, o);
    FAIL() << "an impossible singularity threshold was accepted";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("singular"), std::string::npos) << e.what();
  }
}

// ---------------------------------------------------------------- readers never print
TEST(Robustness, BadUrdfIsAParseErrorAndPrintsNothing) {
  testing::internal::CaptureStderr();
  testing::internal::CaptureStdout();
  try {
    parse_robot_urdf("<robot name='x'><link name='a'/><joint name='j' type='revolute'>",
                     "broken.urdf");
    ADD_FAILURE() << "accepted a truncated URDF";
  } catch (const ParseError& e) {
    EXPECT_NE(std::string(e.what()).find("broken.urdf"), std::string::npos);
  }
  const std::string err = testing::internal::GetCapturedStderr();
  const std::string out = testing::internal::GetCapturedStdout();
  EXPECT_EQ(err, "") << "the library printed to stderr";
  EXPECT_EQ(out, "");
}

}  // namespace
}  // namespace stiff
