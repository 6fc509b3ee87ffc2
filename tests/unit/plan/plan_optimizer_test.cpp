// Measurement planning optimizers: annealing vs exhaustive search, the ROKAE arm against the
// paper's printed design, NLopt refinement.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>

#include "plan_test_support.hpp"
#include "stiff/plan/plan.hpp"
#include "test_support.hpp"

namespace stiff {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

using test::paper_pool;

TEST(PlanAnnealing, FindsExhaustiveOptimumOnSmallPool) {
  const RobotModel robot = test::rokae();
  const CandidatePool pool = build_pool(robot, paper_pool(4, 4, 3));
  ASSERT_EQ(pool.size(), 16);
  PlanOptions o;
  o.count = 4;
  for (const std::string crit : {"kappa_a", "d_opt"}) {
    o.criterion = crit;
    // Exhaustive: all C(16, 4) = 1820 subsets.
    double best = -INFINITY;
    std::vector<int> arg;
    for (int a = 0; a < 16; ++a)
      for (int b = a + 1; b < 16; ++b)
        for (int c = b + 1; c < 16; ++c)
          for (int d = c + 1; d < 16; ++d) {
            const double s = set_score(robot, pool, {a, b, c, d}, o);
            if (s > best) {
              best = s;
              arg = {a, b, c, d};
            }
          }
    o.annealing.iterations = 5000;
    int hits = 0, exchange_hits = 0;
    const int seeds = 100;
    for (int seed = 1; seed <= seeds; ++seed) {
      o.seed = static_cast<uint64_t>(seed);
      const SetSearchResult r = anneal(robot, pool, o);
      if (r.score >= best - 1e-12 * std::abs(best)) ++hits;
      EXPECT_LE(r.score, best + 1e-12 * std::abs(best));
      const SetSearchResult x = exchange(robot, pool, o);
      if (x.score >= best - 1e-12 * std::abs(best)) ++exchange_hits;
    }
    std::printf(
        "%s: exhaustive optimum %.6g; annealing found it in %d/%d seeds, exchange in %d/%d\n",
        crit.c_str(), crit == "kappa_a" ? best : best, hits, seeds, exchange_hits, seeds);
    EXPECT_GE(hits, 95);  // >= 95 %
  }
}

TEST(PlanAnnealing, ReproducibleWithSeed) {
  const RobotModel robot = test::rokae();
  const CandidatePool pool = build_pool(robot, paper_pool(50, 20));
  PlanOptions o;
  o.annealing.iterations = 5000;
  const SetSearchResult a = anneal(robot, pool, o), b = anneal(robot, pool, o);
  EXPECT_EQ(a.elements, b.elements);
  EXPECT_EQ(a.score, b.score);
}

TEST(PlanAnnealing, RokaeSetAtLeastAsGoodAsPaperDesign) {
  const RobotModel robot = test::rokae();
  const auto paper = evaluate_criteria(robot, test::paper_design_a());
  const auto paper_j = evaluate_criteria(robot, test::paper_design_j());
  const CandidatePool pool = build_pool(robot, paper_pool(500, 100));
  PlanOptions o;
  o.count = 10;
  o.criterion = "kappa_a";  // the paper's criterion, compared with the paper's design
  o.annealing.iterations = 100000;
  o.exchange.enabled = false;
  const auto t0 = std::chrono::steady_clock::now();
  const PlanResult r = plan_measurements(robot, pool, o);
  const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const auto ours = evaluate_criteria(robot, plan_to_dataset(r));
  std::printf("ROKAE, N = 10, pool %d x %d = %d, %ld iterations in %.3f s (plan %.3f s)\n",
              r.pool_poses, r.pool_loads, r.pool_size, r.trace[0].iterations, r.trace[0].seconds,
              sec);
  std::printf(
      "kappa_F^-1(A): annealed %.5f | paper kappa_A design %.5f | paper kappa_J design %.5f\n",
      ours.at("kappa_a"), paper.at("kappa_a"), paper_j.at("kappa_a"));
  std::printf(
      "kappa_F^-1(J): annealed %.5f | paper kappa_A design %.5f | paper kappa_J design %.5f\n",
      ours.at("kappa_j"), paper.at("kappa_j"), paper_j.at("kappa_j"));
  EXPECT_GE(ours.at("kappa_a"), paper.at("kappa_a"));
  EXPECT_NEAR(ours.at("kappa_a"), r.value, 1e-9);
  EXPECT_EQ(r.found_by, "annealing");
}

TEST(PlanRefine, NloptDoesNotWorsenAndRespectsLimits) {
  const RobotModel robot = test::rokae();
  PoolOptions po = paper_pool(60, 30);
  po.load_max_magnitude_N = 50.0;
  const CandidatePool pool = build_pool(robot, po);
  for (const std::string crit : {"kappa_a", "d_opt"}) {
    PlanOptions o;
    o.criterion = crit;
    o.annealing.iterations = 5000;
    o.exchange.enabled = false;
    o.refine.enabled = true;
    o.refine.max_evaluations = 1500;
    const PlanResult r = plan_measurements(robot, pool, o);
    ASSERT_EQ(r.trace.size(), 2u);
    const OptimizerTrace& t = r.trace[1];
    std::printf("%s: annealing %.6g -> nlopt %.6g (%ld evaluations, %s), found by %s\n",
                crit.c_str(), r.trace[0].best_value, t.best_value, t.evaluations, t.message.c_str(),
                r.found_by.c_str());
    EXPECT_GE(t.best_score, t.start_score);
    EXPECT_GE(r.score, r.trace[0].best_score - 1e-9 * std::abs(r.trace[0].best_score));
    for (const auto& m : r.measurements) {
      for (int j = 0; j < 6; ++j) {
        const auto& jt = robot.joints[j];
        const double mid = 0.5 * (jt.lower + jt.upper), half = 0.5 * (jt.upper - jt.lower) * 0.95;
        EXPECT_GE(m.q_rad(j), mid - half - 1e-12);
        EXPECT_LE(m.q_rad(j), mid + half + 1e-12);
      }
      EXPECT_EQ(m.q_rad(5), 0.0);
      for (int k = 0; k < 3; ++k) {
        EXPECT_GE(std::abs(m.force_base_N(k)), 15.0 - 1e-12);
        EXPECT_LE(std::abs(m.force_base_N(k)), 35.0 + 1e-12);
      }
      EXPECT_LE(m.force_base_N.norm(), 50.0 + 1e-9);
      EXPECT_GE(translational_conditioning(robot, m.q_rad).sigma_min, po.min_sigma_m - 1e-12);
    }
  }
}

}  // namespace
}  // namespace stiff
