// Measurement planning: pool, criteria, incremental updates, errors, output.
#include "stiff/plan/plan.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>

#include "plan_test_support.hpp"
#include "stiff/error.hpp"
#include "stiff/model/model.hpp"
#include "stiff/random.hpp"
#include "test_support.hpp"
// The optimizers' packed fast path is internal; it is tested against the generic kernels.
#include "plan/plan_internal.hpp"

namespace stiff {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

using test::paper_pool;

TEST(PlanPool, BlocksEqualObservationBlockAndJoint6Drops) {
  const RobotModel robot = test::rokae();
  const CandidatePool pool = build_pool(robot, paper_pool(20, 10));
  EXPECT_EQ(pool.size(), 200);
  ASSERT_EQ(pool.identified_joints, (std::vector<int>{0, 1, 2, 3, 4}));
  for (int e = 0; e < pool.size(); e += 17) {
    const Eigen::VectorXd& q = pool.poses[pool.element_pose[e]];
    EXPECT_EQ(q(5), 0.0);
    const ChainState s = robot.chain(q);
    const Matrix6X<double> j = robot.jacobian_at(s, robot.point_position(s, robot.measured_point));
    Eigen::Matrix<double, 6, 1> w;
    w << pool.forces[pool.element_load[e]], Eigen::Vector3d::Zero();
    const Eigen::Matrix<double, 3, Eigen::Dynamic> full = observation_block(j, j, w);
    EXPECT_LT((pool.block(e) - full.leftCols(5)).norm(), 1e-12 * full.norm());
    EXPECT_LT(pool.sigma_min_m[pool.element_pose[e]] + 1e-15, 1e9);
    EXPECT_GE(pool.sigma_min_m[pool.element_pose[e]], pool.min_sigma_m);
  }
  for (const auto& f : pool.forces)
    for (int k = 0; k < 3; ++k) {
      EXPECT_GE(std::abs(f(k)), 15.0);
      EXPECT_LE(std::abs(f(k)), 35.0);
      EXPECT_EQ(std::fmod(std::abs(f(k)), 5.0), 0.0);
    }
}

TEST(PlanPool, FullGridFixtureAndCandidateFile) {
  const RobotModel robot = test::rokae();
  PoolOptions o = paper_pool(3, 0);
  o.load_max_magnitude_N = 40.0;
  const CandidatePool grid = build_pool(robot, o);
  for (const auto& f : grid.forces) EXPECT_LE(f.norm(), 40.0 + 1e-9);
  EXPECT_GT(grid.forces.size(), 0u);
  EXPECT_LT(grid.forces.size(), 1000u);

  PoolOptions fx = paper_pool(3, 0);
  fx.fixture_directions = {Eigen::Vector3d::UnitX(), -Eigen::Vector3d::UnitY(),
                           Eigen::Vector3d(1, 1, 1)};
  fx.fixture_forces_N = {20.0, 30.0};
  EXPECT_EQ(build_pool(robot, fx).forces.size(), 6u);

  PoolOptions file = paper_pool(0, 5);
  file.candidate_file = test::source_path("examples/paper/design_kappa_a.csv");
  const CandidatePool fp = build_pool(robot, file);
  EXPECT_EQ(fp.poses.size(), 10u);
  EXPECT_EQ(fp.size(), 50);
  file.candidate_loads_from_file = true;
  file.min_sigma_m = 0.0;
  EXPECT_EQ(build_pool(robot, file).size(), 10);
}

TEST(PlanIncremental, EqualsFullRecomputationOverLongSwapSequences) {
  const RobotModel robot = test::rokae();
  const CandidatePool pool = build_pool(robot, paper_pool(200, 50));
  Rng rng(7);
  std::vector<int> set;
  for (int i = 0; i < 10; ++i) set.push_back(static_cast<int>(rng.index(pool.size())));
  IncrementalInformation inc(pool, set);
  double worst = 0.0;
  for (int step = 1; step <= 20000; ++step) {
    inc.replace(static_cast<int>(rng.index(10)), static_cast<int>(rng.index(pool.size())));
    if (step % 1000 == 0) {
      const Eigen::MatrixXd full = inc.recomputed_information();
      worst = std::max(worst, (inc.information() - full).norm() / full.norm());
    }
  }
  std::printf("max relative difference after up to 20000 rank-3 updates: %.3g\n", worst);
  EXPECT_LT(worst, 1e-12);
  // A single rank-3 update equals A_in^T A_in - A_out^T A_out of observation blocks.
  const Eigen::MatrixXd before = inc.recomputed_information();
  const int out = inc.elements()[3];
  inc.replace(3, 5);
  const Eigen::MatrixXd expect = before + pool.information(5) - pool.information(out);
  EXPECT_LT((inc.information() - expect).norm(), 1e-12 * expect.norm());
}

// The optimizers' fast path (packed storage, fixed size, per-element table) gives the same
// criterion values as the generic path (full storage, runtime size, on-the-fly elements) on
// random sets: bit for bit, since it does the same operations in the same order.
template <plan_detail::Crit C>
void expect_same_scores(const CandidatePool& pool, const plan_detail::Context& ctx, Rng& rng) {
  using namespace plan_detail;
  const int m = pool.identified_count(), t = packed_size(m);
  const bool jac = C == Crit::kappa_j;
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<double> full(m * m, 0.0), packed(t, 0.0), fixed(t, 0.0), g(t);
    for (int i = 0; i < 10; ++i) {
      const int e = static_cast<int>(rng.index(pool.size()));
      if (jac) {
        add_jacobian<0>(pool, e, 1.0, full.data());
        element_jacobian_information<0>(pool, e, g.data());
      } else {
        add_element<0>(pool, e, 1.0, full.data());
        element_information<0>(pool, e, g.data());
        if (const double* table = kernel_of(pool).element_table()) {
          const double* row = table + static_cast<size_t>(e) * kernel_of(pool).element_table_stride;
          for (int q = 0; q < t; ++q) ASSERT_EQ(g[q], row[q]);
        }
      }
      for (int q = 0; q < t; ++q) packed[q] += g[q];
    }
    const double generic = score<0>(ctx, full.data(), full.data());
    EXPECT_EQ((score_packed<5, C>(ctx, packed.data())), generic) << static_cast<int>(C);
    EXPECT_EQ((score_packed<0, C>(ctx, packed.data())), generic) << static_cast<int>(C);
    EXPECT_TRUE(std::isfinite(generic));
  }
}

// The packed layout is a bijection onto 0 .. m (m + 1) / 2 - 1 whose first
// packed_bound_size(m) positions are the 2 x 2 diagonal blocks the bound reads.
TEST(PlanFastPath, PackedLayoutPutsTheBoundBlocksFirst) {
  using namespace plan_detail;
  for (int m = 1; m <= kMaxM; ++m) {
    std::vector<int> hits(packed_size(m), 0);
    for (int r = 0; r < m; ++r)
      for (int c = 0; c <= r; ++c) {
        const int at = packed_index(m, r, c);
        ASSERT_GE(at, 0);
        ASSERT_LT(at, packed_size(m));
        ++hits[at];
        EXPECT_EQ(at < packed_bound_size(m), r / 2 == c / 2) << m << " " << r << " " << c;
      }
    for (int h : hits) EXPECT_EQ(h, 1) << "m = " << m;
  }
  EXPECT_EQ(packed_bound_size(5), 7);
}

TEST(PlanFastPath, SameCriterionValuesAsGenericPathOnRandomSets) {
  using namespace plan_detail;
  const RobotModel robot = test::rokae();
  const CandidatePool pool = build_pool(robot, paper_pool(200, 50));
  ASSERT_EQ(pool.identified_count(), 5);
  // Table stored, rows on 64-byte lines, two lines each.
  const KernelData& k = kernel_of(pool);
  ASSERT_NE(k.element_table(), nullptr);
  ASSERT_EQ(reinterpret_cast<std::uintptr_t>(k.element_table()) % 64, 0u);
  ASSERT_EQ(k.element_table_stride, 16);
  // A copy of the kernel data (as a pool without a shared kernel would make) is aligned too.
  const KernelData copy = k;
  ASSERT_EQ(reinterpret_cast<std::uintptr_t>(copy.element_table()) % 64, 0u);
  for (int e : {0, pool.size() / 2, pool.size() - 1})
    for (int q = 0; q < 15; ++q)
      ASSERT_EQ(copy.element_table()[16 * e + q], k.element_table()[16 * e + q]);
  const std::vector<double> task =
      task_information(robot, test::paper_design_j(), pool.identified_joints);
  Rng rng(11);
  for (Crit id : {Crit::kappa_a, Crit::kappa_j, Crit::d_opt, Crit::a_opt, Crit::e_opt, Crit::o1,
                  Crit::task}) {
    Context ctx;
    ctx.id = id;
    ctx.m = 5;
    ctx.count = 10;
    ctx.task = task.data();
    switch (id) {
      case Crit::kappa_a:
        expect_same_scores<Crit::kappa_a>(pool, ctx, rng);
        break;
      case Crit::kappa_j:
        expect_same_scores<Crit::kappa_j>(pool, ctx, rng);
        break;
      case Crit::d_opt:
        expect_same_scores<Crit::d_opt>(pool, ctx, rng);
        break;
      case Crit::a_opt:
        expect_same_scores<Crit::a_opt>(pool, ctx, rng);
        break;
      case Crit::e_opt:
        expect_same_scores<Crit::e_opt>(pool, ctx, rng);
        break;
      case Crit::o1:
        expect_same_scores<Crit::o1>(pool, ctx, rng);
        break;
      case Crit::task:
        expect_same_scores<Crit::task>(pool, ctx, rng);
        break;
    }
  }
  // Singular sets give the worst value on both paths.
  std::vector<double> zero_full(25, 0.0), zero_packed(15, 0.0);
  Context ctx;
  ctx.m = 5;
  ctx.count = 10;
  EXPECT_EQ((score_packed<5, Crit::kappa_a>(ctx, zero_packed.data())), 0.0);
  ctx.id = Crit::d_opt;
  EXPECT_EQ((score_packed<5, Crit::d_opt>(ctx, zero_packed.data())),
            score<0>(ctx, zero_full.data(), zero_full.data()));
}

TEST(PlanFastPath, AnnealingWithAndWithoutElementTableAndFastRng) {
  using namespace plan_detail;
  // FastRng is std::mt19937_64, hence Rng's stream.
  for (uint64_t seed : {1ULL, 42ULL, (1ULL << 63) + 5}) {
    Rng a(seed), b(seed);
    FastRng f(seed), g(seed);
    for (int i = 0; i < 2000; ++i) ASSERT_EQ(f(), a.engine()());
    for (int i = 0; i < 2000; ++i) ASSERT_EQ(g.index(7 + i), b.index(7 + i));
  }
  // A pool above the table budget computes the elements on the fly: same plan.
  const RobotModel robot = test::rokae();
  const CandidatePool pool = build_pool(robot, paper_pool(100, 20));
  ASSERT_NE(plan_detail::kernel_of(pool).element_table(), nullptr);
  CandidatePool no_table = pool;
  auto k = std::make_shared<plan_detail::KernelData>(plan_detail::kernel_of(pool));
  k->element_table_storage.clear();
  no_table.kernel = k;
  ASSERT_EQ(plan_detail::kernel_of(no_table).element_table(), nullptr);
  PlanOptions o;
  o.annealing.iterations = 5000;
  o.exchange.max_passes = 2;
  for (const std::string crit : {"kappa_a", "d_opt", "a_opt"}) {
    o.criterion = crit;
    const SetSearchResult a = anneal(robot, pool, o), b = anneal(robot, no_table, o);
    EXPECT_EQ(a.elements, b.elements) << crit;
    EXPECT_EQ(a.score, b.score) << crit;
    const SetSearchResult x = exchange(robot, pool, o), y = exchange(robot, no_table, o);
    EXPECT_EQ(x.elements, y.elements) << crit;
    EXPECT_EQ(x.score, y.score) << crit;
    EXPECT_NEAR(a.score, set_score(robot, pool, a.elements, o), 1e-12 * std::abs(a.score)) << crit;
  }
}

// The annealing's closed form (Schur complement, adjugates) against Eigen's LLT for m = 1..6,
// on weighted information matrices of the size the pools produce (entries ~1e13) with column
// scales over four decades (condition numbers up to ~1e9); rank-deficient ones are declined.
template <int M>
void pack_lower(const Eigen::MatrixXd& info, double* packed) {
  for (int i = 0; i < M; ++i)
    for (int j = 0; j <= i; ++j) packed[plan_detail::packed_index(M, i, j)] = info(i, j);
}

// A weighted information matrix as the pools produce it: 3M + 3 Gaussian rows, column scales
// over four decades, entries ~1e13 (condition numbers up to ~1e9).
template <int M>
Eigen::MatrixXd random_information(Rng& rng) {
  Eigen::MatrixXd a(3 * M + 3, M);
  for (int i = 0; i < a.rows(); ++i)
    for (int j = 0; j < M; ++j) a(i, j) = rng.normal();
  for (int j = 0; j < M; ++j) a.col(j) *= std::pow(10.0, 2.0 * rng.uniform());
  return 1e10 * (a.transpose() * a);
}

template <int M>
void expect_closed_form_matches_cholesky(Rng& rng) {
  using namespace plan_detail;
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::MatrixXd info = random_information<M>(rng);
    double packed[21];
    pack_lower<M>(info, packed);
    ClosedForm f;
    ASSERT_TRUE(closed_form<M>(packed, f)) << "m = " << M;
    const Eigen::LLT<Eigen::MatrixXd> llt(info);
    const double trinv = llt.solve(Eigen::MatrixXd::Identity(M, M)).trace();
    const double logdet = 2.0 * llt.matrixLLT().diagonal().array().log().sum();
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(info);
    const double cond = svd.singularValues()(0) / svd.singularValues()(M - 1);
    // Adjugate products lose about cond * eps.
    const double tol = 64 * std::numeric_limits<double>::epsilon() * std::max(1.0, cond);
    EXPECT_NEAR(f.num / f.den, trinv, tol * trinv) << "m = " << M << " cond " << cond;
    EXPECT_NEAR(std::log(f.det_num / f.det_den), logdet, tol * std::abs(logdet) + tol)
        << "m = " << M;
    EXPECT_NEAR(f.tr, info.trace(), 1e-15 * info.trace());
  }
  if constexpr (M > 1) {
    // Rank M - 1: declined, the caller falls back to the Cholesky path.
    Eigen::MatrixXd a(3 * M, M);
    for (int i = 0; i < a.rows(); ++i)
      for (int j = 0; j < M; ++j) a(i, j) = rng.normal();
    a.col(M - 1) = a.col(0) - 0.5 * a.col(M - 2);
    const Eigen::MatrixXd info = 1e10 * (a.transpose() * a);
    double packed[21];
    pack_lower<M>(info, packed);
    ClosedForm f;
    EXPECT_FALSE(closed_form<M>(packed, f)) << "m = " << M;
  }
}

TEST(PlanFastPath, ClosedFormEqualsCholeskyForEveryM) {
  Rng rng(11);
  expect_closed_form_matches_cholesky<1>(rng);
  expect_closed_form_matches_cholesky<2>(rng);
  expect_closed_form_matches_cholesky<3>(rng);
  expect_closed_form_matches_cholesky<4>(rng);
  expect_closed_form_matches_cholesky<5>(rng);
  expect_closed_form_matches_cholesky<6>(rng);
}

// The annealing's early rejection (bound_rejects: block-diagonal bounds on tr M^-1 and det M)
// never rejects a proposal the exact test accepts, for m = 1..6 and each closed-form criterion,
// with thresholds spread around the exact value (relative 0.5 ... 2 and within 1e-9 of it);
// and it is not vacuous: it rejects most proposals whose exact value misses the threshold by a
// factor of 4, and for m = 1 and 2 (one block: the bound is exact) every one that misses at all.
template <int M, plan_detail::Crit C>
void expect_bound_is_a_bound(Rng& rng) {
  using namespace plan_detail;
  int missed = 0, missed_by_4 = 0, rejected = 0, rejected_by_4 = 0;
  for (int trial = 0; trial < 400; ++trial) {
    double packed[21];
    pack_lower<M>(random_information<M>(rng), packed);
    double p, q;
    const bool closed = raw_fraction<M, C>(packed, p, q);
    ASSERT_TRUE(closed);
    const double exact = p / q;
    for (const double f : {0.25, 0.5, 0.9, 1.0 - 1e-9, 1.0 + 1e-9, 1.1, 2.0, 4.0}) {
      // For d_opt the test passes when det >= threshold, for the others when value <= threshold.
      const double threshold = C == Crit::d_opt ? exact / f : exact * f;
      const bool exact_accepts = within<C>(p, q, threshold);
      const bool bound = bound_rejects<M, C>(packed, threshold);
      EXPECT_FALSE(bound && exact_accepts) << "m = " << M << " factor " << f;
      if (!exact_accepts) {
        ++missed;
        rejected += bound;
        if (f == 0.25) {
          ++missed_by_4;
          rejected_by_4 += bound;
        }
      }
    }
  }
  ASSERT_GT(missed_by_4, 0);
  if (M <= 2)
    EXPECT_EQ(rejected, missed) << "m = " << M;  // one block: the bound is the exact value
  else
    EXPECT_GT(rejected_by_4, missed_by_4 / 2) << "m = " << M;
}

template <plan_detail::Crit C>
void expect_bound_for_every_m(Rng& rng) {
  expect_bound_is_a_bound<1, C>(rng);
  expect_bound_is_a_bound<2, C>(rng);
  expect_bound_is_a_bound<3, C>(rng);
  expect_bound_is_a_bound<4, C>(rng);
  expect_bound_is_a_bound<5, C>(rng);
  expect_bound_is_a_bound<6, C>(rng);
}

TEST(PlanFastPath, EarlyRejectionIsABound) {
  using plan_detail::Crit;
  Rng rng(17);
  expect_bound_for_every_m<Crit::kappa_a>(rng);
  expect_bound_for_every_m<Crit::kappa_j>(rng);
  expect_bound_for_every_m<Crit::a_opt>(rng);
  expect_bound_for_every_m<Crit::d_opt>(rng);
}

// The annealing's engine (xoshiro256++): integers uniform over [0, n) by a chi-square test
// (bound at about 6 standard deviations of the statistic), uniforms in (0, 1] with the right
// mean, seeds giving different streams.
// The Metropolis test's Exp(1) variates (ziggurat): the layers close (the recursion from the
// tail ends at x = 0), and 1e6 draws pass Kolmogorov-Smirnov at the 0.1 % level against
// 1 - exp(-x), with mean and variance 1 within 5 standard errors.
TEST(PlanFastPath, ZigguratDrawsExponential) {
  using namespace plan_detail;
  const ExponentialZiggurat& z = kExponentialZiggurat;
  EXPECT_NEAR(-std::log(z.v / z.x[255] + std::exp(-z.x[255])), 0.0, 1e-12);
  for (int i = 0; i < 256; ++i) ASSERT_GT(z.x[i], z.x[i + 1]) << i;
  Xoshiro256pp rng(5);
  const int n = 1000000;
  std::vector<double> e(n);
  double sum = 0, sum2 = 0;
  for (double& v : e) {
    v = standard_exponential(rng);
    ASSERT_GE(v, 0.0);
    sum += v;
    sum2 += v * v;
  }
  const double mean = sum / n, var = sum2 / n - mean * mean;
  EXPECT_NEAR(mean, 1.0, 5.0 / std::sqrt(n));       // Var E = 1
  EXPECT_NEAR(var, 1.0, 5.0 * std::sqrt(8.0 / n));  // (mu4 - 1) / n, mu4 = 9
  std::sort(e.begin(), e.end());
  double d = 0;
  for (int i = 0; i < n; ++i) {
    const double cdf = -std::expm1(-e[i]);
    d = std::max({d, cdf - static_cast<double>(i) / n, static_cast<double>(i + 1) / n - cdf});
  }
  EXPECT_LT(d, 1.95 / std::sqrt(n));  // K-S critical value at alpha = 0.001
  // The tail beyond r = 7.697 (probability e^-r = 4.5e-4) is drawn: about 450 of 1e6.
  const long tail = e.end() - std::upper_bound(e.begin(), e.end(), z.r);
  EXPECT_NEAR(static_cast<double>(tail), n * std::exp(-z.r), 5.0 * std::sqrt(n * std::exp(-z.r)));
}

TEST(PlanFastPath, AnnealingEngineDrawsUniformly) {
  using namespace plan_detail;
  for (uint32_t n : {7u, 1000u, 10007u}) {
    Xoshiro256pp rng(n);
    const long draws = 200L * n;
    std::vector<long> count(n, 0);
    for (long i = 0; i < draws; ++i) {
      const uint32_t k = fast_index(rng, n);
      ASSERT_LT(k, n);
      ++count[k];
    }
    const double expect = static_cast<double>(draws) / n;
    double chi2 = 0;
    for (long c : count) chi2 += (c - expect) * (c - expect) / expect;
    const double dof = n - 1.0;
    EXPECT_LT(chi2, dof + 6.0 * std::sqrt(2.0 * dof) + 10.0) << "n = " << n;
    EXPECT_GT(chi2, dof - 6.0 * std::sqrt(2.0 * dof) - 10.0) << "n = " << n;
  }
  Xoshiro256pp rng(3);
  const int n = 1000000;
  double sum = 0, lo = 1, hi = 0;
  for (int i = 0; i < n; ++i) {
    const double u = rng.uniform_open();
    sum += u;
    lo = std::min(lo, u);
    hi = std::max(hi, u);
  }
  EXPECT_GT(lo, 0.0);
  EXPECT_LE(hi, 1.0);
  EXPECT_NEAR(sum / n, 0.5, 5.0 * std::sqrt(1.0 / 12.0 / n));
  Xoshiro256pp a(1), b(2);
  int same = 0;
  for (int i = 0; i < 1000; ++i) same += a() == b();
  EXPECT_EQ(same, 0);
  // jump(): a stream disjoint from the next draws of the original, and deterministic.
  Xoshiro256pp c(7), d(7), e(7);
  d.jump();
  e.jump();
  std::vector<uint64_t> head(100000);
  for (auto& x : head) x = c();
  std::sort(head.begin(), head.end());
  int shared = 0;
  for (int i = 0; i < 1000; ++i) {
    const uint64_t x = d();
    shared += std::binary_search(head.begin(), head.end(), x);
    ASSERT_EQ(x, e());
  }
  EXPECT_EQ(shared, 0);
}

TEST(PlanCriteria, RegistryAndEvaluateAgreeWithPoolKernel) {
  const RobotModel robot = test::rokae();
  const Dataset design = test::paper_design_a();
  const auto values = evaluate_criteria(robot, design);
  EXPECT_EQ(values.at("m"), 5.0);
  EXPECT_EQ(values.at("count"), 10.0);
  EXPECT_TRUE(std::isnan(values.at("task")));
  const CandidatePool pool = pool_from_dataset(robot, design);
  std::vector<int> all(10);
  for (int i = 0; i < 10; ++i) all[i] = i;
  PlanOptions o;
  for (const auto& name : criterion_names()) {
    if (name == "task") continue;
    o.criterion = name;
    const double s = set_score(robot, pool, all, o);
    const double v = find_criterion(name).larger_is_better ? s : -s;
    EXPECT_NEAR(v, values.at(name), 1e-9 * std::abs(values.at(name))) << name;
  }
  // kappa_a by its definition on the stacked (unweighted) A: weighting by a constant sigma
  // does not change it.
  const Eigen::MatrixXd a = observation_matrix(robot, design).leftCols(5);
  const Eigen::MatrixXd ata = a.transpose() * a;
  const double kappa = 5.0 / std::sqrt(ata.trace() * ata.inverse().trace());
  EXPECT_NEAR(values.at("kappa_a"), kappa, 1e-10);
  // O1 from the singular values of the weighted A.
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(a / 10e-6);
  const double o1 = std::pow(svd.singularValues().prod(), 1.0 / 5) / std::sqrt(10.0);
  EXPECT_NEAR(values.at("o1"), o1, 1e-9 * o1);
  // Task criterion: sqrt(mean_t tr(B_t M^-1 B_t^T) / 3).
  CriteriaOptions co;
  co.task = test::paper_design_j();
  const double task = evaluate_criteria(robot, design, co).at("task");
  const Eigen::MatrixXd cov = (ata / (10e-6 * 10e-6)).inverse();
  const Eigen::MatrixXd b = observation_matrix(robot, co.task).leftCols(5);
  const double expect = std::sqrt((b * cov * b.transpose()).trace() / (3.0 * co.task.size()));
  EXPECT_NEAR(task, expect, 1e-9 * expect);
  std::printf(
      "paper kappa_F^-1(A) design: kappa_a %.5f kappa_j %.5f d_opt %.4f o1 %.4g task %.3g m\n",
      values.at("kappa_a"), values.at("kappa_j"), values.at("d_opt"), values.at("o1"), task);
}

TEST(PlanErrors, BadRequestsAreInvalidArgument) {
  const RobotModel robot = test::rokae();
  const CandidatePool pool = build_pool(robot, paper_pool(4, 4));
  PlanOptions o;
  o.annealing.iterations = 100;
  o.count = 17;
  EXPECT_THROW(plan_measurements(robot, pool, o), InvalidArgument);
  o.count = 1;  // 3 rows < 5 compliances
  try {
    plan_measurements(robot, pool, o);
    FAIL();
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("too small"), std::string::npos);
  }
  o.count = 4;
  o.criterion = "kappa_x";
  try {
    plan_measurements(robot, pool, o);
    FAIL();
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("kappa_a, kappa_j, d_opt"), std::string::npos) << e.what();
  }
  EXPECT_THROW(find_criterion("nope"), InvalidArgument);
  o.criterion = "task";  // no task given
  EXPECT_THROW(plan_measurements(robot, pool, o), InvalidArgument);

  PoolOptions bad = paper_pool(4, 4);
  bad.load_min_N = 30;
  bad.load_max_N = 20;
  EXPECT_THROW(build_pool(robot, bad), InvalidArgument);
  bad = paper_pool(4, 4);
  bad.load_min_N = 16;
  bad.load_max_N = 19;  // no multiple of 5 N inside
  EXPECT_THROW(build_pool(robot, bad), InvalidArgument);
  bad = paper_pool(4, 4);
  bad.min_sigma_m = 10.0;  // every pose "singular"
  try {
    build_pool(robot, bad);
    FAIL();
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("near-singular"), std::string::npos);
  }
}

TEST(PlanOutput, DatasetAndJson) {
  const RobotModel robot = test::rokae();
  const CandidatePool pool = build_pool(robot, paper_pool(30, 20));
  PlanOptions o;
  o.annealing.iterations = 3000;
  const PlanResult r = plan_measurements(robot, pool, o);
  ASSERT_EQ(r.measurements.size(), 10u);
  double leverage = 0;
  for (const auto& m : r.measurements) {
    leverage += m.contribution;
    const Eigen::Matrix3d rot = robot.chain(m.q_rad).flange.block<3, 3>(0, 0);
    EXPECT_LT((rot * m.force_flange_N - m.force_base_N).norm(), 1e-9);
  }
  EXPECT_NEAR(leverage, 5.0, 1e-8);  // leverages sum to m
  const Dataset d = plan_to_dataset(r);
  const Dataset back = parse_measurements_csv(format_measurements_csv(d), "plan.csv", 6);
  EXPECT_FALSE(back.has_displacement);
  EXPECT_GE(back.extra_index("fx_flange_N"), 0);
  EXPECT_GE(back.extra_index("contribution"), 0);
  const auto again = evaluate_criteria(robot, back);
  EXPECT_NEAR(again.at("kappa_a"), r.criteria.at("kappa_a"), 1e-9);
  const std::string json = plan_summary_json(r);
  for (const auto& name : criterion_names())
    EXPECT_NE(json.find("\"" + name + "\""), std::string::npos);
  EXPECT_NE(json.find("\"found_by\""), std::string::npos);
}

TEST(PlanProgress, CallbackCanCancel) {
  const RobotModel robot = test::rokae();
  const CandidatePool pool = build_pool(robot, paper_pool(30, 20));
  PlanOptions o;
  o.annealing.iterations = 100000;
  long calls = 0;
  o.progress = [&](const PlanProgress& p) {
    ++calls;
    EXPECT_EQ(p.optimizer, "annealing");
    return p.iteration < 5000;
  };
  EXPECT_THROW(plan_measurements(robot, pool, o), Cancelled);
  EXPECT_EQ(calls, 5);
}

}  // namespace
}  // namespace stiff
