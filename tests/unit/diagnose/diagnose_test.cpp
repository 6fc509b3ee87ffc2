// Diagnosis (diagnose.hpp): distribution tails against reference values, and hidden-effect
// scenarios on the virtual robot (docs/diagnosis.md, section 5): the hidden effect is
// ranked first or reported in the ambiguous group, controls stay `adequate`, a left-out
// effect is not claimed confidently, and adding the suggested effect brings the validation
// error to the noise floor. Multi-seed sweeps are in tests named *Slow*.
#include "stiff/diagnose/diagnose.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <random>
#include <set>
#include <stdexcept>

#include "../effects/effect_truths.hpp"
#include "diagnose/analysis.hpp"
#include "stiff/error.hpp"
#include "stiff/identify/identify.hpp"
#include "stiff/io/robot_io.hpp"
#include "stiff/kinematics/joint_torque.hpp"
#include "stiff/model/model.hpp"
#include "stiff/sim/simulate.hpp"

namespace stiff {
namespace {

// ---------------------------------------------------------------- distribution tails

TEST(DiagnoseStats, IncompleteGammaMatchesReference) {
  for (double x : {0.1, 1.0, 3.0, 10.0})
    EXPECT_NEAR(stats::gamma_p(1.0, x), 1 - std::exp(-x), 1e-14);
  EXPECT_NEAR(stats::gamma_p(2.5, 1.7), 0.36143007689620493, 1e-13);           // scipy gammainc
  EXPECT_NEAR(stats::gamma_q(7.5, 30.0) / 2.522085078696141e-07, 1.0, 1e-10);  // gammaincc
  EXPECT_NEAR(stats::gamma_p(4.0, 2.0) + stats::gamma_q(4.0, 2.0), 1.0, 1e-15);
  EXPECT_EQ(stats::gamma_p(3.0, 0.0), 0.0);
  EXPECT_THROW(stats::gamma_p(-1.0, 1.0), InvalidArgument);
}

TEST(DiagnoseStats, ChiSquareTail) {
  EXPECT_NEAR(stats::chi2_sf(3.841458820694124, 1), 0.05, 1e-12);
  EXPECT_NEAR(stats::chi2_sf(18.307038053275146, 10), 0.05, 1e-12);
  EXPECT_NEAR(stats::chi2_sf(0.5, 3), 0.9188914116546758, 1e-12);
  EXPECT_NEAR(stats::chi2_sf(100, 10) / 5.4497019829205215e-17, 1.0, 1e-9);
  // The log tail where the tail itself underflows: scipy chi2.logsf(1000, 6).
  EXPECT_NEAR(stats::log_chi2_sf(1000, 6), -488.25993099435027, 1e-9);
  const double far = stats::log_chi2_sf(1e5, 6);  // exp() of it underflows
  EXPECT_TRUE(std::isfinite(far));
  EXPECT_NEAR(far, -0.5e5 + 2 * std::log(0.5e5) - std::lgamma(3.0), 1e-3);
}

TEST(DiagnoseStats, IncompleteBetaAndFTail) {
  EXPECT_NEAR(stats::beta_i(2, 3, 0.4), 0.5248, 1e-13);
  EXPECT_NEAR(stats::beta_i(2, 3, 0.4) + stats::beta_i(3, 2, 0.6), 1.0, 1e-14);
  EXPECT_NEAR(stats::f_sf(3.0, 5, 20), 0.035201337452666626, 1e-12);
  EXPECT_NEAR(stats::f_sf(40.0, 6, 170) / 4.135481326368689e-30, 1.0, 1e-8);
  EXPECT_NEAR(stats::log_f_sf(500, 6, 150), -220.45405579814857, 1e-8);
  EXPECT_TRUE(std::isfinite(stats::log_f_sf(1e7, 6, 150)));
  EXPECT_EQ(stats::f_sf(0.0, 3, 10), 1.0);
  EXPECT_THROW(stats::beta_i(1, 1, 1.5), InvalidArgument);
}

TEST(DiagnoseStats, PairedFallTestsTheErrorsLengths) {
  using diagnose_detail::paired_fall_p;
  // A fall carried by two rows of twenty (validation errors of a softening joint's step, um):
  // scipy ttest_1samp(a - b, alternative='greater') gives 0.018894; on the squares a^2 - b^2
  // (the large rows' own scatter in the variance) 0.0529 would hide it at 5 %.
  const std::vector<double> a = {669, 559, 276, 178, 150, 140, 122, 114, 106, 90,
                                 89,  85,  77,  77,  72,  71,  68,  66,  64,  64};
  const std::vector<double> b = {28, 48, 80, 116, 91, 38,  59, 32, 42, 80,
                                 46, 83, 58, 43,  77, 193, 49, 56, 82, 56};
  EXPECT_NEAR(paired_fall_p(a, b), 0.018893980902336016, 1e-12);
  EXPECT_EQ(paired_fall_p(b, a), 1.0);  // the other way round: no fall on average
  std::vector<double> c = b, nan_row = a;
  for (double& x : c) x -= 5.0;  // every row 5 um lower: no scatter, certain
  EXPECT_EQ(paired_fall_p(b, c), 0.0);
  nan_row[3] = std::nan("");  // a row not used is skipped, not a fall
  std::vector<double> a19 = a, b19 = b;
  a19.erase(a19.begin() + 3);
  b19.erase(b19.begin() + 3);
  EXPECT_DOUBLE_EQ(paired_fall_p(nan_row, b), paired_fall_p(a19, b19));
  EXPECT_EQ(paired_fall_p({1.0, 2.0}, {0.5, 1.0}), 1.0);  // fewer than three pairs
}

TEST(DiagnoseStats, HolmAdjustment) {
  const std::vector<double> p = {0.01, 0.04, 0.03, 0.005};
  std::vector<double> lp;
  for (double x : p) lp.push_back(std::log(x));
  const auto a = stats::holm_adjust(lp);
  // sorted: 0.005*4=0.02, 0.01*3=0.03, 0.03*2=0.06, 0.04*1 -> max(0.06, 0.04)=0.06
  EXPECT_NEAR(a[3], 0.02, 1e-12);
  EXPECT_NEAR(a[0], 0.03, 1e-12);
  EXPECT_NEAR(a[2], 0.06, 1e-12);
  EXPECT_NEAR(a[1], 0.06, 1e-12);
}

// ---------------------------------------------------------------- scenarios

constexpr double kTrackerSigma = 10e-6;

NoiseModel realistic_noise(uint64_t seed) {
  NoiseModel n;
  n.tracker_sigma_m = kTrackerSigma;
  n.tracker_ppm = 5.0;
  n.force_relative = 0.01;
  n.force_absolute_N = 0.3;
  n.seed = seed;
  return n;
}

struct Scenario {
  Dataset calib, valid;
  std::vector<int> outliers;
};

Scenario make_scenario(const std::string& hidden, uint64_t seed, double outlier_rate = 0.0) {
  const RobotModel robot = test::rokae();
  const Truth truth = test::effect_truth(hidden, robot);
  Scenario s;
  NoiseModel n = realistic_noise(7000 + seed);
  n.outlier_rate = outlier_rate;
  n.outlier_size_m = 150e-6;
  s.calib = simulate(robot, truth, test::design60(seed, 60), n, &s.outliers);
  n = realistic_noise(9000 + seed);
  n.outlier_rate = 0;
  s.valid = simulate(robot, truth, test::design60(50000 + seed, 40), n);
  return s;
}

/// The paper's joint compliances and one effect with the named parameters set (the others at
/// their null values).
Truth joint_and(const std::string& effect,
                const std::vector<std::pair<std::string, double>>& values) {
  const DeflectionModel m(test::rokae(), {"joint", effect});
  Truth truth;
  truth.effects = {"joint", effect};
  truth.theta = m.null_parameters();
  truth.theta.head(6) = test::paper_stiffness().cwiseInverse();
  for (const auto& [name, value] : values)
    m.effects()[1]->set_parameter(truth.theta.data() + m.offset(1), name, value);
  return truth;
}

/// The example truth of `hidden` (test::effect_truth) with the hidden effect's parameters
/// scaled by `scale` (the joint compliances as they are).
Truth scaled_truth(const std::string& hidden, const RobotModel& robot, double scale) {
  Truth truth = test::effect_truth(hidden, robot);
  const DeflectionModel m(robot, truth.effects);
  const int at = m.offset(static_cast<int>(truth.effects.size()) - 1);
  truth.theta.tail(truth.theta.size() - at) *= scale;
  return truth;
}

/// 60 calibration and 40 validation poses of `truth` with the realistic noise; `stream`
/// separates the designs and noises of one test from another's.
Scenario scenario_of(const Truth& truth, uint64_t seed, uint64_t stream) {
  const RobotModel robot = test::rokae();
  Scenario s;
  s.calib =
      simulate(robot, truth, test::design60(seed, 60), realistic_noise(7000 + 100 * stream + seed));
  s.valid = simulate(robot, truth, test::design60(50000 + 1000 * stream + seed, 40),
                     realistic_noise(9000 + 100 * stream + seed));
  return s;
}

Diagnosis run(const Scenario& s,
              const DiagnosisOptions& o = {},
              const std::vector<std::string>& model = {"joint"}) {
  return diagnose(test::rokae(), s.calib, &s.valid, model, o);
}

void print(const std::string& hidden, uint64_t seed, const Diagnosis& d) {
  std::printf("%-20s seed %2d: %-15s fit %.1f val %.1f floor %.1f um chi2p %.2g | ", hidden.c_str(),
              static_cast<int>(seed), d.verdict.c_str(), d.fit.fit_rms_m * 1e6,
              d.fit.validation_rms_m * 1e6, d.fit.validation_floor_m * 1e6, d.fit.chi2_p);
  for (size_t i = 0; i < std::min<size_t>(3, d.candidates.size()); ++i) {
    const auto& c = d.candidates[i];
    std::printf("%s(F %.3g padj %.2g drop %.1f) ", c.effect.c_str(), c.statistic, c.p_adjusted,
                c.expected_rms_drop_m * 1e6);
  }
  if (d.after_valid)
    std::printf("| after val %.1f chi2p %.2g", d.after.validation_rms_m * 1e6, d.after.chi2_p);
  if (!d.ambiguous_group.empty()) std::printf(" group %zu", d.ambiguous_group.size());
  std::printf("\n");
}

double validation_ratio(const Diagnosis& d) {
  return d.after.validation_rms_m / d.after.validation_floor_m;
}

/// The effect a `missing_effect` verdict names: the one its suggested model adds (the top
/// candidate, or a rival whose chain the validation poses chose).
std::string named(const Diagnosis& d) {
  const size_t plus = d.suggested_model.rfind('+');
  return plus == std::string::npos ? "" : d.suggested_model.substr(plus + 1);
}

bool found(const Diagnosis& d, const std::string& hidden) {
  if (d.verdict == "missing_effect") return named(d) == hidden;
  if (d.verdict == "ambiguous")
    return std::find(d.ambiguous_group.begin(), d.ambiguous_group.end(), hidden) !=
           d.ambiguous_group.end();
  return false;
}

bool claimed(const Diagnosis& d) {
  return d.verdict == "missing_effect" || d.verdict == "ambiguous";
}

/// Effects visible above the realistic noise at the magnitudes of effect_truths.hpp.
const std::vector<std::string>& visible_effects() {
  static const std::vector<std::string> e = {
      "link",          "gravity_compensator", "nonlinear_joint", "backlash",        "coupling",
      "tracker_frame", "force_frame",         "point_offset",    "tool_compliance", "drift"};
  return e;
}

struct Tally {
  int runs = 0, found = 0, val_ok = 0, wrong = 0;
  double worst_ratio = 0, base_val = 0, after_val = 0, floor = 0;
};

Tally hidden_sweep(const std::string& hidden, int seeds) {
  Tally t;
  for (int seed = 1; seed <= seeds; ++seed) {
    const Diagnosis d = run(make_scenario(hidden, seed));
    print(hidden, seed, d);
    ++t.runs;
    if (!found(d, hidden)) {
      t.wrong += claimed(d);
      continue;
    }
    ++t.found;
    const double r = validation_ratio(d);
    t.worst_ratio = std::max(t.worst_ratio, r);
    t.val_ok += r <= 1.25;
    t.base_val += d.fit.validation_rms_m;
    t.after_val += d.after.validation_rms_m;
    t.floor += d.after.validation_floor_m;
  }
  std::printf(
      "  %-20s found %d/%d (wrong claims %d), validation %.1f -> %.1f um (floor %.1f um), within "
      "1.25x "
      "floor %d/%d (worst %.2f)\n",
      hidden.c_str(), t.found, t.runs, t.wrong, 1e6 * t.base_val / std::max(1, t.found),
      1e6 * t.after_val / std::max(1, t.found), 1e6 * t.floor / std::max(1, t.found), t.val_ok,
      t.found, t.worst_ratio);
  return t;
}

class HiddenEffect : public ::testing::TestWithParam<std::string> {};

// Every visible effect is ranked first (or in the reported ambiguous group), and adding it
// brings the validation error to within 1.25x the noise floor. Fast: 2 seeds each.
// Tracker-frame rotation and drift sit at ~0.2-0.3 sigma of this noise, below the detection
// power of 60 poses once the stated noise is itself allowed 10 % uncertainty: two seeds cannot
// demand a find there. For them a miss must be `adequate` (no wrong claim) and a find must reach
// the floor; their detection rate is asserted over 20 seeds in the Slow sweep below.
TEST_P(HiddenEffect, RankedFirstAndErrorFalls) {
  const Tally t = hidden_sweep(GetParam(), 2);
  const bool weak = GetParam() == "tracker_frame" || GetParam() == "drift";
  if (weak)
    EXPECT_EQ(t.wrong, 0);
  else
    EXPECT_EQ(t.found, t.runs);
  EXPECT_EQ(t.val_ok, t.found);
}

// Tracker-frame rotation (1 deg) and drift (5-8 um) are visible at only ~0.2-0.3 sigma of this
// noise (22 um with 5 ppm at 2 m): detection power is partial there (spec 2.9: "below ~0.3
// sigma visible RMS nothing works"); a miss must then be `adequate`, never a wrong effect.
TEST_P(HiddenEffect, SlowRankedFirstAndErrorFallsManySeeds) {
  const Tally t = hidden_sweep(GetParam(), 20);
  const bool weak = GetParam() == "tracker_frame" || GetParam() == "drift";
  EXPECT_GE(t.found, weak ? 6 : 18) << "top-1 / group accuracy too low";
  EXPECT_LE(t.wrong, 1) << "wrong effect claimed";
  EXPECT_GE(t.val_ok, t.found - 1);
}

INSTANTIATE_TEST_SUITE_P(Diagnose,
                         HiddenEffect,
                         ::testing::ValuesIn(visible_effects()),
                         [](const auto& p) { return p.param; });

/// The robot file a user has: every link's and the tool's mass off by 30 % (1.3 or 0.7 times
/// the true one) and its centre of mass moved by 30 % of its distance from the link frame's
/// origin in a random direction (docs/effects.md, backlash: users know both to about 30 %).
RobotModel misweighed(const RobotModel& truth, uint64_t seed) {
  RobotModel r = truth;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g;
  auto perturb = [&](double& mass, Eigen::Vector3d& com) {
    if (!(mass > 0)) return;
    mass *= g(rng) > 0 ? 1.3 : 0.7;
    Eigen::Vector3d u(g(rng), g(rng), g(rng));
    com += 0.3 * com.norm() * u.normalized();
  };
  for (auto& j : r.joints) perturb(j.mass, j.com);
  perturb(r.tool_mass, r.tool_com);
  return r;
}

// Backlash simulated with the true masses and diagnosed with a robot file whose masses and
// centres of mass are 30 % off: the jump decision near the torque reversal then differs on a
// part of the rows, and the effect finds the preload the data support. The verdict must still
// be backlash (ranked first or in the ambiguous group) on every seed, and adding it must lower
// the validation error. The floor itself is not asserted: rows whose decision no preload scale
// can place (a centre of mass moved sideways changes the preload's shape over the poses) keep a
// part of the jump unexplained (seed 2: 1.37x the floor, 1.19x with the true masses).
TEST(DiagnoseMassModel, SlowBacklashWithMassesThirtyPercentOff) {
  const RobotModel truth = test::rokae();
  for (uint64_t seed = 1; seed <= 3; ++seed) {
    const Scenario s = make_scenario("backlash", seed);
    const RobotModel file = misweighed(truth, 40 + seed);
    const Diagnosis d = diagnose(file, s.calib, &s.valid, {"joint"}, {});
    print("backlash, masses off", seed, d);
    EXPECT_TRUE(found(d, "backlash")) << "seed " << seed << ": " << d.summary;
    if (d.after_valid) {
      EXPECT_LT(d.after.validation_rms_m, d.fit.validation_rms_m);
    }
  }
}

/// A robot file whose masses are 30 % light and whose centres of mass are turned by `angle`
/// about their link's joint axis (the link frame's z): the preloads differ from the true ones by
/// a scale and by a shape no scale reproduces.
RobotModel turned(const RobotModel& truth, double angle) {
  RobotModel r = truth;
  const Eigen::Matrix3d rz = Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  for (auto& j : r.joints) {
    j.mass *= 0.7;
    j.com = rz * j.com;
  }
  r.tool_mass *= 0.7;
  return r;
}

/// The data as a user without a noise statement has them: no sigma_d, no metadata.
void hide_noise(Dataset& d) {
  d.has_sigma = false;
  for (auto& r : d.rows) r.sigma_d = 0;
  d.metadata.clear();
}

// Without a noise statement the verdict rests on the fit-versus-validation F test, and the
// right model (joint + backlash) must pass it although the file's preload is off: masses 30 %
// light and centres of mass turned by 0.3 rad about the joint axes, a preload error that is a
// scale and a change of shape over the poses. The rows near the torque reversal whose decision
// the calibration leaves open (the preload's scale and the turn of its lumped centre of mass
// anywhere in their confidence set) are scored by the prediction closest to them. Without that,
// validation rows decided on the wrong side (a jump of b |J_j(P)|, several sigma each) make the
// test reject the right model (2 of these 8 seeds) and the verdict falls to `unexplained`. At
// alpha = 5 % a right model is rejected on 2 or more of 8 seeds with probability 5.7 %
// (binomial); the target of two thirds right verdicts is the one for independent data at
// reduced size.
TEST(DiagnoseMassModel, SlowBacklashWithPreloadOffAndNoiseUnknown) {
  const RobotModel file = turned(test::rokae(), 0.3);
  const int seeds = 8;
  int right = 0, rejected = 0, uncertain = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    Scenario s = make_scenario("backlash", static_cast<uint64_t>(seed));
    hide_noise(s.calib);
    hide_noise(s.valid);
    const Diagnosis d = diagnose(file, s.calib, &s.valid, {"joint"}, {});
    print("backlash, preload off, noise unknown", static_cast<uint64_t>(seed), d);
    EXPECT_EQ(d.noise_source, "none");
    right += found(d, "backlash");
    ASSERT_TRUE(d.after_valid) << d.summary;
    ASSERT_EQ(d.after.model, "joint+backlash");
    rejected += d.after.validation_to_fit_p < 0.05;
    uncertain += d.after.validation_uncertain_rows;
  }
  EXPECT_LE(rejected, 1);
  EXPECT_GE(3 * right, 2 * seeds);
  EXPECT_GT(uncertain, 0);
}

// Twice the calibration poses (N = 120), a lost motion of 1.5 arcmin and a robot file whose
// masses are 30 % off and centres of mass moved sideways: rows whose jump the calibration
// decides on the wrong side, beyond the preload's confidence set, cost several sigma each, and
// the calibration's outlier rule now has the power to exclude them, which lowers the fit's
// mean square. The validation rows decided wrongly in the same way must leave the
// fit-versus-validation ratio alike; a trimmed fit against an untrimmed validation rejected the
// right model (joint + backlash) on 4 of these 8 seeds (ratios 1.5-2.1). At alpha = 5 % a right
// model is rejected on 2 or more of 8 seeds with probability 5.7 %.
TEST(DiagnoseMassModel, SlowBacklashWithMorePosesJudgesBothSidesAlike) {
  const RobotModel robot = test::rokae();
  Truth truth = test::effect_truth("backlash", robot);
  {  // lost motion of 1.5 arcmin (3x the example): a wrong side costs more sigma
    const DeflectionModel m(robot, truth.effects);
    const int off = m.offset(m.find("backlash"));
    for (int j = 0; j < robot.dof(); ++j) truth.theta(off + j) *= 3.0;
  }
  const int seeds = 8;
  int rejected = 0, trimmed = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    NoiseModel n = realistic_noise(7100 + seed);
    Dataset calib = simulate(robot, truth, test::design60(200 + seed, 120), n);
    n = realistic_noise(9100 + seed);
    Dataset valid = simulate(robot, truth, test::design60(60000 + seed, 40), n);
    hide_noise(calib);
    hide_noise(valid);
    const RobotModel file = misweighed(robot, 40 + seed);
    const Diagnosis d = diagnose(file, calib, &valid, {"joint", "backlash"}, {});
    print("backlash, N = 120, preload off", static_cast<uint64_t>(seed), d);
    std::printf("  used %d of %d, validation/fit %.3f p %.3g, trimmed %d\n", d.fit.used,
                d.fit.measurements, d.fit.validation_to_fit, d.fit.validation_to_fit_p,
                d.fit.validation_outliers);
    rejected += d.fit.validation_to_fit_p < 0.05;
    trimmed += d.fit.validation_outliers > 0;
  }
  EXPECT_LE(rejected, 1);
  EXPECT_GT(trimmed, 0);
}

/// Each joint's jump decision on every row of `data` (sign of preload + load torque against
/// the preload's, exactly as the threshold regression decides it) as a function of the scales
/// of the file's link masses.
struct JumpDecisions {
  std::vector<Eigen::MatrixXd> by_link;  // tau_g,jk per row
  std::vector<Eigen::VectorXd> tau;      // the load's joint torques per row
  JumpDecisions(const RobotModel& file, const Dataset& data) {
    for (const Measurement& row : data.rows) {
      const ChainState c = file.chain(row.q);
      const Eigen::Vector3d l = file.point_position(c, file.load_point);
      by_link.push_back(gravity_torques_by_link(file, c));
      Eigen::VectorXd t(file.dof());
      for (int j = 0; j < file.dof(); ++j) {
        Eigen::Vector3d w;
        lever_arm(c.axis.col(j), c.origin.col(j), l, w);
        t(j) = force_torque(w, row.force);
      }
      tau.push_back(t);
    }
  }
  std::vector<int> operator()(const Eigen::VectorXd& mass) const {
    auto sgn = [](double x) { return (x > 0) - (x < 0); };
    std::vector<int> out;
    for (size_t r = 0; r < tau.size(); ++r) {
      const Eigen::VectorXd pre = by_link[r] * mass;
      for (int j = 0; j < pre.size(); ++j) out.push_back(sgn(pre(j) + tau[r](j)) - sgn(pre(j)));
    }
    return out;
  }
};

/// Rows x joints 2-5 (those with a gravity preload) whose backlash jump the model `m`, built on
/// `data` with the robot file `file`, decides otherwise than the true masses (`truth`) do:
/// `*by_file` with the file's masses, `*by_found` with the link masses' errors m_k that m's
/// backlash effect found from the data; `*moved` counts the links whose m_k is not 0.
void jump_decisions(const RobotModel& truth,
                    const RobotModel& file,
                    const Dataset& data,
                    const DeflectionModel& m,
                    int* by_file,
                    int* by_found,
                    int* moved) {
  const int off = m.offset(m.find("backlash")), n = file.dof();
  Eigen::VectorXd mass(n);
  *by_file = *by_found = *moved = 0;
  for (int k = 0; k < n; ++k) {
    mass(k) = 1 + m.spec(off + n + k).null_value;
    *moved += mass(k) != 1;
  }
  const Eigen::VectorXd ones = Eigen::VectorXd::Ones(n);
  const JumpDecisions decisions(file, data);
  const std::vector<int> truly = JumpDecisions(truth, data)(ones);
  const std::vector<int> with_file = decisions(ones), with_found = decisions(mass);
  for (size_t i = 0; i < truly.size(); ++i) {
    const int j = static_cast<int>(i % n);
    if (j < 1 || j >= 5) continue;
    *by_file += truly[i] != with_file[i];
    *by_found += truly[i] != with_found[i];
  }
}

/// The robot file of an arm whose every mass is 1.3 times what the file says (centres of mass
/// right): the true preload of each joint is 1.3 times the file's.
RobotModel light_file(const RobotModel& truth) {
  RobotModel file = truth;
  for (auto& j : file.joints) j.mass /= 1.3;
  file.tool_mass /= 1.3;
  return file;
}

/// The truth of `effects` on `robot` ("joint" first): the paper's joint compliances and every
/// other effect's example parameters.
Truth examples_of(const RobotModel& robot, const std::vector<std::string>& effects) {
  const DeflectionModel full(robot, effects);
  Truth t;
  t.effects = effects;
  t.theta = full.null_parameters();
  const Eigen::VectorXd c = test::effect_truth("joint", robot).theta;
  t.theta.head(c.size()) = c;
  for (size_t e = 1; e < effects.size(); ++e)
    if (!full.effects()[e]->example_parameters(c,
                                               t.theta.data() + full.offset(static_cast<int>(e))))
      throw std::runtime_error("effect '" + effects[e] + "' gives no example_parameters()");
  return t;
}

// What the data tell about the preload: with every mass 30 % heavier than the robot file says
// (the centres of mass right), the true preload of each joint is 1.3 times the file's. The
// link masses the backlash effect finds from the calibration data must reproduce the true jump
// decisions on more rows than the file's masses do.
TEST(DiagnoseMassModel, BacklashFindsThePreloadScale) {
  const RobotModel truth = test::rokae();
  const RobotModel file = light_file(truth);
  const Scenario s = make_scenario("backlash", 5);
  const DeflectionModel m(file, {"joint", "backlash"}, &s.calib);
  const int off = m.offset(1), n = file.dof();
  int wrong_file = 0, wrong_found = 0, moved = 0;
  jump_decisions(truth, file, s.calib, m, &wrong_file, &wrong_found, &moved);
  std::printf("  rows x joints with the wrong jump decision: file masses %d, found %d\n",
              wrong_file, wrong_found);
  EXPECT_GT(moved, 0);
  EXPECT_GT(wrong_file, 0);
  EXPECT_LT(wrong_found, wrong_file);
  int with_range = 0;
  for (int k = 0; k < n; ++k) {
    const ParameterSpec& mk = m.spec(off + n + k);
    std::printf("  link %d: m %.3f in [%.3f, %.3f]\n", k + 1, mk.null_value, mk.confidence_lower,
                mk.confidence_upper);
    with_range += std::isfinite(mk.confidence_lower);  // not a link without mass in the file
  }
  // The fit reports them as decided from the data, with their range: not as parameters the
  // data cannot identify.
  const FitResult f = identify(file, s.calib, {"joint", "backlash"});
  int decided = 0;
  for (const auto& w : f.warnings) {
    const bool preload = w.rfind("backlash.m", 0) == 0 || w.rfind("backlash.g", 0) == 0;
    if (!preload) continue;
    EXPECT_NE(w.find(" is decided from the data, not fitted"), std::string::npos) << w;
    decided += w.find("do not exclude") != std::string::npos;
  }
  EXPECT_EQ(decided, with_range + n);
}

// Masses off link by link in opposite directions (the forearm 1.5 times the file's, the tool
// half of it): each joint's preload then differs from the file's by a shape over the poses that
// no scale of it reproduces (J3's preload is the forearm's and the tool's), but that the link
// masses do. From 120 poses the masses found must decide fewer rows x joints wrongly than the
// file's masses (the decisions near the reversal, a few rows, stay open: the masses of two
// links trade against each other there), and the true masses must lie in the confidence box of
// the two links.
TEST(DiagnoseMassModel, BacklashFindsEachLinksMass) {
  const RobotModel truth = test::rokae();
  RobotModel file = truth;
  file.joints[2].mass /= 1.5;
  file.tool_mass /= 0.5;
  const Truth t = test::effect_truth("backlash", truth);
  const Dataset calib = simulate(truth, t, test::design60(11, 120), realistic_noise(7011));
  const DeflectionModel m(file, {"joint", "backlash"}, &calib);
  int by_file = 0, by_found = 0, moved = 0;
  jump_decisions(truth, file, calib, m, &by_file, &by_found, &moved);
  const int off = m.offset(1), n = file.dof();
  const ParameterSpec& forearm = m.spec(off + n + 2);
  const ParameterSpec& tool = m.spec(off + n + n - 1);
  std::printf(
      "  wrong jump decisions: file masses %d, found %d; forearm m %.2f in [%.2f, %.2f], "
      "last link and tool m %.2f in [%.2f, %.2f]\n",
      by_file, by_found, forearm.null_value, forearm.confidence_lower, forearm.confidence_upper,
      tool.null_value, tool.confidence_lower, tool.confidence_upper);
  EXPECT_GT(by_file, 0);
  EXPECT_LT(by_found, by_file);
  EXPECT_LE(forearm.confidence_lower, 0.5);
  EXPECT_GE(forearm.confidence_upper, 0.5);
  EXPECT_LE(tool.confidence_lower, -0.5);
  EXPECT_GE(tool.confidence_upper, -0.5);
}

// Every mass vector that decides the calibration rows' jumps alike fits them alike; the one the
// search returns must sit in the middle of that set along each link's mass (the room to the
// nearer wall at least 0.6 times that to the farther: an axis-by-axis centring of a slanted
// cell is not exact), not on its wall next to a row's reversal, where a new pose is most easily
// decided wrongly. The walls are found here independently, by scanning each moved link's mass
// in steps of 0.001 until a calibration row's decision changes. And on 200 new poses the masses
// found must decide fewer jumps wrongly than the file's (the file 30 % light, 60 poses, over 6
// seeds).
TEST(DiagnoseMassModel, SlowBacklashMassesInTheMiddleOfWhatTheDataAllow) {
  const RobotModel truth = test::rokae();
  const RobotModel file = light_file(truth);
  const Truth t = test::effect_truth("backlash", truth);
  const int n = file.dof();
  int file_total = 0, found_total = 0, centred = 0, walls = 0;
  for (uint64_t seed = 1; seed <= 6; ++seed) {
    const Dataset calib =
        simulate(truth, t, test::design60(seed, 60), realistic_noise(7100 + seed));
    const Dataset fresh = simulate(truth, t, test::design60(60000 + seed, 200), NoiseModel{});
    const DeflectionModel m(file, {"joint", "backlash"}, &calib);
    const int off = m.offset(1);
    Eigen::VectorXd mass(n);
    for (int k = 0; k < n; ++k) mass(k) = 1 + m.spec(off + n + k).null_value;
    int by_file = 0, by_found = 0, moved = 0;
    jump_decisions(truth, file, fresh, m, &by_file, &by_found, &moved);
    file_total += by_file;
    found_total += by_found;
    const JumpDecisions decisions(file, calib);
    const std::vector<int> cell = decisions(mass);
    for (int k = 0; k < n; ++k) {
      if (mass(k) == 1) continue;
      double side[2];
      for (int s = 0; s < 2; ++s) {
        Eigen::VectorXd probe = mass;
        double step = 0;
        while (step < 1.0) {
          probe(k) = mass(k) + (s ? 1 : -1) * (step + 0.001);
          if (probe(k) < 0 || probe(k) > 2 || decisions(probe) != cell) break;
          step += 0.001;
        }
        side[s] = step;
      }
      ++walls;
      centred += std::min(side[0], side[1]) >= 0.6 * std::max(side[0], side[1]);
      std::printf("  seed %d link %d: m %.3f, room below %.3f, above %.3f\n",
                  static_cast<int>(seed), k + 1, mass(k) - 1, side[0], side[1]);
    }
    std::printf("  seed %d: wrong jump decisions on 200 new poses: file masses %d, found %d\n",
                static_cast<int>(seed), by_file, by_found);
  }
  EXPECT_GE(walls, 6);
  EXPECT_EQ(centred, walls);
  EXPECT_LT(found_total, file_total);
}

// Two effects at once: an SMR offset and backlash, the file's masses 30 % light. The preload
// is decided on what the model's other effects leave (their columns among the threshold
// regression's regressors): regressed on joint compliance and backlash alone, the offset's
// signal inflates the residual variance, no threshold beats the file's masses, and the jump
// decisions stay those of the wrong preload. 60 poses decide few rows' jumps, and the masses
// of the links trade against each other there (five masses from the rows near the reversals:
// on 3 of these 8 seeds the masses found decide 2-4 more rows x joints wrongly than the file's),
// so the test asks for fewer wrong decisions over the seeds, not on each.
TEST(DiagnoseMassModel, BacklashPreloadDecidedOnWhatTheOtherEffectsLeave) {
  const RobotModel truth = test::rokae();
  const RobotModel file = light_file(truth);
  const std::vector<std::string> effects = {"joint", "point_offset", "backlash"};
  const Truth t = examples_of(truth, effects);
  int moved_total = 0, file_total = 0, found_total = 0;
  for (uint64_t seed = 1; seed <= 8; ++seed) {
    const Dataset calib =
        simulate(truth, t, test::design60(seed, 60), realistic_noise(7000 + seed));
    const DeflectionModel m(file, effects, &calib);
    int by_file = 0, by_found = 0, moved = 0;
    jump_decisions(truth, file, calib, m, &by_file, &by_found, &moved);
    std::printf("  seed %d: wrong jump decisions: file masses %d, found %d; %d links moved\n",
                static_cast<int>(seed), by_file, by_found, moved);
    moved_total += moved;
    file_total += by_file;
    found_total += by_found;
  }
  EXPECT_GE(moved_total, 2);
  EXPECT_LT(found_total, file_total);
}

// Masses off link by link by up to 30 % either way (uniform, the file's error 0.17 RMS): many
// mass vectors fit 60 rows about alike, and the one with the smallest residual lies far from
// the truth (without the file's masses as a prior, measured: 0.49 RMS alone, 0.36 with a point
// offset, new poses' jumps decided wrongly about twice as often as by the file's masses; with
// it 1.2-1.4 times as often: near the file, 60 rows move the masses by chance). The masses found
// must stay within the 30 % the file is off by (RMS over 10 seeds and the five links that load
// a joint with a preload), with backlash alone and with a point offset beside it.
TEST(DiagnoseMassModel, SlowBacklashMassesStayNearTheFileWhereTheDataAllowMany) {
  const RobotModel truth = test::rokae();
  const int n = truth.dof();
  for (const auto& effects : {std::vector<std::string>{"joint", "backlash"},
                              std::vector<std::string>{"joint", "point_offset", "backlash"}}) {
    const Truth t = examples_of(truth, effects);
    std::mt19937_64 rng(42);
    std::uniform_real_distribution<double> off_by(-0.3, 0.3);
    double err2 = 0;
    int count = 0, file_total = 0, found_total = 0;
    for (uint64_t seed = 1; seed <= 10; ++seed) {
      RobotModel file = truth;
      Eigen::VectorXd m_true(n);
      for (int k = 0; k < n; ++k) {
        m_true(k) = off_by(rng);  // the true mass is 1 + m_k times the file's
        file.joints[k].mass /= 1 + m_true(k);
        if (k == n - 1) file.tool_mass /= 1 + m_true(k);
      }
      const Dataset calib =
          simulate(truth, t, test::design60(seed, 60), realistic_noise(7300 + seed));
      const Dataset fresh = simulate(truth, t, test::design60(61000 + seed, 200), NoiseModel{});
      const DeflectionModel m(file, effects, &calib);
      const int off = m.offset(m.find("backlash"));
      for (int k = 1; k < n; ++k) {  // link 1's weight loads no joint with a preload
        err2 += std::pow(m.spec(off + n + k).null_value - m_true(k), 2);
        ++count;
      }
      int by_file = 0, by_found = 0, moved = 0;
      jump_decisions(truth, file, fresh, m, &by_file, &by_found, &moved);
      file_total += by_file;
      found_total += by_found;
    }
    const double rms = std::sqrt(err2 / count);
    std::printf("  %s: mass error RMS %.3f; wrong jump decisions on new poses: file %d, found %d\n",
                effects[1].c_str(), rms, file_total, found_total);
    EXPECT_LT(rms, 0.3) << effects[1];
  }
}

// Near a reversal the masses found leave a new pose's jump to chance: the model predicts the
// expected jump there, over the masses' posterior (a Gaussian preload with covariance t^T V t),
// and the decided jump on the rows the masses were decided on. Masses off link by link by up to
// 30 % either way, the true gaps and compliances: on 200 new poses per seed the expected jump
// must predict better than the jump at the masses found (squared error over 10 seeds), and on
// the calibration poses exactly as the decided jump does.
TEST(DiagnoseMassModel, SlowBacklashPredictsTheExpectedJumpWhereTheDataLeaveItOpen) {
  const RobotModel truth = test::rokae();
  const int n = truth.dof();
  const std::vector<std::string> effects = {"joint", "backlash"};
  const Truth t = examples_of(truth, effects);
  std::mt19937_64 rng(43);
  std::uniform_real_distribution<double> off_by(-0.3, 0.3);
  double expected = 0, decided = 0, calib_change = 0;
  int spread_rows = 0;
  for (uint64_t seed = 1; seed <= 10; ++seed) {
    RobotModel file = truth;
    for (int k = 0; k < n; ++k) {
      const double m_true = off_by(rng);
      file.joints[k].mass /= 1 + m_true;
      if (k == n - 1) file.tool_mass /= 1 + m_true;
    }
    const Dataset calib =
        simulate(truth, t, test::design60(seed, 60), realistic_noise(7400 + seed));
    const Dataset fresh = simulate(truth, t, test::design60(62000 + seed, 200), NoiseModel{});
    const DeflectionModel m(file, effects, &calib);
    const int off = m.offset(1);
    Eigen::VectorXd with = m.null_parameters();
    with.head(n) = t.theta.head(n);                  // the true compliances
    with.segment(off, n) = t.theta.segment(off, n);  // and gaps
    Eigen::VectorXd without = with;
    for (int k = 0; k < m.parameter_count(); ++k)
      if (m.spec(k).spread) without(k) = 0;
    ASSERT_NE(with, without) << "seed " << seed << ": the data left the masses no spread";
    for (size_t r = 0; r < fresh.rows.size(); ++r) {
      const Measurement& row = fresh.rows[r];
      const MeasurementContext c = m.context(row, static_cast<int>(r));
      const Eigen::Vector3d a = m.predict(with, row, c).head<3>();
      const Eigen::Vector3d b = m.predict(without, row, c).head<3>();
      expected += (a - row.displacement).squaredNorm();
      decided += (b - row.displacement).squaredNorm();
      spread_rows += (a - b).norm() > 1e-6;
    }
    for (size_t r = 0; r < calib.rows.size(); ++r) {
      const MeasurementContext c = m.context(calib.rows[r], static_cast<int>(r));
      calib_change = std::max(
          calib_change, (m.predict(with, calib.rows[r], c) - m.predict(without, calib.rows[r], c))
                            .head<3>()
                            .norm());
    }
  }
  std::printf(
      "  new poses: RMS %.1f um expected jump, %.1f um decided jump (%d of 2000 rows "
      "moved by more than 1 um)\n",
      1e6 * std::sqrt(expected / 6000), 1e6 * std::sqrt(decided / 6000), spread_rows);
  EXPECT_GT(spread_rows, 0);
  EXPECT_LT(expected, decided);
  EXPECT_EQ(calib_change, 0.0);
  // One path: a fit's prediction of new poses by predict_dataset is the expected jump of a
  // model that has seen no data, as the C API's is.
  const RobotModel file = light_file(truth);
  const Dataset calib = simulate(truth, t, test::design60(1, 60), realistic_noise(7401));
  const Dataset fresh = simulate(truth, t, test::design60(62001, 200), NoiseModel{});
  const FitResult fit = identify(file, calib, effects);
  const Eigen::MatrixXd pred = predict_dataset(file, fit, fresh);
  const DeflectionModel blind(file, effects);
  double most = 0;
  for (size_t r = 0; r < fresh.rows.size(); ++r)
    most = std::max(most, (pred.row(r).transpose() -
                           blind.predict(fit.theta(), fresh.rows[r],
                                         blind.context(fresh.rows[r], static_cast<int>(r))))
                              .norm());
  EXPECT_LT(most, 1e-12);
}

// A joint that gravity does not preload (the example arm's vertical joint 1) rests anywhere in
// its gap when unloaded: each reading's deflection is b/2 sgn(tau_1) less that rest, uniform in
// the gap, a scatter of variance b^2/12 along the joint's column that no parameter predicts.
// The model states it (DeflectionModel::displacement_scatter, checked here against joint 1's
// column by finite differences of the forward kinematics), and with the noise stated the
// diagnosis adds it to the floor: the right model (joint + backlash) must be named on every
// seed with its residual at that floor (within 3 standard deviations of sqrt(chi2/dof), about
// 1 + 3/sqrt(2 dof)). Taken as noise alone the scatter leaves seed 4 at 1.28 times the floor
// (bound 1.16, p = 4e-7 on the chi-square test), where a verdict falls to `unexplained`.
TEST(DiagnoseMassModel, SlowUnpreloadedJointsRestInItsGapIsScatterNotStructure) {
  const RobotModel robot = test::rokae();
  const double b = 1.5e-4;  // rad, half an arcminute
  const Truth truth = joint_and("backlash", {{"b1", b}});
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> rest(-b / 2, b / 2);
  auto unsettle = [&](Dataset& data) {
    for (auto& row : data.rows) {
      const ChainState c = robot.chain(row.q);
      Eigen::Vector3d w;
      lever_arm(c.axis.col(0), c.origin.col(0), robot.point_position(c, robot.measured_point), w);
      row.displacement -= rest(rng) * w;
    }
  };
  {
    const Scenario s = scenario_of(truth, 1, 31);
    const DeflectionModel m(robot, truth.effects);
    const Measurement& row = s.calib.rows[0];
    const Eigen::Matrix3d cov = m.displacement_scatter(truth.theta, row, m.context(row, 0));
    const double h = 1e-6;
    Eigen::VectorXd up = row.q, down = row.q;
    up(0) += h;
    down(0) -= h;
    const Eigen::Vector3d col = (robot.point_position(robot.chain(up), robot.measured_point) -
                                 robot.point_position(robot.chain(down), robot.measured_point)) /
                                (2 * h);
    EXPECT_LT((cov - b * b / 12 * col * col.transpose()).norm(), 1e-6 * cov.norm());
    const DeflectionModel plain(robot, {"joint"});
    EXPECT_EQ(plain
                  .displacement_scatter(m.null_parameters().head(plain.parameter_count()), row,
                                        plain.context(row, 0))
                  .norm(),
              0.0);
  }
  for (uint64_t seed = 1; seed <= 4; ++seed) {
    Scenario s = scenario_of(truth, seed, 31);
    unsettle(s.calib);
    unsettle(s.valid);
    const Diagnosis d = run(s);
    print("backlash 1, rest in the gap", seed, d);
    EXPECT_TRUE(found(d, "backlash")) << "seed " << seed << ": " << d.summary;
    ASSERT_TRUE(d.after_valid) << d.summary;
    EXPECT_EQ(d.after.model, "joint+backlash");
    EXPECT_LT(d.after.residual_to_floor, 1.0 + 3.0 / std::sqrt(2.0 * d.after.dof));
  }
}

int control_claims(int seeds, double outlier_rate, int* adequate, int* missed_outliers) {
  int claims = 0;
  *adequate = 0;
  *missed_outliers = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    const Scenario s = make_scenario("joint", 300 + seed, outlier_rate);
    const Diagnosis d = run(s);
    claims += claimed(d);
    *adequate += d.verdict == "adequate";
    // A gross error of 150 um is > 5 sigma: every one must be flagged, and only a few others.
    int flagged = 0;
    for (const auto& r : d.residuals) flagged += r.outlier;
    for (int r : s.outliers)
      if (!d.residuals[r].outlier && d.residuals[r].norm_sigma > 6) {
        ++*missed_outliers;
        print("missed outlier", static_cast<uint64_t>(300 + seed), d);
      }
    EXPECT_LE(flagged, static_cast<int>(s.outliers.size()) + 2);
  }
  std::printf("  control (outlier rate %.2f): %d claims, %d adequate of %d seeds\n", outlier_rate,
              claims, *adequate, seeds);
  return claims;
}

// Controls without a hidden effect: `adequate`, no effect claimed.
TEST(DiagnoseControl, NoHiddenEffect) {
  int adequate = 0, missed = 0;
  EXPECT_LE(control_claims(8, 0.0, &adequate, &missed), 1);
  EXPECT_GE(adequate, 6);
}

TEST(DiagnoseControl, SlowGrossOutliersAreFlaggedNotExplained) {
  int adequate = 0, missed = 0;
  EXPECT_LE(control_claims(8, 0.05, &adequate, &missed), 1);
  EXPECT_GE(adequate, 6);
  EXPECT_EQ(missed, 0);
}

// False-claim rate: at most 5 % over 100 seeded controls (Holm, FWER 5 %), and at most 5 %
// with 5 % gross outliers (40 seeds).
TEST(DiagnoseControl, SlowFalseClaimRate) {
  int adequate = 0, missed = 0;
  EXPECT_LE(control_claims(100, 0.0, &adequate, &missed), 5);
  EXPECT_GE(adequate, 85);
  EXPECT_LE(control_claims(40, 0.05, &adequate, &missed), 2);
  EXPECT_GE(adequate, 32);
  EXPECT_EQ(missed, 0);
}

// Marginal evidence (alpha/10 <= p_adj < alpha) is claimed only with the validation poses'
// support (Fisher's combination of p_adj and the paired test of their errors' fall): a
// control where a point offset reached p_adj = 0.043 was `ambiguous`, and is `adequate`; a
// coupling at half size that reaches p_adj = 0.013-0.023 is still named, its validation fall
// enough beside it.
TEST(DiagnoseControl, MarginalEvidenceNeedsTheNewPoses) {
  const Diagnosis control = run(make_scenario("joint", 303));
  ASSERT_FALSE(control.candidates.empty());
  EXPECT_GT(control.candidates[0].p_adjusted, 0.005);
  EXPECT_LT(control.candidates[0].p_adjusted, 0.05);
  EXPECT_EQ(control.verdict, "adequate") << control.summary;
  EXPECT_NE(control.summary.find("reached p_adj"), std::string::npos) << control.summary;
  const RobotModel robot = test::rokae();
  for (const uint64_t seed : {2, 4}) {
    const Diagnosis d = run(scenario_of(scaled_truth("coupling", robot, 0.5), seed, 5));
    ASSERT_FALSE(d.candidates.empty());
    EXPECT_GT(d.candidates[0].p_adjusted, 0.005) << seed;
    EXPECT_EQ(d.verdict, "missing_effect") << seed << ": " << d.summary;
    EXPECT_EQ(named(d), "coupling") << seed;
  }
}

// Complementary (geometric) stiffness at 15-35 N is ~1 um, below the noise: the honest answer
// is `adequate`, never a claim.
TEST(DiagnoseHonesty, ComplementaryBelowNoiseIsAdequate) {
  for (int seed = 1; seed <= 3; ++seed) {
    const Diagnosis d = run(make_scenario("complementary", seed));
    print("complementary", seed, d);
    EXPECT_FALSE(claimed(d));
  }
}

// A common force scale error is exactly a compliance scale: not identifiable from
// displacements. Not claimed; force_frame's common-scale direction is reported unidentifiable.
TEST(DiagnoseHonesty, CommonForceScaleIsUnidentifiable) {
  const RobotModel robot = test::rokae();
  DeflectionModel m(robot, {"joint", "force_frame"});
  Truth t;
  t.effects = {"joint", "force_frame"};
  t.theta = m.null_parameters();
  t.theta.head(6) = test::paper_stiffness().cwiseInverse();
  for (int k = 3; k < 6; ++k) t.theta(m.offset(1) + k) = 0.03;
  const Dataset calib = simulate(robot, t, test::design60(11), realistic_noise(11));
  const Dataset valid = simulate(robot, t, test::design60(12, 40), realistic_noise(12));
  const Diagnosis d = diagnose(robot, calib, &valid, {"joint"});
  print("force common scale", 11, d);
  EXPECT_FALSE(claimed(d));
  for (const auto& c : d.candidates)
    if (c.effect == "force_frame") {
      EXPECT_FALSE(c.identifiable);
      // The common gain of the flange sensor and that of a base-fixed load are both exactly
      // a compliance scale: two directions the displacements cannot see.
      EXPECT_EQ(c.df, c.parameters - 2) << c.reason;
    }
}

// The hidden effect is left out of the candidate list: no confident wrong claim.
TEST(DiagnoseHonesty, SlowLeftOutEffectIsUnexplainedNotMisattributed) {
  for (const std::string hidden : {"nonlinear_joint", "point_offset", "force_frame", "backlash"})
    for (int seed = 1; seed <= 2; ++seed) {
      DiagnosisOptions o;
      for (const auto& n : effect_names())
        if (n != hidden && n != "joint") o.candidates.push_back(n);
      const Diagnosis d = run(make_scenario(hidden, seed), o);
      print("left out " + hidden, seed, d);
      // A small preloaded gap is an asymmetric compliance (stiffer in one load direction):
      // nonlinear_joint's secant about the gravity preload (softer on one side of it) is its
      // smooth relative, and at 0.5 arcmin the two can fit the data equally
      // (docs/diagnosis.md, limits).
      // And the other way round: a soft zone about the torque reversal with its knee well below
      // the load torques is what a preloaded gap looks like; named so, the model predicts the
      // new poses within the 1.25 times the floor a right model reaches.
      if (hidden == "backlash" && d.verdict == "missing_effect") {
        EXPECT_EQ(named(d), "nonlinear_joint") << d.summary;
        continue;
      }
      if (hidden == "nonlinear_joint" && d.verdict == "missing_effect") {
        EXPECT_EQ(named(d), "backlash") << d.summary;
        ASSERT_TRUE(d.after_valid);
        EXPECT_LE(validation_ratio(d), 1.25) << d.summary;
        continue;
      }
      EXPECT_TRUE(d.verdict == "unexplained" || d.verdict == "ambiguous") << d.summary;
      if (d.verdict == "unexplained") {
        EXPECT_FALSE(d.unexplained_signature.empty());
      }
    }
}

/// The joint-only virtual robot's scenario of `seed` with `alter` applied to both data sets (an
/// effect outside the library added by hand), its noise statement removed unless `stated`.
Scenario altered_scenario(const std::function<void(Dataset&)>& alter, uint64_t seed, bool stated) {
  Scenario s = make_scenario("joint", seed);
  alter(s.calib);
  alter(s.valid);
  if (!stated) {
    hide_noise(s.calib);
    hide_noise(s.valid);
  }
  return s;
}

/// Claims (`missing_effect` or `adequate`) in `seeds` seeds of the virtual robot's joints-only
/// scenario, the noise stated or not, with `alter` putting an effect outside the library into
/// both sessions' data; an `unexplained` verdict must say what the residual follows.
int claims_outside_library(const char* what,
                           const std::function<void(Dataset&)>& alter,
                           bool stated = true,
                           int seeds = 4) {
  int claims = 0;
  for (uint64_t seed = 1; seed <= static_cast<uint64_t>(seeds); ++seed) {
    const Diagnosis d = run(altered_scenario(alter, seed, stated));
    print(what, seed, d);
    claims += d.verdict == "missing_effect" || d.verdict == "adequate";
    if (d.verdict == "unexplained") {
      EXPECT_FALSE(d.unexplained_signature.empty());
    }
  }
  return claims;
}

// An effect outside the library, added to the virtual robot's data by hand: the pedestal tilts
// about the base x and y axes under the load's moment about the base (6e4 and 9e4 N*m/rad, a
// stand that is not grouted). With the noise stated, the chain that mimics it on the
// calibration poses (link, then a force-frame rotation) fits them within the noise allowance
// but predicts the validation poses 1.3 times the floor: the validation rows' own chi-square
// refutes it where, pooled with that fit, they passed (claimed in 3 of these 4 seeds). Where the
// chain predicts the new poses within 1.12 times the floor (one seed) the residual still turns
// with the base moment (the `base_tilt` trend test): claimed in none of the seeds, where that
// seed was claimed before the test (and 2 of the 8 without a statement). A stiffer pedestal:
// AStiffPedestalIsNotNamedLink.
void tilt_pedestal(Dataset& data, double stiffness_x = 6.0e4) {
  const RobotModel robot = test::rokae();
  const Eigen::Vector3d c(1.0 / stiffness_x, 1.0 / (1.5 * stiffness_x), 0.0);
  for (auto& m : data.rows) {
    const ChainState chain = robot.chain(m.q);
    const Eigen::Vector3d load = robot.point_position(chain, robot.load_point);
    const Eigen::Vector3d point = robot.point_position(chain, robot.measured_point);
    const Eigen::Vector3d moment = load.cross(m.force) + m.moment;  // about the base origin
    m.displacement += c.cwiseProduct(moment).cross(point);
  }
}

TEST(DiagnoseHonesty, SlowPedestalTiltIsNotClaimed) {
  const auto tilt = [](Dataset& d) { tilt_pedestal(d); };
  EXPECT_EQ(claims_outside_library("pedestal tilt", tilt), 0);
  // Without a statement, link then a force-frame step: the second step's gain on the new
  // poses is no more than chance in most seeds, so the chain is not confirmed (claimed in 6
  // of these 8 seeds before a later step had to lower the validation error significantly).
  EXPECT_EQ(claims_outside_library("pedestal tilt, noise unknown", tilt, false, 8), 0);
}

// A pedestal three times stiffer (2e5 and 3e5 N*m/rad) turns the arm about horizontal axes by
// little more than the noise, much as a spring in the upper arm does: `link` explains the
// misfit and its model predicts the new poses near the floor, and it was named. The `base_tilt`
// mechanism explains link's evidence away as well (link's partial F test given it is not
// significant), so the data cannot tell them apart: `ambiguous` with link alone and
// `outside_rival` base_tilt, or `unexplained` where the tilt's trend is left after link; never
// `missing_effect`.
TEST(DiagnoseHonesty, AStiffPedestalIsNotNamedLink) {
  const auto tilt = [](Dataset& d) { tilt_pedestal(d, 2.0e5); };
  for (uint64_t seed = 1; seed <= 4; ++seed) {
    const Diagnosis d = run(altered_scenario(tilt, seed, true));
    print("stiff pedestal", seed, d);
    EXPECT_NE(d.verdict, "missing_effect") << d.summary;
    EXPECT_NE(d.verdict, "adequate") << d.summary;
    if (d.verdict == "ambiguous" && d.ambiguous_group == std::vector<std::string>{"link"}) {
      EXPECT_EQ(d.outside_rival, "base_tilt") << d.summary;
      EXPECT_NE(diagnosis_to_json(d).find("\"outside_rival\": \"base_tilt\""), std::string::npos);
    }
  }
}

// The model that mimics the tilt, diagnosed on its own (no loop): no candidate is left
// significant and it predicts the new poses as well as it fits, but its residual still turns
// with the base moment, a strong trend that no candidate explains: `unexplained`, naming it,
// with the noise stated or not (it was `adequate` before the single model's verdict looked at
// the trends).
TEST(DiagnoseHonesty, TheModelThatMimicsAPedestalTiltIsNotAdequate) {
  const std::vector<std::string> mimic = {"joint", "link", "force_frame"};
  int adequate = 0, named = 0;
  for (const bool stated : {true, false})
    for (uint64_t seed = 1; seed <= 4; ++seed) {
      const Diagnosis d =
          run(altered_scenario([](Dataset& x) { tilt_pedestal(x); }, seed, stated), {}, mimic);
      print(stated ? "pedestal, mimic" : "pedestal, mimic, noise unknown", seed, d);
      adequate += d.verdict == "adequate";
      named +=
          d.verdict == "unexplained" && d.summary.find("turning as a whole") != std::string::npos;
    }
  EXPECT_EQ(adequate, 0);
  EXPECT_GE(named, 6);
}

// Cross-talk between a force sensor's axes (the symmetric off-diagonal part of its calibration
// matrix, 5-7 %, within a data sheet's allowance), put into the virtual robot's force readings
// by hand: force_frame's cross-talk terms represent it, so the diagnosis names force_frame,
// with the noise stated and without, and the validation error after it falls to within 1.25
// times the floor. Before the library had them, these runs were `unexplained` or `ambiguous`
// (the tool compliance and the point offset take up part of it on the calibration poses).
TEST(DiagnoseForceFrame, SlowSensorCrosstalkIsFound) {
  const RobotModel robot = test::rokae();
  Eigen::Matrix3d x;
  x << 0, 0.06, -0.05, 0.06, 0, 0.07, -0.05, 0.07, 0;
  auto crosstalk = [&](Dataset& data) {
    for (auto& m : data.rows) {
      const Eigen::Matrix3d r = robot.chain(m.q).flange.block<3, 3>(0, 0);
      m.force -= r * x * r.transpose() * m.force;  // the sensor reads (I + R X R^T)^-1 F
    }
  };
  for (uint64_t seed = 1; seed <= 3; ++seed) {
    double floor = 0;  // the stated noise's floor on the validation rows (the same draw)
    for (const bool stated : {true, false}) {
      const Diagnosis d = run(altered_scenario(crosstalk, seed, stated));
      print(stated ? "sensor crosstalk" : "crosstalk, no statement", seed, d);
      EXPECT_TRUE(found(d, "force_frame")) << d.summary;
      ASSERT_TRUE(d.after_valid);
      if (stated) floor = d.after.validation_floor_m;
      EXPECT_LE(d.after.validation_rms_m, 1.25 * floor) << d.summary;
    }
  }
}

/// Per joint, the motion of the measured point when that joint turns by one radian (base
/// frame, 3 x n) and the load torque J(L)^T W of the row (n): what an effect outside the library
/// made of joint deflections needs.
std::pair<Eigen::Matrix3Xd, Eigen::VectorXd> joint_motion_and_torque(const RobotModel& robot,
                                                                     const Measurement& m) {
  const ChainState chain = robot.chain(m.q);
  const Matrix6X<double> jm =
      robot.jacobian_at(chain, robot.point_position(chain, robot.measured_point));
  const Matrix6X<double> jl =
      robot.jacobian_at(chain, robot.point_position(chain, robot.load_point));
  Eigen::Matrix<double, 6, 1> w;
  w << m.force, m.moment;
  return {jm.topRows<3>(), jl.transpose() * w};
}

// A joint whose compliance varies with another joint's angle, the form the library does not
// have (the development data's outside type is joint 2 with q3): the wrist's joint 5 with q4
// and the forearm's joint 3 with q2, the compliance c_j + a c_j cos(q_k + 0.5) with a = 2.5
// and 0.5 (the joint model's fit 1.3-1.8 times the floor). Coupling, the gravity compensator,
// link compliance or backlash take part of it up on the calibration poses; what they leave
// follows the joint's deflection times the angles' harmonics (the pose_compliance trend tests),
// so nothing is claimed but in runs close to the floor: one of twenty, the joint-3 law named
// without a statement (two, named nonlinear_joint or the compensator at 1.14-1.3 times the
// floor, before a pose-dependent group that takes up more than the candidate became its rival,
// docs/diagnosis.md section 3, rule 3).
TEST(DiagnoseHonesty, SlowAJointCompliancePoseDependentIsNotClaimed) {
  const RobotModel robot = test::rokae();
  const Eigen::VectorXd c = test::paper_stiffness().cwiseInverse();
  int claims = 0;
  for (const auto& [j, k, a] : {std::tuple{4, 3, 2.5}, std::tuple{2, 1, 0.5}}) {
    auto vary = [&, j = j, k = k, a = a](Dataset& data) {
      for (auto& m : data.rows) {
        const auto [motion, tau] = joint_motion_and_torque(robot, m);
        m.displacement += motion.col(j) * (a * c(j) * std::cos(m.q(k) + 0.5) * tau(j));
      }
    };
    const std::string what = "joint " + std::to_string(j + 1) + " by q" + std::to_string(k + 1);
    claims += claims_outside_library(what.c_str(), vary);
    claims += claims_outside_library((what + ", no statement").c_str(), vary, false, 6);
  }
  EXPECT_LE(claims, 2);  // of 20 runs, the 90 % without a claim asked of such effects (8 claims
                         // before the pose_compliance trend tests)
}

// The arm's response to the load growing over each session, by a quarter from its first reading
// to its last (the reducers softening as they warm up, or a force sensor's gain drifting). The
// joint model fits the mean; the rest scales with the deflection and the time, which no
// candidate has (drift is a translation), so the diagnosis names no effect (without the
// load_response_drift trend test one seed of six without a statement was called adequate).
TEST(DiagnoseHonesty, SlowALoadResponseThatDriftsIsNotClaimed) {
  const RobotModel robot = test::rokae();
  const Eigen::VectorXd c = test::paper_stiffness().cwiseInverse();
  auto warm = [&](Dataset& data) {
    const double n = static_cast<double>(data.rows.size());
    for (size_t i = 0; i < data.rows.size(); ++i) {
      auto& m = data.rows[i];
      const auto [motion, tau] = joint_motion_and_torque(robot, m);
      m.displacement += 0.25 * (static_cast<double>(i) / n) * (motion * c.cwiseProduct(tau));
    }
  };
  EXPECT_EQ(claims_outside_library("load response drifting", warm), 0);
  EXPECT_EQ(claims_outside_library("load response drifting, no statement", warm, false, 6), 0);
}

// The arm on a compliant base plate: it shifts as a whole under the load's force, by a
// compliance fixed in the base frame (softer sideways than down, 1-3 um/N). A tool compliance
// turns with the flange and takes only part of it up; what it leaves follows the force in the
// base frame (the base_shift trend test), so no effect is claimed.
TEST(DiagnoseHonesty, SlowBaseShiftIsNotClaimed) {
  Eigen::Matrix3d cb;
  cb << 2.2, 0.3, 0.0, 0.3, 1.6, 0.1, 0.0, 0.1, 1.1;
  cb *= 1e-6;  // m/N
  auto shift = [&](Dataset& data) {
    for (auto& m : data.rows) m.displacement += cb * m.force;
  };
  EXPECT_EQ(claims_outside_library("base shift", shift), 0);
  EXPECT_EQ(claims_outside_library("base shift, no statement", shift, false, 6), 0);
}

// A force sensor whose gain changes with the load's level (its non-linearity): it reads
// F (1 + g), g = k (|F| / F0 - 1) about the data's mean level F0, so the arm's response is not
// in proportion to the force written; alike at every joint, which no joint's law has. A
// reducer law (nonlinear_joint) or a gap (backlash) takes part of it up on the calibration
// poses; what they leave follows the response scaled by the level (the load_response_level
// trend test), so nothing is claimed (3 of these 20 runs were, without it: `adequate` or
// nonlinear_joint, without a noise statement, at k = 0.4).
TEST(DiagnoseHonesty, SlowAForceSensorNonLinearityIsNotClaimed) {
  int claims = 0;
  for (const double k : {0.4, 0.8}) {
    auto read = [k](Dataset& data) {
      double f0 = 0;
      for (const auto& m : data.rows) f0 += m.force.norm();
      f0 /= static_cast<double>(data.rows.size());
      for (auto& m : data.rows) m.force *= 1.0 + k * (m.force.norm() / f0 - 1.0);
    };
    claims += claims_outside_library("sensor non-linearity", read);
    claims += claims_outside_library("sensor non-linearity, no statement", read, false, 6);
  }
  EXPECT_EQ(claims, 0);
}

// A zero offset of the force reading (a sensor not tared, its zero drifted; a load cell's bias
// under a fixture): the force written is the arm's plus a constant, 3-4 N in the base frame. The
// arm's response to that constant changes with the pose; drift and backlash take part of it up
// on independent data, and what they leave follows the model's response to a constant force
// error (the sensor_offset trend test, each row's own residual variance). Those models,
// diagnosed on their own without a statement, were called `adequate` or claimed a further step
// in 3 of these 12 runs without the test, in 1 with it; the whole loop claims nothing either way.
TEST(DiagnoseHonesty, SlowAZeroOffsetOfTheForceReadingIsNotClaimed) {
  const Eigen::Vector3d b(-2.5, 1.0, 3.0);
  auto read = [&](Dataset& data) {
    for (auto& m : data.rows) m.force += b;
  };
  int claims = claims_outside_library("base offset, no statement", read, false, 6);
  for (const auto& mimic : {std::vector<std::string>{"joint", "drift", "backlash"},
                            std::vector<std::string>{"joint", "backlash"}})
    for (uint64_t seed = 1; seed <= 6; ++seed) {
      const Diagnosis d = run(altered_scenario(read, seed, false), {}, mimic);
      print("base offset, mimic", seed, d);
      claims += d.verdict == "missing_effect" || d.verdict == "adequate";
    }
  EXPECT_LE(claims, 1);
}

// The same in a flange sensor's frame (a constant force error that turns with the flange),
// without a noise statement. At 2.7 N nothing is claimed on 6 seeds. At 2.1 N the joint
// model's score test finds a force-frame error on seed 3 (p_adj 0.006) that the validation
// poses refute, and what is left follows a trend of a mechanism outside the library (joint 2's
// compliance varying with the pose) at alpha > p_adj > alpha/10: two pieces of evidence that
// the residual is not noise, neither of them a library effect, so `unexplained` (it was
// `adequate`, a trend at that level being left to chance on its own). Smaller offsets on other
// seeds stay `adequate`: within what 60 poses tell from the force reading's own noise.
TEST(DiagnoseHonesty, SlowAFlangeSensorsZeroOffsetIsNotCalledAdequate) {
  const RobotModel robot = test::rokae();
  const Eigen::Vector3d along = Eigen::Vector3d(1.0, -0.5, -0.33).normalized();
  Eigen::Vector3d f0 = 2.7 * along;
  auto read = [&](Dataset& data) {
    for (auto& m : data.rows) m.force += robot.chain(m.q).flange.topLeftCorner<3, 3>() * f0;
  };
  EXPECT_EQ(claims_outside_library("flange offset, no statement", read, false, 6), 0);
  f0 = 2.1 * along;
  const Diagnosis d = run(altered_scenario(read, 3, false));
  print("flange offset 2.1 N", 3, d);
  EXPECT_EQ(d.verdict, "unexplained") << d.summary;
  EXPECT_FALSE(d.unexplained_signature.empty());
}

// The nonlinear reducer in the forms the library's example does not use: hardening about the
// unloaded state (the compliance of joints 2 and 3 falls by half of c per 100 N*m of load
// torque), softening about the gravity preload (a stiff zone, e = -0.4 c), hardening with the
// cube of the total torque (h = -0.5 c), a bilinear curve, 30 % softer on one side of the
// torque reversal than on the other (r = +-0.3 c), hardening with the cube of the load
// torque (g = -3 c: the compliance change g tau^2 / T0^2 is about a tenth of g at the load
// torques of a few tens of N*m; at -0.5 c it stays within the noise) and a curve 30 % softer one
// way of the load than the other (k = +-0.3 c). Found as `nonlinear_joint` (or in its group), the
// fit keeps the terms that carry the truth, and the validation error after it sits within 1.25x the
// floor (as the hidden-effect sweep asks).
TEST(DiagnoseNonlinearJoint, SlowLoadCentredHardeningAndSofteningAreFound) {
  const Eigen::VectorXd c = test::paper_stiffness().cwiseInverse();
  struct Form {
    const char* what;
    std::vector<std::pair<std::string, double>> values;
  };
  const std::vector<Form> forms = {
      {"load-centred hardening", {{"s2", -0.5 * c(1)}, {"s3", -0.5 * c(2)}}},
      {"softening about the preload", {{"e2", -0.4 * c(1)}, {"e3", -0.4 * c(2)}}},
      {"hardening with the total torque", {{"h2", -0.5 * c(1)}, {"h3", -0.5 * c(2)}}},
      {"a kink at the torque reversal", {{"r2", 0.3 * c(1)}, {"r3", -0.3 * c(2)}}},
      {"hardening with the cube of the load torque", {{"g2", -3.0 * c(1)}, {"g3", -3.0 * c(2)}}},
      {"a kink at the unloaded state", {{"k2", 0.3 * c(1)}, {"k3", -0.3 * c(2)}}}};
  for (const auto& form : forms)
    for (uint64_t seed = 1; seed <= 2; ++seed) {
      const Diagnosis d = run(scenario_of(joint_and("nonlinear_joint", form.values), seed, 1));
      print(form.what, seed, d);
      ASSERT_TRUE(found(d, "nonlinear_joint")) << form.what << ": " << d.summary;
      ASSERT_TRUE(d.after_valid);
      EXPECT_LE(validation_ratio(d), 1.25) << form.what;
      // The fit of the suggested model keeps a term of the truth, and a kept term has the
      // truth's sign (hardening is not taken for softening): the criterion keeps a term only
      // when it is more than sqrt(ln 3N) ~ 2.3 standard errors from zero. A term whose effect
      // stays near the noise may be left out.
      if (d.verdict != "missing_effect") continue;
      int kept = 0;
      for (const auto& [name, value] : form.values) {
        const auto& names = d.after.parameter_names;
        const auto it = std::find(names.begin(), names.end(), "nonlinear_joint." + name);
        ASSERT_NE(it, names.end());
        const double fitted = d.after.parameter_values[it - names.begin()];
        if (fitted == 0.0) continue;
        ++kept;
        EXPECT_GT(fitted * value, 0.0) << form.what << " " << name;
      }
      EXPECT_GE(kept, 1) << form.what;
    }
}

/// Diagnoses the joints and `effect` with one parameter set (the effect's others at their
/// null), expects the effect found and the model with it within 1.25x the validation floor.
Diagnosis expect_found(const std::string& effect,
                       const std::string& parameter,
                       double value,
                       uint64_t seed,
                       uint64_t stream) {
  const Diagnosis d = run(scenario_of(joint_and(effect, {{parameter, value}}), seed, stream));
  print(effect + " " + parameter, seed, d);
  EXPECT_TRUE(found(d, effect)) << parameter << ": " << d.summary;
  EXPECT_TRUE(d.after_valid) << parameter;
  if (d.after_valid) {
    EXPECT_LE(validation_ratio(d), 1.25) << parameter;
  }
  return d;
}

// Coupling between joints that are not neighbours (a tendon or belt running past joint 3
// couples 2 with 4; a coupled wrist couples 3 with 5 through its transmission): found as
// `coupling` (or in its group), the fit keeps the true pair among its fifteen optional pairs,
// with the truth's sign, and the validation error after it sits within 1.25x the floor.
TEST(DiagnoseCoupling, PairsThatAreNotNeighboursAreFound) {
  const Eigen::VectorXd c = test::paper_stiffness().cwiseInverse();
  const std::vector<std::pair<std::string, double>> forms = {
      {"c24", 0.5 * std::sqrt(c(1) * c(3))}, {"c35", -0.5 * std::sqrt(c(2) * c(4))}};
  for (const auto& [pair, value] : forms)
    for (uint64_t seed = 1; seed <= 2; ++seed) {
      const Diagnosis d = expect_found("coupling", pair, value, seed, 2);
      if (!d.after_valid) continue;
      const auto& names = d.after.parameter_names;
      const auto it = std::find(names.begin(), names.end(), "coupling." + pair);
      ASSERT_NE(it, names.end());
      EXPECT_GT(d.after.parameter_values[it - names.begin()] * value, 0.0) << pair;
      // A pair whose truth is 0 stays with probability ~2 % each (docs/identifiability.md).
      int others = 0;
      for (size_t k = 0; k < names.size(); ++k)
        others += names[k].rfind("coupling.", 0) == 0 && names[k] != "coupling." + pair &&
                  d.after.parameter_values[k] != 0.0;
      EXPECT_LE(others, 1) << pair;
    }
}

// A link compliance outside the upper arm and forearm is the same physical class, and the
// model that adds `link` predicts the new poses as a right model does. The column (link 1,
// three times as stiff as joint 1, like the example's arm links) tilts the arm out of its plane
// about nearly the axes of the upper arm's two springs: the fit may keep either. A wrist link
// deflects the flange as a series compliance would: at this noise it is visible only when
// softer than its joint, and then `link` and `tool_compliance` explain the same residual
// (found: named or in the ambiguous group).
TEST(DiagnoseLink, SpringsOfTheColumnAndTheWristAreFound) {
  const Eigen::VectorXd k = test::paper_stiffness();
  const std::vector<std::pair<std::string, double>> springs = {{"c_link1_x", 1.0 / (3 * k(0))},
                                                               {"c_link5_x", 2.0 / k(4)}};
  for (const auto& [spring, value] : springs)
    for (uint64_t seed = 1; seed <= 2; ++seed) expect_found("link", spring, value, seed, 4);
}

// A spring in the wrist (link 4, about its x axis) moves the measured point much as a compliant
// tool does: on 60 calibration poses the two explain each other's evidence away (ambiguity
// group link + tool_compliance). At three times the wrist joint's compliance the 40 validation
// poses tell them apart: with link they are predicted significantly better (F test at alpha),
// so the verdict names link. At twice it they do not, the verdict stays `ambiguous`, and the
// loop still takes the group's step the validation poses confirm: the final model predicts the
// new poses at the floor, within three standard deviations of an RMS over 3 x 40 components
// (1 + 3 / sqrt(240) = 1.19).
TEST(DiagnoseLink, AWristSpringToolComplianceCannotMimicOnNewPosesIsNamed) {
  const double c5 = 1.0 / test::paper_stiffness()(4);
  DiagnosisOptions o;
  o.auto_loop = true;
  for (uint64_t seed = 1; seed <= 4; ++seed) {
    const Diagnosis d = run(scenario_of(joint_and("link", {{"c_link4_x", 3 * c5}}), seed, 78), o);
    print("link c_link4_x x3", seed, d);
    EXPECT_EQ(d.verdict, "missing_effect") << d.summary;
    EXPECT_EQ(named(d), "link") << d.summary;
  }
  for (uint64_t seed = 1; seed <= 4; ++seed) {
    const Diagnosis d = run(scenario_of(joint_and("link", {{"c_link4_x", 2 * c5}}), seed, 78), o);
    print("link c_link4_x x2", seed, d);
    EXPECT_TRUE(found(d, "link")) << d.summary;
    ASSERT_GE(d.steps.size(), 2u) << d.summary;
    const ModelQuality& end = d.steps.back().quality;
    EXPECT_TRUE(end.model == "joint+link" || end.model == "joint+tool_compliance") << end.model;
    EXPECT_LT(end.validation_rms_m, d.fit.validation_rms_m);
    EXPECT_LE(end.validation_rms_m / end.validation_floor_m, 1.19);
  }
}

// A spring part-way along the forearm (60 % of the way from the elbow to the wrist centre),
// bending it in the arm's plane (about joint 3's direction, as stiff as joint 3) and across it
// (twice as stiff), put into the virtual robot's data by its own statics: the arm beyond turns
// about the spring's point by c u . M, M the load's moment about that point. No root spring
// has this form (the in-plane spring turns about a point off joint 3's axis). `link`'s bending
// terms do: named link (or ambiguous with it), with the noise stated and without, and the final
// model predicts the new poses within three standard deviations of an RMS over 3 x 40
// components of the floor (1.19); here at most 1.16. With the root springs alone the loop went
// on to a point offset that is not there in 4 of the 6 runs (up to 1.22 times the floor), and
// one run without a statement ended with a nonlinear joint and a tool compliance before link.
constexpr double kSoftness = 3.0;  // the spring's compliance over joint 3's
void bend_forearm(Dataset& data) {
  const RobotModel robot = test::rokae();
  const double k3 = test::paper_stiffness()(2);
  for (auto& m : data.rows) {
    const ChainState chain = robot.chain(m.q);
    const Eigen::Vector3d root = chain.origin.col(2), end = chain.origin.col(3);
    const Eigen::Vector3d o = root + 0.6 * (end - root);
    const Eigen::Vector3d along = (end - root).normalized();
    const Eigen::Vector3d in_plane = chain.axis.col(2);
    const Eigen::Vector3d across = along.cross(in_plane).normalized();
    const Eigen::Vector3d load = robot.point_position(chain, robot.load_point);
    const Eigen::Vector3d point = robot.point_position(chain, robot.measured_point);
    const Eigen::Vector3d moment = (load - o).cross(m.force) + m.moment;
    const Eigen::Vector3d turn =
        (in_plane * in_plane.dot(moment) + across * across.dot(moment)) * (kSoftness / k3);
    m.displacement += turn.cross(point - o);
  }
}

TEST(DiagnoseLink, SlowASpringPartWayAlongTheForearmIsFound) {
  DiagnosisOptions o;
  o.auto_loop = true;
  for (const bool stated : {true, false})
    for (uint64_t seed = 1; seed <= 3; ++seed) {
      const Diagnosis d = run(altered_scenario(bend_forearm, seed, stated), o);
      print(stated ? "forearm spring" : "forearm spring, noise unknown", seed, d);
      EXPECT_TRUE(found(d, "link")) << d.summary;
      EXPECT_TRUE(d.verdict == "missing_effect" || d.verdict == "ambiguous") << d.summary;
      ASSERT_GE(d.steps.size(), 2u) << d.summary;
      const ModelQuality& end = d.steps.back().quality;
      EXPECT_EQ(end.model, "joint+link") << d.summary;
      if (stated) {
        EXPECT_LE(end.validation_rms_m / end.validation_floor_m, 1.19) << d.summary;
      }
    }
}

// An effect at half the example's size, often strongly significant in the calibration but
// small against the prediction variance of its parameters on 40 new poses. When the validation
// poses neither confirm nor refute it, the verdict names it (`ambiguous` with it) instead of
// `unexplained` ("not in the candidate list"), which would send the user looking outside the
// library for an effect the library has. `unexplained` stays for validation errors that rise
// significantly (paired test at alpha = 5 %): at most one seed in twelve per effect; a claim
// names the truth.
TEST(DiagnoseHonesty, SlowSmallEffectIsNotCalledUnexplained) {
  const RobotModel robot = test::rokae();
  for (const std::string hidden : {"nonlinear_joint", "coupling", "point_offset", "link"}) {
    int unexplained = 0;
    for (uint64_t seed = 1; seed <= 12; ++seed) {
      const Diagnosis d = run(scenario_of(scaled_truth(hidden, robot, 0.5), seed, 3));
      print("half " + hidden, seed, d);
      unexplained += d.verdict == "unexplained";
      if (claimed(d)) {
        EXPECT_TRUE(found(d, hidden)) << hidden << ": " << d.summary;
      }
    }
    EXPECT_LE(unexplained, 1) << hidden;
  }
}

// Two hidden effects: the loop finds both (in either order) and ends adequate, the validation
// error falling at every step.
TEST(DiagnoseAuto, FindsTwoEffectsInSequence) {
  const RobotModel robot = test::rokae();
  DeflectionModel m(robot, {"joint", "point_offset", "force_frame"});
  Truth t;
  t.effects = {"joint", "point_offset", "force_frame"};
  t.theta = m.null_parameters();
  t.theta.head(6) = test::paper_stiffness().cwiseInverse();
  t.theta(m.offset(1) + 0) = 0.03;   // meas_x
  t.theta(m.offset(1) + 3) = 0.03;   // load_x
  t.theta(m.offset(1) + 4) = -0.02;  // load_y
  t.theta(m.offset(2) + 2) = 0.087;  // 5 deg clocking
  const Dataset calib = simulate(robot, t, test::design60(21), realistic_noise(21));
  const Dataset valid = simulate(robot, t, test::design60(22, 40), realistic_noise(22));
  DiagnosisOptions o;
  o.auto_loop = true;
  const Diagnosis d = diagnose(robot, calib, &valid, {"joint"}, o);
  for (const auto& s : d.steps)
    std::printf("  step %d +%-14s %-15s fit %.1f um, validation %.1f um (floor %.1f um)\n", s.step,
                s.added.c_str(), s.verdict.c_str(), s.quality.fit_rms_m * 1e6,
                s.quality.validation_rms_m * 1e6, s.quality.validation_floor_m * 1e6);
  ASSERT_EQ(d.steps.size(), 3u);
  std::set<std::string> added = {d.steps[1].added, d.steps[2].added};
  EXPECT_EQ(added, (std::set<std::string>{"point_offset", "force_frame"}));
  EXPECT_EQ(d.final_verdict, "adequate");
  EXPECT_EQ(d.final_model, "joint+" + d.steps[1].added + "+" + d.steps[2].added);
  for (size_t i = 1; i < d.steps.size(); ++i)
    EXPECT_LT(d.steps[i].quality.validation_rms_m, d.steps[i - 1].quality.validation_rms_m);
  EXPECT_LT(d.steps.back().quality.validation_rms_m,
            1.25 * d.steps.back().quality.validation_floor_m);
  // Re-running with the suggested model: the error has fallen and nothing more is missing.
  const Diagnosis again = diagnose(robot, calib, &valid, parse_model_string(d.final_model));
  EXPECT_EQ(again.verdict, "adequate");
}

/// The example values of `effects` in both sessions, and a force sensor clocked by 1.7 degrees
/// in the calibration session only (remounted true for the validation session).
std::pair<Truth, Truth> clocked_in_calibration_only(std::vector<std::string> effects) {
  const RobotModel robot = test::rokae();
  effects.push_back("force_frame");
  Truth calib = examples_of(robot, effects);
  const DeflectionModel m(robot, effects);
  const int f = static_cast<int>(effects.size()) - 1, at = m.offset(f);
  const int size = m.effects()[f]->size();
  calib.theta(at + 2) = 0.03;  // 1.7 deg clocking
  Truth valid = calib;
  valid.theta.segment(at, size) = m.null_parameters().segment(at, size);
  return {calib, valid};
}

/// `--auto` from the joints alone on 60 calibration poses of one truth and 40 validation poses
/// of the other; `stream` selects independent designs and noise for the same seed.
Diagnosis auto_loop(const Truth& calib_truth,
                    const Truth& valid_truth,
                    uint64_t seed,
                    uint64_t stream) {
  const RobotModel robot = test::rokae();
  const Dataset calib =
      simulate(robot, calib_truth, test::design60(seed, 60), realistic_noise(300 * stream + seed));
  const Dataset valid = simulate(robot, valid_truth, test::design60(500 + 200 * stream + seed, 40),
                                 realistic_noise(900 + 200 * stream + seed));
  DiagnosisOptions o;
  o.auto_loop = true;
  return diagnose(robot, calib, &valid, {"joint"}, o);
}

// A force sensor clocked by 1.7 degrees in the calibration session and remounted true for the
// validation session, on a robot with link compliance (both sessions): after link, the
// force-frame candidate is significant on the calibration poses and predicts the validation
// poses worse. Such a candidate neither confirms nor refutes the step the validation poses
// confirmed: the verdict names link, never `unexplained`, and `--auto` keeps link in the final
// model with the validation error lower. (Without that rule the first seed already ended
// `unexplained` with the model `joint`.) With the noise stated and link's model at the floor,
// the candidate the validation poses do not confirm is calibration noise taken up: link is
// named `missing_effect` (before that rule 3 of 4 seeds left it `ambiguous`), or `ambiguous`
// with link alone because a pedestal tilt explains its evidence as well (the example's
// upper-arm springs turn the arm about horizontal axes much as a tilting pedestal does; 3 of
// the 4 seeds), never because of the refuted candidate.
TEST(DiagnoseAuto, ACandidateTheValidationRefutesDoesNotUndoAConfirmedStep) {
  const auto [calib_truth, valid_truth] = clocked_in_calibration_only({"joint", "link"});
  int kept = 0, claimed = 0;
  for (uint64_t seed = 1; seed <= 4; ++seed) {
    const Diagnosis d = auto_loop(calib_truth, valid_truth, seed, 0);
    print("link, force frame in calibration only", seed, d);
    kept += found(d, "link");
    claimed += (d.verdict == "missing_effect" && named(d) == "link") ||
               (d.verdict == "ambiguous" && d.outside_rival == "base_tilt" &&
                d.ambiguous_group == std::vector<std::string>{"link"});
    EXPECT_NE(d.verdict, "unexplained") << d.summary;
    EXPECT_NE(d.final_model.find("link"), std::string::npos) << d.final_model;
    ASSERT_GE(d.steps.size(), 2u);
    EXPECT_LT(d.steps[1].quality.validation_rms_m, d.steps[0].quality.validation_rms_m);
  }
  EXPECT_EQ(kept, 4);
  EXPECT_GE(claimed, 3);
}

// The same one level deeper: an SMR offset and link compliance in both sessions, the force
// sensor clocked in the calibration session only. The chain offset, then link (or the reverse)
// is confirmed step by step; the force-frame candidate left after both is refuted by the
// validation poses. That marginal evidence beyond two confirmed steps does not make the first
// step `unexplained` (the model with one effect is far above the floor, but that misfit is the
// second effect's): the loop goes on to both, the validation error falling at each step.
// The same holds when the refuted candidate is the top right after the offset: link, the next
// candidate, leads (its step confirmed, only that marginal evidence beyond it). Before these
// rules all four seeds stopped at `unexplained` with the model `joint`.
TEST(DiagnoseAuto, SlowARefutedCandidateAfterTwoConfirmedStepsLeavesBoth) {
  const auto [calib_truth, valid_truth] =
      clocked_in_calibration_only({"joint", "point_offset", "link"});
  int both = 0;
  for (uint64_t seed = 1; seed <= 4; ++seed) {
    const Diagnosis d = auto_loop(calib_truth, valid_truth, seed, 1);
    print("offset, link, force frame in calibration only", seed, d);
    std::printf("  final model %s (%s)\n", d.final_model.c_str(), d.final_verdict.c_str());
    EXPECT_NE(d.verdict, "unexplained") << d.summary;
    both += d.final_model.find("point_offset") != std::string::npos &&
            d.final_model.find("link") != std::string::npos;
    for (size_t k = 1; k < d.steps.size(); ++k)
      EXPECT_LT(d.steps[k].quality.validation_rms_m, d.steps[k - 1].quality.validation_rms_m)
          << "step " << k;
  }
  EXPECT_EQ(both, 4);
}

// Link compliance in both sessions and, in the calibration session only, a nonlinear reducer
// (0.3 of the example's): after link, candidates that do not separate (backlash and the
// nonlinear joint) take up the calibration-only part, and neither lowers the validation
// error. Like a refuted candidate, such a group neither confirms nor refutes the
// step the validation poses confirmed: link is named (alone in an ambiguous group, or as
// missing) and `--auto` keeps it, with the noise stated and without. Before this rule 4 of
// these 6 runs ended `unexplained` with the model `joint`.
TEST(DiagnoseAuto, SlowAGroupTheValidationDoesNotConfirmDoesNotUndoAConfirmedStep) {
  const RobotModel robot = test::rokae();
  Truth v = examples_of(robot, {"joint", "link", "nonlinear_joint"});
  const DeflectionModel m(robot, v.effects);
  const int at = m.offset(2), size = m.effects()[2]->size();
  Truth calib = v;
  v.theta.segment(at, size) = m.null_parameters().segment(at, size);
  calib.theta.segment(at, size) =
      v.theta.segment(at, size) + 0.3 * (calib.theta.segment(at, size) - v.theta.segment(at, size));
  int kept = 0;
  for (uint64_t seed = 1; seed <= 3; ++seed)
    for (bool stated : {true, false}) {
      Dataset c = simulate(robot, calib, test::design60(seed, 60), realistic_noise(300 + seed));
      Dataset w = simulate(robot, v, test::design60(500 + seed, 40), realistic_noise(900 + seed));
      if (!stated) {
        hide_noise(c);
        hide_noise(w);
      }
      DiagnosisOptions o;
      o.auto_loop = true;
      const Diagnosis d = diagnose(robot, c, &w, {"joint"}, o);
      print(stated ? "link, reducer in calibration only" : "the same, noise unknown", seed, d);
      EXPECT_NE(d.verdict, "unexplained") << d.summary;
      kept += d.final_model.find("link") != std::string::npos;
    }
  EXPECT_GE(kept, 5);
}

// Two effects of which one is backlash, as a user has them: an SMR offset and backlash, the
// robot file's masses 30 % light, no noise statement. The preload is decided on what the
// offset leaves, and the calibration rows whose jump the data leave undecided enter the tests by
// their closest prediction (docs/diagnosis.md, section 1). Before both, 2 of these 4 seeds named
// both, one ended with `nonlinear_joint` in place of backlash and one stopped at `unexplained`;
// with them 3 of 4 name both and none names another effect.
TEST(DiagnoseAuto, SlowFindsOffsetAndBacklashWithMassesOff) {
  const RobotModel truth = test::rokae();
  const RobotModel file = light_file(truth);
  const std::vector<std::string> effects = {"joint", "point_offset", "backlash"};
  const Truth t = examples_of(truth, effects);
  DiagnosisOptions o;
  o.auto_loop = true;
  const int seeds = 4;
  int both = 0, wrong = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    Dataset calib = simulate(truth, t, test::design60(seed, 60), realistic_noise(7100 + seed));
    Dataset valid =
        simulate(truth, t, test::design60(60000 + seed, 40), realistic_noise(9100 + seed));
    hide_noise(calib);
    hide_noise(valid);
    const Diagnosis d = diagnose(file, calib, &valid, {"joint"}, o);
    std::set<std::string> added;
    for (const auto& st : d.steps)
      if (!st.added.empty()) added.insert(st.added);
    std::printf("  seed %d: %s, final model %s\n", seed, d.final_verdict.c_str(),
                d.final_model.c_str());
    both += added.count("point_offset") && added.count("backlash");
    for (const auto& a : added) wrong += a != "point_offset" && a != "backlash";
  }
  EXPECT_GE(both, seeds - 1);
  EXPECT_EQ(wrong, 0);
}

// Without any stated noise the partial F-tests still find a large effect; the absolute check
// is skipped and said so. Replicated measurements give the noise floor.
TEST(DiagnoseNoise, UnknownNoiseAndReplicates) {
  Scenario s = make_scenario("point_offset", 3);
  s.calib.has_sigma = false;
  for (auto& r : s.calib.rows) r.sigma_d = 0;
  s.calib.metadata.clear();
  const Diagnosis d = run(s);
  EXPECT_EQ(d.noise_source, "none");
  EXPECT_FALSE(d.noise_force_error);  // nothing stated: every row weighs alike
  EXPECT_EQ(d.verdict, "missing_effect");
  EXPECT_EQ(named(d), "point_offset");
  EXPECT_FALSE(d.warnings.empty());

  const RobotModel robot = test::rokae();
  Dataset design = test::design60(5, 30);
  const size_t n = design.rows.size();
  for (size_t r = 0; r < n; ++r) {
    Measurement m = design.rows[r];
    m.id += "_rep";
    design.rows.push_back(m);
  }
  NoiseModel noise = realistic_noise(5);
  noise.force_relative = noise.force_absolute_N = noise.tracker_ppm = 0;
  Dataset rep = simulate(robot, test::effect_truth("joint", robot), design, noise);
  rep.has_sigma = false;
  rep.metadata.clear();
  const Diagnosis dr = diagnose(robot, rep, nullptr, {"joint"});
  EXPECT_EQ(dr.noise_source, "replicates");
  EXPECT_NEAR(dr.noise_floor_m, kTrackerSigma, 0.25 * kTrackerSigma);
  EXPECT_EQ(dr.verdict, "adequate");
}

// ---------------------------------------------------------------- validation leverage

// A right model predicts a new pose with the noise plus its parameters' uncertainty there:
// sigma^2 (1 + h_r). Validation loads about 2.7 times the calibration's put the validation rows
// at about 7 times the calibration rows' leverage p/n; over 100 seeds the validation mean
// square of the right (joint) model matches the floor sigma^2 (1 + h) it reports, and not
// sigma^2 (1 + p/n). Per seed the ratio scatters by the noise (chi2 of 60: relative sd 0.18)
// and by the shared parameter error (a quadratic form in 5 estimates, relative sd
// sqrt(2/5) h/(1 + h) ~ 0.23): about 0.3, so 0.03 for the mean of 100, and 0.1 is more than 3
// of them.
TEST(DiagnoseValidation, SlowRightModelPredictsNewPosesAtItsLeverage) {
  const RobotModel robot = test::rokae();
  const Truth truth = test::effect_truth("joint", robot);
  double ratio = 0, ratio_mean_leverage = 0;
  constexpr int kSeeds = 100;
  for (int seed = 1; seed <= kSeeds; ++seed) {
    RandomDesignOptions o;
    o.count = 20;
    o.load_min_N = 10.0;
    o.load_max_N = 20.0;
    o.seed = static_cast<uint64_t>(seed);
    const Dataset cdesign = random_design(robot, o);
    o.load_min_N = 30.0;
    o.load_max_N = 50.0;
    o.seed = 1000 + static_cast<uint64_t>(seed);
    const Dataset vdesign = random_design(robot, o);
    NoiseModel noise;
    noise.tracker_sigma_m = kTrackerSigma;
    noise.seed = static_cast<uint64_t>(seed);
    const Dataset calib = simulate(robot, truth, cdesign, noise);
    noise.seed += 5000;
    const Dataset valid = simulate(robot, truth, vdesign, noise);
    const Diagnosis d = diagnose(robot, calib, &valid, {"joint"});
    ASSERT_TRUE(d.fit.has_validation);
    const double pn = static_cast<double>(d.fit.parameters) / (3.0 * d.fit.used);
    const double h = d.fit.validation_leverage;
    EXPECT_GT(h, 3 * pn) << "seed " << seed;
    const double r = std::pow(d.fit.validation_rms_m / d.fit.validation_floor_m, 2);
    ratio += r / kSeeds;
    ratio_mean_leverage += r * (1 + h) / (1 + pn) / kSeeds;
  }
  EXPECT_NEAR(ratio, 1.0, 0.1);
  EXPECT_GT(ratio_mean_leverage, 1.3);  // what p/n would have called 30 % above the floor
}

// ---------------------------------------------------------------- noise statements

/// Per-axis displacement sigma of a row with a stated tracker sigma and force error, written
/// here from the specification convention (independent of diagnose's code).
double spec_sigma(const Measurement& m, double tracker, double rel, double abs_n, bool linear) {
  double s2 = 0;
  for (int k = 0; k < 3; ++k) {
    const double a = rel * std::abs(m.force(k));
    const double sk = linear ? a + abs_n : std::sqrt(a * a + abs_n * abs_n);
    s2 += sk * sk;
  }
  const double f2 = m.force.squaredNorm();
  return std::sqrt(tracker * tracker + m.displacement.squaredNorm() * s2 / (3 * f2));
}

// "1 % + 0.3 N" is a linear sum (instrument-specification convention); a file may state a
// quadrature sum instead. The floor is the RMS of the per-row sigmas.
TEST(DiagnoseNoise, ForceSpecificationIsALinearSumUnlessStated) {
  Scenario s = make_scenario("link", 3);
  s.calib.has_sigma = false;
  s.calib.set_meta("tracker_sigma_m", "2e-05");
  s.calib.set_meta("force_relative", "0.01");
  s.calib.set_meta("force_absolute_N", "0.3");
  for (const bool linear : {true, false}) {
    s.calib.set_meta("force_error_sum", linear ? "linear" : "quadrature");
    double ss = 0;
    for (const auto& m : s.calib.rows) ss += std::pow(spec_sigma(m, 2e-5, 0.01, 0.3, linear), 2);
    const double expected = std::sqrt(ss / s.calib.rows.size());
    const Diagnosis d = run(s);
    EXPECT_NEAR(d.noise_floor_m, expected, 1e-9 * expected) << (linear ? "linear" : "quadrature");
  }
  s.calib.set_meta("force_error_sum", "");  // unstated: the specification convention
  const Diagnosis d = run(s);
  double ss = 0;
  for (const auto& m : s.calib.rows) ss += std::pow(spec_sigma(m, 2e-5, 0.01, 0.3, true), 2);
  EXPECT_NEAR(d.noise_floor_m, std::sqrt(ss / s.calib.rows.size()), 1e-12);
}

// A stated noise level is itself uncertain: a clean control whose stated sigma is 7 % below
// the actual one (well inside a data sheet's 10-25 %) is not `unexplained`, and the report
// says how far the residual sits from the floor.
TEST(DiagnoseNoise, StatedNoiseSlightlyLowIsAllowedAndReported) {
  int claims = 0, adequate = 0;
  for (int seed = 1; seed <= 4; ++seed) {
    Scenario s = make_scenario("joint", 400 + seed);
    for (auto& m : s.calib.rows) m.sigma_d /= 1.07;
    for (auto& m : s.valid.rows) m.sigma_d /= 1.07;
    const Diagnosis d = run(s);
    print("sigma 7 % low", seed, d);
    claims += d.verdict == "missing_effect";
    adequate += d.verdict == "adequate";
    // sqrt(chi2/dof) estimates actual/stated sigma: 1.07 give or take the chi2 scatter
    // (sd sqrt(1/(2 dof)) ~ 0.055) and the force part of the floor, which is not scaled.
    EXPECT_GT(d.fit.residual_to_floor, 1.07 - 4 * 0.055);
    EXPECT_LT(d.fit.residual_to_floor, 1.07 + 4 * 0.055);
  }
  EXPECT_EQ(claims, 0);
  EXPECT_GE(adequate, 3);
}

// With a stated noise the floor test pools the validation rows: a model that fits the
// calibration poses at the floor but predicts the validation poses well above it does not
// explain the data. Here the validation session carries link compliance that the calibration
// session does not (another set-up), so no candidate fitted on the calibration can explain it;
// the calibration alone is at the floor. Before the pooling every seed was `adequate`.
TEST(DiagnoseNoise, ValidationAboveTheFloorIsNotAdequate) {
  int adequate = 0, clean_adequate = 0;
  for (int seed = 1; seed <= 3; ++seed) {
    const Scenario clean = make_scenario("joint", 500 + seed);
    Scenario s = clean;
    s.valid = make_scenario("link", 500 + seed).valid;
    const Diagnosis d = run(s);
    const Diagnosis c = run(clean);
    print("valid with link", seed, d);
    std::printf("  validation / floor %.2f (clean %.2f), calibration / floor %.2f\n",
                d.fit.validation_to_floor, c.fit.validation_to_floor, d.fit.residual_to_floor);
    EXPECT_LT(d.fit.residual_to_floor, 1.1);
    EXPECT_GT(d.fit.validation_to_floor, 1.2);
    EXPECT_LT(c.fit.validation_to_floor, 1.15);
    adequate += d.verdict == "adequate";
    clean_adequate += c.verdict == "adequate";
    EXPECT_NE(d.verdict, "missing_effect");
  }
  EXPECT_EQ(adequate, 0);
  EXPECT_GE(clean_adequate, 2);
}

// On a soft arm the force reading's error moves the point as much as the tracker's noise does,
// and not alike in every direction: by the arm's compliance at the pose times the force error.
// With the error stated, each row's covariance is the tracker's sigma^2 I plus G S G^T (G the
// model's displacement per unit force, S the stated force variances), so that the residual
// of a right model is white: its chi-square sits at its degrees of freedom and the trend tests
// of force-like directions (force frame, base tilt) keep their level. The arm here is four times
// the example's compliance (deflections of 1-4 mm). With the force error spread equally over
// the three axes, force_frame was significant in 5 of these 6 controls (p_adj 5e-11 to 1e-4),
// 3 of them were not `adequate`, and 3 residuals sat 1.16-1.42 times the floor.
TEST(DiagnoseNoise, AForceErrorMovesThePointAlongTheArmsCompliance) {
  const RobotModel robot = test::rokae();
  Truth truth;
  truth.effects = {"joint"};
  truth.theta = 4.0 * test::paper_stiffness().cwiseInverse();
  int adequate = 0;
  for (uint64_t seed = 1; seed <= 6; ++seed) {
    Scenario s;
    s.calib = simulate(robot, truth, test::design60(seed, 60), realistic_noise(7700 + seed));
    s.valid =
        simulate(robot, truth, test::design60(57000 + seed, 40), realistic_noise(9700 + seed));
    const Diagnosis d = run(s);
    print("soft arm", seed, d);
    EXPECT_TRUE(d.noise_force_error);
    // 175 degrees of freedom: the whitened chi-square's relative spread is sqrt(2/175) ~ 0.11,
    // its square root's 0.05; 0.85-1.15 is three of those.
    EXPECT_NEAR(d.fit.residual_to_floor, 1.0, 0.15) << seed;
    adequate += d.verdict == "adequate";
  }
  EXPECT_GE(adequate, 5);
}

TEST(DiagnoseApi, RejectsBadInputAndWritesJson) {
  const RobotModel robot = test::rokae();
  const Scenario s = make_scenario("drift", 1);
  DiagnosisOptions o;
  o.candidates = {"no_such_effect"};
  EXPECT_THROW(diagnose(robot, s.calib, nullptr, {"joint"}, o), InvalidArgument);
  o = {};
  o.alpha = 1.5;
  EXPECT_THROW(diagnose(robot, s.calib, nullptr, {"joint"}, o), InvalidArgument);
  EXPECT_THROW(diagnose(robot, s.calib, nullptr, {}, {}), InvalidArgument);
  EXPECT_THROW(diagnose(robot, s.calib, nullptr, {"joint", "bogus"}, {}), InvalidArgument);
  Dataset plan = s.calib;
  plan.has_displacement = false;
  EXPECT_THROW(diagnose(robot, plan, nullptr, {"joint"}, {}), InvalidArgument);

  o = {};
  o.command_prefix = "stiff diagnose --robot rokae --data c.csv";
  const Diagnosis d = diagnose(robot, s.calib, &s.valid, {"joint"}, o);
  // This drift (5-8 um, ~0.3 sigma) is at the detection threshold: the partial F test is
  // significant but adding drift need not improve 40 validation poses, so `adequate` is as
  // right as `missing_effect`; a claim of another effect is not.
  EXPECT_TRUE(d.verdict == "adequate" || (d.verdict == "missing_effect" && named(d) == "drift"))
      << d.verdict << ": " << d.summary;
  const auto drift = std::find_if(d.candidates.begin(), d.candidates.end(),
                                  [](const CandidateScore& c) { return c.effect == "drift"; });
  ASSERT_NE(drift, d.candidates.end());
  EXPECT_EQ(drift->command, "stiff diagnose --robot rokae --data c.csv --model joint+drift");
  // Ranks are 1..k over the testable candidates, p_adjusted >= p_value.
  for (size_t i = 0; i < d.candidates.size(); ++i) {
    const auto& c = d.candidates[i];
    if (!c.testable) continue;
    EXPECT_EQ(c.rank, static_cast<int>(i) + 1);
    EXPECT_GE(c.p_adjusted, c.p_value);
  }
  const std::string js = diagnosis_to_json(d);
  for (const char* key :
       {"\"verdict\"", "\"model\"", "\"rms_m\"", "\"validation\"", "\"noise_floor_m\"",
        "\"candidates\"", "\"p_adjusted\"", "\"expected_rms_drop_m\"", "\"identifiable\"",
        "\"group\"", "\"steps\"", "\"where\"", "\"covariates\"", "\"worst_poses\""})
    EXPECT_NE(js.find(key), std::string::npos) << key;
  // The drift shows in the covariate tests (offset or time).
  bool trend = false;
  for (const auto& c : d.covariates)
    if ((c.covariate == "offset" || c.covariate == "time") && c.p_value < 0.01) trend = true;
  EXPECT_TRUE(trend);
}

}  // namespace
}  // namespace stiff
