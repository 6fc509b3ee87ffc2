// identify(): robust nonlinear identification with Ceres — agreement with the linear
// solution, robust losses against gross tracker errors, identifiability reports, errors.
#include <gtest/gtest.h>

#include <cstdio>
#include <set>

#include "../effects/effect_truths.hpp"
#include "stiff/error.hpp"
#include "stiff/identify/fit.hpp"
#include "stiff/identify/identify.hpp"

namespace stiff {
namespace {

constexpr double kNoise = 10e-6;

Dataset simulated(const Truth& truth,
                  uint64_t seed,
                  double outlier_rate = 0.0,
                  std::vector<int>* outliers = nullptr,
                  int count = 60) {
  NoiseModel noise;
  noise.tracker_sigma_m = kNoise;
  noise.outlier_rate = outlier_rate;
  noise.outlier_size_m = 0.5e-3;
  noise.seed = 7000 + seed;
  return simulate(test::rokae(), truth, test::design60(seed, count), noise, outliers);
}

double validation_rms(const FitResult& fit, const Dataset& val) {
  const Eigen::MatrixXd pred = predict_dataset(test::rokae(), fit, val);
  double ss = 0;
  for (size_t r = 0; r < val.size(); ++r)
    ss += (val.rows[r].displacement - pred.row(r).head<3>().transpose()).squaredNorm();
  return std::sqrt(ss / (3.0 * val.size()));
}

bool has_warning(const FitResult& f, const std::string& text) {
  for (const auto& w : f.warnings)
    if (w.find(text) != std::string::npos) return true;
  return false;
}

// A point offset of several centimetres turns the wrist joints' load torques, and with them the
// side a backlash jump falls on. identify decides the jumps again with the offset it fitted
// (docs/effects.md, backlash). Pooled over 8 seeds the model predicts 40 new poses each within
// the 1.25 times the floor a right model reaches that the diagnosis asks of a suggested model
// (floor: the noise with the prediction variance, sigma sqrt(1 + p/n), 18 parameters on 180
// equations): 1.19 measured. Deciding once, with the robot file's points, gave 1.34 (seeds 1, 3
// and 6 at 1.3-1.9).
TEST(IdentifyCeres, BacklashDecidesWithTheFittedPointOffset) {
  const RobotModel robot = test::rokae();
  const std::vector<std::string> effects = {"joint", "point_offset", "backlash"};
  const DeflectionModel model(robot, effects);
  Truth truth;
  truth.effects = effects;
  truth.theta = model.null_parameters();
  truth.theta.head(6) = test::paper_stiffness().cwiseInverse();
  const double offset[6] = {0.06, 0.03, 0.05, 0.06, 0.03, 0.06};  // meas, load [m]
  for (int k = 0; k < 6; ++k) truth.theta(model.offset(1) + k) = offset[k];
  for (int j = 0; j < 6; ++j) truth.theta(model.offset(2) + j) = 3e-4;  // b_j [rad]
  constexpr int kSeeds = 8;
  double ms = 0;
  for (uint64_t seed = 1; seed <= kSeeds; ++seed) {
    const Dataset calib = simulated(truth, seed);
    const Dataset valid = simulated(truth, 100 + seed, 0.0, nullptr, 40);
    const FitResult fit = identify(robot, calib, effects);
    ms += std::pow(validation_rms(fit, valid), 2) / kSeeds;
    // The link masses and their spread are decided from the data, not fitted, and say so.
    for (int k = 0; k < model.parameter_count(); ++k)
      if (model.spec(k).from_data) {
        EXPECT_FALSE(fit.parameters[k].identified) << fit.parameters[k].name;
        EXPECT_EQ(fit.parameters[k].held, "decided") << fit.parameters[k].name;
      }
  }
  const double floor = kNoise * std::sqrt(1.0 + 18.0 / 180.0);
  EXPECT_LT(std::sqrt(ms), 1.25 * floor);
}

TEST(IdentifyCeres, JointModelEqualsTheLinearSolution) {
  const Truth truth = joint_truth(test::paper_stiffness());
  const Dataset data = simulated(truth, 1);
  const FitResult lin = identify_joint_linear(test::rokae(), data);
  const FitResult fit = identify(test::rokae(), data, {"joint"});
  EXPECT_EQ(fit.method, "ceres");
  EXPECT_EQ(fit.loss, "none");
  EXPECT_EQ(fit.measurements, 60);
  EXPECT_EQ(fit.rank, 5);
  EXPECT_EQ(fit.dof, 175);
  ASSERT_EQ(fit.parameters.size(), 6u);
  for (int j = 0; j < 5; ++j) {
    // Same least-squares problem: agreement far below the standard errors.
    EXPECT_NEAR(fit.parameters[j].value, lin.parameters[j].value,
                1e-4 * lin.parameters[j].standard_error);
    EXPECT_NEAR(fit.parameters[j].standard_error, lin.parameters[j].standard_error,
                1e-3 * lin.parameters[j].standard_error);
  }
  EXPECT_NEAR(fit.rms_m, lin.rms_m, 1e-3 * lin.rms_m);
  EXPECT_NEAR(fit.sigma_hat_m, lin.sigma_hat_m, 1e-3 * lin.sigma_hat_m);
  EXPECT_NEAR(fit.condition_number, lin.condition_number, 1e-3 * lin.condition_number);
  EXPECT_GT(fit.chi2, 0.0);
  EXPECT_EQ(fit.weights.size(), 60);
  EXPECT_EQ(fit.residuals.size(), 180);
}

TEST(IdentifyCeres, JointSixOnTheFlangeAxisIsHeldAndReported) {
  const Dataset data = simulated(joint_truth(test::paper_stiffness()), 2);
  const FitResult fit = identify(test::rokae(), data, {"joint"});
  EXPECT_FALSE(fit.parameters[5].identified);
  EXPECT_EQ(fit.parameters[5].value, 0.0);
  EXPECT_TRUE(std::isnan(fit.parameters[5].standard_error));
  EXPECT_TRUE(std::isnan(fit.covariance(5, 5)));
  EXPECT_TRUE(has_warning(fit, "joint.c6 is not identifiable")) << fit.warnings.size();
  EXPECT_EQ(fit.parameters[5].held, "undetermined");
  for (int j = 0; j < 5; ++j) EXPECT_TRUE(fit.parameters[j].identified);
}

TEST(IdentifyCeres, CommonForceScaleIsNamedAndHeld) {
  const RobotModel robot = test::rokae();
  const Truth truth = test::effect_truth("force_frame", robot);
  const FitResult fit = identify(robot, simulated(truth, 3), truth.effects);
  const auto& sz = fit.parameters[6 + 5];
  ASSERT_EQ(sz.name, "scale_z");
  EXPECT_FALSE(sz.identified);
  bool named = false;
  for (const auto& w : fit.warnings)
    if (w.find("force_frame.scale_z") != std::string::npos &&
        w.find("joint.c1") != std::string::npos &&
        w.find("force_frame.scale_x") != std::string::npos)
      named = true;
  EXPECT_TRUE(named) << "warning must name the combination";
}

// `full` as a version without the parameters `later` names wrote it: those left out, with their
// rows and columns of the covariance; in `full` they are set to 0, as that version holds them.
template <typename Later>
FitResult as_older_fit(FitResult* full, Later later) {
  FitResult old = *full;
  old.parameters.clear();
  std::vector<int> kept;
  for (size_t k = 0; k < full->parameters.size(); ++k) {
    if (later(full->parameters[k])) {
      full->parameters[k].value = 0.0;
      continue;
    }
    old.parameters.push_back(full->parameters[k]);
    kept.push_back(static_cast<int>(k));
  }
  old.covariance = Eigen::MatrixXd(kept.size(), kept.size());
  for (size_t a = 0; a < kept.size(); ++a)
    for (size_t b = 0; b < kept.size(); ++b)
      old.covariance(a, b) = full->covariance(kept[a], kept[b]);
  return old;
}

// The older fit written and read back; it predicts `data` as `full` (its later terms at 0) does.
FitResult read_back_predicts_alike(const RobotModel& robot,
                                   const FitResult& old,
                                   const FitResult& full,
                                   const Dataset& data) {
  FitResult back = fit_from_json(fit_to_json(old), "old_fit.json");
  const Eigen::MatrixXd a = predict_dataset(robot, back, data);
  const Eigen::MatrixXd b = predict_dataset(robot, full, data);
  EXPECT_LT((a - b).cwiseAbs().maxCoeff(), 1e-15);
  return back;
}

// A fit written before its effect gained optional terms (link's column and wrist springs, then
// its bending terms) still applies: the terms it lacks enter at their null value, held, and it
// predicts as the same fit with them written at 0 does. A fit that lacks a term that is not
// optional is refused.
TEST(FitCompatibility, AFitWithoutLaterOptionalTermsStillApplies) {
  const RobotModel robot = test::rokae();
  const Truth truth = test::effect_truth("link", robot);
  const Dataset data = simulated(truth, 3);
  FitResult full = identify(robot, data, truth.effects);
  const FitResult old = as_older_fit(&full, [](const FitParameter& p) {
    return p.effect == "link" && p.name != "c_link2_x" && p.name != "c_link2_y" &&
           p.name != "c_link3_x";
  });
  ASSERT_EQ(old.parameters.size() + 9, full.parameters.size());
  const FitResult back = read_back_predicts_alike(robot, old, full, data);
  const DeflectionModel model(robot, full.model);
  const FitResult conformed = fit_for_model(back, robot, model, "test");
  ASSERT_EQ(conformed.parameters.size(), full.parameters.size());
  for (size_t k = 0; k < full.parameters.size(); ++k)
    EXPECT_EQ(conformed.parameters[k].name, full.parameters[k].name);
  EXPECT_FALSE(conformed.parameters[6].identified);  // link.c_link1_x, inserted
  EXPECT_TRUE(std::isnan(conformed.covariance(6, 6)));
  FitResult broken = old;
  broken.parameters.erase(broken.parameters.begin() + 6);  // link.c_link2_x: not optional
  broken.covariance = Eigen::MatrixXd();
  EXPECT_THROW(predict_dataset(robot, broken, data), InvalidArgument);
}

// A nonlinear_joint fit written before the laws of the total torque (h, r) still applies and
// predicts as the same fit with them at 0.
TEST(FitCompatibility, ANonlinearJointFitWithoutTheTotalTorqueLawsStillApplies) {
  const RobotModel robot = test::rokae();
  const Truth truth = test::effect_truth("nonlinear_joint", robot);
  const Dataset data = simulated(truth, 3);
  FitResult full = identify(robot, data, truth.effects);
  const FitResult old = as_older_fit(&full, [](const FitParameter& p) {
    return p.effect == "nonlinear_joint" && (p.name[0] == 'h' || p.name[0] == 'r');
  });
  ASSERT_EQ(old.parameters.size() + 6, full.parameters.size());
  read_back_predicts_alike(robot, old, full, data);
}

// A backlash fit written before the masses' spread (v11..v66) was reported still applies: the
// spread enters at 0, the decided jumps of that version's prediction.
TEST(FitCompatibility, ABacklashFitWithoutTheSpreadPredictsTheDecidedJumps) {
  const RobotModel robot = test::rokae();
  RobotModel file = robot;
  for (auto& j : file.joints) j.mass *= 0.7;
  file.tool_mass *= 0.7;
  const Truth truth = test::effect_truth("backlash", robot);
  const Dataset data = simulated(truth, 5);
  FitResult full = identify(file, data, truth.effects);
  auto is_spread = [](const FitParameter& p) { return p.effect == "backlash" && p.name[0] == 'v'; };
  int spread = 0;
  for (const auto& p : full.parameters) spread += is_spread(p) && p.value != 0.0;
  ASSERT_GT(spread, 0);  // the data left the masses a spread: the test can tell
  const FitResult old = as_older_fit(&full, is_spread);  // full's spread 0: the decided jumps
  read_back_predicts_alike(file, old, full, simulated(truth, 6));
}

// 5 % gross tracker errors of 0.5 mm (50 sigma): Huber keeps the validation error at the
// clean fit's level; plain least squares is pulled away; the flagged rows are the outliers.
TEST(IdentifyCeres, RobustLossResistsGrossOutliers) {
  const Truth truth = joint_truth(test::paper_stiffness());
  const int seeds = 12;
  double clean_ss = 0, huber_ss = 0, lsq_ss = 0;
  int tp = 0, fp = 0, fn = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    std::vector<int> bad;
    const Dataset dirty = simulated(truth, seed, 0.05, &bad);
    const Dataset clean = simulated(truth, seed, 0.0);
    const Dataset val = simulated(truth, 500 + seed);
    IdentifyOptions huber;
    huber.loss = "huber";
    const FitResult fc = identify(test::rokae(), clean, {"joint"});
    const FitResult fh = identify(test::rokae(), dirty, {"joint"}, huber);
    const FitResult fl = identify(test::rokae(), dirty, {"joint"});
    clean_ss += std::pow(validation_rms(fc, val), 2);
    huber_ss += std::pow(validation_rms(fh, val), 2);
    lsq_ss += std::pow(validation_rms(fl, val), 2);
    EXPECT_EQ(fh.loss, "huber");
    EXPECT_NEAR(fh.loss_scale_m, 3 * kNoise, 1e-12);
    std::set<int> truth_rows(bad.begin(), bad.end()), flagged;
    for (const auto& o : fh.outliers) {
      flagged.insert(o.row);
      EXPECT_LT(o.weight, 0.5);
      EXPECT_FALSE(o.reason.empty());
    }
    for (int r : flagged) (truth_rows.count(r) ? tp : fp)++;
    for (int r : truth_rows) fn += flagged.count(r) ? 0 : 1;
  }
  const double clean = std::sqrt(clean_ss / seeds), hub = std::sqrt(huber_ss / seeds),
               lsq = std::sqrt(lsq_ss / seeds);
  const double precision = tp / double(tp + fp), recall = tp / double(tp + fn);
  std::printf("  validation RMS: clean LSQ %.2f um, Huber %.2f um, LSQ with outliers %.2f um\n",
              clean * 1e6, hub * 1e6, lsq * 1e6);
  std::printf("  outliers: %d true, %d flagged correctly, %d false; precision %.3f recall %.3f\n",
              tp + fn, tp, fp, precision, recall);
  ASSERT_GT(tp + fn, 10) << "too few outliers drawn to test";
  EXPECT_LT(hub, 1.2 * clean);
  // Least squares is pulled by the outliers: its estimation error (the part of the validation
  // error above the noise floor) is several times the clean one.
  const double excess_clean = std::sqrt(std::max(0.0, clean * clean - kNoise * kNoise));
  const double excess_lsq = std::sqrt(std::max(0.0, lsq * lsq - kNoise * kNoise));
  std::printf("  estimation error above the noise: clean %.2f um, LSQ with outliers %.2f um\n",
              excess_clean * 1e6, excess_lsq * 1e6);
  EXPECT_GT(lsq, 1.3 * clean);
  EXPECT_GT(excess_lsq, 3 * excess_clean);
  EXPECT_GE(precision, 0.9);
  EXPECT_GE(recall, 0.9);
}

TEST(IdentifyCeres, EveryLossRuns) {
  const Dataset data = simulated(joint_truth(test::paper_stiffness()), 4, 0.05);
  for (const auto& loss : loss_names()) {
    IdentifyOptions o;
    o.loss = loss;
    const FitResult f = identify(test::rokae(), data, {"joint"}, o);
    EXPECT_EQ(f.loss, loss);
    for (int j = 0; j < 5; ++j) {
      // Least squares lets the 0.5 mm outliers inflate the residual scale about tenfold: the
      // stiffest joint's compliance is then not determined (standard error above its typical
      // magnitude and a third of its value) and is held, named in a warning.
      if (loss == "none" && !f.parameters[j].identified) {
        bool named = false;
        for (const auto& w : f.warnings)
          named = named || w.find("joint.c" + std::to_string(j + 1)) != std::string::npos;
        EXPECT_TRUE(named) << "joint " << j + 1;
        continue;
      }
      EXPECT_TRUE(std::isfinite(f.parameters[j].standard_error)) << loss << " joint " << j + 1;
    }
  }
}

TEST(IdentifyCeres, LeastSquaresListsGrossResidualsToo) {
  std::vector<int> bad;
  const Dataset data = simulated(joint_truth(test::paper_stiffness()), 5, 0.1, &bad);
  ASSERT_FALSE(bad.empty());
  const FitResult f = identify(test::rokae(), data, {"joint"});
  EXPECT_FALSE(f.outliers.empty());
  for (const auto& o : f.outliers) EXPECT_NE(o.reason.find("robust loss"), std::string::npos);
}

// A stated noise that the model does not reach (here a tenth of the real one) makes most rows
// exceed five of its sigmas: that is a misfit or an understated noise, not outliers. Least
// squares judges rows against the residuals' own robust scale and says why; the gross rows
// stay flagged and the clean rows (a 5-sigma norm of 3 components: P = 2e-5 each) do not.
TEST(IdentifyCeres, OutliersAreJudgedAgainstTheResidualsWhenTheStatedNoiseIsTooSmall) {
  std::vector<int> bad;
  Dataset data = simulated(joint_truth(test::paper_stiffness()), 6, 0.05, &bad, 120);
  ASSERT_FALSE(bad.empty());
  data.has_sigma = true;
  for (auto& m : data.rows) m.sigma_d = 0.1 * kNoise;
  const FitResult f = identify(test::rokae(), data, {"joint"});
  EXPECT_TRUE(has_warning(f, "times the stated noise"));
  std::set<int> flagged;
  for (const auto& o : f.outliers) flagged.insert(o.row);
  for (int r : bad) EXPECT_TRUE(flagged.count(r)) << "gross row " << r << " not flagged";
  EXPECT_LE(flagged.size(), bad.size() + 1) << "clean rows flagged as outliers";
  // With the true noise stated, no such warning: the residuals are at the stated level.
  for (auto& m : data.rows) m.sigma_d = kNoise;
  EXPECT_FALSE(has_warning(identify(test::rokae(), data, {"joint"}), "times the stated noise"));
}

TEST(IdentifyCeres, ClearErrors) {
  const RobotModel robot = test::rokae();
  const Dataset data = simulated(joint_truth(test::paper_stiffness()), 6);
  IdentifyOptions bad_loss;
  bad_loss.loss = "l1";
  try {
    identify(robot, data, {"joint"}, bad_loss);
    FAIL();
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("huber"), std::string::npos) << e.what();
  }
  try {
    identify(robot, data, {"joint", "pedestal_tilt"});
    FAIL();
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("known effects"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("backlash"), std::string::npos) << e.what();
  }
  RobotModel massless = robot;
  for (auto& j : massless.joints) j.mass = 0;
  massless.tool_mass = 0;
  try {
    identify(massless, data, {"joint", "nonlinear_joint"});
    FAIL();
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("masses"), std::string::npos) << e.what();
  }
  EXPECT_THROW(identify(robot, data, {}), InvalidArgument);
  IdentifyOptions o;
  o.max_iterations = 0;
  EXPECT_THROW(identify(robot, data, {"joint"}, o), InvalidArgument);
  o = {};
  o.loss_scale_m = NAN;
  EXPECT_THROW(identify(robot, data, {"joint"}, o), InvalidArgument);
  o = {};
  o.outlier_weight = 0;
  EXPECT_THROW(identify(robot, data, {"joint"}, o), InvalidArgument);
  Dataset zero_sigma = data;
  zero_sigma.rows[3].sigma_d = 0;
  EXPECT_THROW(identify(robot, zero_sigma, {"joint"}), InvalidArgument);
  Dataset nan = data;
  nan.rows[2].displacement(1) = NAN;
  EXPECT_THROW(identify(robot, nan, {"joint"}), InvalidArgument);
  Dataset few = simulated(joint_truth(test::paper_stiffness()), 6, 0.0, nullptr, 1);
  EXPECT_THROW(identify(robot, few, {"joint", "tool_compliance"}), InvalidArgument);
}

TEST(IdentifyCeres, NoLoadMeansNothingIdentifiable) {
  Dataset data = simulated(joint_truth(test::paper_stiffness()), 7);
  for (auto& m : data.rows) m.force.setZero();
  EXPECT_THROW(identify(test::rokae(), data, {"joint"}), NumericalError);
}

TEST(IdentifyCeres, ComplementaryWithoutJointIsReportedNotFitted) {
  const Dataset data = simulated(joint_truth(test::paper_stiffness()), 8);
  const FitResult f = identify(test::rokae(), data, {"complementary", "tool_compliance"});
  EXPECT_FALSE(f.parameters[0].identified);
  EXPECT_TRUE(has_warning(f, "complementary.gamma is not identifiable"));
}

TEST(IdentifyCeres, ProgressCanCancel) {
  const Dataset data = simulated(joint_truth(test::paper_stiffness()), 9);
  IdentifyOptions o;
  int calls = 0;
  o.progress = [&](int, double) { return ++calls < 1; };
  EXPECT_THROW(identify(test::rokae(), data, {"joint", "force_frame"}, o), Cancelled);
  EXPECT_GE(calls, 1);
  o.progress = [&](int, double cost) { return std::isfinite(cost); };
  EXPECT_NO_THROW(identify(test::rokae(), data, {"joint", "force_frame"}, o));
}

TEST(IdentifyCeres, WithoutSigmaUsesRobustScale) {
  Dataset data = simulated(joint_truth(test::paper_stiffness()), 10, 0.05);
  data.has_sigma = false;
  for (auto& m : data.rows) m.sigma_d = 0;
  data.metadata.clear();
  IdentifyOptions o;
  o.loss = "huber";
  const FitResult f = identify(test::rokae(), data, {"joint"}, o);
  EXPECT_EQ(f.noise_floor_m, 0.0);
  // 3 x a MAD estimate of the 10 um noise (taken at the least-squares start).
  EXPECT_GT(f.loss_scale_m, 2.0 * kNoise);
  EXPECT_LT(f.loss_scale_m, 5.0 * kNoise);
  EXPECT_NEAR(f.sigma_hat_m, kNoise, 0.25 * kNoise);
}

}  // namespace
}  // namespace stiff

namespace stiff {
namespace {

// The identification's fast derivative path (DeflectionModel::evaluate_jet, geometry in double
// with 3 x kJetStride derivative blocks) equals the generic evaluate<Jet> to round-off, for
// parameters that move the points (point_offset), that act after the geometry (joint, link,
// tracker_frame) and with every parameter seeded, pass by pass.
TEST(IdentifyCeres, FastJetEvaluationEqualsTheGenericOne) {
  const RobotModel robot = test::rokae();
  const Dataset data = test::design60(3, 12);
  for (const std::vector<std::string>& effects :
       {std::vector<std::string>{"joint"},
        std::vector<std::string>{"joint", "link", "point_offset"},
        std::vector<std::string>{"joint", "point_offset", "tracker_frame"}}) {
    const DeflectionModel model(robot, effects, &data);
    const int p = model.parameter_count();
    Eigen::VectorXd theta = model.start_parameters();
    for (int k = 0; k < p; ++k) theta(k) += 0.1 * std::abs(model.spec(k).typical) * (k % 3 - 1);
    const auto ctx = model.contexts(data);
    EvalState<Jet> scratch;
    for (size_t r = 0; r < data.rows.size(); ++r) {
      for (int first = 0; first < p; first += kJetStride) {
        std::vector<Jet> t(p);
        for (int k = 0; k < p; ++k) t[k] = Jet(theta(k));
        for (int k = first; k < std::min(p, first + kJetStride); ++k) t[k].v(k - first) = 1.0;
        Vector3<Jet> slow, fast;
        model.evaluate<Jet>(t.data(), data.rows[r], ctx[r], &slow, nullptr);
        model.evaluate_jet(t.data(), data.rows[r], ctx[r], scratch, &fast);
        for (int i = 0; i < 3; ++i) {
          EXPECT_NEAR(fast(i).a, slow(i).a, 1e-15 + 1e-12 * std::abs(slow(i).a));
          for (int k = 0; k < kJetStride; ++k)
            EXPECT_NEAR(fast(i).v(k), slow(i).v(k), 1e-15 + 1e-11 * slow(i).v.cwiseAbs().maxCoeff())
                << model.model_string() << " row " << r << " pass " << first << " slot " << k;
        }
      }
    }
  }
}

// Effects find the stages they act in from the stage functions they define (Effect::stages).
TEST(IdentifyCeres, EffectsKnowTheirStages) {
  const RobotModel robot = test::rokae();
  const Dataset data = test::design60(3, 4);
  EffectSetup setup;
  setup.robot = &robot;
  setup.data = &data;
  EXPECT_EQ(make_effect("point_offset", setup)->stages(), unsigned{kWrenchStage});
  EXPECT_EQ(make_effect("force_frame", setup)->stages(), unsigned{kWrenchStage});
  EXPECT_EQ(make_effect("joint", setup)->stages(), unsigned{kJointStage});
  EXPECT_EQ(make_effect("link", setup)->stages(), unsigned{kCartesianStage});
  EXPECT_EQ(make_effect("tracker_frame", setup)->stages(), unsigned{kMeasurementStage});
}

// The analytic columns of linear effects (Effect::displacement_derivatives) equal the automatic
// derivatives to 1e-12, with the other parameters differentiated by evaluate_jet passes; a
// model with an effect that acts on d after the geometry (or a linear effect without analytic
// derivatives) is differentiated automatically throughout.
TEST(IdentifyCeres, AnalyticColumnsEqualAutomaticDerivatives) {
  const RobotModel robot = test::rokae();
  const Dataset data = test::design60(3, 12);
  for (const std::vector<std::string>& effects :
       {std::vector<std::string>{"joint"}, std::vector<std::string>{"joint", "link"},
        std::vector<std::string>{"joint", "link", "point_offset"},
        std::vector<std::string>{"link", "force_frame"}}) {
    const DeflectionModel model(robot, effects, &data);
    ASSERT_TRUE(model.analytic()) << model.model_string();
    const int p = model.parameter_count();
    Eigen::VectorXd theta = model.start_parameters();
    for (int k = 0; k < p; ++k) theta(k) += 0.1 * std::abs(model.spec(k).typical) * (k % 3 - 1);
    const std::vector<int>& jp = model.jet_parameters();
    for (int k : jp) EXPECT_FALSE(model.owner(k).has_displacement_derivatives());
    const auto ctx = model.contexts(data);
    EvalState<Jet> scratch;
    EvalState<double> ds;
    for (size_t r = 0; r < data.rows.size(); ++r) {
      Eigen::Matrix<double, 3, Eigen::Dynamic> fast(3, p);
      fast.setConstant(NAN);
      // kJetStride parameters per pass, as identify() differentiates them.
      for (size_t first = 0; first < std::max<size_t>(jp.size(), 1); first += kJetStride) {
        std::vector<Jet> t(p);
        for (int k = 0; k < p; ++k) t[k] = Jet(theta(k));
        const size_t last = std::min(jp.size(), first + kJetStride);
        for (size_t i = first; i < last; ++i) t[jp[i]].v(i - first) = 1.0;
        Vector3<Jet> d;
        model.evaluate_jet(t.data(), data.rows[r], ctx[r], scratch, &d);
        for (size_t i = first; i < last; ++i)
          for (int k = 0; k < 3; ++k) fast(k, jp[i]) = d(k).v(i - first);
      }
      model.analytic_columns(scratch, ds, fast.data());
      const auto ad = model.displacement_jacobian(theta, data.rows[r], ctx[r]);
      for (int k = 0; k < p; ++k)
        EXPECT_LE((fast.col(k) - ad.col(k)).norm(), 1e-12 * ad.col(k).norm() + 1e-300)
            << model.model_string() << " " << model.spec(k).name << " row " << r;
    }
  }
  for (const std::vector<std::string>& effects :
       {std::vector<std::string>{"joint", "point_offset", "tracker_frame"},
        std::vector<std::string>{"joint", "link", "coupling"},
        std::vector<std::string>{"point_offset"}}) {
    const DeflectionModel model(robot, effects, &data);
    EXPECT_FALSE(model.analytic()) << model.model_string();
    EXPECT_EQ(static_cast<int>(model.jet_parameters().size()), model.parameter_count());
  }
}

// Models made only of linear effects (Effect::linear) predict d affine in theta, so that
// identify() needs one Jacobian per measurement; effects that move the points or the wrench,
// rotate the measurement or multiply the compliances are not linear, nor is backlash, whose
// preload errors s_j move the torque at which it jumps.
TEST(IdentifyCeres, LinearEffectsGiveAnAffineModel) {
  const RobotModel robot = test::rokae();
  const Dataset data = test::design60(5, 8);
  for (const std::vector<std::string>& effects :
       {std::vector<std::string>{"joint"},
        std::vector<std::string>{"joint", "link", "coupling", "gravity_compensator",
                                 "tool_compliance", "drift"},
        std::vector<std::string>{"joint", "nonlinear_joint"}}) {
    const DeflectionModel model(robot, effects, &data);
    ASSERT_TRUE(model.linear()) << model.model_string();
    const int p = model.parameter_count();
    Eigen::VectorXd t0 = model.start_parameters(), t1 = t0;
    for (int k = 0; k < p; ++k) {
      t0(k) += 0.3 * std::abs(model.spec(k).typical) * (k % 3 - 1);
      t1(k) += 0.7 * std::abs(model.spec(k).typical) * (k % 2 ? 1 : -0.5);
    }
    const auto ctx = model.contexts(data);
    for (size_t r = 0; r < data.rows.size(); ++r) {
      const auto j0 = model.displacement_jacobian(t0, data.rows[r], ctx[r]);
      const auto j1 = model.displacement_jacobian(t1, data.rows[r], ctx[r]);
      const double scale = j0.cwiseAbs().maxCoeff();
      EXPECT_LE((j1 - j0).cwiseAbs().maxCoeff(), 1e-12 * scale) << model.model_string();
      const Eigen::Vector3d d0 = model.predict(t0, data.rows[r], ctx[r]).head<3>();
      const Eigen::Vector3d d1 = model.predict(t1, data.rows[r], ctx[r]).head<3>();
      EXPECT_LE((d1 - d0 - j0 * (t1 - t0)).cwiseAbs().maxCoeff(), 1e-12 * d1.cwiseAbs().maxCoeff())
          << model.model_string();
    }
  }
  for (const char* other :
       {"point_offset", "tracker_frame", "force_frame", "complementary", "backlash"})
    EXPECT_FALSE(DeflectionModel(robot, {"joint", other}, &data).linear()) << other;
}

// A parameter whose unconstrained optimum lies beyond its bound ends exactly on the bound
// (held there by the active set rather than approached by clipped steps) and the solution
// satisfies the bound's optimality condition: moving the parameter into the feasible range
// raises the cost.
TEST(IdentifyCeres, ParameterOnItsBoundIsOptimal) {
  Truth truth = joint_truth(test::paper_stiffness());
  const Dataset data = simulated(truth, 21, 0.0, nullptr, 10);
  const FitResult f = identify(test::rokae(), data, {"joint", "link", "point_offset"});
  int at_bound = -1;
  for (size_t k = 0; k < f.parameters.size(); ++k)
    if (f.parameters[k].identified && f.parameters[k].effect == "link" &&
        f.parameters[k].value == 0.0)
      at_bound = static_cast<int>(k);
  ASSERT_GE(at_bound, 0) << "no link spring ended on its bound with this seed";
  const DeflectionModel model(test::rokae(), f.model, &data);
  Eigen::VectorXd theta(f.parameters.size());
  for (size_t k = 0; k < f.parameters.size(); ++k) theta(k) = f.parameters[k].value;
  const auto ctx = model.contexts(data);
  auto rss = [&](const Eigen::VectorXd& t) {
    double ss = 0;
    for (size_t r = 0; r < data.rows.size(); ++r)
      ss += (data.rows[r].displacement - model.predict(t, data.rows[r], ctx[r]).head<3>())
                .squaredNorm();
    return ss;
  };
  Eigen::VectorXd up = theta;
  up(at_bound) += 0.01 * std::abs(model.spec(at_bound).typical);
  EXPECT_GT(rss(up), rss(theta));
}

}  // namespace
}  // namespace stiff

namespace stiff {
namespace {

// Tukey's biweight from the least-squares start stopped where it started when 4 of 40 rows were
// 2 mm off (rank 0, stiffness = the start, "at the noise floor"); on clean data it flagged 12
// of 40 rows (its scale was Huber's). It now starts from the Huber fit with the scale of equal
// Gaussian efficiency.
TEST(IdentifyCeres, TukeyStartsFromHuberAndFlagsOnlyTheOutliers) {
  const Truth truth = joint_truth(test::paper_stiffness());
  for (int seed = 1; seed <= 3; ++seed) {
    const Dataset clean = simulated(truth, seed, 0.0, nullptr, 40);
    Dataset dirty = clean;
    const std::set<int> bad = {3, 11, 20, 33};
    for (int r : bad) dirty.rows[r].displacement(0) += 2e-3;
    const Dataset val = simulated(truth, 600 + seed);
    IdentifyOptions tukey;
    tukey.loss = "tukey";
    const FitResult fc = identify(test::rokae(), clean, {"joint"});
    const FitResult ft = identify(test::rokae(), dirty, {"joint"}, tukey);
    EXPECT_EQ(ft.rank, fc.rank) << "seed " << seed;
    EXPECT_LT(validation_rms(ft, val), 1.2 * validation_rms(fc, val)) << "seed " << seed;
    std::set<int> flagged;
    for (const auto& o : ft.outliers) flagged.insert(o.row);
    EXPECT_EQ(flagged, bad) << "seed " << seed;
    // Clean data: a clean row is below the weight 1/2 of a 10.4 sigma biweight unless its
    // 3-D residual exceeds 5.6 sigma (probability ~1e-6): none is flagged.
    const FitResult ftc = identify(test::rokae(), clean, {"joint"}, tukey);
    EXPECT_TRUE(ftc.outliers.empty())
        << ftc.outliers.size() << " clean rows flagged, seed " << seed;
  }
}

// A robust fit that rejects most rows is not a fit.
TEST(IdentifyCeres, RobustFitRejectingMostRowsIsAnError) {
  const Truth truth = joint_truth(test::paper_stiffness());
  Dataset d = simulated(truth, 4, 0.0, nullptr, 40);
  IdentifyOptions huber;
  huber.loss = "huber";
  huber.loss_scale_m = 1e-9;  // 1 nm: every row is 10^4 scales off
  try {
    identify(test::rokae(), d, {"joint"}, huber);
    FAIL() << "accepted";
  } catch (const NumericalError& e) {
    EXPECT_NE(std::string(e.what()).find("rejected"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace stiff

namespace stiff {

// A common gain of the load is exactly a common scale of every compliance-like term
// (d(s F) = s d(F)), a combination that must be held. The load's gains are held, not a
// coupling: a coupling held goes to 0, where it drops out of the combination, which then
// forms again among the others, and the selection of optional terms on that near-singular
// linearisation let every coupling go "at no cost" (a coupling of joints 2 and 4 beside a
// flange sensor's frame error was fitted at 50 um RMS when force_frame came first in the
// model, at the noise floor the other way round). The fit does not depend on the order.
TEST(IdentifyCeres, LoadGainsAreHeldNotTheCouplings) {
  const RobotModel robot = test::rokae();
  const Dataset design = test::design60(21);
  const std::vector<std::string> truth_effects{"joint", "force_frame", "coupling"};
  const DeflectionModel tm(robot, truth_effects, &design);
  Truth truth;
  truth.effects = truth_effects;
  truth.theta = tm.null_parameters();
  truth.theta.head(6) = test::paper_stiffness().cwiseInverse();
  const int ff = tm.offset(tm.find("force_frame")), cp = tm.offset(tm.find("coupling"));
  const double frame[12] = {-0.07, -0.12, -0.01, -0.04, 0.04, -0.04, 0, 0, 0, 0, 0, 0};
  for (int k = 0; k < 12; ++k) truth.theta(ff + k) = frame[k];
  int c24 = -1;
  for (int k = 0; k < tm.effects()[tm.find("coupling")]->size(); ++k)
    if (tm.spec(cp + k).name == "c24") c24 = cp + k;
  ASSERT_GE(c24, 0);
  truth.theta(c24) = 4.5e-5;  // rad/(N*m): half the geometric mean of c2 and c4
  NoiseModel noise;
  noise.tracker_sigma_m = 20e-6;
  noise.seed = 5;
  const Dataset data = simulate(robot, truth, design, noise);
  double rms[2];
  int at = 0;
  for (const std::vector<std::string>& effects :
       {truth_effects, std::vector<std::string>{"joint", "coupling", "force_frame"}}) {
    const FitResult fit = identify(robot, data, effects, IdentifyOptions{});
    rms[at++] = fit.rms_m;
    const std::map<std::string, double> v = fit.values();
    const FitParameter* c = nullptr;
    for (const auto& par : fit.parameters)
      if (par.effect == "coupling" && par.name == "c24") c = &par;
    ASSERT_NE(c, nullptr);
    EXPECT_TRUE(c->identified) << effects[1];
    EXPECT_LT(std::abs(c->value - 4.5e-5), 4.0 * c->standard_error + 1e-12) << effects[1];
    // At the noise (20 um per axis of a displacement; the fit's degrees of freedom lower it).
    EXPECT_LT(fit.rms_m, 1.1 * noise.tracker_sigma_m) << effects[1];
  }
  // Without the last gain of each frame held, the two differ by 3 %.
  EXPECT_NEAR(rms[0], rms[1], 0.01 * rms[1]);
}

// Beside a reducer whose compliance changes with the cube of the load torque the model is no
// longer homogeneous in the load, and the data seem to see a common gain of the force sensor
// (it trades against the reducer's level terms): the last gain of each frame is held all the
// same, and the fit predicts new poses at the noise.
TEST(IdentifyCeres, ACommonGainIsHeldBesideANonlinearReducer) {
  const RobotModel robot = test::rokae();
  const std::vector<std::string> effects{"joint", "force_frame", "nonlinear_joint"};
  const Dataset design = test::design60(23), fresh = test::design60(24, 40);
  const DeflectionModel tm(robot, effects, &design);
  Truth truth;
  truth.effects = effects;
  truth.theta = tm.null_parameters();
  const Eigen::VectorXd c = test::paper_stiffness().cwiseInverse();
  truth.theta.head(6) = c;
  const int ff = tm.offset(tm.find("force_frame")), nj = tm.offset(tm.find("nonlinear_joint"));
  const double frame[6] = {-0.07, 0.1, 0.02, 0.04, -0.02, 0.045};  // rotation, flange gains
  for (int k = 0; k < 6; ++k) truth.theta(ff + k) = frame[k];
  for (int k = 0; k < tm.effects()[tm.find("nonlinear_joint")]->size(); ++k) {
    const std::string& name = tm.spec(nj + k).name;
    if (name == "g2") truth.theta(nj + k) = -3.0 * c(1);  // softening with the cube
    if (name == "g3") truth.theta(nj + k) = -3.0 * c(2);
  }
  NoiseModel noise;
  noise.tracker_sigma_m = 20e-6;
  noise.seed = 7;
  const Dataset data = simulate(robot, truth, design, noise);
  noise.seed = 8;
  const Dataset valid = simulate(robot, truth, fresh, noise);
  const FitResult fit = identify(robot, data, effects, IdentifyOptions{});
  for (const auto& par : fit.parameters)
    if (par.effect == "force_frame" && (par.name == "scale_z" || par.name == "scale_base_z")) {
      EXPECT_FALSE(par.identified) << par.name;
      EXPECT_EQ(par.value, 0.0) << par.name;
    }
  const DeflectionModel fm(robot, effects, &data);
  const Eigen::VectorXd theta = fit.theta();
  const auto ctx = fm.contexts(valid);
  double ss = 0;
  for (size_t r = 0; r < valid.rows.size(); ++r)
    ss += (valid.rows[r].observed() - fm.predict(theta, valid.rows[r], ctx[r]).head<3>())
              .squaredNorm();
  const double rms = std::sqrt(ss / (3.0 * static_cast<double>(valid.rows.size())));
  // New poses: the noise and the fitted parameters' own error (about p / n of it, 17 / 180).
  EXPECT_LT(rms, 1.2 * noise.tracker_sigma_m);
}
}  // namespace stiff

namespace stiff {
// A force-reading error sits in one frame: a sensor turned on the flange, or a fixture pulling
// askew in the base frame. On 30 rows the other frame's six terms stood in for part of the
// true frame's and raised the error on new poses (1.30 times what the true frame reaches on an
// independent simulator's scenario); the fit now drops the frame the data do not support as a
// whole, whichever it is.
TEST(IdentifyCeres, AForceFrameErrorIsFittedInItsOwnFrame) {
  const RobotModel robot = test::rokae();
  const std::vector<std::string> effects{"joint", "force_frame"};
  for (const bool base : {true, false}) {
    double full_ss = 0, chosen_ss = 0;
    for (int seed = 0; seed < 3; ++seed) {
      const Dataset design = test::design60(31 + seed, 30), fresh = test::design60(41 + seed, 40);
      const DeflectionModel tm(robot, effects, &design);
      Truth truth;
      truth.effects = effects;
      truth.theta = tm.null_parameters();
      truth.theta.head(6) = test::paper_stiffness().cwiseInverse();
      const int ff = tm.offset(tm.find("force_frame")) + (base ? 6 : 0);
      const double frame[5] = {0.06, -0.03, -0.09, -0.08, 0.05};  // rotation, gains x and y
      for (int k = 0; k < 5; ++k) truth.theta(ff + k) = frame[k];
      NoiseModel noise;
      noise.tracker_sigma_m = 20e-6;
      noise.seed = 50 + seed;
      const Dataset data = simulate(robot, truth, design, noise);
      noise.seed = 60 + seed;
      const Dataset valid = simulate(robot, truth, fresh, noise);
      IdentifyOptions all;
      all.select_terms = false;
      const FitResult chosen = identify(robot, data, effects, IdentifyOptions{});
      const FitResult full = identify(robot, data, effects, all);
      for (const auto& par : chosen.parameters) {
        if (par.effect != "force_frame" || par.name.rfind("crosstalk", 0) == 0) continue;
        const bool in_base = par.name.find("base") != std::string::npos;
        const bool gauge = par.name == "scale_z" || par.name == "scale_base_z";
        if (in_base != base) {
          EXPECT_FALSE(par.identified) << par.name << " base " << base << " seed " << seed;
          if (!gauge) EXPECT_EQ(par.held, "left_out") << par.name;
        } else if (!gauge) {
          EXPECT_TRUE(par.identified) << par.name << " base " << base << " seed " << seed;
        }
      }
      // The dropped frame is reported in one line naming its six terms (the gauge gain, held
      // before the selection, with them), not a line for each.
      const std::string dropped =
          base ? "force_frame.omega_x, omega_y, omega_z, scale_x and scale_y are left out, with "
                 "scale_z: "
               : "force_frame.omega_base_x, omega_base_y, omega_base_z, scale_base_x and "
                 "scale_base_y are left out, with scale_base_z: ";
      const std::string other = base ? "force_frame.scale_" : "force_frame.scale_base_";
      int lines = 0, frame_lines = 0;
      for (const std::string& w : chosen.warnings) {
        lines += w.rfind(dropped, 0) == 0;
        bool gain = false;
        for (const char* axis : {"x ", "y ", "z "}) gain = gain || w.rfind(other + axis, 0) == 0;
        frame_lines += w.rfind("force_frame.omega", 0) == 0 || gain;
      }
      EXPECT_EQ(lines, 1) << "base " << base << " seed " << seed;
      EXPECT_EQ(frame_lines, 1) << "base " << base << " seed " << seed;
      const DeflectionModel fm(robot, effects, &data);
      const auto ctx = fm.contexts(valid);
      for (const FitResult* f : {&chosen, &full}) {
        const Eigen::VectorXd theta = f->theta();
        double ss = 0;
        for (size_t r = 0; r < valid.rows.size(); ++r)
          ss += (valid.rows[r].observed() - fm.predict(theta, valid.rows[r], ctx[r]).head<3>())
                    .squaredNorm();
        (f == &chosen ? chosen_ss : full_ss) += ss;
      }
    }
    // Six parameters fewer on 90 components: new poses predicted better (20.8 and 21.0 um, both
    // frames 22.8 and 22.9), and near the noise (20 um, about p / n of it more from the fitted
    // parameters, 10 / 90).
    const double n = 3.0 * 3.0 * 40.0;
    EXPECT_LT(chosen_ss, full_ss) << "base " << base;
    EXPECT_LT(std::sqrt(chosen_ss / n), 1.15 * 20e-6) << "base " << base;
  }
}
}  // namespace stiff
