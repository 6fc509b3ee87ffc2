// Bugs found by fuzzing (docs/reliability.md, "Bugs found and fixed"), one test each. The
// inputs that found them are also in tests/fuzz/corpus/<target>/regression-* (FuzzCorpus).
#include <gtest/gtest.h>

#include <string>

#include "stiff/error.hpp"
#include "stiff/identify/fit.hpp"
#include "stiff/io/path_io.hpp"
#include "stiff/io/robot_io.hpp"
#include "stiff/sim/simulate.hpp"
#include "stiff/stiff.h"
#include "test_support.hpp"

namespace stiff {
namespace {

// yaml-cpp's BadConversion escaped parse_robot_yaml (C ABI: STIFF_E_INTERNAL) for a key or
// value of the wrong YAML type, e.g. a flow list where a key was expected.
TEST(FuzzRegressions, RobotYamlWithAListAsKeyIsAParseError) {
  const std::string text =
      "name: x\nconvention: standard_dh\nunits: {length: m, angle: deg}\njoints:\n"
      "  - {alpha: 0, a: 0.4, d: 0, [-266, 266]: 1}\n";
  EXPECT_THROW(parse_robot_yaml(text, "r.yaml"), ParseError);
  EXPECT_THROW(parse_robot_yaml("[a, b]: 1\n", "r.yaml"), ParseError);
}

TEST(FuzzRegressions, TruthAndNoiseYamlWithAMapAsKeyAreParseErrors) {
  try {
    parse_truth_yaml("{}:\n  1\n", "t.yaml", test::rokae());
    FAIL();
  } catch (const ParseError& e) {
    EXPECT_NE(std::string(e.what()).find("t.yaml:"), std::string::npos) << e.what();
  }
  EXPECT_THROW(parse_noise_yaml("{a: 1}: 2\n", "n.yaml"), ParseError);
  EXPECT_THROW(parse_truth_yaml("effects:\n  [backlash]: {b1: 1}\n", "t.yaml", test::rokae()),
               ParseError);
}

// robot_to_yaml wrote names in double quotes without escaping: a name holding a quote, a
// backslash or a control character gave a file its own reader rejects (e.g. the robot.yaml
// of an exported FMU).
TEST(FuzzRegressions, RobotNamesWithQuotesAndControlCharactersRoundTrip) {
  RobotModel r = test::rokae();
  r.name = "arm \"7\" \\ {x: 1} # not a comment\t";
  r.joints[2].name = "j\"3\\";
  const RobotModel again = parse_robot_yaml(robot_to_yaml(r), "roundtrip.yaml");
  EXPECT_EQ(again.name, r.name);
  EXPECT_EQ(again.joints[2].name, r.joints[2].name);
  EXPECT_EQ(again.dof(), r.dof());
}

// nlohmann::json throws out_of_range (406), not parse_error, for a number that overflows.
TEST(FuzzRegressions, FitJsonWithAnOverflowingNumberIsAParseError) {
  try {
    fit_from_json("{\"format\": \"stiff-fit\", \"version\": 1e1873}", "f.json");
    FAIL();
  } catch (const ParseError& e) {
    EXPECT_NE(std::string(e.what()).find("f.json"), std::string::npos) << e.what();
  }
}

// Finite but absurd values (1e308) overflowed the linear identification: an Eigen assertion
// on an empty vector (moment 1e308) and a "successful" fit with an infinite compliance
// (displacement -1e308). Both are now STIFF_E_NUMERICAL naming the units.
class Overflow : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_EQ(stiff_robot_load(&robot, test::source_path("examples/robots/rokae.yaml").c_str()),
              STIFF_OK);
  }
  void TearDown() override { stiff_robot_destroy(robot); }
  stiff_status identify(double moment_x,
                        double displacement_y,
                        const char* model = nullptr,
                        double sign = 1.0) {
    const double q[18] = {0.4,  0.3,  0.2, 0.1, 0.5, 0.0, 0.0,  0.0, 0.0,
                          -0.5, -0.5, 0.5, 0.1, 0.8, 0.4, -0.3, 1.0, 0.2};
    const double f[9] = {40, 50, 50, 50, 50, 50, 50, 50, 50};
    const double m[9] = {moment_x, -0.4, -0.5, 0, 5, 5, 5, 4.9, 5};
    double d[9] = {-1.6e-5, displacement_y, 0, -1.4e-5, -9.2e-5, 1e-16, 1.3e-5, 2e-5, -3e-5};
    for (double& v : d) v *= sign;
    stiff_dataset* ds = nullptr;
    EXPECT_EQ(stiff_dataset_create(&ds, 3, 6, q, f, m, d, nullptr), STIFF_OK);
    stiff_result* fit = nullptr;
    stiff_identify_options o = STIFF_IDENTIFY_OPTIONS_INIT;
    o.model = model;
    o.max_iterations = 20;
    const stiff_status s = stiff_identify(&fit, robot, ds, &o);
    if (s == STIFF_OK) {
      double c[6];
      EXPECT_EQ(stiff_result_parameters(c, nullptr, 6, nullptr, fit), STIFF_OK);
      for (double v : c) EXPECT_TRUE(std::isfinite(v));
    } else {
      EXPECT_EQ(fit, nullptr);
    }
    stiff_result_destroy(fit);
    stiff_dataset_destroy(ds);
    return s;
  }
  stiff_robot* robot = nullptr;
};

TEST_F(Overflow, HugeMomentIsANumericalError) {
  EXPECT_EQ(identify(-1e308, 1e-5), STIFF_E_NUMERICAL);
  EXPECT_NE(std::string(stiff_last_error()).find("units"), std::string::npos) << stiff_last_error();
}

TEST_F(Overflow, HugeDisplacementIsANumericalError) {
  EXPECT_EQ(identify(5.0, -1e308), STIFF_E_NUMERICAL);
  EXPECT_NE(std::string(stiff_last_error()).find("units"), std::string::npos) << stiff_last_error();
}

// The Ceres path: the overflowing Jacobian reached a QR of an empty matrix (Eigen assertion).
TEST_F(Overflow, HugeDisplacementWithCeresIsANumericalError) {
  EXPECT_EQ(identify(5e-324, -1e308, "joint+tracker_frame"), STIFF_E_NUMERICAL)
      << stiff_last_error();
}

// Ordinary values, with displacements along the loads (the joint model fits them with
// compliances >= 0).
TEST_F(Overflow, OrdinaryValuesStillIdentify) {
  EXPECT_EQ(identify(5.0, 1e-5, nullptr, -1), STIFF_OK);
}

// The same displacements with the opposite sign go against the loads: least squares puts every
// compliance the data determine below 0. A fit of them could not be used (no model is built
// from a negative compliance); the error says what to check.
TEST_F(Overflow, DisplacementsAgainstTheLoadsAreAClearError) {
  EXPECT_EQ(identify(5.0, 1e-5), STIFF_E_NUMERICAL);
  EXPECT_NE(std::string(stiff_last_error()).find("sign conventions"), std::string::npos)
      << stiff_last_error();
}

// A G1 move of 1e30 mm with segmentation converted ~1e31 segments to int (UB).
TEST(FuzzRegressions, GcodeMoveWithTooManySegmentsIsAParseError) {
  PathOptions o;
  o.segment_m = 0.01;
  try {
    parse_gcode("G21 G90\nG1 X0 Y0 Z0 F100\nG1 X1e30\n", "p.nc", o);
    FAIL();
  } catch (const ParseError& e) {
    EXPECT_NE(std::string(e.what()).find("p.nc:3"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace stiff
