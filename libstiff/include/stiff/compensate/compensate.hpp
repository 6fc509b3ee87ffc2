/// \file compensate.hpp
/// Deflection compensation along a path (docs/compensation.md): joint targets q_cmd such that
/// the loaded tool reaches the nominal pose,
///   p(q_cmd) + d(q_cmd, W) = p_nom  and  Exp(rot(q_cmd, W)) R(q_cmd) = R_nom,
/// solved by one quasi-Newton solver (solve_compensation) that the path compensation, the C
/// ABI and the FMU all call. Units SI, base frame; wrenches (F [N], M [N*m]) act at the load
/// point, base frame.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <vector>

#include "stiff/compensate/ik.hpp"
#include "stiff/model/model.hpp"

namespace stiff {

using Vector6d = Eigen::Matrix<double, 6, 1>;

struct CompensationOptions {
  /// Converged when the larger of the position [m] and orientation [rad] residuals is at most
  /// this; the iteration goes on to round-off (1e-15) while the residual still falls fast.
  double tolerance_m = 1e-12;
  int max_iterations = 50;
  /// Also compensate the orientation (6-D deflection); needs dof >= 6. False: position only
  /// (minimum-norm joint correction).
  bool orientation = true;
  double jump_threshold_rad = 0.35;  ///< a larger joint step between points is reported
  IkOptions ik;
};

/// Predicted deflection (dx, dy, dz [m], rx, ry, rz [rad]) at q under wrench (F, M).
Vector6d predict_deflection(const DeflectionModel& model,
                            const Eigen::VectorXd& theta,
                            const Eigen::VectorXd& q,
                            const Vector6d& wrench);

/// Loaded tool pose: FK(q) displaced by the deflection d (position) and rotated by rot.
Eigen::Matrix4d loaded_pose(const Eigen::Matrix4d& pose, const Vector6d& deflection);

/// The tool pose (base frame) the model predicts when the joints are commanded to q under
/// wrench (F, M) at the load point: for a model of absolute accuracy the calibrated model's
/// (DeflectionModel::tool_pose: corrected chain, deflection under the wrench and the robot's
/// weight, no instrument; thermal expansion at its 20 C reference), else FK(q) displaced by
/// the deflection (loaded_pose). `time` [s] for effects that drift with time.
Eigen::Matrix4d predicted_tool_pose(const DeflectionModel& model,
                                    const Eigen::VectorXd& theta,
                                    const Eigen::VectorXd& q,
                                    const Vector6d& wrench,
                                    double time = 0.0);

struct PoseCompensation {
  Eigen::VectorXd q_cmd;  ///< commanded joints [rad]
  int iterations = 0;
  /// Remaining model error: max(position [m], orientation [rad]); position only when the
  /// orientation is not compensated.
  double residual = 0.0;
  bool converged = false;
};

/// The loaded tool pose (base frame) when the joints are commanded to q.
using LoadedPoseFunction = std::function<Eigen::Matrix4d(const Eigen::VectorXd& q)>;

/// The compensation solver: joints q with loaded(q) = target, from q0. Damped least squares on
/// a Jacobian that starts as the rigid geometric Jacobian at the measured point and learns the
/// deflection's own dependence on q by Broyden updates (superlinear where a fixed Jacobian
/// contracts only by |dd/dq| / |J| per step), with step halving when a step does not reduce
/// the residual (sign changes of backlash-like effects). Non-finite joints are returned as
/// they are, with converged = false.
PoseCompensation solve_compensation(const RobotModel& robot,
                                    const LoadedPoseFunction& loaded,
                                    const Eigen::Matrix4d& target,
                                    const Eigen::VectorXd& q0,
                                    const CompensationOptions& options = {});

/// Joint command that makes the loaded tool reach `target` (tool pose, base frame), starting
/// from q_nominal (the unloaded IK solution of target).
PoseCompensation compensate_pose(const DeflectionModel& model,
                                 const Eigen::VectorXd& theta,
                                 const Eigen::Matrix4d& target,
                                 const Eigen::VectorXd& q_nominal,
                                 const Vector6d& wrench,
                                 const CompensationOptions& options = {});

struct PathCompensation {
  IkPath nominal;             ///< IK of the nominal path (q, status, branch)
  Eigen::MatrixXd q_cmd;      ///< rows x dof compensated joints [rad]
  Eigen::MatrixXd predicted;  ///< rows x 6 model deflection at the nominal joints
  Eigen::VectorXd residual;   ///< rows: model residual after compensation
  std::vector<int> status;    ///< PointFlag bits (IK flags | kPointNotConverged)
  std::vector<int> iterations;
};

/// Compensate every pose of a path: IK with the branch kept (from q_start; empty = middle of
/// the limits), then compensate_pose from each nominal solution. `wrench` is rows x 6, or
/// 1 x 6 for a constant wrench. Unreachable points hold the previous command. Throws
/// InvalidArgument on bad sizes or non-finite input.
PathCompensation compensate_path(const DeflectionModel& model,
                                 const Eigen::VectorXd& theta,
                                 const std::vector<Eigen::Matrix4d>& poses,
                                 const Eigen::MatrixXd& wrench,
                                 const Eigen::VectorXd& q_start,
                                 const CompensationOptions& options = {});

/// Deviation of the loaded tool from the nominal poses when the joints are at q (rows x dof)
/// under the wrenches, on `model` (e.g. the true model of a virtual robot): rows x 6,
/// (position [m], rotation vector [rad]) of loaded - nominal.
Eigen::MatrixXd loaded_deviation(const DeflectionModel& model,
                                 const Eigen::VectorXd& theta,
                                 const std::vector<Eigen::Matrix4d>& poses,
                                 const Eigen::MatrixXd& q,
                                 const Eigen::MatrixXd& wrench);

}  // namespace stiff
