// Signatures of mechanisms outside the library, as groups of columns that the residual is
// tested against in "where it fails" (docs/diagnosis.md, section 2). None is an effect: the
// library neither fits nor compensates them; a residual that follows one says what is left.
// Each mechanism is one function here and one line in kMechanisms.
#include <algorithm>
#include <cmath>

#include "diagnose/analysis.hpp"

namespace stiff::diagnose_detail {

namespace {

using Groups = std::vector<OutsideTrend>;

/// The arm turning as a whole about the axes of its mounting plane (base x and y) under the
/// load's moment there (a compliant pedestal, floor, wall or mounting plate): theta = (c_x M_x,
/// c_y M_y, 0), the base moment M = L x F + m, and the displacement theta x (P + h e_z) about a
/// pivot h below the base frame (four columns: c_x, c_y and their products with h). The
/// joints, the links and a force-frame error take part of it up; what they leave shows here.
void base_tilt(const Context& cx, const Analysis& a, const std::string& name, Groups* out) {
  const RobotModel& robot = *cx.robot;
  MatrixXd z = MatrixXd::Zero(a.n, 4);
  const Eigen::Vector3d ex = Eigen::Vector3d::UnitX(), ey = Eigen::Vector3d::UnitY();
  const Eigen::Vector3d ez = Eigen::Vector3d::UnitZ();
  for (size_t i = 0; i < a.used.rows.size(); ++i) {
    const auto& m = a.used.rows[i];
    const auto& c = a.ctx[i];
    const Eigen::Vector3d p = robot.point_position(c.chain, robot.measured_point);
    const Eigen::Vector3d l = robot.point_position(c.chain, robot.load_point);
    const Eigen::Vector3d mb = l.cross(m.force) + m.moment;
    const Eigen::Vector3d cols[4] = {mb.x() * ex.cross(p), mb.y() * ey.cross(p),
                                     mb.x() * ex.cross(ez), mb.y() * ey.cross(ez)};
    for (int k = 0; k < 4; ++k) z.block<3, 1>(3 * i, k) = a.W[i] * cols[k];
  }
  out->push_back(
      {name,
       "the arm turning as a whole about the base x and y axes (its mounting plane) "
       "under the load's moment there (pedestal or floor compliance, not in the library)",
       std::move(z), false});
}

/// A joint whose compliance varies with the arm's angles (a reducer's stiffness over its output
/// turn, a shoulder stiffer as the forearm folds): per joint j its deflection under the load,
/// J_j(P) tau_j, times the first harmonics cos q_k, sin q_k of each angle that moves the arm
/// (the mean compliance is the joint model's). Ten columns take up much of what the library's
/// pose-dependent laws (nonlinear joint, compensator) leave, so the group counts only beyond
/// each candidate; and not with a law decided from the data (backlash): its preload follows the
/// gravity torque, a function of the same angles, so a preload shape off the truth leaves
/// exactly this pattern at its joints.
void pose_compliance(const Context& cx, const Analysis& a, const std::string& name, Groups* out) {
  if (has_confidence_sets(*a.model)) return;
  const RobotModel& robot = *cx.robot;
  const int dof = robot.dof(), angles = std::max(1, dof - 1);
  std::vector<MatrixXd> z(dof, MatrixXd::Zero(a.n, 2 * angles));
  for (size_t i = 0; i < a.used.rows.size(); ++i) {
    const auto& m = a.used.rows[i];
    const auto& c = a.ctx[i];
    const Matrix6X<double> jm =
        robot.jacobian_at(c.chain, robot.point_position(c.chain, robot.measured_point));
    const VectorXd tau = load_torques(robot, m, c);
    for (int j = 0; j < dof; ++j) {
      const Eigen::Vector3d deflection = a.W[i] * (tau(j) * jm.block<3, 1>(0, j));
      for (int k = 0; k < angles; ++k) {
        z[j].block<3, 1>(3 * i, 2 * k) = std::cos(m.q(k)) * deflection;
        z[j].block<3, 1>(3 * i, 2 * k + 1) = std::sin(m.q(k)) * deflection;
      }
    }
  }
  for (int j = 0; j < dof; ++j)
    out->push_back({name + std::to_string(j + 1),
                    "the compliance of joint " + std::to_string(j + 1) +
                        " varying with the arm's angles (not in the library)",
                    std::move(z[j]), true});
}

/// The arm shifting as a whole under the load's force (a compliant base plate or floor):
/// d = C_b F with C_b symmetric in the base frame (six columns). A series compliance at the
/// tool turns with the flange; this does not.
void base_shift(const Context&, const Analysis& a, const std::string& name, Groups* out) {
  MatrixXd z = MatrixXd::Zero(a.n, 6);
  const int pairs[6][2] = {{0, 0}, {1, 1}, {2, 2}, {0, 1}, {0, 2}, {1, 2}};
  for (size_t i = 0; i < a.used.rows.size(); ++i) {
    const Eigen::Vector3d& f = a.used.rows[i].force;
    for (int k = 0; k < 6; ++k) {
      Eigen::Vector3d col = Eigen::Vector3d::Zero();
      col(pairs[k][0]) += f(pairs[k][1]);
      if (pairs[k][0] != pairs[k][1]) col(pairs[k][1]) += f(pairs[k][0]);
      z.block<3, 1>(3 * i, k) = a.W[i] * col;
    }
  }
  out->push_back({name,
                  "the arm shifting as a whole under the load's force, fixed in the base frame "
                  "(base plate or floor compliance, not in the library)",
                  std::move(z), false});
}

/// Each session's mean reading time (the rows' times are from the session's first reading).
std::vector<double> session_mean_times(const Analysis& a) {
  std::vector<double> sum, count;
  for (const auto& c : a.ctx) {
    const size_t s = static_cast<size_t>(c.session);
    if (s >= sum.size()) sum.resize(s + 1, 0.0), count.resize(s + 1, 0.0);
    sum[s] += c.time;
    count[s] += 1;
  }
  for (size_t s = 0; s < sum.size(); ++s) sum[s] /= std::max(count[s], 1.0);
  return sum;
}

/// The response to the load not in proportion to it: the model's deflection under the row's
/// load (its prediction less that without load, so that drift terms cancel), taken once per row,
/// scaled by
///  - the reading's time from its session's mean time: the response changing in scale over a
///    session (the joints softening as their reducers warm up, a force sensor's gain drifting);
///  - the load's level relative to the mean level of the rows with a force, |F|/F0 - 1: the
///    whole arm's response scaled by the level alike at every joint (a force sensor whose gain
///    changes with the level, its non-linearity; a fixture that settles further under a larger
///    load). A joint's compliance changing with its own torque is nonlinear_joint's; this is the
///    part no joint's law has.
/// One column each.
void load_response(const Context&, const Analysis& a, const std::string& name, Groups* out) {
  const std::vector<double> mean_time = session_mean_times(a);
  double mean_level = 0;
  int forces = 0;
  for (const auto& m : a.used.rows)
    if (m.force.squaredNorm() > 0.0) mean_level += m.force.norm(), ++forces;
  if (forces > 0) mean_level /= forces;
  MatrixXd drift = MatrixXd::Zero(a.n, 1), level = MatrixXd::Zero(a.n, 1);
  for (size_t i = 0; i < a.used.rows.size(); ++i) {
    const auto& m = a.used.rows[i];
    if (m.force.squaredNorm() == 0.0 && m.moment.squaredNorm() == 0.0) continue;
    const auto& c = a.ctx[i];
    Measurement unloaded = m;
    unloaded.force.setZero();
    unloaded.moment.setZero();
    const Eigen::Vector3d deflection = a.model->predict(a.theta, m, c).head<3>() -
                                       a.model->predict(a.theta, unloaded, c).head<3>();
    drift.block<3, 1>(3 * i, 0) =
        (c.time - mean_time[static_cast<size_t>(c.session)]) * (a.W[i] * deflection);
    if (m.force.squaredNorm() > 0.0)
      level.block<3, 1>(3 * i, 0) = (m.force.norm() / mean_level - 1.0) * (a.W[i] * deflection);
  }
  out->push_back({name + "drift",
                  "the response to the load changing in scale over the session (joints warming "
                  "up, a force sensor's gain drifting; not in the library)",
                  std::move(drift), false});
  if (forces > 0)
    out->push_back({name + "level",
                    "the response not in proportion to the load, scaled by the load's level "
                    "alike at every joint (a force sensor's non-linearity; not in the library)",
                    std::move(level), false});
}

/// A zero offset of the force reading, an error that force_frame (the reading's linear map:
/// rotations, gains, cross-talk) does not have: a sensor not tared or its zero drifted with
/// temperature, a load cell's bias under a fixture. The displacement it leaves is the model's
/// own response to the force error, G(q) dF, with G the model's displacement per unit force at
/// the row (Analysis::force_response), so that the columns are those of whatever the arm's
/// compliance is: dF = R e_k in the sensor frame and e_k in the base frame, six columns. The
/// force reading's own noise moves the point along these very directions, by each row's
/// compliance: the group is tested with each row's own residual variance (robust_group), where
/// one variance for all rows reads a soft arm's force noise as an offset when the data do not
/// state it (stated, it is in each row's covariance). Only rows with a written force have it.
void force_reading(const Context&, const Analysis& a, const std::string& name, Groups* out) {
  MatrixXd offset = MatrixXd::Zero(a.n, 6);
  for (size_t i = 0; i < a.used.rows.size(); ++i) {
    const auto& m = a.used.rows[i];
    if (m.force.squaredNorm() == 0.0) continue;  // an unloaded (absolute) row: no reading
    const auto& c = a.ctx[i];
    const Eigen::Matrix3d wg = a.W[i] * a.force_response[i];
    const Eigen::Matrix3d rot = c.chain.flange.topLeftCorner<3, 3>();
    for (int k = 0; k < 3; ++k) {
      offset.block<3, 1>(3 * i, k) = wg * rot.col(k);
      offset.block<3, 1>(3 * i, 3 + k) = wg.col(k);
    }
  }
  out->push_back({name + "offset",
                  "the model's response to a constant force error in the sensor or the base "
                  "frame (a force reading's zero offset, not in the library)",
                  std::move(offset), false, true});
}

/// Thermal growth of the arm between its readings (links lengthening as they warm, a
/// temperature change of the base): the measured point moves by a strain times its position
/// from the base frame, eps P, the same eps for the rows of a session read in one order, and
/// growing or shrinking over it. Two columns per session: P and P times the reading's time from
/// the session's mean. The library's drift is a translation and its thermal effect needs a
/// temperature column and absolute positions.
void thermal_growth(const Context& cx, const Analysis& a, const std::string& name, Groups* out) {
  const RobotModel& robot = *cx.robot;
  const std::vector<double> mean = session_mean_times(a);
  MatrixXd z = MatrixXd::Zero(a.n, 2 * static_cast<Eigen::Index>(mean.size()));
  for (size_t i = 0; i < a.used.rows.size(); ++i) {
    const auto& c = a.ctx[i];
    const size_t s = static_cast<size_t>(c.session);
    const Eigen::Vector3d p = robot.point_position(c.chain, robot.measured_point);
    z.block<3, 1>(3 * i, 2 * s) = a.W[i] * p;
    z.block<3, 1>(3 * i, 2 * s + 1) = (c.time - mean[s]) * (a.W[i] * p);
  }
  out->push_back({name,
                  "the measured point moving in proportion to its position from the base "
                  "(thermal growth of the arm between the readings, not in the library)",
                  std::move(z), false});
}

/// A mechanism: the name its groups take (a trailing '_' is followed by what tells its groups
/// apart: a joint's number, a kind of error) and the function that makes them.
struct Mechanism {
  const char* name;
  void (*groups)(const Context&, const Analysis&, const std::string& name, Groups*);
};
const Mechanism kMechanisms[] = {{"base_tilt", base_tilt},   {"pose_compliance_", pose_compliance},
                                 {"base_shift", base_shift}, {"load_response_", load_response},
                                 {"sensor_", force_reading}, {"thermal_growth", thermal_growth}};

}  // namespace

std::vector<OutsideTrend> outside_trends(const Context& cx, const Analysis& a) {
  Groups out;
  for (const Mechanism& m : kMechanisms) m.groups(cx, a, m.name, &out);
  return out;
}

bool is_outside_library(const std::string& covariate) {
  return std::any_of(std::begin(kMechanisms), std::end(kMechanisms), [&](const Mechanism& m) {
    const std::string n = m.name;
    return n.back() == '_' ? covariate.rfind(n, 0) == 0 : covariate == n;
  });
}

}  // namespace stiff::diagnose_detail
