/// \file effect.hpp
/// The compliance model as a sum of physical-effect terms (docs/effects.md).
///
/// The displacement of the measured point P under the wrench W applied at the load point L is
/// evaluated in stages; every effect may act in any of them:
///  1. wrench:      the wrench and the points as the set-up really has them
///                  (force-sensor frame, offsets of P and L from the flange axis);
///  2. joint:       joint deflection dtheta from the external joint torques tau = J(L)^T W
///                  (joint compliance, coupling, nonlinear reducer, backlash, compensator);
///     (then d = J_p(P) dtheta, rot = J_r dtheta)
///  3. cartesian:   displacement added in the base frame (link compliance, tool compliance);
///  4. measurement: what the tracker reports (tracker frame rotation, drift).
/// An absolute row (Measurement::absolute: the position of the target in the instrument's
/// frame) also runs, between stages 3 and 4,
///  G. geometry:    corrections of the kinematic chain (joint offsets, axis errors); the model
///                  then evaluates the corrected forward kinematics of the measured point and
///                  adds the deflection d of stages 1-3, so that stage 4 receives the absolute
///                  position in `d` and maps it into the instrument frame (registration).
///                  The probe's orientation follows the same way: the corrected chain's
///                  flange rotation times the probe's rotation on the flange (`probe`, set by
///                  tool_orientation), turned by the deflection's small rotation, is
///                  `orientation`, which stage 4 maps into the instrument frame.
/// Each effect writes its stage functions once as templates on the scalar T (double or
/// ceres::Jet) so that Ceres differentiates them automatically; EffectT instantiates them.
#pragma once

#include <ceres/jet.h>

#include <limits>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "stiff/io/dataset.hpp"
#include "stiff/kinematics/robot_model.hpp"

namespace stiff {

/// Jet used for automatic differentiation of the model (DynamicAutoDiffCostFunction stride).
constexpr int kJetStride = 8;
using Jet = ceres::Jet<double, kJetStride>;

/// One parameter of an effect, SI units.
struct ParameterSpec {
  std::string name;     ///< unique within the effect, e.g. "c2"
  std::string unit;     ///< e.g. "rad/(N*m)"
  std::string meaning;  ///< one line of physics
  double lower = -1e300;
  double upper = 1e300;
  double typical = 1.0;     ///< typical magnitude (for scaling and priors)
  double null_value = 0.0;  ///< value at which the effect vanishes
  double start = 0.0;       ///< start value of a fit
  /// A term of a family of forms (e.g. the second-order terms of a nonlinear reducer) that
  /// overlaps the others: identification keeps it only when the data support it (backward
  /// elimination by the Bayesian information criterion, docs/identifiability.md) and holds it
  /// at its null value otherwise. False: kept whenever the data determine it.
  bool optional_term = false;
  /// Decided by the effect from the data it is built on, not fitted: its null and start value
  /// are that decision, the model has no derivative with respect to it, and a fit holds it
  /// (backlash's preload errors, found by threshold regression).
  bool from_data = false;
  /// For a parameter decided from the data: the values the data do not exclude (a confidence
  /// set, as an interval), NaN when not known. A prediction on new data that changes across
  /// it (a backlash row near its torque reversal) is uncertain between the values it takes
  /// there; the diagnosis's fit-versus-validation test takes the one closest to the row.
  double confidence_lower = std::numeric_limits<double>::quiet_NaN();
  double confidence_upper = std::numeric_limits<double>::quiet_NaN();
  /// A parameter decided from the data that spreads the prediction of a new pose over what the
  /// data leave open (backlash's mass covariance: the expected jump near a reversal); 0 gives
  /// the prediction at the decided values alone, which the diagnosis's closest-value scoring
  /// starts from before it tries the confidence sets' ends.
  bool spread = false;
  /// A parameter of the measurement session (its thermal state, its instrument set-up), not of
  /// the robot: another session has its own value (a warm-up restarts, its course depends on
  /// the day and on the protocol), which only that session's own readings can tell. A
  /// comparison on a session the fit has not seen re-estimates it from that session's rows
  /// (DeflectionModel::align_sessions) instead of carrying the calibration's value over.
  bool per_session = false;
  /// A gain of the load along one axis of a frame (its number, > 0; 0: not a gain). The gains
  /// of one frame share a common part, a scale of every compliance-like term (d(s F) = s d(F)
  /// for every term homogeneous in the load; terms of the total torque or of the gravity
  /// preload break the identity only weakly), which only an independent force reference can
  /// tell. Identification always holds the last gain of each frame, so that the others are
  /// relative to it: a compliance held instead goes to its null value,
  /// 0, where it no longer takes part in the combination, which then forms again among the
  /// others; and a common gain left free trades against a nonlinear reducer's level terms.
  int gauge = 0;
};

/// Data of one measurement that does not depend on the parameters (computed once).
struct MeasurementContext {
  ChainState chain;
  Eigen::VectorXd tau_gravity;  ///< gravity torques [N*m] (zeros without a mass model)
  /// The same by link (gravity_torques_by_link): tau_gravity holds its row sums.
  Eigen::MatrixXd tau_gravity_links;
  int session = 0;    ///< index of the measurement's session (0..sessions-1)
  double time = 0.0;  ///< time of the reading [s] (row index when the file has no t)
};

/// Evolving state of one evaluation (see the stages above). Sizes are the robot's dof.
template <typename T>
struct EvalState {
  const RobotModel* robot = nullptr;
  const Measurement* measurement = nullptr;
  const MeasurementContext* context = nullptr;
  Vector3<T> force;      ///< force at L, base frame [N]
  Vector3<T> moment;     ///< moment about L, base frame [N*m]
  Vector3<T> r_meas;     ///< measured point P in the flange frame [m]
  Vector3<T> r_load;     ///< load point L in the flange frame [m]
  Vector3<T> p_meas;     ///< P in the base frame [m] (after stage 1)
  Vector3<T> p_load;     ///< L in the base frame [m] (after stage 1)
  Matrix6X<T> jac_meas;  ///< geometric Jacobian at P (after stage 1)
  Matrix6X<T> jac_load;  ///< geometric Jacobian at L (after stage 1)
  VectorX<T> tau;        ///< external joint torques J(L)^T W [N*m] (after stage 1)
  VectorX<T> dtheta;     ///< joint deflection [rad] (stage 2)
  /// Diagonal joint compliances c_j [rad/(N*m)] as set by the `joint` effect in stage 2
  /// (empty when the model has no joint effect); read by second-order effects in stage 3.
  VectorX<T> compliance;
  Vector3<T> d;    ///< displacement of P [m] (stages 3-4); absolute rows: position (stage 4)
  Vector3<T> rot;  ///< small rotation of the flange [rad] (stages 3-4)
  /// Geometry stage (absolute rows): corrections added to the joint angles [rad] and, per
  /// joint, a small transform inserted after the joint's `pre` transform (in that frame):
  /// translation (0-2) [m] and rotation vector (3-5) [rad]. Both start at zero.
  VectorX<T> dq;
  Matrix6X<T> joint_error;
  /// Absolute rows: rotation of the probe frame in the flange frame (geometry stage; starts
  /// at the identity) and the predicted rotation of the probe frame, base frame after the
  /// geometry stage, instrument frame after stage 4 (identity when not evaluated: `oriented`
  /// false).
  Matrix3<T> probe;
  Matrix3<T> orientation;
  bool oriented = false;
  /// Set by a caller that evaluates the same row at the same parameter values again, only for
  /// other derivative directions (one pass per kJetStride parameters): the model may reuse the
  /// plain values it kept on the previous pass (`kept`) instead of computing them again.
  bool same_values = false;
  std::vector<double> kept;
  /// Set by DeflectionModel::absolute_jacobian on an absolute row's first pass: the model
  /// seeds derivative directions 0-2 on the position the measurement stage receives (their
  /// derivatives at the end are that stage's map into the instrument frame) and keeps its
  /// value in `instrument_input`.
  bool seed_instrument = false;
  Eigen::Vector3d instrument_input = Eigen::Vector3d::Zero();
  /// With `oriented` too, the same directions are a small rotation phi (base frame) of the
  /// predicted orientation the stage receives, R -> Exp(phi) R, whose value R is kept here (a
  /// measurement stage maps the position and the orientation each from itself alone).
  Eigen::Matrix3d instrument_orientation = Eigen::Matrix3d::Identity();
};

/// First-order maps of an absolute row's predicted position y (instrument frame, after every
/// stage) and, on rows with a measured orientation, of its orientation discrepancy o (rows
/// 3-5; `rows()` is then 6), at the row's values, from a change of what an effect writes in
/// its stage (filled by DeflectionModel::absolute_jacobian for Effect::absolute_columns):
///  - `dtheta` (rows x n): d(y, o)/d dtheta_j, a joint deflection added in the joint stage
///    (through the nominal chain's J_p at P and its axis z_j, then the measurement stage);
///  - `dq` (rows x n): d(y, o)/d dq_j, a joint angle correction of the geometry stage:
///    z_j x (P - o_j) and z_j of the corrected chain (axis z_j, origin o_j of joint j's error
///    frame);
///  - `joint_error` (rows x 6n): d(y, o)/d joint_error(i, j) in column 6 j + i: translations
///    (i < 3) move P by R_B e_i (R_B: joint j's frame after `pre`); rotation-vector
///    components w_i turn P and the flange about R_E J_r(w) e_i through o_j (R_E: after the
///    error's rotation, J_r the right Jacobian of SO(3));
///  - `instrument` (3 x 3): dy/dx, the measurement stage's map of the base-frame position x it
///    receives (the registration's rotation), by automatic differentiation of that stage;
///  - `position`: x itself;
///  - `turn` (3 x 3, oriented rows): do/dphi, the map of a small rotation phi (base frame) of
///    the predicted orientation the measurement stage receives, R -> Exp(phi) R, through that
///    stage and the discrepancy (automatic differentiation); zero on rows without one;
///  - `orientation`: that R.
/// (Fixed capacity, kMaxTangentJoints joints: no allocation per row.)
constexpr int kMaxTangentJoints = 32;
struct AbsoluteTangents {
  using PerJoint =
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, 6, kMaxTangentJoints>;
  PerJoint dtheta;
  PerJoint dq;
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, 6, 6 * kMaxTangentJoints>
      joint_error;
  Eigen::Matrix3d instrument;
  Eigen::Vector3d position;
  Eigen::Matrix3d turn = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d orientation = Eigen::Matrix3d::Identity();
  int rows() const { return static_cast<int>(dq.rows()); }
};

/// What an effect needs from the robot file or the data.
enum Requirement : unsigned {
  kNeedsNothing = 0,
  kNeedsMasses = 1u << 0,    ///< link masses (gravity torques)
  kNeedsTime = 1u << 1,      ///< a `t` column or meaningful row order
  kNeedsSessions = 1u << 2,  ///< a `session` column
  /// Absolute rows: the effect is identified from positions in the instrument frame; a
  /// loaded-minus-unloaded displacement does not see it (constant geometry and self-weight
  /// cancel there) or another effect already models what it sees (the tool's target offset is
  /// point_offset's measured point). The diagnosis does not propose it on data without them.
  kNeedsAbsolute = 1u << 3,
  kNeedsTemperature = 1u << 4,  ///< a `temp` column (absolute rows)
  /// Absolute rows with a measured orientation (a 6-D probe): the effect models the probe's
  /// frame, which positions do not see. A model with such an effect predicts the probe's
  /// orientation, and the identification adds the orientation residuals.
  kNeedsOrientation = 1u << 5,
};

/// The stages of an evaluation (Effect::stages).
enum Stage : unsigned {
  kWrenchStage = 1u << 0,
  kJointStage = 1u << 1,
  kCartesianStage = 1u << 2,
  kMeasurementStage = 1u << 3,
  kGeometryStage = 1u << 4,
  kAllStages = 31u,
};

/// A physical effect configured for one robot (and, where it matters, one dataset).
class Effect {
 public:
  virtual ~Effect() = default;
  virtual const std::string& name() const = 0;
  /// One-line physical explanation.
  virtual std::string description() const = 0;
  /// The model and its literature reference (docs).
  virtual std::string reference() const = 0;
  virtual unsigned requirements() const { return kNeedsNothing; }
  /// True when a stage reads EvalState::jac_meas or jac_load (DeflectionModel::evaluate_jet
  /// fills them only then).
  virtual bool reads_jacobians() const { return false; }
  /// True when the effect's contribution is linear in its parameters with coefficients that
  /// no parameter changes as long as every effect of the model is linear (it only adds to
  /// dtheta, d or rot, and moves neither the points nor the wrench). A model of linear effects
  /// predicts d affine in theta (identify() then needs one Jacobian per measurement).
  virtual bool linear() const { return false; }
  /// Optional analytic derivatives of a linear effect (automatic differentiation otherwise):
  /// true when displacement_derivatives is provided.
  virtual bool has_displacement_derivatives() const { return false; }
  /// dd/dp, the derivatives of the effect's additions to d with respect to its parameters (3 x
  /// size(), column-major) at the state s of stage 1 (points, wrench, tau and the
  /// translational rows of jac_meas); an addition to dtheta reaches d through jac_meas. Used
  /// by DeflectionModel::analytic_columns when every other effect acts only in the wrench
  /// stage.
  virtual void displacement_derivatives(const EvalState<double>& /*s*/, double* /*out*/) const {}
  /// Optional analytic derivatives of an absolute row's predicted position and orientation
  /// (one evaluation instead of one pass of automatic differentiation per kJetStride
  /// parameters): true when absolute_columns is provided. Such an effect writes only what
  /// AbsoluteTangents maps (dtheta in the joint stage, linearly in its parameters; dq and
  /// joint_error, linearly, or the probe's rotation on the flange in the geometry stage; or,
  /// as the model's only measurement-stage effect, the position and orientation it receives)
  /// and reads nothing another effect's parameters change but the measured point. The tests
  /// compare every such effect's columns with automatic differentiation.
  virtual bool has_absolute_columns() const { return false; }
  /// d(y, o)/dp (t.rows() x size(), column-major, zeroed by the caller) of the absolute row
  /// whose values are in `s` (after its evaluation at p) through the tangents `t` of that
  /// evaluation.
  virtual void absolute_columns(const double* /*p*/,
                                const EvalState<double>& /*s*/,
                                const AbsoluteTangents& /*t*/,
                                double* /*out*/) const {}
  /// The stages the effect acts in (Stage bits); EffectT finds them from the stage functions
  /// the effect defines.
  virtual unsigned stages() const { return kAllStages; }
  /// Parameters, in the order of the parameter block.
  virtual const std::vector<ParameterSpec>& parameters() const = 0;
  int size() const { return static_cast<int>(parameters().size()); }
  /// A representative true value of the effect on an arm whose joint compliances are
  /// `joint_compliance` [rad/(N*m)], written over p (which holds the null values): the virtual
  /// robot's example of the effect and the truth of the registry-driven tests. Parameters that
  /// a flange-centred set-up cannot see stay null. False when the effect gives none.
  virtual bool example_parameters(const Eigen::VectorXd& /*joint_compliance*/,
                                  double* /*p*/) const {
    return false;
  }
  /// The physically common sub-forms of a family of forms, each a set of parameter indices
  /// (e.g. the adjacent pairs of a coupling): the diagnosis's score test takes the best of the
  /// whole effect and these, with the Bonferroni correction for the number tried, so that a
  /// common sub-form is not tested diluted among every term the family has. Empty: the whole
  /// effect only.
  virtual std::vector<std::vector<int>> sub_forms() const { return {}; }
  /// The forms the score test tries besides the whole effect: the common sub-forms, and forms
  /// of rare terms that the whole would dilute among other rare terms (link's root springs
  /// without its bending terms). Trying a form does not make its terms common.
  virtual std::vector<std::vector<int>> score_forms() const { return sub_forms(); }
  /// Whether the sub-forms are alternatives, of which a set-up usually has one (a force sensor
  /// on the flange or a fixture in the base frame): a fit's selection of optional terms then
  /// also weighs dropping each sub-form's terms at once (identify_ceres.cpp, select_terms).
  virtual bool alternative_forms() const { return false; }
  /// Per parameter: whether it belongs to one of the common sub-forms (every parameter when
  /// the effect has none). A term outside them is a rare one.
  std::vector<bool> common_terms() const;
  /// The variance [rad^2] the effect adds to each joint's deflection that no parameter
  /// predicts, added to `var` (size dof): a state of the mechanism that the readings do not
  /// set (a reducer's rest anywhere in its gap when nothing preloads it). `s` is the row's
  /// state after its evaluation at p. The diagnosis adds what it makes of the measured point's
  /// displacement to a stated noise (DeflectionModel::displacement_scatter).
  virtual void joint_scatter(const double* /*p*/,
                             const EvalState<double>& /*s*/,
                             Eigen::VectorXd& /*var*/) const {}
  virtual bool scatters() const { return false; }  ///< true when joint_scatter adds anything
  /// Experiments that tell this effect from its look-alikes, one sentence each (the
  /// diagnosis's advice when the data cannot decide).
  virtual std::vector<std::string> experiment_hints() const { return {}; }
  /// p[k] = value for the parameter called `name`; throws InvalidArgument when there is none.
  void set_parameter(double* p, const std::string& name, double value) const;

  virtual void wrench(const double* p, EvalState<double>& s) const = 0;
  virtual void wrench(const Jet* p, EvalState<Jet>& s) const = 0;
  virtual void joint(const double* p, EvalState<double>& s) const = 0;
  virtual void joint(const Jet* p, EvalState<Jet>& s) const = 0;
  virtual void cartesian(const double* p, EvalState<double>& s) const = 0;
  virtual void cartesian(const Jet* p, EvalState<Jet>& s) const = 0;
  virtual void measurement(const double* p, EvalState<double>& s) const = 0;
  virtual void measurement(const Jet* p, EvalState<Jet>& s) const = 0;
  virtual void geometry(const double* p, EvalState<double>& s) const = 0;
  virtual void geometry(const Jet* p, EvalState<Jet>& s) const = 0;
};

/// CRTP helper: an effect defines any of
///   template <typename T> void wrench_t(const T* p, EvalState<T>& s) const;
///   ... joint_t, cartesian_t, measurement_t
/// and this class instantiates them for double and Jet. Stages it does not define do nothing.
template <typename Derived>
class EffectT : public Effect {
 public:
  template <typename T>
  void wrench_t(const T*, EvalState<T>&) const {}
  template <typename T>
  void joint_t(const T*, EvalState<T>&) const {}
  template <typename T>
  void cartesian_t(const T*, EvalState<T>&) const {}
  template <typename T>
  void measurement_t(const T*, EvalState<T>&) const {}
  template <typename T>
  void geometry_t(const T*, EvalState<T>&) const {}

  void wrench(const double* p, EvalState<double>& s) const final { self().wrench_t(p, s); }
  void wrench(const Jet* p, EvalState<Jet>& s) const final { self().wrench_t(p, s); }
  void joint(const double* p, EvalState<double>& s) const final { self().joint_t(p, s); }
  void joint(const Jet* p, EvalState<Jet>& s) const final { self().joint_t(p, s); }
  void cartesian(const double* p, EvalState<double>& s) const final { self().cartesian_t(p, s); }
  void cartesian(const Jet* p, EvalState<Jet>& s) const final { self().cartesian_t(p, s); }
  void measurement(const double* p, EvalState<double>& s) const final {
    self().measurement_t(p, s);
  }
  void measurement(const Jet* p, EvalState<Jet>& s) const final { self().measurement_t(p, s); }
  void geometry(const double* p, EvalState<double>& s) const final { self().geometry_t(p, s); }
  void geometry(const Jet* p, EvalState<Jet>& s) const final { self().geometry_t(p, s); }
  unsigned stages() const override {
    // A stage function the effect does not define is this class's: its member pointer type
    // names EffectT.
    using Fn = void (EffectT::*)(const double*, EvalState<double>&) const;
    using std::is_same;
    return (is_same<decltype(&Derived::template wrench_t<double>), Fn>::value ? 0u : kWrenchStage) |
           (is_same<decltype(&Derived::template joint_t<double>), Fn>::value ? 0u : kJointStage) |
           (is_same<decltype(&Derived::template cartesian_t<double>), Fn>::value
                ? 0u
                : kCartesianStage) |
           (is_same<decltype(&Derived::template measurement_t<double>), Fn>::value
                ? 0u
                : kMeasurementStage) |
           (is_same<decltype(&Derived::template geometry_t<double>), Fn>::value ? 0u
                                                                                : kGeometryStage);
  }

 private:
  const Derived& self() const { return static_cast<const Derived&>(*this); }
};

/// What a factory gets: the robot and, optionally, the data the model will be used with
/// (sessions, time span).
struct EffectSetup {
  const RobotModel* robot = nullptr;
  const Dataset* data = nullptr;  ///< may be null (prediction without data)
  int sessions = 1;               ///< number of distinct sessions in the data
  /// Their labels in the model's session order (from the data, else from a fit).
  std::vector<std::string> session_labels;
  /// For an effect that decides parameters from the data (ParameterSpec::from_data): the
  /// displacement columns dd/dtheta of the model's other effects at their start values, a
  /// 3-row block per row of `data` (zero for absolute rows), so that it decides on what those
  /// effects leave (backfitting) and not on the raw displacements. Empty otherwise.
  Eigen::MatrixXd companion_columns;
  /// Where the model's other effects put a row's measured point and load point (flange frame
  /// [m]) and its applied force and moment (base frame), read after the wrench stage.
  struct CompanionRow {
    Eigen::Vector3d r_meas, r_load, force, moment;
  };
  /// For such an effect, per row of `data`: the other effects' wrench stage at the values the
  /// decision is taken at (DeflectionModel's `decide_at`, a previous fit of the model: a point
  /// offset moves the lever arms and the load torques that decide a backlash jump). Empty: the
  /// robot file's points and the measured wrench (the other effects at their start values).
  std::vector<CompanionRow> companion_rows;
};

using EffectFactory = std::unique_ptr<Effect> (*)(const EffectSetup&);

/// Registry entry.
struct EffectEntry {
  const char* name;
  EffectFactory factory;
};

/// Every effect the library knows, in the registry's order.
const std::vector<EffectEntry>& effect_registry();
/// Names of every registered effect.
std::vector<std::string> effect_names();
/// Create an effect by name; throws InvalidArgument listing the known names if unknown, or if
/// the robot or data lack what it needs (e.g. masses).
std::unique_ptr<Effect> make_effect(const std::string& name, const EffectSetup& setup);

}  // namespace stiff
