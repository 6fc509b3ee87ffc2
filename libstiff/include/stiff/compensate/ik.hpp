/// \file ik.hpp
/// Inverse kinematics of the measured point (tool) pose: analytic for 6R arms with a spherical
/// wrist, numerical (damped least squares) for every other chain. Joint limits are respected;
/// solutions are never NaN (docs/compensation.md).
///
/// Analytic solver (wrist-centre decoupling on the general pre * Rot(axis, q) * post form):
///  - the last three axes must intersect in one point c (the wrist centre);
///  - axes 2 and 3 must be parallel and axis 1 not parallel to axis 2 (anthropomorphic arms:
///    rokae, puma560, abb_irb120, most industrial 6R arms; offsets a1, a3, d2, d4 allowed).
/// Then q1 follows from the plane of the arm (A cos q1 + B sin q1 = C, two branches), q3 from
/// the distance of c to axis 2 (two branches), q2 from a planar rotation, q5 from the tool
/// axis (two branches), q4 and q6 from planar rotations: up to 8 solutions. Branch id bits:
/// 1 = shoulder (q1), 2 = elbow (q3), 4 = wrist (q5). A solution is polished by Newton steps
/// so that FK(q) reproduces the pose to about 1e-14 m.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "stiff/kinematics/robot_model.hpp"

namespace stiff {

/// What the analytic solver needs from the robot, and what it found.
struct WristStructure {
  bool spherical = false;  ///< the last three axes intersect in one point
  bool analytic = false;   ///< the analytic solver applies (see the file comment)
  std::string reason;      ///< why not analytic (empty when it is)
  Eigen::Vector3d centre_link3 = Eigen::Vector3d::Zero();  ///< wrist centre, link frame 3 [m]
  Eigen::Vector3d centre_tool = Eigen::Vector3d::Zero();   ///< wrist centre, tool frame [m]
};

/// Analyse the chain (6R, spherical wrist, parallel axes 2 and 3).
WristStructure analyse_wrist(const RobotModel& robot);

struct IkOptions {
  double tolerance = 1e-12;      ///< accepted position [m] and orientation [rad] error
  int max_iterations = 100;      ///< per numerical solve (damped least squares)
  int restarts = 24;             ///< random starts of the numerical solver
  uint64_t seed = 1;             ///< for the random starts (same seed, same answer)
  double singular_sigma = 1e-5;  ///< smallest singular value of the 6 x n Jacobian below
                                 ///< which a solution is flagged singular
  bool respect_limits = true;    ///< drop solutions outside the joint limits
  bool force_numerical = false;  ///< use the numerical solver even for spherical wrists
};

/// One solution.
struct IkSolution {
  Eigen::VectorXd q;   ///< joint positions [rad], within the limits
  int branch = -1;     ///< analytic branch id (bits 1 shoulder, 2 elbow, 4 wrist); -1 numerical
  double error = 0.0;  ///< position [m] + orientation [rad] error of FK(q)
  bool singular = false;
};

/// Pose error: position [m] and orientation [rad] (rotation vector of target * actual^T).
Eigen::Matrix<double, 6, 1> pose_error(const Eigen::Matrix4d& target,
                                       const Eigen::Matrix4d& actual);

class InverseKinematics {
 public:
  explicit InverseKinematics(const RobotModel& robot, const IkOptions& options = {});

  const RobotModel& robot() const { return robot_; }
  const WristStructure& structure() const { return wrist_; }
  bool analytic() const { return wrist_.analytic && !options_.force_numerical; }
  const IkOptions& options() const { return options_; }

  /// Every solution within the limits (analytic: up to 8, sorted by branch id; numerical:
  /// the distinct solutions the random starts found). Each joint takes the representation
  /// (q + 2 pi k) within its limits nearest `seed` (0 when null). Empty: unreachable.
  std::vector<IkSolution> solve_all(const Eigen::Matrix4d& pose,
                                    const Eigen::VectorXd* seed = nullptr) const;

  /// The solution nearest `seed` (Euclidean joint distance). Returns false when the pose is
  /// unreachable within the limits (then *out is untouched).
  bool solve_nearest(const Eigen::Matrix4d& pose,
                     const Eigen::VectorXd& seed,
                     IkSolution* out) const;

  /// Damped least squares from `start`; true on convergence to options.tolerance.
  bool solve_numerical(const Eigen::Matrix4d& pose,
                       const Eigen::VectorXd& start,
                       Eigen::VectorXd* q) const;

  /// Smallest singular value of the 6 x n Jacobian at q (n < 6: of the 6 x n matrix).
  double sigma_min(const Eigen::VectorXd& q) const;

 private:
  std::vector<IkSolution> analytic_all(const Eigen::Matrix4d& pose) const;
  bool fit_limits(Eigen::VectorXd* q, const Eigen::VectorXd& seed) const;
  void finish(IkSolution* s, const Eigen::Matrix4d& pose) const;

  RobotModel robot_;
  IkOptions options_;
  WristStructure wrist_;
};

/// Path status flags (bitwise OR), one value per point; equal to the C ABI's STIFF_POINT_*.
enum PointFlag : int {
  kPointOk = 0,
  kPointSingular = 1,      ///< near a singularity (sigma_min below IkOptions::singular_sigma)
  kPointUnreachable = 2,   ///< no solution within the limits: the previous q is held
  kPointBranchChange = 4,  ///< the analytic branch changed (e.g. a wrist flip)
  kPointJump = 8,          ///< a joint moved more than the jump threshold from the last point
  kPointNotConverged = 16  ///< the compensation did not reach its tolerance
};

/// Joint path of a pose sequence, branch kept: each point takes the solution nearest the
/// previous one (the first: nearest q_start, or the middle of the limits when empty).
struct IkPath {
  Eigen::MatrixXd q;        ///< rows x dof [rad]
  std::vector<int> status;  ///< PointFlag bits per point
  std::vector<int> branch;  ///< analytic branch per point (-1 numerical or unreachable)
};
IkPath solve_path(const InverseKinematics& ik,
                  const std::vector<Eigen::Matrix4d>& poses,
                  const Eigen::VectorXd& q_start,
                  double jump_threshold_rad = 0.35);

/// Human-readable description of a status value, e.g. "singular, wrist flip".
std::string describe_point_status(int status);

}  // namespace stiff
