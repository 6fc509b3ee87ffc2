// Deflection compensation: quasi-Newton on the loaded tool pose (compensate.hpp).
#include "stiff/compensate.hpp"

#include <Eigen/Geometry>
#include <Eigen/LU>
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
  l.deflection = model.predict(theta, m, c);
  l.rigid = c.chain.flange;
  l.rigid.block<3, 1>(0, 3) = model.robot().point_position(c.chain, model.robot().measured_point);
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
  const bool six = options.orientation && robot.dof() >= 6;
  PoseCompensation out;
  out.q_cmd = q_nominal;
  // Jacobian of the rigid kinematics at the nominal joints; the deflection changes slowly
  // with q, so the fixed-Jacobian iteration contracts by about |dd/dq| / |J| per step.
  const Eigen::MatrixXd jac = robot.jacobian(q_nominal);
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod;
  Eigen::PartialPivLU<Eigen::MatrixXd> lu;
  const bool square = six && robot.dof() == 6;
  if (square)
    lu.compute(jac);
  else
    cod.compute(six ? jac : Eigen::MatrixXd(jac.topRows(3)));
  double step = 1.0;
  double previous = INFINITY;
  Eigen::VectorXd q_prev = out.q_cmd;
  for (int it = 0; it <= options.max_iterations; ++it) {
    const Loaded l = evaluate_loaded(model, theta, out.q_cmd, wrench);
    const Vector6d e = pose_error(target, l.loaded);
    const double pos = e.head<3>().norm(), ang = e.tail<3>().norm();
    const double res = six ? pos + ang : pos;
    if (!(res < previous) && it > 0) {
      // Not contracting (a strongly nonlinear effect): back off along the last step.
      step *= 0.5;
      out.q_cmd = q_prev + step * (out.q_cmd - q_prev);
      if (step < 1e-3) break;
      continue;
    }
    out.residual = res;
    out.iterations = it;
    if (pos <= options.tolerance_m && (!six || ang <= options.tolerance_m)) {
      out.converged = true;
      break;
    }
    if (it == options.max_iterations) break;
    previous = res;
    q_prev = out.q_cmd;
    Eigen::VectorXd dq;
    if (square)
      dq = lu.solve(Eigen::VectorXd(e));
    else if (six)
      dq = cod.solve(Eigen::VectorXd(e));
    else
      dq = cod.solve(Eigen::VectorXd(e.head<3>()));
    if (!dq.allFinite()) break;
    out.q_cmd += step * dq;
    step = std::min(1.0, step * 2.0);
  }
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
    out.predicted.row(i) = predict_deflection(model, theta, qn, wi).transpose();
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
