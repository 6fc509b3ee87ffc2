// Absolute (geometric) calibration: the geometric effects against an independently perturbed
// robot, automatic derivatives against central differences, recovery on the virtual robot,
// the checks of absolute data against the nominal robot, and the statistical identifiability
// test holding a parameter the data cannot determine.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <random>

#include "stiff/diagnose/diagnose.hpp"
#include "stiff/error.hpp"
#include "stiff/identify/identify.hpp"
#include "stiff/model/model.hpp"
#include "stiff/sim/simulate.hpp"
#include "test_support.hpp"

namespace stiff {
namespace {

RobotModel ur5() { return load_robot(test::source_path("examples/robots/ur5.urdf")); }

/// True geometry of a virtual robot, in the effects' own terms.
struct Geometry {
  Eigen::VectorXd dq;                  ///< joint offsets [rad]
  Eigen::MatrixXd axis;                ///< 4 x n: du, dv [m], ru, rv [rad] per joint
  Eigen::Vector3d tool;                ///< target offset, flange frame [m]
  std::vector<Eigen::Matrix3d> rot;    ///< per session: instrument <- base
  std::vector<Eigen::Vector3d> trans;  ///< per session
};

/// The robot with its joints' `pre` transforms moved as the kinematic effect describes,
/// evaluated by RobotModel::chain (not by the model's corrected kinematics).
RobotModel perturbed(const RobotModel& nominal, const Geometry& g) {
  RobotModel r = nominal;
  for (int j = 0; j < r.dof(); ++j) {
    r.joints[j].pre = r.joints[j].pre * test::axis_error_transform(r.joints[j].axis, g.axis.col(j));
  }
  r.measured_point += g.tool;
  return r;
}

Geometry random_geometry(int n, int sessions, std::mt19937_64& rng) {
  std::normal_distribution<double> z(0.0, 1.0);
  Geometry g;
  g.dq = Eigen::VectorXd::NullaryExpr(n, [&] { return 1e-3 * z(rng); });
  g.axis.resize(4, n);
  for (int j = 0; j < n; ++j) {
    g.axis(0, j) = 3e-4 * z(rng);
    g.axis(1, j) = 3e-4 * z(rng);
    g.axis(2, j) = 1e-3 * z(rng);
    g.axis(3, j) = 1e-3 * z(rng);
  }
  g.tool = Eigen::Vector3d(0.01 * z(rng), 0.01 * z(rng), 0.05 + 0.01 * z(rng));
  for (int s = 0; s < sessions; ++s) {
    const Eigen::Vector3d w(0.3 * z(rng), 0.3 * z(rng), 2.0 + 0.3 * z(rng));
    g.rot.push_back(Eigen::AngleAxisd(w.norm(), w.normalized()).matrix());
    g.trans.emplace_back(2.0 + 0.1 * z(rng), -1.0 + 0.1 * z(rng), 0.3 * z(rng));
  }
  return g;
}

/// Absolute measurements of random poses, `per_session` per session, on the perturbed robot
/// with per-axis tracker noise sigma [m]: p = R_s FK(q + dq) + t_s.
Dataset measure(const RobotModel& nominal,
                const Geometry& g,
                int per_session,
                double sigma,
                std::mt19937_64& rng) {
  const RobotModel truth = perturbed(nominal, g);
  std::uniform_real_distribution<double> uq(-0.9 * 3.14159, 0.9 * 3.14159);
  std::normal_distribution<double> z(0.0, 1.0);
  Dataset d;
  d.dof = nominal.dof();
  d.has_id = d.has_session = d.has_position = true;
  for (size_t s = 0; s < g.rot.size(); ++s)
    for (int i = 0; i < per_session; ++i) {
      Measurement m;
      m.id = "s" + std::to_string(s) + "_" + std::to_string(i);
      m.session = "S" + std::to_string(s);
      m.absolute = true;
      m.q = Eigen::VectorXd::NullaryExpr(d.dof, [&] { return uq(rng); });
      const Eigen::Matrix4d t = truth.tool_pose(m.q + g.dq);
      m.position = g.rot[s] * t.topRightCorner<3, 1>() + g.trans[s];
      for (int k = 0; k < 3; ++k) m.position(k) += sigma * z(rng);
      d.rows.push_back(m);
    }
  return d;
}

/// theta of a geometric model {registration, tool, joint_offset, kinematic} for g.
Eigen::VectorXd geometric_theta(const DeflectionModel& m, const Geometry& g) {
  Eigen::VectorXd t = m.start_parameters();
  const int n = m.robot().dof();
  const int reg = m.offset(m.find("registration"));
  for (size_t s = 0; s < g.rot.size(); ++s) {
    const Eigen::AngleAxisd aa(g.rot[s]);
    t.segment<3>(reg + 6 * s) = aa.angle() * aa.axis();
    t.segment<3>(reg + 6 * s + 3) = g.trans[s];
  }
  t.segment<3>(m.offset(m.find("tool"))) = g.tool;
  t.segment(m.offset(m.find("joint_offset")), n) = g.dq;
  for (int j = 0; j < n; ++j) t.segment<4>(m.offset(m.find("kinematic")) + 4 * j) = g.axis.col(j);
  return t;
}

const std::vector<std::string> kGeometric = {"registration", "tool", "joint_offset", "kinematic"};

/// theta as Jets carrying the derivative directions of parameters first .. first + kJetStride - 1
/// (one pass of a Jacobian, as identify makes them).
std::vector<Jet> seeded(const Eigen::VectorXd& theta, int first) {
  const int p = static_cast<int>(theta.size());
  std::vector<Jet> t(p);
  for (int k = 0; k < p; ++k) t[k] = Jet(theta(k));
  for (int k = first; k < std::min(p, first + kJetStride); ++k) t[k].v(k - first) = 1.0;
  return t;
}

TEST(AbsoluteEffects, ModelEqualsTheIndependentlyPerturbedRobot) {
  const RobotModel robot = ur5();
  std::mt19937_64 rng(7);
  const Geometry g = random_geometry(robot.dof(), 2, rng);
  const Dataset data = measure(robot, g, 20, 0.0, rng);
  const DeflectionModel m(robot, kGeometric, &data);
  const Eigen::VectorXd theta = geometric_theta(m, g);
  const auto ctx = m.contexts(data);
  for (size_t r = 0; r < data.size(); ++r) {
    const Eigen::Vector3d p = m.predict(theta, data.rows[r], ctx[r]).head<3>();
    EXPECT_LT((p - data.rows[r].position).norm(), 1e-10) << "row " << r;
  }
}

TEST(AbsoluteEffects, AutodiffJacobianMatchesCentralDifferences) {
  const RobotModel robot = ur5();  // has masses: the joint effect sees the gravity torques
  std::mt19937_64 rng(11);
  const Geometry g = random_geometry(robot.dof(), 2, rng);
  const Dataset data = measure(robot, g, 6, 0.0, rng);
  std::vector<std::string> all = kGeometric;
  all.push_back("gravity_lumped");
  all.push_back("joint");
  const DeflectionModel m(robot, all, &data);
  Eigen::VectorXd theta = geometric_theta(m, g);
  for (int k = m.offset(m.find("gravity_lumped")); k < m.parameter_count(); ++k)
    theta(k) = 0.7 * m.spec(k).typical;
  const auto ctx = m.contexts(data);
  for (size_t r = 0; r < data.size(); ++r) {
    const auto ad = m.displacement_jacobian(theta, data.rows[r], ctx[r]);
    for (int k = 0; k < m.parameter_count(); ++k) {
      const double h = 1e-5 * std::max(std::abs(theta(k)), m.spec(k).typical);
      Eigen::VectorXd tp = theta, tm = theta;
      tp(k) += h;
      tm(k) -= h;
      const Eigen::Vector3d fd = (m.predict(tp, data.rows[r], ctx[r]).head<3>() -
                                  m.predict(tm, data.rows[r], ctx[r]).head<3>()) /
                                 (2 * h);
      // Positions of ~3 m: rounding 1e-16 * 3 / h; truncation (h / scale)^2.
      const double tol = 1e-6 * ad.col(k).norm() + 1e-15 * 3.0 / h;
      EXPECT_LT((ad.col(k) - fd).norm(), tol)
          << m.owner(k).name() << "." << m.spec(k).name << " row " << r << ": ad "
          << ad.col(k).transpose() << " fd " << fd.transpose();
    }
  }
}

// The identification's fast derivative path (DeflectionModel::evaluate_jet) on absolute rows
// with deflection effects (gravity compliance, harmonics, the joint compliance under the gravity
// torque) equals the generic evaluate<Jet> to round-off, pass by pass.
TEST(AbsoluteEffects, FastJetEvaluationEqualsTheGenericOne) {
  const RobotModel robot = ur5();
  std::mt19937_64 rng(12);
  const Geometry g = random_geometry(robot.dof(), 2, rng);
  const Dataset data = measure(robot, g, 5, 0.0, rng);
  // With deflection effects (the fast Jet path) and without (the geometric short cut); the
  // later passes of a row reuse the chain kept by the first (same_values), as identify's do.
  for (const bool deflecting : {true, false}) {
    std::vector<std::string> all = kGeometric;
    if (deflecting)
      for (const char* e : {"gravity_lumped", "harmonic", "joint"}) all.push_back(e);
    const DeflectionModel m(robot, all, &data);
    const int p = m.parameter_count();
    Eigen::VectorXd theta = geometric_theta(m, g);
    if (deflecting)
      for (int k = m.offset(m.find("gravity_lumped")); k < p; ++k)
        theta(k) = 0.7 * m.spec(k).typical * (k % 3 - 1);
    const auto ctx = m.contexts(data);
    EvalState<Jet> scratch;
    for (size_t r = 0; r < data.size(); ++r)
      for (int first = 0; first < p; first += kJetStride) {
        const std::vector<Jet> t = seeded(theta, first);
        Vector3<Jet> slow, fast;
        m.evaluate<Jet>(t.data(), data.rows[r], ctx[r], &slow, nullptr);
        scratch.same_values = first > 0;
        m.evaluate_jet(t.data(), data.rows[r], ctx[r], scratch, &fast);
        for (int i = 0; i < 3; ++i) {
          EXPECT_NEAR(fast(i).a, slow(i).a, 1e-15 + 1e-12 * std::abs(slow(i).a));
          for (int k = 0; k < kJetStride; ++k)
            EXPECT_NEAR(fast(i).v(k), slow(i).v(k), 1e-15 + 1e-11 * slow(i).v.cwiseAbs().maxCoeff())
                << (deflecting ? "deflecting" : "geometric") << " row " << r << " parameter "
                << first + k;
        }
      }
  }
}

/// A 6-D probe on the flange turned by `probe` (rotation vector, flange frame): the rows of
/// `data` get the orientation the instrument measures, R_s R_06(true chain) R(probe), turned by
/// a random small rotation of sigma_o [rad] per axis.
void add_orientation(const RobotModel& nominal,
                     const Geometry& g,
                     const Eigen::Vector3d& probe,
                     double sigma_o,
                     std::mt19937_64& rng,
                     Dataset* data) {
  const RobotModel truth = perturbed(nominal, g);
  const Eigen::Matrix3d rp = probe.norm() > 0
                                 ? Eigen::AngleAxisd(probe.norm(), probe.normalized()).matrix()
                                 : Eigen::Matrix3d::Identity();
  std::normal_distribution<double> z(0.0, 1.0);
  data->has_orientation = true;
  for (auto& m : data->rows) {
    const int s = std::stoi(m.session.substr(1));
    const Eigen::Vector3d n(sigma_o * z(rng), sigma_o * z(rng), sigma_o * z(rng));
    const Eigen::Matrix3d noise = n.norm() > 0
                                      ? Eigen::AngleAxisd(n.norm(), n.normalized()).matrix()
                                      : Eigen::Matrix3d::Identity();
    m.has_orientation = true;
    m.orientation = noise * g.rot[s] * truth.tool_pose(m.q + g.dq).topLeftCorner<3, 3>() * rp;
  }
}

// Every registered effect that gives its absolute columns analytically
// (Effect::has_absolute_columns) against automatic differentiation of the whole model
// (displacement_jacobian, orientation_jacobian): alone, after a wrench-stage effect that the
// same pass differentiates automatically (the tool), and with every other such effect and every
// wrench-stage effect, at random poses and parameter values, on positions and on a 6-D probe's
// poses (a second measurement with its own rows). A new effect is covered without editing this
// test.
TEST(AbsoluteEffects, AnalyticColumnsEqualAutomaticDerivatives) {
  const RobotModel robot = ur5();
  std::mt19937_64 rng(23);
  const Geometry g = random_geometry(robot.dof(), 2, rng);
  Dataset data = measure(robot, g, 6, 0.0, rng);
  data.has_time = data.has_temperature = true;
  for (size_t r = 0; r < data.size(); ++r) {
    data.rows[r].time = 30.0 * static_cast<double>(r);
    data.rows[r].temperature = 20.0 + 6.0 * std::sin(0.7 * static_cast<double>(r));
  }
  Dataset posed = data;
  add_orientation(robot, g, Eigen::Vector3d(0.2, -0.1, 0.4), 1e-3, rng, &posed);
  posed.rows[1].has_orientation = false;  // a position-only row among them
  EffectSetup setup;
  setup.robot = &robot;
  setup.data = &data;
  setup.sessions = 2;
  std::vector<std::string> analytic, wrench;
  for (const auto& name : effect_names()) {
    const auto e = make_effect(name, setup);
    if (e->has_absolute_columns())
      analytic.push_back(name);
    else if (e->stages() == kWrenchStage)
      wrench.push_back(name);
  }
  ASSERT_FALSE(analytic.empty());
  std::vector<std::vector<std::string>> models;
  for (const auto& name : analytic) {
    models.push_back({name});
    models.push_back({"tool", name});
  }
  std::vector<std::string> all = wrench;
  all.insert(all.end(), analytic.begin(), analytic.end());
  models.push_back(all);
  models.push_back(analytic);
  std::normal_distribution<double> z(0.0, 1.0);
  int compared = 0, together = 0;
  for (const Dataset* rows : {&data, &posed}) {
    const int dim = rows->has_orientation ? 6 : 3;
    for (const auto& effects : models) {
      const DeflectionModel m(robot, effects, rows);
      std::string label;
      for (const auto& e : effects) label += (label.empty() ? "" : "+") + e;
      if (dim == 6) label = "6-D " + label;
      // Every analytic effect alone or after a wrench-stage one qualifies; a combination may
      // not (two measurement-stage effects), and then the automatic path is the only one.
      if (effects.size() <= 2) {
        ASSERT_TRUE(m.analytic_absolute()) << label;
      }
      if (!m.analytic_absolute()) continue;
      const int p = m.parameter_count();
      Eigen::VectorXd theta = m.start_parameters();
      for (size_t e = 0; e < m.effects().size(); ++e)
        m.effects()[e]->example_parameters(Eigen::VectorXd::Constant(robot.dof(), 1e-6),
                                           theta.data() + m.offset(static_cast<int>(e)));
      for (int k = 0; k < p; ++k) theta(k) += 0.3 * m.spec(k).typical * z(rng);
      const auto ctx = m.contexts(*rows);
      EvalState<Jet> js;
      EvalState<double> ds;
      std::vector<Jet> t;
      Eigen::MatrixXd fast(dim, p);
      for (size_t r = 0; r < rows->size(); ++r) {
        const Measurement& row = rows->rows[r];
        Eigen::VectorXd d(dim);
        m.absolute_jacobian(theta.data(), row, ctx[r], js, ds, t, d.data(), fast.data(), dim);
        Eigen::MatrixXd ad = Eigen::MatrixXd::Zero(dim, p);
        ad.topRows(3) = m.displacement_jacobian(theta, row, ctx[r]);
        Eigen::VectorXd y = Eigen::VectorXd::Zero(dim);
        Vector3<double> yp, yo;
        m.evaluate<double>(theta.data(), row, ctx[r], &yp, nullptr, dim == 6 ? &yo : nullptr);
        y.head<3>() = yp;
        if (dim == 6) {
          y.tail<3>() = yo;
          ad.bottomRows(3) = m.orientation_jacobian(theta, row, ctx[r]);
        }
        EXPECT_LT((d - y).norm(), 1e-12 * y.norm()) << label << " row " << r;
        for (int k = 0; k < p; ++k) {
          // Positions and orientations apart: the two are in different units. The automatic
          // derivative of the deflection's Exp(rot) goes through Rodrigues' (1 - cos t) / t^2
          // at t ~ 1e-3 rad, which keeps about eps / t^2 ~ 1e-10 of its digits.
          for (int part = 0; part < dim / 3; ++part) {
            const Eigen::Vector3d a = fast.col(k).segment<3>(3 * part);
            const Eigen::Vector3d b = ad.col(k).segment<3>(3 * part);
            const double rel = part ? 1e-10 : 1e-12;
            EXPECT_LE((a - b).norm(), rel * std::max(b.norm(), ad.col(k).norm() * 1e-3))
                << label << ": " << m.owner(k).name() << "." << m.spec(k).name << " row " << r
                << (part ? " orientation" : " position") << ": analytic " << a.transpose()
                << ", automatic " << b.transpose();
          }
        }
        compared += row.has_orientation;
        together += row.has_orientation && effects.size() == analytic.size();
      }
    }
  }
  EXPECT_GT(compared, 0);
  EXPECT_GT(together, 0);  // the analytic effects all in one model (one measurement stage)
}

// The loop on absolute data (stiff diagnose --auto from the nominal registration and tool)
// on a robot with geometric errors and an error outside the candidate list (0.3 mm/rad^2 x
// q2 q3 along the instrument's z, as a cable's drag might give; no sum of per-joint terms):
// no candidate explains everything, so no verdict names a single missing effect, yet the loop
// adds the geometry because the held-out poses confirm it, and every step lowers the held-out
// error.
TEST(AbsoluteDiagnosis, LoopAddsWhatTheHeldOutPosesConfirm) {
  const RobotModel robot = ur5();
  std::mt19937_64 rng(21);
  Geometry g = random_geometry(robot.dof(), 1, rng);
  g.axis *= 3.0;  // errors of a few tenths of a millimetre at the tool
  auto drag = [](Dataset d) {
    for (auto& m : d.rows) m.position(2) += 3e-4 * m.q(1) * m.q(2);
    return d;
  };
  const Dataset calib = drag(measure(robot, g, 120, 20e-6, rng));
  const Dataset valid = drag(measure(robot, g, 40, 20e-6, rng));
  DiagnosisOptions o;
  o.auto_loop = true;
  o.max_steps = 3;
  o.candidates = {"joint_offset", "kinematic", "gravity_lumped", "harmonic"};
  const Diagnosis d = diagnose(robot, calib, &valid, {"registration", "tool"}, o);
  ASSERT_GE(d.steps.size(), 2u) << d.summary;
  // Step 0 names no single missing effect: the loop walks on the held-out poses' evidence.
  EXPECT_TRUE(d.steps[0].verdict == "unexplained" || d.steps[0].verdict == "ambiguous")
      << d.summary;
  const std::string& first = d.steps[1].added;
  EXPECT_TRUE(first == "kinematic" || first == "joint_offset") << first;
  for (size_t i = 1; i < d.steps.size(); ++i)
    EXPECT_LT(d.steps[i].quality.validation_rms_m, d.steps[i - 1].quality.validation_rms_m)
        << "step " << i << " (" << d.steps[i].added << ")";
  // The drag is outside the list: nothing may call the final model adequate.
  EXPECT_NE(d.final_verdict, "adequate") << d.summary;
}

// Validation poses measured from another placement of the instrument (a session the
// calibration does not have): the diagnosis registers that placement from a fifth of its rows
// and scores the model on the rest, so the validation error is the model's, at the tracker
// noise, not the metres between the two placements.
TEST(AbsoluteDiagnosis, ValidationFromANewSetUpIsRegisteredFromPartOfItsRows) {
  const RobotModel robot = ur5();
  std::mt19937_64 rng(33);
  const Geometry g = random_geometry(robot.dof(), 2, rng);
  Geometry g0 = g, g1 = g;
  g0.rot.resize(1);
  g0.trans.resize(1);
  g1.rot.erase(g1.rot.begin());
  g1.trans.erase(g1.trans.begin());
  const double sigma = 20e-6;
  const Dataset calib = measure(robot, g0, 150, sigma, rng);
  Dataset valid = measure(robot, g1, 60, sigma, rng);
  for (auto& m : valid.rows) m.session = "S1";
  DiagnosisOptions o;
  o.candidates = {"harmonic"};
  const Diagnosis d = diagnose(robot, calib, &valid, kGeometric, o);
  ASSERT_EQ(d.notes.size(), 1u);
  EXPECT_NE(d.notes[0].find("'S1'"), std::string::npos) << d.notes[0];
  EXPECT_EQ(d.fit.validation_error_m.size(), 48u);  // 12 of 60 rows register S1
  // Per-axis RMS of a right model on new poses: the noise, inflated by the geometry's and the
  // 12-row registration's estimation error (about sqrt(1 + 6/12) at most).
  EXPECT_LT(d.fit.validation_rms_m, 1.6 * sigma) << d.summary;
  // Too few rows to register a new placement and score the model: named.
  valid.rows.resize(8);
  try {
    diagnose(robot, calib, &valid, kGeometric, o);
    ADD_FAILURE() << "8 rows of a new set-up accepted";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("'S1'"), std::string::npos) << e.what();
  }
}

// Calibration poses in a narrow range of every joint, where periodic joint errors (harmonics,
// 24 parameters) mimic a joint offset and also soak up part of an error outside the list; held-
// out poses over the whole range. The calibration ranks the harmonics first; the loop adds the
// candidate that predicts the held-out poses best (here the joint offsets), not the calibration's
// first.
TEST(AbsoluteDiagnosis, TheHeldOutPosesChooseWhatTheLoopAdds) {
  const RobotModel robot = ur5();
  std::mt19937_64 rng(8);
  Geometry g = random_geometry(robot.dof(), 1, rng);
  g.axis.setZero();
  g.dq *= 3.0;  // offsets of a few mrad
  const double sigma = 20e-6;
  const RobotModel truth = perturbed(robot, g);
  const Eigen::VectorXd centre = (Eigen::VectorXd(6) << 0.3, -1.2, 1.4, -1.6, -1.3, 0.5).finished();
  auto poses = [&](int count, double half) {
    Dataset d = measure(robot, g, count, sigma, rng);
    std::uniform_real_distribution<double> u(-half, half);
    std::normal_distribution<double> z(0.0, 1.0);
    for (auto& m : d.rows) {
      for (int j = 0; j < robot.dof(); ++j) m.q(j) = centre(j) + u(rng);
      const Eigen::Matrix4d t = truth.tool_pose(m.q + g.dq);
      m.position = g.rot[0] * t.topRightCorner<3, 1>() + g.trans[0];
      m.position(2) += 3e-4 * m.q(1) * m.q(2);  // outside the list: nothing explains it all
      for (int k = 0; k < 3; ++k) m.position(k) += sigma * z(rng);
    }
    return d;
  };
  const Dataset calib = poses(150, 0.35);
  const Dataset valid = poses(60, 1.5);
  DiagnosisOptions o;
  o.auto_loop = true;
  o.max_steps = 2;
  o.candidates = {"joint_offset", "harmonic"};
  const Diagnosis d = diagnose(robot, calib, &valid, {"registration", "tool"}, o);
  ASSERT_GE(d.steps.size(), 2u) << d.summary;
  // Each candidate alone, refitted and scored on the held-out poses.
  auto held_out = [&](const std::string& effect, const std::string& other) {
    DiagnosisOptions one;
    one.candidates = {other};
    return diagnose(robot, calib, &valid, {"registration", "tool", effect}, one)
        .fit.validation_rms_m;
  };
  const std::string better =
      held_out("joint_offset", "harmonic") < held_out("harmonic", "joint_offset") ? "joint_offset"
                                                                                  : "harmonic";
  ASSERT_NE(d.steps[0].top, better) << "the scenario needs the calibration to rank the other first";
  EXPECT_EQ(d.steps[1].added, better) << d.summary;
  EXPECT_LT(d.steps[1].quality.validation_rms_m, d.steps[0].quality.validation_rms_m);
}

/// Mean of the finite held-out errors of a step: its validation rows and its cross-validated
/// calibration rows.
double held_out_mean(const DiagnosisStep& s) {
  double sum = 0;
  int n = 0;
  for (const auto* v : {&s.quality.validation_error_m, &s.quality.cross_validation_error_m})
    for (double e : *v)
      if (std::isfinite(e)) {
        sum += e;
        ++n;
      }
  return n ? sum / n : NAN;
}

// Without validation poses the loop on absolute data still has held-out evidence: the
// calibration's own poses, cross-validated (5 folds). From the nominal model it adds the
// geometry, and the cross-validated error falls at every step.
TEST(AbsoluteDiagnosis, WithoutValidationPosesTheLoopCrossValidates) {
  const RobotModel robot = ur5();
  std::mt19937_64 rng(5);
  Geometry g = random_geometry(robot.dof(), 1, rng);
  g.axis *= 3.0;
  const Dataset calib = measure(robot, g, 150, 20e-6, rng);
  DiagnosisOptions o;
  o.auto_loop = true;
  o.max_steps = 2;
  o.candidates = {"joint_offset", "kinematic", "harmonic"};
  const Diagnosis d = diagnose(robot, calib, nullptr, {"registration", "tool"}, o);
  ASSERT_GE(d.steps.size(), 2u) << d.summary;
  EXPECT_TRUE(d.steps[1].added == "kinematic" || d.steps[1].added == "joint_offset")
      << d.steps[1].added;
  for (size_t i = 0; i < d.steps.size(); ++i)
    ASSERT_EQ(d.steps[i].quality.cross_validation_error_m.size(), calib.rows.size());
  for (size_t i = 1; i < d.steps.size(); ++i)
    EXPECT_LT(held_out_mean(d.steps[i]), held_out_mean(d.steps[i - 1])) << "step " << i;
}

// A robot with geometric errors and a small error outside the candidates (a cable's drag,
// 20 um/rad^2 x q2 q3), measured with 20 um tracker noise, whose data sheet states a
// repeatability of 0.1 mm. Once the geometry is calibrated, the held-out mean error is below
// that: the loop stops there and says what remains is at the robot's repeatability. Without
// the statement the same model is not adequate (the drag leaves structure).
TEST(AbsoluteDiagnosis, LoopStopsAtTheStatedRepeatability) {
  const RobotModel robot = ur5();
  std::mt19937_64 rng(17);
  Geometry g = random_geometry(robot.dof(), 1, rng);
  g.axis *= 3.0;
  auto drag = [](Dataset d) {
    for (auto& m : d.rows) m.position(2) += 2e-5 * m.q(1) * m.q(2);
    return d;
  };
  const Dataset calib = drag(measure(robot, g, 150, 20e-6, rng));
  const Dataset valid = drag(measure(robot, g, 40, 20e-6, rng));
  DiagnosisOptions o;
  o.auto_loop = true;
  o.max_steps = 3;
  o.candidates = {"joint_offset", "kinematic", "gravity_lumped", "harmonic"};
  const Diagnosis free = diagnose(robot, calib, &valid, {"registration", "tool"}, o);
  o.repeatability_m = 1e-4;
  const Diagnosis d = diagnose(robot, calib, &valid, {"registration", "tool"}, o);
  ASSERT_GE(d.steps.size(), 2u) << d.summary;
  const size_t last = d.steps.size() - 1;
  for (size_t i = 0; i < last; ++i)
    EXPECT_GT(held_out_mean(d.steps[i]), o.repeatability_m) << "step " << i;
  EXPECT_LE(held_out_mean(d.steps[last]), o.repeatability_m);
  EXPECT_EQ(d.final_verdict, "adequate") << d.summary;
  ASSERT_FALSE(d.notes.empty());
  EXPECT_NE(d.notes.back().find("repeatability"), std::string::npos) << d.notes.back();
  EXPECT_NE(free.final_verdict, "adequate") << free.summary;
}

/// Zero the truth of every parameter the fit held (the data see only combinations there).
void zero_held(const DeflectionModel& m, const FitResult& f, Geometry* g) {
  const int n = m.robot().dof();
  for (int k = 0; k < m.parameter_count(); ++k) {
    if (f.parameters[k].identified) continue;
    const std::string& e = m.owner(k).name();
    const int i = k - m.offset(m.find(e));
    if (e == "joint_offset")
      g->dq(i) = 0.0;
    else if (e == "kinematic")
      g->axis(i % 4, i / 4) = 0.0;
    else
      ADD_FAILURE() << e << "." << m.spec(k).name << " held";
  }
  (void)n;
}

/// Robots of every kind the geometric calibration must handle: a URDF with parallel axes 2-3-4
/// (UR5), modified DH with parallel axes 2-3 (PUMA 560), and two 7-joint URDF arms (KUKA iiwa
/// with intersecting axes, Franka Panda with offset axes).
class GeometryRecovery : public ::testing::TestWithParam<const char*> {};

TEST_P(GeometryRecovery, WithinThreeStandardErrors) {
  const RobotModel robot = load_robot(test::source_path(GetParam()));
  int inside = 0, total = 0;
  double worst_validation = 0;
  for (int seed = 1; seed <= 4; ++seed) {
    std::mt19937_64 rng(100 + seed);
    Geometry g = random_geometry(robot.dof(), 2, rng);
    const double sigma = 20e-6;
    // The set the data determine, then the truth restricted to it (the same poses and noise
    // again): a held parameter's truth would otherwise bias its partners.
    // Repeated until the held set is stable (what is held depends a little on the truth).
    const std::mt19937_64 start = rng;
    Dataset data;
    FitResult f;
    for (int round = 0; round < 4; ++round) {
      rng = start;
      data = measure(robot, g, 60, sigma, rng);
      f = identify(robot, data, kGeometric);
      const Geometry before = g;
      zero_held(DeflectionModel(robot, kGeometric, &data), f, &g);
      if (before.dq == g.dq && before.axis == g.axis) break;
    }
    const DeflectionModel m(robot, kGeometric, &data);
    const Eigen::VectorXd truth = geometric_theta(m, g);
    for (int k = 0; k < m.parameter_count(); ++k) {
      if (!f.parameters[k].identified) continue;
      ++total;
      const double z = std::abs(f.parameters[k].value - truth(k)) / f.parameters[k].standard_error;
      if (z <= 3.0) ++inside;
    }
    // New poses of the same sessions: the calibrated model predicts them at the noise level.
    const Dataset valid = measure(robot, g, 30, 0.0, rng);
    const auto ctx = m.contexts(valid);
    for (size_t r = 0; r < valid.size(); ++r)
      worst_validation = std::max(
          worst_validation,
          (m.predict(f.theta(), valid.rows[r], ctx[r]).head<3>() - valid.rows[r].position).norm());
    EXPECT_LT(f.sigma_hat_m, 1.3 * sigma) << "seed " << seed;
  }
  // Within 3 standard errors in >= 95 % of (parameter, seed) pairs (99.7 % expected).
  EXPECT_GE(inside, 0.95 * total) << inside << " of " << total;
  // A complete, minimal model of a serial arm has 4R + 2P + 6 parameters (Everett & Roth), 3
  // fewer with positions only: at least 4 per revolute joint are identified in every seed.
  EXPECT_GE(total, 4 * 4 * robot.dof()) << "identified (parameter, seed) pairs";
  // Prediction error of a calibrated model: a few sigma at most (poses like the calibration).
  EXPECT_LT(worst_validation, 6 * 20e-6);
}

INSTANTIATE_TEST_SUITE_P(Robots,
                         GeometryRecovery,
                         ::testing::Values("examples/robots/ur5.urdf",
                                           "examples/robots/puma560.yaml",
                                           "tests/data/urdf/iiwa14.urdf",
                                           "tests/data/urdf/panda.urdf"));

// Geometry and gravity compliance together (lumped gravity-torque parameters, no mass model):
// known geometric errors, registrations, tool and compliance are recovered within three
// standard errors, and the calibrated model predicts new poses at the noise level.
TEST(GeometryAndGravityRecovery, WithinThreeStandardErrors) {
  const RobotModel robot = ur5();
  std::vector<std::string> effects = kGeometric;
  effects.push_back("gravity_lumped");
  const double sigma = 20e-6;
  int inside = 0, total = 0, gravity = 0;
  double z2 = 0;
  for (int seed = 1; seed <= 4; ++seed) {
    std::mt19937_64 rng(700 + seed);
    const Geometry g = random_geometry(robot.dof(), 2, rng);
    std::normal_distribution<double> z(0.0, 1.0);
    const Dataset poses = measure(robot, g, 80, 0.0, rng);
    const DeflectionModel m(robot, effects, &poses);
    Eigen::VectorXd truth = geometric_theta(m, g);
    const int g0 = m.offset(m.find("gravity_lumped"));
    for (int k = g0; k < m.parameter_count(); ++k) truth(k) = m.spec(k).typical * z(rng);
    // Measured by the model itself at the truth, with tracker noise; the truth of what the
    // fit holds is set to its null value and the same poses measured again (as above).
    const std::vector<double> noise = [&] {
      std::vector<double> v(3 * poses.size());
      for (double& x : v) x = sigma * z(rng);
      return v;
    }();
    auto measured = [&](const Eigen::VectorXd& t) {
      Dataset d = poses;
      const auto ctx = m.contexts(d);
      for (size_t r = 0; r < d.size(); ++r)
        d.rows[r].position = m.predict(t, poses.rows[r], ctx[r]).head<3>() +
                             Eigen::Vector3d(noise[3 * r], noise[3 * r + 1], noise[3 * r + 2]);
      return d;
    };
    Dataset data = measured(truth);
    FitResult f = identify(robot, data, effects);
    for (int round = 0; round < 4; ++round) {
      Eigen::VectorXd restricted = truth;
      for (int k = 0; k < m.parameter_count(); ++k)
        if (!f.parameters[k].identified) restricted(k) = m.spec(k).null_value;
      if (restricted == truth) break;
      truth = restricted;
      data = measured(truth);
      f = identify(robot, data, effects);
    }
    for (int k = 0; k < m.parameter_count(); ++k) {
      if (!f.parameters[k].identified) continue;
      ++total;
      gravity += k >= g0;
      const double zk = (f.parameters[k].value - truth(k)) / f.parameters[k].standard_error;
      z2 += zk * zk;
      if (std::abs(zk) <= 3.0) ++inside;
    }
    EXPECT_LT(f.sigma_hat_m, 1.3 * sigma) << "seed " << seed;
  }
  EXPECT_GE(inside, 0.95 * total) << inside << " of " << total;
  EXPECT_GE(gravity, 4 * 4) << "identified gravity parameters over four seeds";
  // The standard errors are the estimates' spread, neither inflated (which would pass the
  // coverage above trivially) nor too small: mean z^2 is 1 for right ones (its spread over
  // four seeds of ~44 correlated parameters is about +-0.3).
  EXPECT_GT(z2 / total, 0.5);
  EXPECT_LT(z2 / total, 2.0);
}

TEST(AbsoluteEffects, RedundantDirectionsAreNamedAndHeld) {
  // The first axis's position and tilt are the registration's; they must be held and named.
  const RobotModel robot = ur5();
  std::mt19937_64 rng(3);
  const Geometry g = random_geometry(robot.dof(), 1, rng);
  const Dataset data = measure(robot, g, 80, 10e-6, rng);
  const FitResult f = identify(robot, data, kGeometric);
  int held = 0;
  for (const auto& p : f.parameters)
    if (!p.identified) {
      ++held;
      EXPECT_TRUE(p.effect == "kinematic" || p.effect == "joint_offset")
          << p.effect << "." << p.name;
    }
  // 6 registration + 3 tool + 6 offsets + 24 axis errors = 39; a position-only tool point
  // leaves 6 + 3 + 4 * 6 + 6 - 6 (base) - 3 (tool orientation and joint 6) ... at least the
  // four of axis 1 and the offset of joint 1 are the registration's.
  EXPECT_GE(held, 5);
  bool named = false;
  for (const auto& w : f.warnings)
    named = named || (w.find("kinematic.du1") != std::string::npos &&
                      w.find("registration") != std::string::npos);
  EXPECT_TRUE(named) << "no warning names kinematic.du1 with the registration";
}

TEST(AbsoluteData, FarAwayFrameWithoutRegistrationIsAnError) {
  const RobotModel robot = ur5();
  std::mt19937_64 rng(5);
  const Geometry g = random_geometry(robot.dof(), 1, rng);
  const Dataset data = measure(robot, g, 20, 10e-6, rng);
  try {
    identify(robot, data, {"tool", "joint_offset"});
    FAIL() << "no error";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("metres away"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("registration"), std::string::npos) << e.what();
  }
}

/// The orientations of `data` (in order), written as Euler angles in `written` and read back
/// as XYZ angles scaled by `unit` (a convention or an angle unit mixed up), are refused naming
/// the cause `what`; the data as they are pass.
void expect_mixed_up_orientations_refused(const RobotModel& robot,
                                          Dataset data,
                                          EulerConvention written,
                                          double unit,
                                          const std::string& what) {
  EXPECT_NO_THROW(check_absolute_data(robot, data, true));
  for (auto& m : data.rows) {
    const Eigen::Vector3d e = matrix_to_euler(written, m.orientation) * unit;
    m.orientation = euler_to_matrix(EulerConvention::xyz, e(0), e(1), e(2));
  }
  try {
    check_absolute_data(robot, data, true);
    FAIL() << "no error";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
}

TEST(AbsoluteData, EulerConventionMixUpIsDetected) {
  // 6-D data written in ZYX but read as XYZ turn by wrong angles between poses.
  const RobotModel robot = ur5();
  std::mt19937_64 rng(9);
  const Geometry g = random_geometry(robot.dof(), 1, rng);
  Dataset data = measure(robot, g, 20, 10e-6, rng);
  add_orientation(robot, g, Eigen::Vector3d::Zero(), 0.0, rng, &data);
  expect_mixed_up_orientations_refused(robot, data, EulerConvention::zyx, 1.0, "Euler convention");
}

TEST(Identifiability, JointTheDataBarelySeeIsHeldNotFittedToNoise) {
  // The measured point 0.24 mm off the joint-6 axis: joint 6's torque lever is 0.24 mm, its
  // deflection 1e-3 of the tracker noise. Its compliance must be held, with a warning.
  RobotModel robot = test::rokae();
  robot.measured_point = Eigen::Vector3d(0.24e-3, 0.0, robot.measured_point(2));
  robot.load_point = robot.measured_point;
  RandomDesignOptions o;
  o.count = 60;
  o.seed = 21;
  const Dataset design = random_design(robot, o);
  NoiseModel noise;
  noise.tracker_sigma_m = 10e-6;
  const Dataset data = simulate(robot, joint_truth(test::paper_stiffness()), design, noise);
  const FitResult f = identify(robot, data, {"joint"});
  EXPECT_FALSE(f.parameters[5].identified)
      << "c6 = " << f.parameters[5].value << " +- " << f.parameters[5].standard_error;
  EXPECT_EQ(f.parameters[5].value, 0.0);  // held at the null value: infinitely stiff
  bool warned = false;
  for (const auto& w : f.warnings) warned = warned || w.find("joint.c6") != std::string::npos;
  EXPECT_TRUE(warned);
  for (int j = 0; j < 5; ++j) EXPECT_TRUE(f.parameters[j].identified) << "joint " << j + 1;
}

/// Rows of `data` whose session is `label`.
Dataset session_rows(const Dataset& data, const std::string& label, int first, int count) {
  Dataset out = data;
  out.rows.clear();
  int seen = 0;
  for (const Measurement& m : data.rows)
    if (m.session == label && seen++ >= first && static_cast<int>(out.rows.size()) < count)
      out.rows.push_back(m);
  return out;
}

/// Held-out RMS of the 3-D position error of fit f on rows.
double held_out_rms(const RobotModel& robot, const FitResult& f, const Dataset& rows) {
  const DeflectionModel m(robot, f.model, &rows);
  const auto ctx = m.contexts(rows);
  double ss = 0;
  for (size_t r = 0; r < rows.size(); ++r)
    ss += (m.predict(f.theta(), rows.rows[r], ctx[r]).head<3>() - rows.rows[r].position)
              .squaredNorm();
  return std::sqrt(ss / static_cast<double>(rows.size()));
}

TEST(AbsoluteEffects, NewPlacementIsRegisteredToACalibratedRobotFromFifteenPoses) {
  // Calibrate on placement S0; register placement S1 alone (--start --refit registration)
  // from 15 poses; predict 200 other poses of S1. With sigma = 20 um per axis, the calibrated
  // geometry's own error is small (200 poses), and six registration parameters from 45
  // equations add about sqrt(6/45) of the noise: the RMS of a held-out 3-D error stays within
  // 1.3 sqrt(3) sigma.
  const RobotModel robot = ur5();
  std::mt19937_64 rng(21);
  const double sigma = 20e-6;
  const Geometry g = random_geometry(robot.dof(), 2, rng);
  const Dataset all = measure(robot, g, 215, sigma, rng);
  const FitResult cal = identify(robot, session_rows(all, "S0", 0, 215), kGeometric);
  IdentifyOptions o;
  o.start = &cal;
  o.refit = {"registration"};
  const Dataset few = session_rows(all, "S1", 0, 15);
  const FitResult reg = identify(robot, few, kGeometric, o);
  // Every parameter but the registration is the calibration's, as it was.
  int fitted = 0;
  for (const FitParameter& q : reg.parameters) {
    if (q.effect == "registration") {
      EXPECT_TRUE(q.identified) << q.name;
      ++fitted;
      continue;
    }
    const auto c = std::find_if(
        cal.parameters.begin(), cal.parameters.end(),
        [&](const FitParameter& x) { return x.effect == q.effect && x.name == q.name; });
    ASSERT_NE(c, cal.parameters.end()) << q.effect << "." << q.name;
    EXPECT_EQ(q.value, c->value) << q.effect << "." << q.name;
    EXPECT_EQ(q.identified, c->identified) << q.effect << "." << q.name;
  }
  EXPECT_EQ(fitted, 6);
  EXPECT_EQ(reg.rank, 6);
  const double rms = held_out_rms(robot, reg, session_rows(all, "S1", 15, 200));
  EXPECT_LT(rms, 1.3 * std::sqrt(3.0) * sigma) << rms;
}

TEST(AbsoluteEffects, ModelErrorAboveTheStatedNoiseIsAVarianceComponent) {
  // A tracker states sigma_p per row, here spread over 2-60 um (log-uniform), while the rows
  // carry 150 um per axis more (what an arm's unmodelled errors add). Weighted by the stated
  // sigma alone, the few rows with the smallest sigma would decide the fit; with the model's
  // error estimated as a variance component of its own, the weights become nearly equal, as
  // the residuals are. Tolerances: the variance estimate from 3N - p = 570 components has a
  // relative standard error sqrt(2 / 570) = 6 %, so s within 10 % (3.4 standard errors of s);
  // the error of the fitted model on held-out poses (measured with the instrument's noise
  // alone) then matches the unweighted fit's within 5 %.
  const RobotModel robot = ur5();
  std::mt19937_64 rng(5);
  const Geometry g = random_geometry(robot.dof(), 1, rng);
  const double excess = 150e-6;
  std::uniform_real_distribution<double> u(std::log(2e-6), std::log(60e-6));
  std::normal_distribution<double> z(0.0, 1.0);
  auto rows = [&](int count, double extra) {
    Dataset d = measure(robot, g, count, 0.0, rng);
    d.has_sigma_p = true;
    for (Measurement& m : d.rows) {
      m.sigma_p = std::exp(u(rng));
      for (int k = 0; k < 3; ++k) m.position(k) += std::hypot(m.sigma_p, extra) * z(rng);
    }
    return d;
  };
  const Dataset cal = rows(200, excess), test = rows(300, 0.0);  // held out: the instrument's noise
  const FitResult f = identify(robot, cal, kGeometric);
  EXPECT_NEAR(f.model_error_m, excess, 0.1 * excess);
  EXPECT_NEAR(f.sigma_hat_m, excess, 0.1 * excess);
  IdentifyOptions plain;
  plain.use_sigma = false;
  const FitResult unweighted = identify(robot, cal, kGeometric, plain);
  const double e = held_out_rms(robot, f, test), e0 = held_out_rms(robot, unweighted, test);
  EXPECT_LT(e, 1.05 * e0) << "weighted " << e << ", unweighted " << e0;

  // Where the stated sigma is the noise, s^2 stays below what a chi2 three standard deviations
  // above its mean gives, 3 sqrt(2 nu) / sum sigma^-2, far below every stated sigma^2.
  const Dataset clean = rows(200, 0.0);
  const FitResult c = identify(robot, clean, kGeometric);
  double info = 0, smallest = INFINITY;
  for (const Measurement& m : clean.rows) {
    info += 3.0 / (m.sigma_p * m.sigma_p);
    smallest = std::min(smallest, m.sigma_p);
  }
  const double nu = static_cast<double>(c.dof);
  EXPECT_LE(c.model_error_m * c.model_error_m, 3.0 * std::sqrt(2.0 * nu) / info);
  EXPECT_LT(c.model_error_m, 0.5 * smallest);
}

TEST(AbsoluteEffects, RefitNeedsAStartFitThatGivesEverythingElse) {
  const RobotModel robot = ur5();
  std::mt19937_64 rng(22);
  const Geometry g = random_geometry(robot.dof(), 1, rng);
  const Dataset data = measure(robot, g, 60, 20e-6, rng);
  const FitResult cal = identify(robot, data, kGeometric);
  IdentifyOptions o;
  o.refit = {"registration"};
  EXPECT_THROW(identify(robot, data, kGeometric, o), InvalidArgument);  // no start
  o.start = &cal;
  o.refit = {"harmonic"};  // not in the model
  EXPECT_THROW(identify(robot, data, kGeometric, o), InvalidArgument);
  // A model with an effect the start fit does not hold, not refitted: named.
  o.refit = {"registration"};
  std::vector<std::string> more = kGeometric;
  more.push_back("harmonic");
  try {
    identify(robot, data, more, o);
    FAIL();
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("harmonic."), std::string::npos) << e.what();
  }
  // A start fit of another robot.
  FitResult other = cal;
  other.robot_name = "other";
  other.robot_digest = "fnv1a64:0000000000000000";
  o.start = &other;
  EXPECT_THROW(identify(robot, data, kGeometric, o), InvalidArgument);
}

TEST(AbsoluteEffects, CalibratedRobotCarriesTheFittedGeometry) {
  // The calibrated robot's plain forward kinematics, put in the instrument frame by the fit's
  // registration, is the model's prediction: the geometry is built into the description.
  const RobotModel robot = ur5();
  std::mt19937_64 rng(23);
  const Geometry g = random_geometry(robot.dof(), 1, rng);
  const Dataset data = measure(robot, g, 120, 20e-6, rng);
  std::vector<std::string> model = kGeometric;
  model.push_back("harmonic");  // depends on the pose: left out, and named
  const FitResult fit = identify(robot, data, model);
  std::vector<std::string> left_out;
  const RobotModel cal = calibrated_robot(robot, fit, &left_out);
  ASSERT_EQ(left_out.size(), 2u);
  EXPECT_EQ(left_out[0].rfind("registration", 0), 0u);
  EXPECT_EQ(left_out[1].rfind("harmonic", 0), 0u);
  const FitResult geometric = identify(robot, data, kGeometric);
  const RobotModel cal2 = calibrated_robot(robot, geometric);
  const DeflectionModel m(robot, kGeometric, &data);
  const auto ctx = m.contexts(data);
  Eigen::Vector3d w, t;
  for (const FitParameter& q : geometric.parameters)
    for (int k = 0; k < 3; ++k) {
      if (q.name == std::string("omega_") + "xyz"[k] + "_S0") w(k) = q.value;
      if (q.name == std::string("t_") + "xyz"[k] + "_S0") t(k) = q.value;
    }
  const Eigen::Matrix3d r = Eigen::AngleAxisd(w.norm(), w.normalized()).matrix();
  for (size_t i = 0; i < data.size(); i += 7) {
    const Eigen::Vector3d model_p = m.predict(geometric.theta(), data.rows[i], ctx[i]).head<3>();
    const Eigen::Vector3d robot_p = r * cal2.tool_pose(data.rows[i].q).topRightCorner<3, 1>() + t;
    EXPECT_LT((model_p - robot_p).norm(), 1e-12) << "row " << i;
  }
  EXPECT_EQ(cal2.name, "ur5_calibrated");
  // A fit of another robot is refused.
  FitResult other = geometric;
  other.robot_digest = "fnv1a64:0000000000000000";
  EXPECT_THROW(calibrated_robot(robot, other), InvalidArgument);
}

// ---- 6-D data: the probe's orientation.

const std::vector<std::string> kFullTool = {"registration", "tool", "tool_orientation",
                                            "joint_offset", "kinematic"};

// The orientation residual's derivatives (automatic, through the chain rule of the fast path
// and through the generic Jet chain) against central differences of the double evaluation, on
// a geometric model with the probe's rotation and on one that deflects under the robot's weight.
TEST(OrientationResidual, DerivativesMatchCentralDifferences) {
  const RobotModel robot = ur5();
  std::mt19937_64 rng(31);
  const Geometry g = random_geometry(robot.dof(), 2, rng);
  Dataset data = measure(robot, g, 4, 0.0, rng);
  add_orientation(robot, g, Eigen::Vector3d(0.4, -1.2, 0.7), 0.0, rng, &data);
  for (const bool deflects : {false, true}) {
    std::vector<std::string> effects = kFullTool;
    if (deflects) {
      effects.push_back("gravity_lumped");
      effects.push_back("joint");
    }
    const DeflectionModel m(robot, effects, &data);
    const int p = m.parameter_count();
    Eigen::VectorXd theta = geometric_theta(m, g);
    // Away from the truth, so that the discrepancy is not zero (where Log is least smooth).
    theta.segment<3>(m.offset(m.find("tool_orientation"))) = Eigen::Vector3d(0.41, -1.18, 0.72);
    if (deflects)
      for (int k = m.offset(m.find("gravity_lumped")); k < p; ++k)
        theta(k) = 0.7 * m.spec(k).typical;
    const auto ctx = m.contexts(data);
    EvalState<Jet> scratch;
    for (size_t r = 0; r < data.size(); ++r)
      for (int first = 0; first < p; first += kJetStride) {
        const std::vector<Jet> t = seeded(theta, first);
        const int last = std::min(p, first + kJetStride);
        Vector3<Jet> d, slow, fast;
        m.evaluate<Jet>(t.data(), data.rows[r], ctx[r], &d, nullptr, &slow);
        m.evaluate_jet(t.data(), data.rows[r], ctx[r], scratch, &d, &fast);
        for (int k = first; k < last; ++k) {
          const double h = 1e-6 * std::max(std::abs(theta(k)), m.spec(k).typical);
          Eigen::VectorXd tp = theta, tm = theta;
          tp(k) += h;
          tm(k) -= h;
          Vector3<double> dd, op, om;
          m.evaluate<double>(tp.data(), data.rows[r], ctx[r], &dd, nullptr, &op);
          m.evaluate<double>(tm.data(), data.rows[r], ctx[r], &dd, nullptr, &om);
          const Eigen::Vector3d fd = (op - om) / (2 * h);
          Eigen::Vector3d ad_slow, ad_fast;
          for (int i = 0; i < 3; ++i) {
            ad_slow(i) = slow(i).v(k - first);
            ad_fast(i) = fast(i).v(k - first);
          }
          // Rotation vectors of ~0.05 rad: rounding 1e-16 / h; truncation (h / scale)^2.
          const double tol = 1e-6 * fd.norm() + 1e-15 / h;
          EXPECT_LT((ad_slow - fd).norm(), tol)
              << m.owner(k).name() << "." << m.spec(k).name << " row " << r << " deflects "
              << deflects << ": ad " << ad_slow.transpose() << " fd " << fd.transpose();
          EXPECT_LT((ad_fast - ad_slow).norm(), 1e-12 * (1.0 + ad_slow.norm()))
              << m.owner(k).name() << "." << m.spec(k).name << " row " << r;
        }
      }
  }
}

// With the model's truth the predicted probe orientation is the measured one, and predict()
// gives it in the instrument frame.
TEST(OrientationResidual, ModelEqualsTheIndependentlyPerturbedRobot) {
  const RobotModel robot = ur5();
  std::mt19937_64 rng(32);
  const Geometry g = random_geometry(robot.dof(), 2, rng);
  Dataset data = measure(robot, g, 10, 0.0, rng);
  const Eigen::Vector3d probe(0.1, 1.5, -0.3);
  add_orientation(robot, g, probe, 0.0, rng, &data);
  const DeflectionModel m(robot, kFullTool, &data);
  Eigen::VectorXd theta = geometric_theta(m, g);
  theta.segment<3>(m.offset(m.find("tool_orientation"))) = probe;
  const auto ctx = m.contexts(data);
  for (size_t r = 0; r < data.size(); ++r) {
    Vector3<double> d, o;
    m.evaluate<double>(theta.data(), data.rows[r], ctx[r], &d, nullptr, &o);
    EXPECT_LT(o.norm(), 1e-12) << "row " << r;
    const Eigen::Vector3d w = m.predict(theta, data.rows[r], ctx[r]).tail<3>();
    const Eigen::Matrix3d rp = Eigen::AngleAxisd(w.norm(), w.normalized()).matrix();
    EXPECT_LT((rp - data.rows[r].orientation).norm(), 1e-12) << "row " << r;
  }
}

// Recovery from 6-D data: registration (with its rotation), the probe's rotation on the flange
// and the kinematic errors within 3 standard errors; the fit's orientation residual at the
// noise level. The same poses without orientation hold the probe's rotation and name it.
TEST(OrientationResidual, SixDimensionalDataIdentifyTheToolFrame) {
  const RobotModel robot = ur5();
  const double sigma = 20e-6, sigma_o = 20e-6;  // 20 um, 20 urad (the default 1 m per rad)
  const Eigen::Vector3d probe(0.2, -0.9, 1.4);
  int inside = 0, total = 0;
  for (int seed = 1; seed <= 3; ++seed) {
    std::mt19937_64 rng(300 + seed);
    Geometry g = random_geometry(robot.dof(), 2, rng);
    const std::mt19937_64 start = rng;
    Dataset data;
    FitResult f;
    for (int round = 0; round < 4; ++round) {
      rng = start;
      data = measure(robot, g, 60, sigma, rng);
      add_orientation(robot, g, probe, sigma_o, rng, &data);
      f = identify(robot, data, kFullTool);
      const Geometry before = g;
      zero_held(
          DeflectionModel(robot, kGeometric, &data),
          [&] {
            FitResult geometric = f;  // the parameters of kGeometric, in its order
            geometric.parameters.erase(
                std::remove_if(
                    geometric.parameters.begin(), geometric.parameters.end(),
                    [](const FitParameter& q) { return q.effect == "tool_orientation"; }),
                geometric.parameters.end());
            return geometric;
          }(),
          &g);
      if (before.dq == g.dq && before.axis == g.axis) break;
    }
    ASSERT_EQ(f.oriented_rows, static_cast<int>(data.size()));
    const DeflectionModel m(robot, kFullTool, &data);
    Eigen::VectorXd truth = geometric_theta(m, g);
    truth.segment<3>(m.offset(m.find("tool_orientation"))) = probe;
    for (int k = 0; k < m.parameter_count(); ++k) {
      const std::string& e = m.owner(k).name();
      if (e == "tool_orientation" || e == "registration" || e == "tool") {
        EXPECT_TRUE(f.parameters[k].identified) << e << "." << m.spec(k).name;
      }
      if (!f.parameters[k].identified) continue;
      ++total;
      const double z = std::abs(f.parameters[k].value - truth(k)) / f.parameters[k].standard_error;
      if (z <= 3.0) ++inside;
    }
    // Both residuals at their noise (3 components each): RMS within 30 %.
    EXPECT_LT(f.rms_m, 1.3 * sigma) << "seed " << seed;
    EXPECT_LT(f.orientation_rms_rad, 1.3 * sigma_o) << "seed " << seed;
    EXPECT_GT(f.orientation_rms_rad, 0.7 * sigma_o) << "seed " << seed;
    // Without the orientations the probe's rotation is invisible: held and named.
    Dataset positions = data;
    positions.has_orientation = false;
    for (auto& row : positions.rows) row.has_orientation = false;
    const FitResult fp = identify(robot, positions, kFullTool);
    EXPECT_EQ(fp.oriented_rows, 0);
    for (const FitParameter& q : fp.parameters)
      if (q.effect == "tool_orientation") {
        EXPECT_FALSE(q.identified) << q.name;
        bool named = false;
        for (const auto& w : fp.warnings)
          named = named || w.find("tool_orientation." + q.name) != std::string::npos;
        EXPECT_TRUE(named) << q.name;
      }
    // More is identified with the orientations than with the positions alone.
    EXPECT_GE(f.rank, fp.rank + 3) << "seed " << seed;
  }
  EXPECT_GE(inside, 0.95 * total) << inside << " of " << total;
}

TEST(OrientationResidual, NonFiniteOrientationIsRefusedNamingTheRow) {
  const RobotModel robot = ur5();
  std::mt19937_64 rng(33);
  const Geometry g = random_geometry(robot.dof(), 1, rng);
  Dataset data = measure(robot, g, 20, 10e-6, rng);
  add_orientation(robot, g, Eigen::Vector3d(0.1, 0.2, 0.3), 10e-6, rng, &data);
  data.rows[7].orientation(1, 2) = NAN;
  try {
    identify(robot, data, kFullTool);
    FAIL() << "no error";
  } catch (const InvalidArgument& e) {
    const std::string w = e.what();
    EXPECT_NE(w.find(data.rows[7].id), std::string::npos) << w;
    EXPECT_NE(w.find("orientation"), std::string::npos) << w;
  }
}

TEST(OrientationResidual, DegreesDeclaredAsRadiansAreDetected) {
  // Euler angles in degrees read as radians turn the probe by wild angles between poses.
  const RobotModel robot = ur5();
  std::mt19937_64 rng(34);
  const Geometry g = random_geometry(robot.dof(), 1, rng);
  Dataset data = measure(robot, g, 20, 10e-6, rng);
  add_orientation(robot, g, Eigen::Vector3d(0.1, 0.2, 0.3), 10e-6, rng, &data);
  expect_mixed_up_orientations_refused(robot, data, EulerConvention::xyz, 180.0 / 3.141592653589793,
                                       "_deg or _rad");
}

}  // namespace
}  // namespace stiff
