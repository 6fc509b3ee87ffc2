/// \file diagnose.hpp
/// Model diagnosis (docs/diagnosis.md): how good is the
/// model against the noise floor, where does it fail, which physical effect of the library is
/// missing, and a verdict. Optionally walks the forward-stepwise loop (add the winner, re-fit,
/// re-score conditionally).
///
/// Statistics. Rows are weighted by 1/sigma (sigma_d, the metadata tracker_sigma_m, or the
/// pooled spread of replicated measurements). The current model is fitted (identify()), its
/// weighted Jacobian X and residual r0 are taken at the fitted parameters. For each candidate
/// effect g not in the model, Z_g = d(prediction)/d(theta_g) at theta_g = null (the model
/// current+g, automatic differentiation) is projected off X, Z~ = (I - P_X) Z, and the
/// numerically null directions of Z~ are dropped (rank-revealing SVD: "not identifiable from
/// this data"). The group score is dRSS_g = ||P_{Z~} r0||^2 (Rao 1948); the partial F-test
/// F = (dRSS_g/df_g) / ((RSS0 - dRSS_g)/(n - p - df_g)) is ranked by its log p-value (no
/// underflow), Holm-corrected across groups (Holm 1979).
#pragma once

#include <cmath>
#include <string>
#include <vector>

#include "stiff/io/dataset.hpp"
#include "stiff/kinematics/robot_model.hpp"

namespace stiff {

/// Distribution tails (no Boost): regularised incomplete gamma and beta functions.
namespace stats {
/// Regularised lower incomplete gamma P(a, x), a > 0, x >= 0.
double gamma_p(double a, double x);
/// Regularised upper incomplete gamma Q(a, x) = 1 - P(a, x).
double gamma_q(double a, double x);
/// log Q(a, x), accurate where Q underflows (large x).
double log_gamma_q(double a, double x);
/// Regularised incomplete beta I_x(a, b), a, b > 0, 0 <= x <= 1.
double beta_i(double a, double b, double x);
/// log I_x(a, b), accurate where I underflows (small x).
double log_beta_i(double a, double b, double x);
/// P(X > x) for X ~ chi2_k, and its natural log.
double chi2_sf(double x, double k);
double log_chi2_sf(double x, double k);
/// P(X > f) for X ~ F(d1, d2), and its natural log.
double f_sf(double f, double d1, double d2);
double log_f_sf(double f, double d1, double d2);
/// Holm step-down adjusted p-values (same order as the input), from log p-values.
std::vector<double> holm_adjust(const std::vector<double>& log_p);
}  // namespace stats

/// Options of diagnose().
struct DiagnosisOptions {
  /// Candidate effects; empty = every registered effect not in the model.
  std::vector<std::string> candidates;
  /// Family-wise error rate of the candidate tests (Holm) and of the other tests.
  double alpha = 0.05;
  /// Canonical correlation between two projected candidate groups above which the data cannot
  /// tell them apart (they are reported as one ambiguous group).
  double ambiguity_correlation = 0.8;
  /// Relative singular value below which a direction of a projected candidate group counts as
  /// numerically null (not identifiable from this data).
  double rank_tolerance = 1e-5;
  /// Walk the loop: add the top effect while the evidence holds, re-fit, re-score.
  bool auto_loop = false;
  int max_steps = 4;
  /// Relative uncertainty of a stated noise level (an instrument specification or a propagated
  /// force error is itself known to 10-25 %): the checks that the residual is at the noise
  /// floor reject only when it is improbably large for a noise (1 + u) times the stated one.
  double noise_uncertainty = 0.1;
  /// Validation rows from a set-up the calibration has not seen (absolute rows of a session
  /// the calibration data do not have, with `registration` in the model): the new placement of
  /// the instrument is registered from this fraction of its rows (spread evenly over the file)
  /// and the model is scored on the others, as a calibrated robot is used in a new cell.
  double validation_registration_fraction = 0.2;
  /// The robot's pose repeatability [m] as its data sheet states it (ISO 9283 RP: the radius
  /// about the mean attained position that holds the repeated attainments, mean distance plus
  /// three standard deviations); 0: not stated. On absolute data a model whose held-out mean
  /// position error is at most this predicts the robot within its own scatter: its verdict is
  /// `adequate` and the loop stops there.
  double repeatability_m = 0.0;
  /// Folds of the cross-validation that adds the calibration's own poses to the held-out
  /// evidence of the loop on absolute data (section 3 of docs/diagnosis.md); 0: none.
  int cross_validation_folds = 5;
  /// Number of worst poses listed.
  int worst_poses = 5;
  /// Flag rows whose residual is improbable under chi2_3 at this family-wise level (after a
  /// robust scale) as outliers; they are excluded from the fit and the tests. 0: no check.
  double outlier_alpha = 0.05;
  /// Start of the command that adds an effect ("stiff diagnose --robot r --data d.csv");
  /// candidates get `<prefix> --model <model>+<effect>`.
  std::string command_prefix = "stiff diagnose";
};

/// One candidate effect and its evidence.
struct CandidateScore {
  std::string effect;
  int rank = 0;  ///< 1 = strongest evidence; 0 for untestable candidates
  bool testable = true;
  std::string reason;                       ///< why it is untestable / partly identifiable
  int parameters = 0;                       ///< columns of the group
  int df = 0;                               ///< identifiable directions after projection
  bool identifiable = true;                 ///< every direction of the group is identifiable here
  std::vector<std::string> unidentifiable;  ///< parameters the data cannot see
  double statistic = 0.0;                   ///< partial F statistic
  double lm = 0.0;     ///< score statistic dRSS / sigma^2 (chi2_df under H0, known sigma)
  double log_p = 0.0;  ///< natural log of p_value
  double p_value = 1.0;
  double p_adjusted = 1.0;  ///< Holm
  bool significant = false;
  double delta_rss = 0.0;            ///< weighted (sigma units squared)
  double expected_rms_drop_m = 0.0;  ///< sqrt(max(0, dRSS - df sigma^2) / n) [m]
  double fit_rms_after_m = 0.0;      ///< fit RMS expected after adding it [m]
  double excess_explained = 0.0;     ///< dRSS / (RSS0 - (n - p)), when the noise is known
  double surviving_fraction = 0.0;   ///< ||Z~|| / ||Z|| (what the model does not absorb)
  double max_correlation = 0.0;      ///< canonical correlation with the top candidate
  std::vector<std::string> group;    ///< ambiguous set this candidate belongs to
  std::string command;
  /// Added-variable plot data (top candidates only): fitted candidate component Z~ theta
  /// and the current residual r0, both per row component [m].
  std::vector<double> av_fitted_m, av_residual_m;
};

/// A test of residual structure against one covariate.
struct CovariateTest {
  std::string covariate;  ///< e.g. "q2", "tau_load_3", "tau_gravity_2", "load_level", "time"
  std::string description;
  std::string test = "partial_F";  ///< or "cluster_robust_F" (docs/diagnosis.md, section 2)
  double statistic = 0.0;          ///< F
  int df = 0;
  double p_value = 1.0, p_adjusted = 1.0;
  bool significant = false;
  double share = 0.0;      ///< the part of the residual sum of squares the group takes up
  bool structure = false;  ///< significant and share large enough (docs/diagnosis.md, rule 1)
  double correlation[3] = {0, 0, 0};  ///< Pearson r of the residual x,y,z with the covariate
};

/// One measurement's residual.
struct PoseResidual {
  int row = 0;
  std::string id;
  double residual_m[3] = {0, 0, 0};
  double predicted_m[3] = {0, 0, 0};
  double norm_m = 0.0;
  double norm_sigma = 0.0;  ///< norm / sigma
  bool outlier = false;
};

/// Fit quality of one model.
struct ModelQuality {
  std::string model;               ///< "joint+link"
  int measurements = 0, used = 0;  ///< rows, rows not flagged as outliers
  int parameters = 0;              ///< rank of the fitted Jacobian
  double fit_rms_m = 0.0;
  double chi2 = 0.0;  ///< RSS / sigma^2 (weighted)
  int dof = 0;
  double chi2_p = 1.0;  ///< P(chi2_dof > chi2); 1 without a noise level
  /// With a stated noise: sqrt(chi2 / dof), how far the residual sits from the floor, and
  /// P(chi2_dof > chi2 / (1 + u)^2), the floor test allowing for the noise uncertainty u. With
  /// validation rows the test pools them (their weighted squared errors over their expected
  /// prediction variance, 3m more degrees of freedom): a model that explains the data predicts
  /// new poses at the floor too.
  double residual_to_floor = NAN;
  double floor_p = 1.0;
  /// With a stated noise and validation rows: sqrt of their weighted mean squared error over its
  /// expectation for a right model (1 + h + the session's leverage), how far the validation
  /// errors sit from the floor (NaN otherwise).
  double validation_to_floor = NAN;
  double sigma_hat_m = 0.0;
  bool has_validation = false;
  double validation_rms_m = 0.0;
  double validation_floor_m = 0.0;  ///< sigma sqrt(1 + h)
  /// Mean leverage h of the validation rows on the identified parameters, per component:
  /// their prediction variance over sigma^2 (a calibration row's mean is p/n; a pose outside
  /// the calibration design has more).
  double validation_leverage = 0.0;
  /// Validation RMS over what the fit residual predicts for new poses, sigma_hat sqrt(1 + h)
  /// (1 when the model explains the data), and P(F(3m, n - p) > ratio^2): a model that leaves
  /// structure predicts new poses worse than it fits them.
  double validation_to_fit = NAN;
  double validation_to_fit_p = 1.0;
  /// Validation rows the fit-versus-validation test leaves out: for a model that predicts by a
  /// decision taken from the data (a backlash jump's side) whose calibration excluded rows as
  /// outliers, the validation rows that the same rule (P(chi2_3) < alpha / m under the fit's
  /// residual scale, at most m/5 of them) calls improbable, so that both sides of the ratio
  /// are judged alike.
  int validation_outliers = 0;
  /// Validation rows whose prediction the calibration leaves undecided (a parameter decided
  /// from the data, e.g. backlash's preload error, anywhere in its confidence interval changes
  /// it): the fit-versus-validation test scores each by the prediction closest to it.
  int validation_uncertain_rows = 0;
  /// Calibration rows (used) whose prediction the data leave undecided in the same way: the
  /// tests (chi2, the candidates' F tests, the residual structure) take each by the prediction
  /// closest to it; the fit RMS is the point prediction's.
  int uncertain_rows = 0;
  std::vector<double> validation_error_m;  ///< per validation row, norm of the error
  /// Absolute data in the loop: per calibration row, the norm of its K-fold cross-validated
  /// prediction error [m] (NaN for rows not used); empty when not computed.
  std::vector<double> cross_validation_error_m;
  /// Directions of the measurement session's own parameters (ParameterSpec::per_session, e.g.
  /// drift) estimated on the validation session, cross-fitted (each half of its rows predicted
  /// with the values from the other half): the validation is another session, and its warm-up
  /// is its own. Their prediction variance enters the fit-versus-validation test.
  int validation_session_parameters = 0;
  /// Their mean leverage on a scored component: the validation mean square of a right model is
  /// sigma^2 (1 + h + this); comparisons between models divide it out.
  double validation_session_leverage = 0.0;
  std::vector<std::string> parameter_names;
  std::vector<double> parameter_values;
};

/// One step of the loop.
struct DiagnosisStep {
  int step = 0;
  std::string added;  ///< effect added at this step ("" for step 0)
  ModelQuality quality;
  std::string verdict;  ///< verdict of this step's model
  std::string top;      ///< top candidate of this step's model ("" if none)
  double top_p_adjusted = 1.0;
  double top_expected_rms_drop_m = 0.0;
};

/// Result of diagnose().
struct Diagnosis {
  std::string robot;
  std::vector<std::string> model;
  /// "missing_effect", "adequate", "ambiguous" or "unexplained".
  std::string verdict;
  std::string summary;          ///< one paragraph for people
  std::string suggested_model;  ///< model with the top effect ("" if none)
  std::string suggested_command;
  std::string experiment;  ///< discriminating experiment (ambiguous)
  std::vector<std::string> ambiguous_group;
  /// The mechanism outside the library (a "where it fails" covariate, e.g. base_tilt) that
  /// explains the group's evidence as well (ambiguous); "" when none.
  std::string outside_rival;
  std::string unexplained_signature;  ///< what the structure looks like (unexplained)
  double noise_floor_m = 0.0;
  std::string noise_source;  ///< "sigma_d", "metadata", "replicates" or "none"
  /// The data state the force error: each row's covariance carries it along the arm's
  /// compliance at the pose (docs/diagnosis.md, section 1).
  bool noise_force_error = false;
  double repeatability_m = 0.0;  ///< the robot's stated repeatability (options); 0: none
  double alpha = 0.05;
  ModelQuality fit;  ///< the model as given
  bool omnibus_rejects = false;
  ModelQuality after;  ///< after adding the top candidate (re-fitted), if any
  bool after_valid = false;
  std::vector<CandidateScore> candidates;  ///< testable by rank, then untestable
  std::vector<PoseResidual> residuals;
  std::vector<PoseResidual> worst;
  double axis_rms_m[3] = {0, 0, 0};
  double axis_chi2_p[3] = {1, 1, 1};
  std::vector<CovariateTest> covariates;
  std::vector<DiagnosisStep> steps;  ///< the loop (auto), step 0 = the given model
  std::string final_model;           ///< auto: model at the end of the loop
  std::string final_verdict;
  std::vector<std::string> notes;  ///< how the data were used (e.g. a new set-up registered)
  std::vector<std::string> warnings;
};

/// Diagnose `model` (effect names) on `calibration` (with displacements); `validation` may be
/// null. Throws InvalidArgument for bad data/model/options, NumericalError when the model
/// cannot be fitted. Never prints.
Diagnosis diagnose(const RobotModel& robot,
                   const Dataset& calibration,
                   const Dataset* validation,
                   const std::vector<std::string>& model,
                   const DiagnosisOptions& options = {});

/// Serialise as JSON (format "stiff-diagnosis" version 1, docs/diagnosis.md).
std::string diagnosis_to_json(const Diagnosis& diagnosis);

}  // namespace stiff
