// Simulate -> identify with the true model, for every effect: every identifiable parameter
// lies within 3 reported standard errors in >= 95 % of seeded runs, and the validation RMS on
// new poses sits at the noise floor.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include "effect_truths.hpp"
#include "stiff/identify/identify.hpp"

namespace stiff {
namespace {

constexpr double kNoise = 10e-6;  // tracker sigma [m]

struct Recovery {
  std::map<std::string, int> inside, runs;  // per parameter: within 3 SE / identified
  std::map<std::string, int> unidentified;
  std::map<std::string, double> se_sum;  // sum of reported standard errors
  std::map<std::string, double> truth;
  // Optional terms (ParameterSpec::optional_term) whose truth is null: how often the fit kept
  // one, out of how many chances.
  int null_kept = 0, null_chances = 0;
  double equations = 0;  ///< weighted residual components of one fit
  double val_ss = 0;
  int val_n = 0;
};

Recovery run(const std::string& effect, int seeds) {
  const RobotModel robot = test::rokae();
  const Truth truth0 = test::effect_truth(effect, robot);
  const Eigen::VectorXd nulls = DeflectionModel(robot, truth0.effects).null_parameters();
  Recovery out;
  for (int seed = 1; seed <= seeds; ++seed) {
    NoiseModel noise;
    noise.tracker_sigma_m = kNoise;
    noise.seed = 1000 + seed;
    // The truth restricted to what the data determine: a parameter the fit holds (redundant
    // with others on these poses) is set to its null value in the truth and the same poses and
    // noise measured again, until the held set is stable; otherwise the held parameter's truth
    // would move its partners. Skipped when that changes no measurement by 1e-3 sigma.
    Truth truth = truth0;
    Dataset data = test::measure(robot, truth, test::design60(seed), noise);
    FitResult fit = identify(robot, data, truth.effects, IdentifyOptions{});
    for (int round = 0; round < 4; ++round) {
      Truth restricted = truth;
      for (size_t k = 0; k < fit.parameters.size(); ++k)
        if (!fit.parameters[k].identified) restricted.theta(k) = nulls(k);
      if (restricted.theta == truth.theta) break;
      const Dataset again = test::measure(robot, restricted, test::design60(seed), noise);
      double moved = 0;
      for (size_t r = 0; r < data.size(); ++r)
        moved = std::max(moved, (again.rows[r].observed() - data.rows[r].observed()).norm());
      truth = restricted;
      if (moved < 1e-3 * kNoise) break;
      data = again;
      fit = identify(robot, data, truth.effects, IdentifyOptions{});
    }
    // A parameter that the effect decides from the data before the fit (ParameterSpec::
    // from_data: backlash's preload errors, found by threshold regression) is not a
    // least-squares estimate with a standard error; its coverage is not tested here.
    const DeflectionModel model(robot, truth.effects, &data);
    out.equations = 3.0 * static_cast<double>(data.size());
    for (size_t k = 0; k < fit.parameters.size(); ++k) {
      const auto& p = fit.parameters[k];
      const std::string key = p.effect + "." + p.name;
      if (model.spec(static_cast<int>(k)).from_data) continue;
      out.truth[key] = truth.theta(k);
      // A null optional term is kept only when its estimate happens to be large: the standard
      // errors do not cover the selection, so it counts towards the false-inclusion rate.
      if (model.spec(static_cast<int>(k)).optional_term && truth.theta(k) == nulls(k)) {
        ++out.null_chances;
        out.null_kept += p.identified;
        continue;
      }
      if (!p.identified) {
        ++out.unidentified[key];
        continue;
      }
      ++out.runs[key];
      out.se_sum[key] += p.standard_error;
      if (std::abs(p.value - truth.theta(k)) <= 3 * p.standard_error) ++out.inside[key];
    }
    noise.seed = 5000 + seed;
    const Dataset val = test::measure(robot, truth, test::design60(100000 + seed), noise);
    const Eigen::MatrixXd pred = predict_dataset(robot, fit, val);
    for (size_t r = 0; r < val.size(); ++r) {
      out.val_ss += (val.rows[r].observed() - pred.row(r).head<3>().transpose()).squaredNorm();
      out.val_n += 3;
    }
  }
  return out;
}

void check(const std::string& effect, int seeds) {
  const Recovery rec = run(effect, seeds);
  // Nominal coverage of +-3 SE is 99.7 %; allow 95 % (at most 2 misses in 40 runs), and 2
  // misses for a term kept in fewer runs (an optional term's estimate moves with the terms the
  // criterion keeps beside it: 1 miss in 13 runs is not a coverage of 92 %).
  for (const auto& [key, n] : rec.runs) {
    const int in = rec.inside.count(key) ? rec.inside.at(key) : 0;
    std::printf("  %-34s within 3 SE in %d of %d runs (truth %.3g, mean SE %.3g)\n", key.c_str(),
                in, n, rec.truth.at(key), rec.se_sum.at(key) / n);
    EXPECT_LE(n - in, std::max(2.0, 0.05 * n)) << key;
  }
  for (const auto& [key, n] : rec.unidentified)
    std::printf("  %-34s held (unidentifiable) in %d runs\n", key.c_str(), n);
  // The information criterion keeps a null term when its chi-square (1 dof) exceeds ln(m), m
  // the residual components: probability erfc(sqrt(ln(m) / 2)) per chance. Binomial count
  // within four standard deviations of that.
  if (rec.null_chances > 0) {
    const double q = std::erfc(std::sqrt(std::log(rec.equations) / 2.0));
    const double mean = q * rec.null_chances;
    std::printf("  optional terms with null truth kept in %d of %d chances (expected %.1f)\n",
                rec.null_kept, rec.null_chances, mean);
    EXPECT_LE(rec.null_kept, mean + 4.0 * std::sqrt(mean * (1.0 - q)) + 1.0);
  }
  // Prediction error on new poses: noise plus the estimation error of ~10-20 parameters from
  // 180 equations, sqrt(1 + p/3N) ~ 1.03-1.05 times the noise; within 10 %.
  const double rms = std::sqrt(rec.val_ss / rec.val_n);
  std::printf("  validation RMS %.2f um (noise %.2f um), ratio %.3f\n", rms * 1e6, kNoise * 1e6,
              rms / kNoise);
  EXPECT_GT(rms, 0.9 * kNoise);
  EXPECT_LT(rms, 1.1 * kNoise);
}

class EffectRecovery : public ::testing::TestWithParam<std::string> {};

TEST_P(EffectRecovery, WithinThreeStandardErrors) { check(GetParam(), 40); }

// Heavier sweep (label-free but named Slow so that ctest -E Slow skips it).
TEST_P(EffectRecovery, SlowWithinThreeStandardErrors200Seeds) { check(GetParam(), 200); }

INSTANTIATE_TEST_SUITE_P(Effects,
                         EffectRecovery,
                         ::testing::ValuesIn(effect_names()),
                         [](const auto& p) { return p.param; });

TEST(EffectRecoveryDetails, PointOffsetMakesJointSixIdentifiable) {
  const RobotModel robot = test::rokae();
  const Truth truth = test::effect_truth("point_offset", robot);
  NoiseModel noise;
  noise.tracker_sigma_m = kNoise;
  const Dataset data = simulate(robot, truth, test::design60(7), noise);
  const FitResult fit = identify(robot, data, truth.effects, IdentifyOptions{});
  ASSERT_TRUE(fit.parameters[5].identified);
  EXPECT_NEAR(fit.parameters[5].value, truth.theta(5), 3 * fit.parameters[5].standard_error);
  EXPECT_LT(fit.parameters[5].standard_error, 0.5 * truth.theta(5));
}

}  // namespace
}  // namespace stiff
