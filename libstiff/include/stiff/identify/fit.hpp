/// \file fit.hpp
/// Result of an identification, and its JSON file (docs/formats.md, "fit.json").
#pragma once

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "stiff/model/model.hpp"

namespace stiff {

/// One identified parameter.
struct FitParameter {
  std::string effect;
  std::string name;
  std::string unit;
  std::string meaning;
  double value = 0.0;
  double standard_error = 0.0;  ///< NaN when not identified
  bool identified = true;       ///< false: the data could not identify it; held at `value`
  /// Why a parameter that is not identified is held (empty when identified or unknown, as in
  /// files written before it): "undetermined" (the data do not determine it), "bound" (least
  /// squares put it past its physical bound, e.g. a negative compliance, and the bounded fit
  /// holds it there), "decided" (decided by its effect from the data, not fitted), "left_out"
  /// (an optional term the information criterion left out).
  std::string held;
};

/// A measurement the robust fit down-weighted.
struct Outlier {
  int row = 0;  ///< 0-based index in the data
  std::string id;
  double residual_m = 0.0;  ///< norm of the displacement residual
  double weight = 1.0;      ///< robust weight in [0, 1]
  std::string reason;
};

/// Result of an identification: the model, its parameters and the fit statistics.
struct FitResult {
  std::string robot_name;
  std::string robot_path;
  /// kinematics_digest() of the robot the fit was identified on; empty in older files.
  std::string robot_digest;
  std::vector<std::string> model;  ///< effect names
  /// Session labels in the model's order (absolute data: one registration each); empty when
  /// the data had no sessions.
  std::vector<std::string> sessions;
  std::string method;  ///< "linear_least_squares" or "ceres"
  std::string loss = "none";
  double loss_scale_m = 0.0;
  std::vector<FitParameter> parameters;
  Eigen::MatrixXd covariance;  ///< P x P (NaN rows/cols for unidentified parameters)
  Eigen::VectorXd residuals;   ///< 3N residuals (measured - predicted) [m]
  Eigen::VectorXd weights;     ///< N robust weights (1 without a robust loss)
  std::vector<Outlier> outliers;
  int measurements = 0;
  int rank = 0;
  double condition_number = 0.0;  ///< of the column-scaled Jacobian / observation matrix
  double rms_m = 0.0;             ///< RMS of the displacement residual components
  double sigma_hat_m = 0.0;       ///< residual standard deviation sqrt(RSS / (3N - rank))
  double noise_floor_m = 0.0;     ///< stated noise (sigma_d or metadata); 0 if unknown
  double chi2 = 0.0;              ///< sum of (residual / sigma)^2 when the noise is known
  int dof = 0;                    ///< residual components (3N, + 3 per oriented row) - rank
  /// Absolute rows with a measured orientation that the fit used (0: positions only).
  int oriented_rows = 0;
  /// 3N orientation residuals Log(R_measured R_predicted^T) [rad], NaN on rows without a
  /// measured orientation; empty when oriented_rows is 0.
  Eigen::VectorXd orientation_residuals;
  double orientation_rms_rad = 0.0;   ///< RMS of the orientation residual components
  double orientation_mean_rad = 0.0;  ///< mean orientation error angle per oriented row
  double orientation_max_rad = 0.0;   ///< largest orientation error angle
  /// The weight the orientation residuals had, as a length: 1 rad of orientation error weighed
  /// as this many metres of position error (median over the oriented rows) [m].
  double orientation_length_m = 0.0;
  /// Standard deviation of the model's error added to each absolute row's stated sigma_p (a
  /// variance component estimated from the residuals, Paule & Mandel 1982) [m]; 0 where the
  /// stated noise explains the residuals or no noise is stated.
  double model_error_m = 0.0;
  /// The same for the orientation residuals of rows with a stated sigma_o [rad].
  double model_error_rad = 0.0;
  std::vector<std::string> warnings;

  /// Parameter vector theta in model order.
  Eigen::VectorXd theta() const;
  /// The parameters' values by qualified name ("point_offset.meas_x"): where a model built
  /// again decides (DeflectionModel's `decide_at`).
  std::map<std::string, double> values() const;
  /// Joint stiffness k_j = 1/c_j [N*m/rad] from the `joint` effect (inf for c_j = 0).
  Eigen::VectorXd joint_stiffness() const;
  /// Standard error of k_j by the delta method, se(c)/c^2 [N*m/rad].
  Eigen::VectorXd joint_stiffness_se() const;
  /// Which joints the data identified.
  std::vector<bool> joint_identified() const;
};

/// Serialise as JSON (stable format "stiff-fit" version 1).
std::string fit_to_json(const FitResult& fit);
/// Parse a fit file; throws ParseError naming the path and what is wrong.
FitResult fit_from_json(const std::string& text, const std::string& name_for_errors);
FitResult read_fit(const std::string& path);
void write_fit(const std::string& path, const FitResult& fit);

/// Noise level stated by the data: median sigma_d, else metadata tracker_sigma_m; 0 if none.
double stated_noise_m(const Dataset& data);

/// A digest of the robot's kinematics (every joint's placement and axis, the measured and load
/// points, rounded to 1e-9 m and rad): a fit identified on one robot is refused on another.
std::string kinematics_digest(const RobotModel& robot);

/// The fit as this model takes it, checked. Every optional term of the model that the fit lacks
/// (a term its effect gained after the fit was written, ParameterSpec::optional_term) is
/// inserted at its null value, held and without a variance, as a fit that left the term out
/// holds it. Throws InvalidArgument (prefixed by `what`) unless the fit then applies to this
/// robot and model: the same robot (digest, or name for files without one), the model's
/// parameters by effect and name in order, every value finite and within its physical range.
FitResult fit_for_model(const FitResult& fit,
                        const RobotModel& robot,
                        const DeflectionModel& model,
                        const std::string& what);

/// The robot with the fit's pose-independent geometry built into its description: the joint
/// offsets and kinematic errors into each joint's fixed transform (pre_j <- pre_j E_j
/// Rot(a_j, dq_j), the corrected chain of the model), the tool offset into the measured point;
/// general convention, named "<name>_calibrated". Effects that depend on the pose or the load
/// (compliance, gravity, harmonics, temperature) or describe the instrument (registration) are
/// not part of a robot description: each is named with why in `left_out`. Throws
/// InvalidArgument unless the fit applies to this robot (fit_for_model).
RobotModel calibrated_robot(const RobotModel& robot,
                            const FitResult& fit,
                            std::vector<std::string>* left_out = nullptr);

/// The registration of one session of a fit: the pose of the robot's base in that session's
/// instrument frame (p_instrument = R p_base + t as a 4 x 4 transform), for placing the
/// calibrated robot in the instrument's (the cell's) frame. `session` empty: the fit's only
/// session. Throws InvalidArgument when the fit has no registration, when a fit of several
/// sessions names none, or when the session is not one of the fit's (the message lists them).
Eigen::Matrix4d registration_pose(const FitResult& fit, const std::string& session = "");

/// Predicted (dx, dy, dz, rx, ry, rz) of every row of `data` under a fit. The model is rebuilt
/// from the fit's effect names for this robot.
Eigen::MatrixXd predict_dataset(const RobotModel& robot, const FitResult& fit, const Dataset& data);

}  // namespace stiff
