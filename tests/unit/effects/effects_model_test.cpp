// Every effect: registry texts, automatic derivatives against central differences, and the
// physics of the second-order (complementary) term against the exact loaded equilibrium.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <set>

#include "effect_truths.hpp"
#include "stiff/error.hpp"
#include "stiff/model/model.hpp"
#include "test_support.hpp"

namespace stiff {
namespace {

// Every registered effect: a new one is covered without editing this file.
const std::vector<std::string> kEffects = test::registered_effects();

TEST(Effects, RegistryHasEveryEffectWithTexts) {
  const auto names = effect_names();
  const RobotModel robot = test::rokae();
  const Dataset design = test::design60(1, 5);
  EffectSetup setup;
  setup.robot = &robot;
  for (const auto& name : kEffects) {
    const Dataset data = test::data_for(name, robot, design);
    setup.data = &data;
    ASSERT_NE(std::find(names.begin(), names.end(), name), names.end()) << name;
    const auto e = make_effect(name, setup);
    EXPECT_EQ(e->name(), name);
    EXPECT_FALSE(e->description().empty()) << name;
    EXPECT_FALSE(e->reference().empty()) << name;
    EXPECT_GT(e->size(), 0) << name;
    std::set<std::string> seen;
    for (const auto& p : e->parameters()) {
      EXPECT_TRUE(seen.insert(p.name).second) << name << "." << p.name << " twice";
      EXPECT_FALSE(p.unit.empty()) << name << "." << p.name;
      EXPECT_FALSE(p.meaning.empty()) << name << "." << p.name;
      EXPECT_LE(p.lower, p.null_value) << name << "." << p.name;
      EXPECT_GE(p.upper, p.null_value) << name << "." << p.name;
      EXPECT_GE(p.start, p.lower) << name << "." << p.name;
      EXPECT_LE(p.start, p.upper) << name << "." << p.name;
      EXPECT_GT(p.typical, 0) << name << "." << p.name;
    }
  }
}

TEST(Effects, LinkKeepsOnlyDirectionsTheJointsCannotAbsorb) {
  // Per link the two axes perpendicular to its joint, less one parallel to the next joint:
  // column, one (the other is joint 2's); upper arm, bending out of plane and torsion;
  // forearm, one (torsion is joint 4's axis); wrist links, one each. Only the upper arm's and
  // forearm's are always fitted; the others are optional terms.
  const RobotModel robot = test::rokae();
  DeflectionModel m(robot, {"link"});
  std::vector<std::string> names, always;
  for (const auto& p : m.effects()[0]->parameters()) {
    names.push_back(p.name);
    if (!p.optional_term) always.push_back(p.name);
  }
  EXPECT_EQ(names, (std::vector<std::string>{
                       "c_link1_x", "c_link2_x", "c_link2_y", "c_link3_x", "c_link4_x", "c_link5_x",
                       "c_link2_y_coupled", "c_link2_y_lateral", "c_link3_z_coupled",
                       "c_link3_z_lateral", "c_link3_x_coupled", "c_link3_x_lateral"}));
  EXPECT_EQ(always, (std::vector<std::string>{"c_link2_x", "c_link2_y", "c_link3_x"}));
}

// The fit prices the column's and wrist's springs and the bending terms as rare (outside the
// common sub-form, the arm's root springs), while the score test also tries every root spring,
// so that a wrist spring is not diluted among the bending terms: trying a form does not make
// its terms common.
TEST(Effects, LinkTriesEveryRootSpringButPricesTheRareTermsAsRare) {
  const RobotModel robot = test::rokae();
  const DeflectionModel m(robot, {"link"});
  const Effect& link = *m.effects()[0];
  std::vector<std::string> common;
  const std::vector<bool> flags = link.common_terms();
  for (int k = 0; k < link.size(); ++k)
    if (flags[static_cast<size_t>(k)]) common.push_back(link.parameters()[k].name);
  EXPECT_EQ(common, (std::vector<std::string>{"c_link2_x", "c_link2_y", "c_link3_x"}));
  std::vector<std::vector<std::string>> tried;
  for (const auto& form : link.score_forms()) {
    tried.emplace_back();
    for (int k : form) tried.back().push_back(link.parameters()[static_cast<size_t>(k)].name);
  }
  EXPECT_EQ(tried,
            (std::vector<std::vector<std::string>>{
                {"c_link2_x", "c_link2_y", "c_link3_x"},
                {"c_link1_x", "c_link2_x", "c_link2_y", "c_link3_x", "c_link4_x", "c_link5_x"}}));
}

// The bending terms are the expansion of a spring a fraction s along the link: with c, -c s and
// c s^2 for its root spring (or the joint that stands for it), coupled and lateral terms, the
// model moves the measured point as a spring at that point does, computed here from the
// chain's statics directly. The forearm (link 3) bent in the arm's plane (about joint 3's
// direction: its root spring is joint 3) and across it (about its frame's x axis, the axis of
// its root spring c_link3_x).
TEST(Effects, LinkBendingTermsAreASpringAlongTheLink) {
  const RobotModel robot = test::rokae();
  const DeflectionModel m(robot, {"joint", "link"});
  const Dataset design = test::design60(4, 6);
  const double c = 2e-5, s = 0.35;
  for (const bool in_plane : {true, false}) {
    Eigen::VectorXd theta = m.null_parameters();
    const Effect& link = *m.effects()[1];
    const std::string tag = in_plane ? "z" : "x";
    if (in_plane)
      theta(2) = c;  // joint 3
    else
      link.set_parameter(theta.data() + m.offset(1), "c_link3_x", c);
    link.set_parameter(theta.data() + m.offset(1), "c_link3_" + tag + "_coupled", -c * s);
    link.set_parameter(theta.data() + m.offset(1), "c_link3_" + tag + "_lateral", c * s * s);
    const auto ctx = m.contexts(design);
    for (size_t r = 0; r < design.size(); ++r) {
      const Measurement& row = design.rows[r];
      const ChainState chain = robot.chain(row.q);
      const Eigen::Vector3d root = chain.origin.col(2), end = chain.origin.col(3);
      const Eigen::Vector3d u =
          in_plane ? chain.axis.col(2) : chain.link[2].block<3, 3>(0, 0).col(0).eval();
      const Eigen::Vector3d o = root + s * (end - root);
      const Eigen::Vector3d load = robot.point_position(chain, robot.load_point);
      const Eigen::Vector3d point = robot.point_position(chain, robot.measured_point);
      const double turn = c * u.dot((load - o).cross(row.force) + row.moment);
      const Eigen::Vector3d expected = turn * u.cross(point - o);
      const Eigen::Vector3d got = m.predict(theta, row, ctx[r]).head<3>();
      EXPECT_LT((got - expected).norm(), 1e-9 * (1.0 + expected.norm()) + 1e-12)
          << tag << " row " << r << ": " << got.transpose() << " vs " << expected.transpose();
    }
  }
}

TEST(Effects, NullParametersSwitchEveryEffectOff) {
  const RobotModel robot = test::rokae();
  const Dataset design = test::design60(2, 8);
  for (const auto& name : kEffects) {
    const Dataset data = test::data_for(name, robot, design);
    DeflectionModel base(robot, {"joint"}, &data), full(robot, {"joint", name}, &data);
    Eigen::VectorXd t = full.null_parameters();
    t.head(6) = test::paper_stiffness().cwiseInverse();
    const auto ctx = full.contexts(data);
    for (size_t r = 0; r < data.size(); ++r) {
      const Eigen::Vector3d d0 = base.predict(t.head(6), data.rows[r], ctx[r]).head<3>();
      const Eigen::Vector3d d1 = full.predict(t, data.rows[r], ctx[r]).head<3>();
      EXPECT_LT((d1 - d0).norm(), 1e-12 * d0.norm()) << name << " row " << r;
    }
  }
}

// The autodiff Jacobian of the displacement equals central differences of predict() for every
// effect alone with the joint effect, and for all effects in one model (stage interplay).
void expect_jacobian_matches(const std::vector<std::string>& effects,
                             const Eigen::VectorXd& theta,
                             const DeflectionModel& m,
                             const Dataset& data) {
  const auto ctx = m.contexts(data);
  for (size_t r = 0; r < data.size(); ++r) {
    const auto ad = m.displacement_jacobian(theta, data.rows[r], ctx[r]);
    const auto ao = m.orientation_jacobian(theta, data.rows[r], ctx[r]);
    const Eigen::Vector3d d = m.predict(theta, data.rows[r], ctx[r]).head<3>();
    // The orientation discrepancy (zero without a measured orientation).
    auto discrepancy = [&](const Eigen::VectorXd& t) {
      Vector3<double> dd, o;
      m.evaluate<double>(t.data(), data.rows[r], ctx[r], &dd, nullptr, &o);
      return Eigen::Vector3d(o);
    };
    for (int k = 0; k < m.parameter_count(); ++k) {
      // Decided from the data, not fitted: the model has no derivative with respect to it.
      if (m.spec(k).from_data) {
        EXPECT_EQ(ad.col(k).norm(), 0.0) << m.spec(k).name;
        continue;
      }
      const double h = 1e-5 * std::max(std::abs(theta(k)), m.spec(k).typical);
      Eigen::VectorXd tp = theta, tm = theta;
      tp(k) += h;
      tm(k) -= h;
      const Eigen::Vector3d fd = (m.predict(tp, data.rows[r], ctx[r]).head<3>() -
                                  m.predict(tm, data.rows[r], ctx[r]).head<3>()) /
                                 (2 * h);
      // Truncation ~ (h/theta)^2 ~ 1e-10 relative; rounding ~ 1e-16 |d| / h.
      const double tol = 1e-6 * ad.col(k).norm() + 1e-13 * d.norm() / h;
      EXPECT_LT((ad.col(k) - fd).norm(), tol)
          << m.model_string() << " " << m.spec(k).name << " row " << r << ": ad "
          << ad.col(k).transpose() << " fd " << fd.transpose();
      // Rotation vectors of order 1 rad at most: rounding ~ 1e-16 / h.
      const Eigen::Vector3d fo = (discrepancy(tp) - discrepancy(tm)) / (2 * h);
      EXPECT_LT((ao.col(k) - fo).norm(), 1e-6 * ao.col(k).norm() + 1e-13 / h)
          << m.model_string() << " " << m.spec(k).name << " row " << r << " (orientation): ad "
          << ao.col(k).transpose() << " fd " << fo.transpose();
    }
  }
  (void)effects;
}

TEST(Effects, AutodiffJacobianMatchesCentralDifferences) {
  const RobotModel robot = test::rokae();
  const Dataset design = test::design60(3, 6);
  for (const auto& name : kEffects) {
    // Absolute rows for an effect that acts on nothing else.
    const Dataset data = test::data_for(name, robot, design);
    DeflectionModel m(robot, {"joint", name}, &data);
    Eigen::VectorXd theta = test::effect_truth(name, robot).theta;
    // Move every parameter off its null value so that every derivative is exercised.
    for (int k = 0; k < m.parameter_count(); ++k)
      if (theta(k) == m.spec(k).null_value)
        theta(k) = std::min(m.spec(k).upper, m.spec(k).null_value + 0.3 * m.spec(k).typical);
    expect_jacobian_matches({"joint", name}, theta, m, data);
    // The effect acts on these rows: a check of zero derivatives would prove nothing.
    const auto ctx = m.contexts(data);
    double largest = 0;
    // (positions, or the orientations for an effect that only they see)
    for (size_t r = 0; r < data.size(); ++r)
      largest = std::max({largest,
                          m.displacement_jacobian(theta, data.rows[r], ctx[r])
                              .rightCols(m.effects()[1]->size())
                              .cwiseAbs()
                              .maxCoeff(),
                          m.orientation_jacobian(theta, data.rows[r], ctx[r])
                              .rightCols(m.effects()[1]->size())
                              .cwiseAbs()
                              .maxCoeff()});
    EXPECT_GT(largest, 0.0) << name;
  }
}

TEST(Effects, AutodiffJacobianOfAllEffectsTogether) {
  const RobotModel robot = test::rokae();
  std::vector<std::string> all = {"joint"};
  all.insert(all.end(), kEffects.begin(), kEffects.end());
  // The first half of the rows as loaded-minus-unloaded rows, the rest as absolute rows (when
  // an effect needs them): both kinds in one model.
  Dataset data = test::design60(4, 6);
  const Dataset converted = test::data_for(all, robot, data);
  data.has_session = converted.has_session;
  data.has_position = converted.has_position;
  data.has_temperature = converted.has_temperature;
  for (size_t r = 0; r < data.size(); ++r)
    if (2 * r >= data.size())
      data.rows[r] = converted.rows[r];
    else
      data.rows[r].session = converted.rows[r].session;
  DeflectionModel m(robot, all, &data);
  Eigen::VectorXd theta(m.parameter_count());
  for (int k = 0; k < m.parameter_count(); ++k)
    theta(k) = std::min(m.spec(k).upper, m.spec(k).null_value + 0.5 * m.spec(k).typical);
  theta.head(6) = test::paper_stiffness().cwiseInverse();
  expect_jacobian_matches(all, theta, m, data);
}

// Exact loaded equilibrium K dtheta = J(L(q + dtheta))^T F by fixed-point iteration (no
// gravity): d_exact = P(q + dtheta) - P(q). The complementary term with gamma = 1 must account
// for the second-order part, leaving a third-order remainder.
// An effect that claims linear() predicts d affine in its parameters with a Jacobian no
// parameter changes (identify() then evaluates one Jacobian per measurement): checked between
// two parameter vectors a few typical sizes apart, to round-off.
TEST(Effects, LinearClaimHoldsNumerically) {
  const RobotModel robot = test::rokae();
  const Dataset design = test::design60(5, 8);
  for (const auto& name : kEffects) {
    const Dataset data = test::data_for(name, robot, design);
    const DeflectionModel model(robot, {"joint", name}, &data);
    if (!model.effects()[1]->linear()) continue;
    ASSERT_TRUE(model.linear()) << name;
    const int p = model.parameter_count();
    Eigen::VectorXd t0 = test::effect_truth(name, robot).theta, t1 = t0;
    for (int k = 0; k < p; ++k) {
      t0(k) += 0.3 * std::abs(model.spec(k).typical) * (k % 3 - 1);
      t1(k) += 0.7 * std::abs(model.spec(k).typical) * (k % 2 ? 1 : -0.5);
    }
    const auto ctx = model.contexts(data);
    for (size_t r = 0; r < data.rows.size(); ++r) {
      const auto j0 = model.displacement_jacobian(t0, data.rows[r], ctx[r]);
      const auto j1 = model.displacement_jacobian(t1, data.rows[r], ctx[r]);
      EXPECT_LE((j1 - j0).cwiseAbs().maxCoeff(), 1e-12 * j0.cwiseAbs().maxCoeff()) << name;
      const Eigen::Vector3d d0 = model.predict(t0, data.rows[r], ctx[r]).head<3>();
      const Eigen::Vector3d d1 = model.predict(t1, data.rows[r], ctx[r]).head<3>();
      EXPECT_LE((d1 - d0 - j0 * (t1 - t0)).cwiseAbs().maxCoeff(), 1e-12 * d1.cwiseAbs().maxCoeff())
          << name << " row " << r;
    }
  }
}

// Every registered effect gives the example its tests and the virtual robot use, and it is not
// the null (switched-off) value.
TEST(Effects, EveryEffectGivesAnExample) {
  const RobotModel robot = test::rokae();
  for (const auto& name : kEffects) {
    DeflectionModel m(robot, {"joint", name});
    const Truth t = test::effect_truth(name, robot);
    EXPECT_NE(t.theta.tail(m.effects()[1]->size()),
              m.null_parameters().tail(m.effects()[1]->size()))
        << name;
  }
}

TEST(Effects, ComplementaryIsTheSecondOrderOfTheExactEquilibrium) {
  RobotModel robot = test::rokae();
  robot.measured_point = Eigen::Vector3d(0.03, -0.02, 0.05);
  robot.load_point = Eigen::Vector3d(0.04, 0.01, 0.06);
  const Dataset data = test::design60(5, 10);
  DeflectionModel m(robot, {"joint", "complementary"}, &data);
  // 20x the paper's compliance so that the second-order part is well above round-off.
  Eigen::VectorXd c = 20.0 * test::paper_stiffness().cwiseInverse();
  Eigen::VectorXd t1(7), t0(7);
  t1 << c, 1.0;
  t0 << c, 0.0;
  const auto ctx = m.contexts(data);
  double second = 0, remainder = 0;
  for (size_t r = 0; r < data.size(); ++r) {
    const auto& meas = data.rows[r];
    Eigen::VectorXd dth = Eigen::VectorXd::Zero(6);
    for (int it = 0; it < 200; ++it) {
      const ChainState s = robot.chain(meas.q + dth);
      const Eigen::Vector3d l = robot.point_position(s, robot.load_point);
      const Matrix6X<double> j = robot.jacobian_at(s, l);
      Eigen::Matrix<double, 6, 1> w;
      w << meas.force, meas.moment;
      dth = c.asDiagonal() * (j.transpose() * w);
    }
    const Eigen::Vector3d p0 = robot.point_position(robot.chain(meas.q), robot.measured_point);
    const Eigen::Vector3d p1 =
        robot.point_position(robot.chain(meas.q + dth), robot.measured_point);
    const Eigen::Vector3d exact = p1 - p0;
    const Eigen::Vector3d lin = m.predict(t0, meas, ctx[r]).head<3>();
    const Eigen::Vector3d quad = m.predict(t1, meas, ctx[r]).head<3>();
    second += (exact - lin).squaredNorm();
    remainder += (exact - quad).squaredNorm();
  }
  // The remainder is third order: smaller than the second-order part by ~ |dtheta| (~1e-2).
  EXPECT_GT(std::sqrt(second), 1e-7);
  EXPECT_LT(std::sqrt(remainder), 0.05 * std::sqrt(second));
}

TEST(Effects, RequirementsAreChecked) {
  RobotModel robot = test::rokae();
  for (auto& j : robot.joints) j.mass = 0;
  robot.tool_mass = 0;
  for (const std::string name : {"nonlinear_joint", "backlash"}) {
    try {
      DeflectionModel m(robot, {"joint", name});
      FAIL() << name << " accepted a robot without masses";
    } catch (const InvalidArgument& e) {
      EXPECT_NE(std::string(e.what()).find("masses"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(DeflectionModel(robot, {"joint", "no_such_effect"}), InvalidArgument);
}

TEST(Effects, DriftHasOneBlockPerSession) {
  const RobotModel robot = test::rokae();
  Dataset data = test::design60(6, 10);
  data.has_session = true;
  for (size_t r = 0; r < data.size(); ++r) data.rows[r].session = r < 5 ? "monday" : "tuesday";
  DeflectionModel m(robot, {"drift"}, &data);
  ASSERT_EQ(m.parameter_count(), 12);
  EXPECT_EQ(m.spec(6).name, "offset_x_s2");
  Eigen::VectorXd t = m.null_parameters();
  t(6) = 1e-5;  // offset x of the second session only
  const auto ctx = m.contexts(data);
  EXPECT_DOUBLE_EQ(m.predict(t, data.rows[0], ctx[0])(0), 0.0);
  EXPECT_DOUBLE_EQ(m.predict(t, data.rows[7], ctx[7])(0), 1e-5);
}

// A validation session's drift is its own (ParameterSpec::per_session): align_sessions
// re-estimates it from that session's rows and leaves every robot parameter as it was. The
// session here drifts by an offset and a rate that the calibration did not have; the estimates
// must agree with the truth within 4.5 standard errors of least squares with 10 um noise
// (intercept and slope on 40 rows: se(b) = sigma sqrt(1/m + tbar^2/Sxx), se(v) = sigma/sqrt(Sxx)).
TEST(Effects, AlignSessionsReestimatesOnlyTheSessionsDrift) {
  const RobotModel robot = test::rokae();
  const int m = 40;
  Dataset data = test::design60(11, m);
  DeflectionModel model(robot, {"joint", "drift"}, &data);
  const int drift = model.offset(model.find("drift"));
  Eigen::VectorXd truth = model.null_parameters();
  const Eigen::VectorXd k = test::paper_stiffness();
  for (int j = 0; j < k.size(); ++j) truth(j) = 1.0 / k(j);
  const Eigen::Vector3d offset(30e-6, -20e-6, 10e-6), rate(0.5e-6, 0.0, -0.3e-6);
  truth.segment<3>(drift) = offset;
  truth.segment<3>(drift + 3) = rate;
  const auto ctx = model.contexts(data);
  const double sigma = 10e-6;
  std::mt19937_64 rng(5);
  std::normal_distribution<double> noise(0.0, sigma);
  for (int r = 0; r < m; ++r) {
    data.rows[r].displacement = model.predict(truth, data.rows[r], ctx[r]).head<3>();
    for (int a = 0; a < 3; ++a) data.rows[r].displacement(a) += noise(rng);
  }
  Eigen::VectorXd fit = truth;
  fit.segment<6>(drift).setZero();  // the calibration session did not drift
  int estimated = -1;
  const Eigen::VectorXd aligned = model.align_sessions(fit, data, ctx, &estimated);
  EXPECT_EQ(estimated, 6);
  for (int j = 0; j < drift; ++j) EXPECT_EQ(aligned(j), fit(j)) << model.spec(j).name;
  double tbar = 0, sxx = 0;
  for (int r = 0; r < m; ++r) tbar += ctx[r].time / m;
  for (int r = 0; r < m; ++r) sxx += (ctx[r].time - tbar) * (ctx[r].time - tbar);
  const double se_b = sigma * std::sqrt(1.0 / m + tbar * tbar / sxx), se_v = sigma / std::sqrt(sxx);
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(aligned(drift + a), offset(a), 4.5 * se_b) << "offset " << a;
    EXPECT_NEAR(aligned(drift + 3 + a), rate(a), 4.5 * se_v) << "rate " << a;
  }
  // Nothing of the session in the model: nothing to align.
  DeflectionModel joint(robot, {"joint"}, &data);
  const Eigen::VectorXd c = truth.head(joint.parameter_count());
  EXPECT_EQ(joint.align_sessions(c, data, joint.contexts(data), &estimated), c);
  EXPECT_EQ(estimated, 0);
}

}  // namespace
}  // namespace stiff
