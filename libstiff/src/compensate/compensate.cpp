// Deflection compensation: one quasi-Newton solver on the loaded tool pose (compensate.hpp).
#include "stiff/compensate/compensate.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "stiff/error.hpp"

namespace stiff {
namespace {

Measurement make_measurement(const Eigen::VectorXd& q, const Vector6d& wrench) {
  Measurement m;
  m.q = q;
  m.force = wrench.head<3>();
  m.moment = wrench.tail<3>();
  return m;
}

/// Loaded pose and the rigid tool pose at q from one chain evaluation.
struct Loaded {
  Eigen::Matrix4d rigid;
  Eigen::Matrix4d loaded;
  Vector6d deflection;
};

Loaded evaluate_loaded(const DeflectionModel& model,
                       const Eigen::VectorXd& theta,
                       const Eigen::VectorXd& q,
                       const Vector6d& wrench) {
  const Measurement m = make_measurement(q, wrench);
  const MeasurementContext c = model.context(m, 0);
  Loaded l;
  l.rigid = c.chain.flange;
  l.rigid.block<3, 1>(0, 3) = model.robot().point_position(c.chain, model.robot().measured_point);
  if (model.absolute_accuracy()) {
    l.loaded = predicted_tool_pose(model, theta, q, wrench);
    l.deflection = -pose_error(l.rigid, l.loaded);
    return l;
  }
  l.deflection = model.predict(theta, m, c);
  l.loaded = loaded_pose(l.rigid, l.deflection);
  return l;
}

Eigen::MatrixXd wrench_rows(const Eigen::MatrixXd& wrench, size_t rows) {
  if (wrench.cols() != 6)
    throw InvalidArgument("wrench must have 6 columns (fx, fy, fz, mx, my, mz), has " +
                          std::to_string(wrench.cols()));
  if (wrench.rows() != 1 && wrench.rows() != static_cast<Eigen::Index>(rows))
    throw InvalidArgument("wrench has " + std::to_string(wrench.rows()) + " rows for " +
                          std::to_string(rows) + " poses (give 1 or one per pose)");
  if (!wrench.allFinite()) throw InvalidArgument("wrench is not finite");
  return wrench;
}

}  // namespace

Vector6d predict_deflection(const DeflectionModel& model,
                            const Eigen::VectorXd& theta,
                            const Eigen::VectorXd& q,
                            const Vector6d& wrench) {
  const Measurement m = make_measurement(q, wrench);
  return model.predict(theta, m, model.context(m, 0));
}

Eigen::Matrix4d loaded_pose(const Eigen::Matrix4d& pose, const Vector6d& d) {
  Eigen::Matrix4d t = pose;
  t.block<3, 1>(0, 3) += d.head<3>();
  const double angle = d.tail<3>().norm();
  if (angle > 0) {
    const Eigen::Matrix3d r = Eigen::AngleAxisd(angle, d.tail<3>() / angle).toRotationMatrix();
    t.block<3, 3>(0, 0) = r * pose.block<3, 3>(0, 0);
  }
  return t;
}

Eigen::Matrix4d predicted_tool_pose(const DeflectionModel& model,
                                    const Eigen::VectorXd& theta,
                                    const Eigen::VectorXd& q,
                                    const Vector6d& wrench,
                                    double time) {
  Measurement m = make_measurement(q, wrench);
  if (!model.absolute_accuracy()) {
    MeasurementContext c = model.context(m, 0);
    c.time = time;
    Eigen::Matrix4d rigid = c.chain.flange;
    rigid.block<3, 1>(0, 3) = model.robot().point_position(c.chain, model.robot().measured_point);
    return loaded_pose(rigid, model.predict(theta, m, c));
  }
  // Where the calibrated model puts the tool under the process wrench and the robot's own
  // weight, in the base frame (the instrument's registration is not the robot's), at the
  // reference temperature of the thermal model (20 C, ISO 1).
  m.absolute = true;
  m.temperature = 20.0;
  MeasurementContext c = model.context(m, 0);
  c.time = time;
  return model.tool_pose(theta, m, c);
}

PoseCompensation compensate_pose(const DeflectionModel& model,
                                 const Eigen::VectorXd& theta,
                                 const Eigen::Matrix4d& target,
                                 const Eigen::VectorXd& q_nominal,
                                 const Vector6d& wrench,
                                 const CompensationOptions& options) {
  const RobotModel& robot = model.robot();
  check_joint_vector(robot, q_nominal, "compensate");
  if (!target.allFinite()) throw InvalidArgument("compensate: the target pose is not finite");
  if (!wrench.allFinite()) throw InvalidArgument("compensate: the wrench is not finite");
  if (theta.size() != model.parameter_count())
    throw InvalidArgument("compensate: theta has " + std::to_string(theta.size()) +
                          " values, the model needs " + std::to_string(model.parameter_count()));
  return solve_compensation(
      robot,
      [&](const Eigen::VectorXd& q) { return evaluate_loaded(model, theta, q, wrench).loaded; },
      target, q_nominal, options);
}

PoseCompensation solve_compensation(const RobotModel& robot,
                                    const LoadedPoseFunction& loaded,
                                    const Eigen::Matrix4d& target,
                                    const Eigen::VectorXd& q0,
                                    const CompensationOptions& options) {
  const bool six = options.orientation && robot.dof() >= 6;
  const Eigen::Index rows = six ? 6 : 3;
  // Damping: negligible against the Jacobian's singular values (>= ~1e-3 m away from a
  // singularity), it only keeps a rank-deficient step bounded.
  constexpr double kLambda2 = 1e-12;
  // Below this the residual is round-off of the pose arithmetic (~1e-16 relative).
  constexpr double kRoundOff = 1e-15;
  const auto residual_of = [&](const Eigen::VectorXd& q, double* norm) {
    const Vector6d e6 = pose_error(target, loaded(q));
    *norm = six ? std::max(e6.head<3>().norm(), e6.tail<3>().norm()) : e6.head<3>().norm();
    return Eigen::VectorXd(e6.head(rows));
  };
  PoseCompensation out;
  out.q_cmd = q0;
  double err = INFINITY;
  Eigen::VectorXd e = residual_of(out.q_cmd, &err);
  Eigen::MatrixXd jac = robot.jacobian(q0).topRows(rows);
  double previous = INFINITY;
  for (int it = 0;; ++it) {
    out.iterations = it;
    out.residual = err;
    if (!std::isfinite(err) || err < kRoundOff) break;
    // Stagnating within the tolerance: what is left is round-off, not model error.
    if (err <= options.tolerance_m && err > 0.1 * previous) break;
    if (it >= options.max_iterations) break;
    Eigen::MatrixXd a = jac * jac.transpose();
    a.diagonal().array() += kLambda2;
    const Eigen::VectorXd dq = jac.transpose() * a.ldlt().solve(e);
    if (!dq.allFinite()) break;
    double step = 1.0, err_new = INFINITY;
    Eigen::VectorXd q_new, e_new;
    for (;;) {
      q_new = out.q_cmd + step * dq;
      e_new = residual_of(q_new, &err_new);
      if (err_new < err || step < 1e-3) break;
      step *= 0.5;
    }
    if (!(err_new < err)) break;  // no descent along the step: at the attainable minimum
    // Broyden update with the observed change of the loaded pose, y = e - e_new.
    const Eigen::VectorXd s_step = q_new - out.q_cmd;
    jac += (e - e_new - jac * s_step) * s_step.transpose() / s_step.squaredNorm();
    previous = err;
    out.q_cmd = q_new;
    e = e_new;
    err = err_new;
  }
  out.converged = std::isfinite(err) && err <= options.tolerance_m && out.q_cmd.allFinite();
  return out;
}

PathCompensation compensate_path(const DeflectionModel& model,
                                 const Eigen::VectorXd& theta,
                                 const std::vector<Eigen::Matrix4d>& poses,
                                 const Eigen::MatrixXd& wrench,
                                 const Eigen::VectorXd& q_start,
                                 const CompensationOptions& options) {
  const Eigen::MatrixXd w = wrench_rows(wrench, poses.size());
  for (size_t i = 0; i < poses.size(); ++i)
    if (!poses[i].allFinite())
      throw InvalidArgument("pose " + std::to_string(i) + " is not finite");
  const InverseKinematics ik(model.robot(), options.ik);
  PathCompensation out;
  out.nominal = solve_path(ik, poses, q_start, options.jump_threshold_rad);
  const auto rows = static_cast<Eigen::Index>(poses.size());
  out.q_cmd = out.nominal.q;
  out.predicted = Eigen::MatrixXd::Zero(rows, 6);
  out.residual = Eigen::VectorXd::Zero(rows);
  out.status = out.nominal.status;
  out.iterations.assign(poses.size(), 0);
  for (Eigen::Index i = 0; i < rows; ++i) {
    const Vector6d wi = w.row(w.rows() == 1 ? 0 : i).transpose();
    const auto k = static_cast<size_t>(i);
    if (out.status[k] & kPointUnreachable) {
      if (i > 0) out.q_cmd.row(i) = out.q_cmd.row(i - 1);
      continue;
    }
    const Eigen::VectorXd qn = out.nominal.q.row(i).transpose();
    out.predicted.row(i) = evaluate_loaded(model, theta, qn, wi).deflection.transpose();
    const PoseCompensation c = compensate_pose(model, theta, poses[k], qn, wi, options);
    out.q_cmd.row(i) = c.q_cmd.transpose();
    out.residual(i) = c.residual;
    out.iterations[k] = c.iterations;
    if (!c.converged) out.status[k] |= kPointNotConverged;
  }
  return out;
}

Eigen::MatrixXd loaded_deviation(const DeflectionModel& model,
                                 const Eigen::VectorXd& theta,
                                 const std::vector<Eigen::Matrix4d>& poses,
                                 const Eigen::MatrixXd& q,
                                 const Eigen::MatrixXd& wrench) {
  const Eigen::MatrixXd w = wrench_rows(wrench, poses.size());
  if (q.rows() != static_cast<Eigen::Index>(poses.size()) || q.cols() != model.robot().dof())
    throw InvalidArgument("q must be " + std::to_string(poses.size()) + " x " +
                          std::to_string(model.robot().dof()));
  Eigen::MatrixXd out(q.rows(), 6);
  for (Eigen::Index i = 0; i < q.rows(); ++i) {
    const Eigen::VectorXd qi = q.row(i).transpose();
    check_joint_vector(model.robot(), qi, "row " + std::to_string(i));
    const Loaded l = evaluate_loaded(model, theta, qi, w.row(w.rows() == 1 ? 0 : i).transpose());
    const Eigen::Matrix4d& nominal = poses[static_cast<size_t>(i)];
    out.row(i) = (-pose_error(nominal, l.loaded)).transpose();
  }
  return out;
}

}  // namespace stiff
