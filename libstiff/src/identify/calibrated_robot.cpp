// The calibrated robot: a fit's pose-independent geometry built into the robot description.
#include <ceres/rotation.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "stiff/error.hpp"
#include "stiff/identify/fit.hpp"
#include "stiff/model/effect.hpp"
#include "stiff/model/model.hpp"

namespace stiff {

namespace {

/// The geometry stage and the measured point of one effect at joint angles q.
struct Contribution {
  Eigen::VectorXd dq;
  Eigen::Matrix<double, 6, Eigen::Dynamic> joint_error;
  Eigen::Vector3d r_meas, r_load, force, moment;
  Eigen::Matrix3d probe;  ///< a 6-D probe's rotation on the flange
};

Contribution contribution(const Effect& e,
                          const double* p,
                          const RobotModel& robot,
                          const Measurement& m,
                          const MeasurementContext& c) {
  const int n = robot.dof();
  EvalState<double> s;
  s.robot = &robot;
  s.measurement = &m;
  s.context = &c;
  s.force.setZero();
  s.moment.setZero();
  s.r_meas = robot.measured_point;
  s.r_load = robot.load_point;
  s.dq = Eigen::VectorXd::Zero(n);
  s.joint_error = Eigen::MatrixXd::Zero(6, n);
  s.probe.setIdentity();
  s.orientation.setIdentity();
  s.oriented = true;
  e.wrench(p, s);
  e.geometry(p, s);
  return {s.dq, s.joint_error, s.r_meas, s.r_load, s.force, s.moment, s.probe};
}

bool same(const Contribution& a, const Contribution& b) {
  return (a.dq - b.dq).cwiseAbs().maxCoeff() < 1e-15 &&
         (a.joint_error - b.joint_error).cwiseAbs().maxCoeff() < 1e-15 &&
         (a.r_meas - b.r_meas).norm() < 1e-15;
}

}  // namespace

RobotModel calibrated_robot(const RobotModel& robot,
                            const FitResult& fit,
                            std::vector<std::string>* left_out) {
  const int n = robot.dof();
  // The fit's model (its sessions named, as for prediction), and two poses to tell an effect
  // that depends on the pose from one that does not.
  const DeflectionModel model(robot, fit.model, nullptr, fit.sessions);
  Dataset data;
  data.dof = n;
  data.has_id = data.has_position = true;
  data.has_session = !fit.sessions.empty();
  for (int pose = 0; pose < 2; ++pose) {
    Measurement m;
    m.id = "pose" + std::to_string(pose);
    m.session = fit.sessions.empty() ? "" : fit.sessions.front();
    m.absolute = true;
    m.q = Eigen::VectorXd::Zero(n);
    for (int j = 0; j < n; ++j) {
      const double lo = std::max(robot.joints[j].lower, -3.0);
      const double hi = std::min(robot.joints[j].upper, 3.0);
      m.q(j) = lo + (pose ? 0.3 : 0.7) * (hi - lo);
    }
    data.rows.push_back(m);
  }
  const Eigen::VectorXd theta = fit_for_model(fit, robot, model, "calibrated robot").theta();
  const auto ctx = model.contexts(data);

  Eigen::VectorXd dq = Eigen::VectorXd::Zero(n);
  Eigen::MatrixXd joint_error = Eigen::MatrixXd::Zero(6, n);
  Eigen::Vector3d r_meas = robot.measured_point;
  std::vector<std::string> out;
  for (size_t e = 0; e < model.effects().size(); ++e) {
    const Effect& eff = *model.effects()[e];
    const double* p = theta.data() + model.offset(static_cast<int>(e));
    const unsigned stages = eff.stages();
    const bool chain_only = (stages & ~(unsigned{kGeometryStage} | unsigned{kWrenchStage})) == 0 &&
                            !eff.reads_jacobians();
    const Contribution a = contribution(eff, p, robot, data.rows[0], ctx[0]);
    const Contribution b = contribution(eff, p, robot, data.rows[1], ctx[1]);
    const bool fixed_geometry = chain_only && same(a, b) &&
                                (a.r_load - robot.load_point).norm() == 0 && a.force.norm() == 0 &&
                                a.moment.norm() == 0;
    if (fixed_geometry && !a.probe.isIdentity(0.0)) {
      // The robot description has a measured point, not a measured frame.
      out.push_back(eff.name() + ": the 6-D probe's frame on the flange, the instrument's");
      continue;
    }
    if (!fixed_geometry) {
      out.push_back(eff.name() + (eff.name() == "registration"
                                      ? ": the instrument's placement, not the robot's"
                                      : ": depends on the pose, the load or the instrument"));
      continue;
    }
    dq += a.dq;
    joint_error += a.joint_error;
    r_meas += a.r_meas - robot.measured_point;
  }

  // pre_j <- pre_j E_j Rot(a_j, dq_j): the corrected chain of the model (model.cpp), in which
  // the joint offset turns with the joint.
  RobotModel cal = robot;
  for (int j = 0; j < n; ++j) {
    Joint& jt = cal.joints[j];
    Eigen::Matrix4d e = Eigen::Matrix4d::Identity();
    Eigen::Matrix3d r;
    const Eigen::Vector3d w = joint_error.block<3, 1>(3, j);
    ceres::AngleAxisToRotationMatrix(w.data(), r.data());
    e.topLeftCorner<3, 3>() = r;
    e.topRightCorner<3, 1>() = joint_error.block<3, 1>(0, j);
    Eigen::Matrix4d z = Eigen::Matrix4d::Identity();
    z.topLeftCorner<3, 3>() = Eigen::AngleAxisd(dq(j), jt.axis.normalized()).toRotationMatrix();
    jt.pre = jt.pre * e * z;
  }
  cal.measured_point = r_meas;
  if (cal.load_point == robot.measured_point) cal.load_point = r_meas;  // one tool point
  cal.convention = Convention::urdf;  // general transforms: no DH table describes them
  cal.name = robot.name + "_calibrated";
  if (left_out) *left_out = out;
  return cal;
}

Eigen::Matrix4d registration_pose(const FitResult& fit, const std::string& session) {
  // The registration effect names its parameters omega_<axis>_<tag>, t_<axis>_<tag>, the tag
  // being the session label (its 1-based number when the data had no labels).
  std::vector<std::string> tags;
  for (const auto& p : fit.parameters)
    if (p.effect == "registration" && p.name.rfind("omega_x_", 0) == 0)
      tags.push_back(p.name.substr(8));
  if (tags.empty())
    throw InvalidArgument("the fit has no registration (model " + [&] {
      std::string m;
      for (const auto& e : fit.model) m += (m.empty() ? "" : "+") + e;
      return m;
    }() + "): it places the robot in no instrument frame");
  std::string list;
  for (const auto& t : tags) list += (list.empty() ? "'" : ", '") + t + "'";
  std::string tag = session;
  if (tag.empty()) {
    if (tags.size() > 1)
      throw InvalidArgument("the fit has " + std::to_string(tags.size()) + " sessions (" + list +
                            "); name the one whose frame to use");
    tag = tags.front();
  } else if (std::find(tags.begin(), tags.end(), tag) == tags.end()) {
    throw InvalidArgument("the fit has no session '" + session + "' (its sessions: " + list + ")");
  }
  double w[3], t[3];
  const char* axis[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    w[a] = t[a] = NAN;
    for (const auto& p : fit.parameters) {
      if (p.effect != "registration") continue;
      if (p.name == std::string("omega_") + axis[a] + "_" + tag) w[a] = p.value;
      if (p.name == std::string("t_") + axis[a] + "_" + tag) t[a] = p.value;
    }
  }
  for (int a = 0; a < 3; ++a)
    if (!std::isfinite(w[a]) || !std::isfinite(t[a]))
      throw InvalidArgument("the fit's registration of session '" + tag +
                            "' is incomplete or not finite");
  Eigen::Matrix3d r;
  ceres::AngleAxisToRotationMatrix(w, r.data());
  Eigen::Matrix4d pose = Eigen::Matrix4d::Identity();
  pose.topLeftCorner<3, 3>() = r;
  pose.topRightCorner<3, 1>() = Eigen::Vector3d(t[0], t[1], t[2]);
  return pose;
}

}  // namespace stiff
