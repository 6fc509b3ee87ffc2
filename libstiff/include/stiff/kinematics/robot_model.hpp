/// \file robot_model.hpp
/// Serial-chain kinematics of the robot: forward kinematics and the geometric Jacobian at the
/// measured point, templated on the scalar so that the same code runs with double and
/// ceres::Jet (automatic differentiation).
///
/// Every joint is revolute and is stored in one general form,
///   T_{i-1,i}(q_i) = pre_i * Rot(axis_i, q_i) * post_i,
/// which covers modified DH (Craig: pre = RotX(alpha) TransX(a) TransZ(d) RotZ(offset), axis z,
/// post = I), standard DH (pre = I, axis z, post = RotZ(offset) TransZ(d) TransX(a) RotX(alpha))
/// and URDF joints (pre = joint origin, axis = joint axis, post = I). Units: m, rad.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

namespace stiff {

template <typename Scalar>
using Vector3 = Eigen::Matrix<Scalar, 3, 1>;
template <typename Scalar>
using Matrix3 = Eigen::Matrix<Scalar, 3, 3>;
template <typename Scalar>
using Matrix4 = Eigen::Matrix<Scalar, 4, 4>;
template <typename Scalar>
using VectorX = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;
template <typename Scalar>
using MatrixX = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
template <typename Scalar>
using Matrix3X = Eigen::Matrix<Scalar, 3, Eigen::Dynamic>;
template <typename Scalar>
using Matrix6X = Eigen::Matrix<Scalar, 6, Eigen::Dynamic>;

/// Most joints a robot may have, everywhere the library takes a joint count (robot files,
/// data sets, the C ABI, the FMU).
constexpr int kMaxJoints = 64;

/// Kinematic convention the joint table was written in (kept for reporting and export).
enum class Convention { modified_dh, standard_dh, urdf };

const char* to_string(Convention c);

/// One revolute joint in the general form pre * Rot(axis, q) * post.
template <typename Scalar>
struct JointTpl {
  std::string name;
  Matrix4<Scalar> pre = Matrix4<Scalar>::Identity();
  Vector3<Scalar> axis = Vector3<Scalar>::UnitZ();  ///< unit vector in the frame after `pre`
  Matrix4<Scalar> post = Matrix4<Scalar>::Identity();
  double lower = -3.141592653589793;  ///< joint limit [rad]
  double upper = 3.141592653589793;   ///< joint limit [rad]
  /// Effort [N*m] and velocity [rad/s] limits a URDF gave (0: unknown); carried to the URDF
  /// export, not used by the models.
  double effort = 0.0;
  double velocity = 0.0;
  /// The DH row it came from (alpha, a, d, theta offset) [rad, m]; NaN for URDF joints.
  double dh[4] = {0, 0, 0, 0};
  /// Mass [kg] of the link moved by this joint and its centre of mass in that link's frame [m].
  double mass = 0.0;
  Eigen::Vector3d com = Eigen::Vector3d::Zero();

  template <typename NewScalar>
  JointTpl<NewScalar> cast() const {
    JointTpl<NewScalar> j;
    j.name = name;
    j.pre = pre.template cast<NewScalar>();
    j.axis = axis.template cast<NewScalar>();
    j.post = post.template cast<NewScalar>();
    j.lower = lower;
    j.upper = upper;
    j.effort = effort;
    j.velocity = velocity;
    for (int k = 0; k < 4; ++k) j.dh[k] = dh[k];
    j.mass = mass;
    j.com = com;
    return j;
  }
};

/// Joint axes and origins of one configuration, base frame (input to Jacobians and effects).
template <typename Scalar>
struct ChainStateTpl {
  std::vector<Matrix4<Scalar>> link;  ///< pose of link frame i (1..n) in the base, index i-1
  Matrix3X<Scalar> axis;              ///< column j: unit axis z_j of joint j+1, base frame
  Matrix3X<Scalar> origin;            ///< column j: a point o_j on that axis, base frame
  Matrix4<Scalar> flange;             ///< flange (last link) pose in the base frame
};

/// Immutable robot description: joints, measured point and load point, masses.
template <typename Scalar>
class RobotModelTpl {
 public:
  std::string name;
  Convention convention = Convention::modified_dh;
  std::vector<JointTpl<Scalar>> joints;
  /// Measured point (SMR / tool point) in the flange frame [m].
  Vector3<Scalar> measured_point = Vector3<Scalar>::Zero();
  /// Point where the external force is applied, in the flange frame [m].
  Vector3<Scalar> load_point = Vector3<Scalar>::Zero();
  /// Tool (sensor, fixture, SMR) mass [kg] and centre of mass in the flange frame [m].
  double tool_mass = 0.0;
  Eigen::Vector3d tool_com = Eigen::Vector3d::Zero();
  /// Gravity acceleration in the base frame [m/s^2].
  Eigen::Vector3d gravity{0.0, 0.0, -9.80665};
  /// Path of the file it was read from (empty when built in code).
  std::string source_path;

  int dof() const { return static_cast<int>(joints.size()); }
  /// True when any link or the tool has a mass (gravity torques are then available).
  bool has_masses() const;

  /// Axes, origins and link poses at joint positions q [rad].
  ChainStateTpl<Scalar> chain(const VectorX<Scalar>& q) const;
  /// Position of a point given in the flange frame, base frame [m].
  Vector3<Scalar> point_position(const ChainStateTpl<Scalar>& s,
                                 const Vector3<Scalar>& p_flange) const;
  /// Tool (measured point) pose in the base frame.
  Matrix4<Scalar> tool_pose(const VectorX<Scalar>& q) const;
  /// 6 x n geometric Jacobian at point p (base frame): rows 0-2 linear velocity of p,
  /// rows 3-5 angular velocity, column j = [z_j x (p - o_j); z_j].
  Matrix6X<Scalar> jacobian_at(const ChainStateTpl<Scalar>& s, const Vector3<Scalar>& p) const;
  /// 6 x n geometric Jacobian at the measured point, base frame.
  Matrix6X<Scalar> jacobian(const VectorX<Scalar>& q) const;

  template <typename NewScalar>
  RobotModelTpl<NewScalar> cast() const {
    RobotModelTpl<NewScalar> r;
    r.name = name;
    r.convention = convention;
    for (const auto& j : joints) r.joints.push_back(j.template cast<NewScalar>());
    r.measured_point = measured_point.template cast<NewScalar>();
    r.load_point = load_point.template cast<NewScalar>();
    r.tool_mass = tool_mass;
    r.tool_com = tool_com;
    r.gravity = gravity;
    r.source_path = source_path;
    return r;
  }
};

using Joint = JointTpl<double>;
using ChainState = ChainStateTpl<double>;
using RobotModel = RobotModelTpl<double>;

/// Homogeneous transforms used to build joints (SI: m, rad).
template <typename Scalar>
Matrix4<Scalar> rot_x(Scalar angle);
template <typename Scalar>
Matrix4<Scalar> rot_z(Scalar angle);
template <typename Scalar>
Matrix4<Scalar> translation(Scalar x, Scalar y, Scalar z);

/// Build a joint from a modified (Craig) DH row alpha_{i-1}, a_{i-1}, d_i, theta offset.
Joint modified_dh_joint(double alpha, double a, double d, double theta_offset);
/// Build a joint from a standard DH row alpha_i, a_i, d_i, theta offset.
Joint standard_dh_joint(double alpha, double a, double d, double theta_offset);

/// Gravity torques tau_g [N*m] that the link and tool weights exert on the joints at q
/// (external torques, same sign convention as tau = J^T F). Zero when no masses are given.
/// `quadrature` (optional) receives, per joint j, the torque of the same weights with their
/// lever arms turned by 90 degrees about its axis, sum z_j . ((z_j x l) x w): how tau_g,j
/// changes when the centres of mass it carries turn about the axis (a centre of mass off the
/// file's line).
Eigen::VectorXd gravity_torques(const RobotModel& robot,
                                const ChainState& s,
                                Eigen::VectorXd* quadrature = nullptr);

/// The same torques link by link: entry (j, k) is the torque on joint j of the weight of link k
/// (the tool's weight counts with the last link), so that tau_g = row sums. A link's mass
/// scales its column: what an error in one link's mass does to every joint's preload.
/// `quadrature` (optional) likewise, per link.
Eigen::MatrixXd gravity_torques_by_link(const RobotModel& robot,
                                        const ChainState& s,
                                        Eigen::MatrixXd* quadrature = nullptr);

/// Smallest singular value and condition number of the translational 3 x n Jacobian at q.
struct JacobianConditioning {
  double sigma_min;
  double condition_number;
};
JacobianConditioning translational_conditioning(const RobotModel& robot, const Eigen::VectorXd& q);

/// Inverse condition number sigma_min / sigma_max (0 at a singularity, 1 at best) of the
/// Jacobian that the pose compensation inverts at q: for n >= 6 joints the 6 x n geometric
/// Jacobian at the measured point with its translational rows divided by the arm's length
/// (sum of the link offsets and the measured point's offset, so that both halves are
/// dimensionless), for n < 6 the translational 3 x n Jacobian (position only).
double compensation_dexterity(const RobotModel& robot, const Eigen::VectorXd& q);

/// A home pose for a robot description that names none, away from singularities: from the
/// middle of every joint's range, one joint at a time takes the value of
/// {m, m +- h/3, m +- 2h/3} (m the middle, h the half range, at most pi) that most raises
/// the Jacobian's singular values relative to the largest, compared from the smallest up (so
/// that at a pose singular in two directions lifting one counts), sweeping the joints until
/// no joint moves (at most 8 sweeps). It stays
/// at least a third of the half range inside every limit. Deterministic; a joint that does not
/// change the dexterity (the base axis, the flange axis through the measured point) stays at
/// the middle.
Eigen::VectorXd home_pose(const RobotModel& robot);

/// Check that q has the robot's joint count and finite values; throws InvalidArgument naming
/// `where` otherwise.
void check_joint_vector(const RobotModel& robot,
                        const Eigen::VectorXd& q,
                        const std::string& where);

}  // namespace stiff

#include "stiff/kinematics/robot_model_impl.hpp"

namespace stiff {
extern template class RobotModelTpl<double>;
}
