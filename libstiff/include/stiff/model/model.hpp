/// \file model.hpp
/// DeflectionModel: a robot plus a list of physical effects with one flat parameter vector
/// theta (the effects' parameter blocks, concatenated in model order). Evaluates the predicted
/// loaded-minus-unloaded displacement and rotation of the measured point.
#pragma once

#include <ceres/rotation.h>

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "stiff/model/effect.hpp"

namespace stiff {

/// The model when none is named: the diagonal joint compliances (the paper's model). Every
/// surface (C ABI, Python, command line) takes its default from here.
inline constexpr const char* kDefaultModel = "joint";

/// Split "joint+link+point_offset" into names; throws InvalidArgument on an empty or
/// duplicated name (unknown names are caught when the model is built).
std::vector<std::string> parse_model_string(const std::string& text);

class DeflectionModel {
 public:
  /// Build from effect names. `data` (may be null) supplies sessions and time for effects that
  /// need them. Throws InvalidArgument for unknown names or missing requirements.
  /// `sessions` names the sessions when there is no data (a model rebuilt from a fit:
  /// FitResult::sessions), so that per-session parameters keep their order. `decide_at` (may be
  /// null) gives values of the model's parameters by qualified name ("point_offset.meas_x"),
  /// e.g. a previous fit: an effect that decides parameters from the data decides them with
  /// the other effects' wrench stage at those values (EffectSetup::companion_rows), not at
  /// their start values.
  DeflectionModel(const RobotModel& robot,
                  const std::vector<std::string>& effects,
                  const Dataset* data = nullptr,
                  const std::vector<std::string>& sessions = {},
                  const std::map<std::string, double>* decide_at = nullptr);

  const RobotModel& robot() const { return robot_; }
  const std::vector<std::unique_ptr<Effect>>& effects() const { return effects_; }
  std::vector<std::string> effect_names() const;
  std::string model_string() const;  ///< "joint+link"
  int parameter_count() const { return count_; }
  /// A model of absolute accuracy: one of its effects corrects the chain (geometry stage) or
  /// is seen only in absolute data (tool, registration, self-weight, temperature). Its tool
  /// pose is the calibrated one (tool_pose), not the nominal pose plus a deflection.
  bool absolute_accuracy() const;
  /// An effect models the frame of a 6-D probe (kNeedsOrientation): the model's probe
  /// orientation is a prediction to compare with a measured one. Without one the probe's
  /// frame on the flange is unknown and measured orientations are not used.
  bool predicts_orientation() const;
  /// Every effect is linear (Effect::linear): d is affine in theta.
  bool linear() const { return linear_; }
  /// The parameters whose derivatives need evaluate_jet passes: all of them, or, when the
  /// model is analytic(), those of the effects without analytic derivatives.
  const std::vector<int>& jet_parameters() const { return jet_parameters_; }
  /// Some effects give their columns of dd/dtheta analytically (analytic_columns): each effect
  /// is linear with Effect::displacement_derivatives or acts only in the wrench stage (so
  /// that the linear effects' additions reach d unchanged).
  bool analytic() const { return analytic_; }
  /// The columns of dd/dtheta (3 x P, column-major, into `jac`) of the effects with analytic
  /// derivatives at the state `js` an evaluate_jet pass at theta left (its values; the other
  /// columns are left as they are). `ds` is scratch (one per thread).
  void analytic_columns(const EvalState<Jet>& js, EvalState<double>& ds, double* jac) const;
  /// An absolute row's Jacobian takes one evaluation (absolute_jacobian): every effect gives
  /// its columns analytically (Effect::has_absolute_columns) or acts only in the wrench stage
  /// (differentiated automatically in the same evaluation), at most one acts in the
  /// measurement stage, and the robot has at most 32 joints.
  bool analytic_absolute() const { return analytic_absolute_; }
  /// The parameters absolute_jacobian differentiates automatically (the wrench-stage effects').
  const std::vector<int>& absolute_jet_parameters() const { return absolute_jet_parameters_; }
  /// The predicted position d (3) and its derivatives dd/dtheta (3 x P, column-major, into
  /// `jac`) of the absolute row m at theta when analytic_absolute(): one evaluate_jet pass
  /// (more only for more than five wrench-stage parameters) whose derivative directions are
  /// the measurement stage's input and the wrench-stage parameters, then every other column
  /// from the effects' absolute_columns through the tangents of that pass (AbsoluteTangents).
  /// With dim 6, d and each column also hold the orientation discrepancy (rows 3-5, zero on a
  /// row without a measured orientation), and the pass's directions 0-2 also the measurement
  /// stage's map of the orientation it receives. Equal to displacement_jacobian and
  /// orientation_jacobian up to round-off. `js`, `ds`, `t` are scratch (one per thread).
  void absolute_jacobian(const double* theta,
                         const Measurement& m,
                         const MeasurementContext& c,
                         EvalState<Jet>& js,
                         EvalState<double>& ds,
                         std::vector<Jet>& t,
                         double* d,
                         double* jac,
                         int dim = 3) const;
  /// Offset of effect e's block in theta.
  int offset(int e) const { return offsets_[e]; }
  /// Index of an effect by name, -1 if absent.
  int find(const std::string& effect) const;
  /// Spec of the k-th parameter of theta, and the effect it belongs to.
  const ParameterSpec& spec(int k) const;
  const Effect& owner(int k) const;
  Eigen::VectorXd null_parameters() const;   ///< every effect switched off
  Eigen::VectorXd start_parameters() const;  ///< fit start values

  /// Data of one measurement that does not depend on theta. `row` is its index in the data set
  /// (the time axis when the data has no `t` column).
  MeasurementContext context(const Measurement& m, int row) const;
  std::vector<MeasurementContext> contexts(const Dataset& data) const;

  /// Predicted displacement d [m] and rotation [rad] of the measured point, base frame; with
  /// `o`, an absolute row with orientation gets its orientation discrepancy
  /// (orientation_discrepancy of the predicted probe orientation; zero on other rows).
  template <typename T>
  void evaluate(const T* theta,
                const Measurement& m,
                const MeasurementContext& c,
                Vector3<T>* d,
                Vector3<T>* rot,
                Vector3<T>* o = nullptr) const;
  /// evaluate<Jet> for repeated derivative evaluations (identification): the same stages,
  /// values and derivatives equal up to round-off, but the geometry stage (lever arms and
  /// external joint torques) is computed in double with the derivative parts as 3 x
  /// kJetStride arrays, skipped when no effect moved the points or the wrench in its wrench
  /// stage, EvalState::jac_meas / jac_load filled only for effects that read them, and
  /// `scratch` (reused between calls with this model, one per thread) avoids allocations.
  /// The displacement d is produced and, with `o`, the orientation discrepancy as evaluate's.
  void evaluate_jet(const Jet* theta,
                    const Measurement& m,
                    const MeasurementContext& c,
                    EvalState<Jet>& scratch,
                    Vector3<Jet>* d,
                    Vector3<Jet>* o = nullptr) const;
  /// evaluate<double> of d (and o) reusing `scratch` (no allocation after the first call; one
  /// per thread).
  void evaluate_double(const double* theta,
                       const Measurement& m,
                       const MeasurementContext& c,
                       EvalState<double>& scratch,
                       Vector3<double>* d,
                       Vector3<double>* o = nullptr) const;
  /// Same in double: (dx, dy, dz, rx, ry, rz); on an absolute row, the position in the
  /// instrument frame and the rotation vector [rad] of the probe's predicted orientation there
  /// (the flange's, turned by tool_orientation and by the deflection).
  Eigen::Matrix<double, 6, 1> predict(const Eigen::VectorXd& theta,
                                      const Measurement& m,
                                      const MeasurementContext& c) const;
  /// Pose of the tool (measured point, flange orientation), base frame, that the model
  /// predicts for an absolute row before the instrument sees it: the corrected chain of the
  /// geometry stage (joint offsets, axis errors, tool) at m.q, its point moved by the
  /// deflection of stages 1-3 under m's wrench (and the robot's weight) and turned by its
  /// small rotation; the measurement stage (registration, tracker frame) is not applied.
  /// Throws InvalidArgument for a displacement row.
  Eigen::Matrix4d tool_pose(const Eigen::VectorXd& theta,
                            const Measurement& m,
                            const MeasurementContext& c) const;
  /// Jacobian of the predicted displacement d (3 x P) with respect to theta at theta
  /// (automatic differentiation); with `from` > 0 only the columns from `from` on (the others
  /// zero): a candidate effect's columns after those of the model it extends.
  Eigen::Matrix<double, 3, Eigen::Dynamic> displacement_jacobian(const Eigen::VectorXd& theta,
                                                                 const Measurement& m,
                                                                 const MeasurementContext& c,
                                                                 int from = 0) const;
  /// Covariance [m^2] of a displacement row's measured point that the model leaves to chance
  /// (Effect::joint_scatter through the translational Jacobian at P: J_p diag(var) J_p^T) at
  /// theta; zero for an absolute row and for a model without such an effect.
  Eigen::Matrix3d displacement_scatter(const Eigen::VectorXd& theta,
                                       const Measurement& m,
                                       const MeasurementContext& c) const;
  bool scatters() const { return scatters_; }  ///< an effect of the model has a joint_scatter
  /// Jacobian (3 x P) of the orientation discrepancy of an absolute row with a measured
  /// orientation (evaluate's `o`; zeros on other rows), by automatic differentiation.
  Eigen::Matrix<double, 3, Eigen::Dynamic> orientation_jacobian(const Eigen::VectorXd& theta,
                                                                const Measurement& m,
                                                                const MeasurementContext& c) const;

  /// theta with the per-session parameters (ParameterSpec::per_session) that act on `data`
  /// re-estimated from its own rows by least squares, every other parameter held: the model's
  /// prediction for a measurement session the fit has not seen (a validation file, another
  /// day), whose drift is its own. `ctx` = contexts(data). `*estimated` (may be null) receives
  /// the number of directions estimated (the rank), which a comparison of mean squares must
  /// count as degrees of freedom used. Rows weighted equally (the comparison's own weighting).
  Eigen::VectorXd align_sessions(const Eigen::VectorXd& theta,
                                 const Dataset& data,
                                 const std::vector<MeasurementContext>& ctx,
                                 int* estimated = nullptr) const;

  /// What the model predicts for measured displacement rows of a session the fit has not seen,
  /// with that session's own parameters cross-fitted: the rows of even position are predicted
  /// with the values align_sessions estimates from the rows of odd position and the other way
  /// round, so that no row is predicted by values fitted to it (docs/effects.md, drift).
  /// `*estimated` (may be null) receives the larger of the two halves' ranks, `*leverage` the
  /// mean leverage this adds to a predicted component (its prediction variance over sigma^2).
  /// With fewer than 4 rows, absolute rows or no per-session parameter: the plain predictions.
  std::vector<Eigen::Vector3d> predict_cross_fitted(const Eigen::VectorXd& theta,
                                                    const Dataset& data,
                                                    const std::vector<MeasurementContext>& ctx,
                                                    int* estimated = nullptr,
                                                    double* leverage = nullptr) const;

  /// Index of a session label (0 for unknown labels and for data without sessions).
  int session_index(const std::string& label) const;
  /// True when the model knows the session label.
  bool has_session(const std::string& label) const { return sessions_.count(label) > 0; }
  /// Session labels in index order.
  std::vector<std::string> session_labels() const;

 private:
  /// `backfit` false: the effects decide from the data alone (the companions' own model).
  DeflectionModel(const RobotModel& robot,
                  const std::vector<std::string>& effects,
                  const Dataset* data,
                  const std::vector<std::string>& sessions,
                  bool backfit,
                  const std::map<std::string, double>* decide_at);
  /// EffectSetup::companion_columns on `data` of `others`, the model's other effects (built
  /// without deciding anything).
  static Eigen::MatrixXd companion_columns(const DeflectionModel& others, const Dataset& data);
  /// EffectSetup::companion_rows: the wrench stage of `others` on each row of `data` at
  /// `values` (qualified names; the rest at their start values). Empty when it moves nothing
  /// (the robot file's points and the measured wrench are the default).
  static std::vector<EffectSetup::CompanionRow> companion_rows(
      const DeflectionModel& others,
      const Dataset& data,
      const std::map<std::string, double>& values);
  /// The wrench stage of row `m`: `s` set to the measured wrench and the robot file's points,
  /// then every effect's wrench() (a point offset, a force-sensor frame) applied at `theta`.
  template <typename T>
  void wrench_stage(const T* theta,
                    const Measurement& m,
                    const MeasurementContext& c,
                    EvalState<T>& s) const;
  template <typename T>
  void evaluate_into(const T* theta,
                     const Measurement& m,
                     const MeasurementContext& c,
                     EvalState<T>& s,
                     bool instrument = true,
                     bool orient = false) const;
  RobotModel robot_;
  std::vector<std::unique_ptr<Effect>> effects_;
  std::vector<int> offsets_;
  int count_ = 0;
  bool jet_jacobians_ = false;  ///< an effect reads EvalState::jac_meas / jac_load
  bool deflects_ = false;  ///< an effect acts in the joint or Cartesian stage or reads Jacobians
  bool linear_ = true;
  bool scatters_ = false;  ///< an effect has a joint_scatter (Effect::scatters)
  bool analytic_ = false;
  std::vector<int> jet_parameters_;
  bool analytic_absolute_ = false;
  std::vector<int> absolute_jet_parameters_;
  std::map<std::string, int> sessions_;
};

extern template void DeflectionModel::evaluate<double>(const double*,
                                                       const Measurement&,
                                                       const MeasurementContext&,
                                                       Vector3<double>*,
                                                       Vector3<double>*,
                                                       Vector3<double>*) const;
extern template void DeflectionModel::evaluate<Jet>(const Jet*,
                                                    const Measurement&,
                                                    const MeasurementContext&,
                                                    Vector3<Jet>*,
                                                    Vector3<Jet>*,
                                                    Vector3<Jet>*) const;

/// The orientation discrepancy of an absolute row with a measured orientation: the rotation
/// vector [rad] of R_predicted R_measured^T (instrument frame; the log map of SO(3) by
/// ceres::RotationMatrixToAngleAxis, differentiable through zero). The identification treats
/// it as the row's predicted orientation against an observed zero, so that the orientation
/// residual (measured - predicted) is Log(R_measured R_predicted^T).
template <typename T>
Vector3<T> orientation_discrepancy(const Matrix3<T>& predicted, const Eigen::Matrix3d& measured) {
  const Matrix3<T> e = predicted * measured.transpose();
  Vector3<T> w;
  ceres::RotationMatrixToAngleAxis(e.data(), w.data());
  return w;
}

/// The paper's observation block (Jiang & Fang 2023): the 3 x n matrix with
/// A[r, j] = Jp(P)[r, j] * (J(L)[:, j] . W), so that d = A c for joint compliances c.
/// `jac_meas`, `jac_load`: 6 x n geometric Jacobians; `wrench` = (F, M) at L.
Eigen::Matrix<double, 3, Eigen::Dynamic> observation_block(
    const Matrix6X<double>& jac_meas,
    const Matrix6X<double>& jac_load,
    const Eigen::Matrix<double, 6, 1>& wrench);
/// Stacked observation matrix A (3N x n) of a dataset for the joint-compliance model.
Eigen::MatrixXd observation_matrix(const RobotModel& robot, const Dataset& data);

}  // namespace stiff
