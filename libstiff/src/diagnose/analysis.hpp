// The diagnosis's working types, shared by its parts (private to diagnose/): the fitted model
// on the calibration rows (Analysis), the candidates scored at one model (Level) and the
// loop of levels that gives the verdict (Chain). docs/diagnosis.md explains the tests.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "diagnose/noise.hpp"
#include "stiff/diagnose/diagnose.hpp"
#include "stiff/identify/fit.hpp"
#include "stiff/io/dataset.hpp"
#include "stiff/model/model.hpp"

namespace stiff::diagnose_detail {

using Eigen::MatrixXd;
using Eigen::VectorXd;

/// The validation data as the diagnosis scores it. Rows of a set-up the calibration has not
/// seen (a session it does not have, with `registration` in the model) split into the rows
/// that register the new instrument placement and the rows scored; other rows are scored as
/// they are.
struct ValidationSplit {
  Dataset scored;
  Dataset registering;             ///< rows of new sessions that register them; may be empty
  std::vector<std::string> notes;  ///< one per new session: how it was registered
};

/// Splits `validation` for the model `model` fitted to `calibration`: a new session's rows,
/// in file order, register it at an even spacing (row i when floor((i + 1) f) > floor(i f),
/// f = `fraction`; at least 6 rows), the others are scored. Throws InvalidArgument naming a
/// new session with too few rows to register and score (9).
ValidationSplit split_validation(const Dataset& calibration,
                                 const Dataset& validation,
                                 const std::vector<std::string>& model,
                                 double fraction);

/// The error of the prediction closest to the observation among those the calibration data do
/// not exclude: each parameter decided from the data with a confidence interval
/// (ParameterSpec::confidence_lower/upper) is set to either end of it where that changes the
/// prediction (a backlash jump decided on one side of the reversal or the other), every
/// combination of those ends tried (of the six parameters that move it most). `e` is the error
/// of the point prediction at `theta` (which may carry a validation session's own cross-fitted
/// parameters: the alternatives enter as changes of the prediction, which those additive terms
/// do not alter); `*uncertain` is set when the prediction changes.
Eigen::Vector3d closest_error(const DeflectionModel& model,
                              const VectorXd& theta,
                              const Measurement& m,
                              const MeasurementContext& c,
                              const Eigen::Vector3d& e,
                              bool* uncertain);
/// True when `model` has a parameter decided from the data with a confidence interval: only
/// then can closest_error differ from the point prediction's error.
bool has_confidence_sets(const DeflectionModel& model);

/// One-sided p-value of a paired t test that the errors `b` (per row, lengths) are lower than
/// `a` on the same rows (the common prefix; NaN entries skipped): 1 with fewer than 3 pairs or
/// no fall on average, 0 when every pair falls by the same amount.
double paired_fall_p(const std::vector<double>& a, const std::vector<double>& b);

/// Prediction errors (observed - predicted position) [m] of `split.scored`'s rows under
/// `model` at `theta`, each new session first registered by the rigid motion that best maps
/// its registering rows' predictions onto their measurements (least squares). On displacement
/// rows the validation session's own parameters (ParameterSpec::per_session: its drift) are
/// cross-fitted (DeflectionModel::align_sessions on the rows of odd position predicts those of
/// even position, and the other way round); `*session_parameters` receives how many
/// directions were estimated, `*session_leverage` the mean leverage this adds to a scored
/// component (its prediction variance over sigma^2). `*closest` (optional) receives per scored
/// row the error of the prediction closest to it among those the calibration does not exclude
/// (parameters decided from the data, anywhere in their confidence interval:
/// ParameterSpec::confidence_lower/upper), `*uncertain_rows` how many rows have more than one.
std::vector<Eigen::Vector3d> validation_errors(const DeflectionModel& model,
                                               const VectorXd& theta,
                                               const ValidationSplit& split,
                                               int* session_parameters = nullptr,
                                               double* session_leverage = nullptr,
                                               std::vector<Eigen::Vector3d>* closest = nullptr,
                                               int* uncertain_rows = nullptr);

struct Context {
  const RobotModel* robot;
  const Dataset* calib;       ///< with explicit time
  const Dataset* validation;  ///< the rows scored (ValidationSplit::scored)
  const Noise* noise;
  const Noise* vnoise;
  const DiagnosisOptions* opt;
  bool had_time = true;                    ///< the calibration data has a `t` column
  const ValidationSplit* split = nullptr;  ///< with `validation`
  bool absolute = false;                   ///< the calibration has absolute rows (rule 5)
};

/// A fitted model on the calibration rows that are not outliers, with everything the tests need.
struct Analysis {
  std::vector<std::string> effects;
  Dataset used;                ///< inlier rows (times kept)
  std::vector<int> used_rows;  ///< their index in the calibration data
  std::vector<bool> outlier;   ///< per calibration row
  std::unique_ptr<DeflectionModel> model;
  FitResult fit;                        ///< the fit on `used`
  std::vector<MeasurementContext> ctx;  ///< of `used`
  VectorXd theta;
  std::vector<bool> identified;
  /// Per used row: W[i] = L_i^-1 and cov_factor[i] = L_i, L_i L_i^T the covariance of the
  /// row's displacement [m^2]: sigma^2 I, or with a stated force error the tracker's sigma^2 I
  /// plus G_i S_i G_i^T (G_i = force_response[i], S_i the force error's variances), since that
  /// error moves the point along the directions of the arm's compliance. Weighted rows are W[i]
  /// times metres; unit weights when the noise is unknown.
  std::vector<Eigen::Matrix3d> W, cov_factor;
  /// Per used row: the model's displacement per unit force along the base axes [m/N], by central
  /// differences of 1e-4 of the reading; zero for a row without a written force. The covariance
  /// above and the force-reading trend groups (outside.cpp) use it.
  std::vector<Eigen::Matrix3d> force_response;
  MatrixXd qx;        ///< orthonormal basis of the weighted Jacobian (3n x p)
  VectorXd r;         ///< weighted residual of the used rows (3n)
  MatrixXd pred_all;  ///< predicted d of every calibration row (N x 3)
  double rss = 0;     ///< ||r||^2
  int n = 0, p = 0;   ///< equations, rank
  ModelQuality quality;
  std::vector<std::string> warnings;
};

/// Fit `effects` to `data` (linear least squares for the joint model, else Ceres).
FitResult fit_model(const RobotModel& robot,
                    const Dataset& data,
                    const std::vector<std::string>& effects);

/// K-fold cross-validated prediction errors of the model of `a` on the calibration rows it
/// used: each session's rows dealt to `folds` folds in a fixed pseudo-random order, each fold
/// predicted by the model refitted on the other folds. Per calibration
/// row the norm of observed - predicted position [m], NaN for rows `a` did not use. Empty when
/// a fold's fit fails or a session has fewer than 2 `folds` rows.
std::vector<double> cross_validation_errors(const Context& cx, const Analysis& a, int folds);

/// Orthonormal basis of the column space of `a` (columns scaled to unit norm first); columns
/// whose relative singular value is below `tol` are dropped. `v_null` (optional) receives the
/// right singular vectors of the dropped directions; `pinv_factor` (optional) a factor F of
/// the pseudo-inverse of the kept part, F F^T = (A^T A)^+ (leverage of a new row j:
/// |j F|^2).
MatrixXd orthonormal_basis(const MatrixXd& a,
                           double tol,
                           VectorXd* sv = nullptr,
                           MatrixXd* v_null = nullptr,
                           double scale_ref = 0.0,
                           MatrixXd* pinv_factor = nullptr);

/// The calibration data with its time axis made explicit (row index when it has no `t`), so
/// that subsets keep each row's time.
Dataset with_explicit_time(const Dataset& d);

/// `fixed` (may be null): use these outlier flags instead of detecting them. Otherwise a row
/// is an outlier only when it is improbable under the current model AND under the current
/// model plus each candidate (linearised about the current fit): rows that an effect
/// explains are that effect's evidence, not outliers.
Analysis analyse(const Context& cx,
                 const std::vector<std::string>& effects,
                 const std::vector<bool>* fixed = nullptr,
                 const std::vector<std::string>& candidates = {});

/// Score of one regressor group Z (weighted, 3n x k) against an analysis.
struct GroupScore {
  int columns = 0, df = 0;
  double drss = 0, f = 0, log_p = 0, surviving = 0;
  bool robust = false;            ///< f and log_p are robust_group's
  MatrixXd u;                     ///< basis of the projected group
  std::vector<int> null_columns;  ///< columns with no (surviving) effect
  VectorXd fitted;                ///< projection of r on the group (weighted)
};

GroupScore score_group(const Analysis& a, const MatrixXd& z, const VectorXd& typical, double tol);

/// Does the group with orthonormal basis ug (projected off the current model) explain away the
/// evidence of the group with basis ut: is t's partial F test given the current model and g not
/// significant at alpha? (True when g spans t, or too few rows are left to test.)
bool explains_away(
    const Analysis& a, const MatrixXd& ut, const MatrixXd& ug, double alpha, double rank_tol);

/// `g` (from score_group) tested with the variance of the score u^T r estimated from each row's
/// own residual (cluster-robust, a row's three components one cluster) instead of one residual
/// variance for all rows: W = s^T V^-1 s, s = u^T r, V = c sum_i u_i^T r_i r_i^T u_i, c = G/(G-1)
/// (N-1)/(N-K), W/df against F(df, G-1) (Cameron & Miller, J. Human Resources 50(2), 2015).
/// Replaces g.f and g.log_p (g.robust); df 0 when fewer than df + 2 rows.
void robust_group(const Analysis& a, GroupScore* g);

/// Everything known about the candidates at one model.
struct Level {
  Analysis a;
  std::vector<CandidateScore> scores;  ///< testable by rank, then untestable
  std::vector<MatrixXd> bases;         ///< projected basis per score (testable)
  std::vector<std::string> group;      ///< ambiguity set around the top (incl. top)
  size_t pick = 0;                     ///< the candidate the next level adds (index in scores)
  std::string rival;          ///< a group member whose chain explains the data as well as the pick
  std::string outside_rival;  ///< a mechanism outside the library that explains the pick's evidence
  bool separable = true;      ///< the top is separable from every group member
  std::string experiment;
  bool cross_validated = false;  ///< a.quality.cross_validation_error_m has been computed
  bool validated = false;        ///< adding the pick lowered the validation error (explained_by)
  bool refuted = false;          ///< adding the pick raised the validation error significantly
  /// decide() found the pick's step confirmed by the validation poses and only marginal
  /// structure after it (verdict `ambiguous`): the loop still takes the step.
  bool tentative = false;
};

/// The experiments that would separate the effects of an ambiguous group: each effect's own
/// hints (Effect::experiment_hints), once each, then the planner's model-discriminating design.
std::string experiment_for(const Context& cx, const std::vector<std::string>& group);

/// Scores every candidate against the analysis `a` (group score / partial-F tests, ambiguity
/// groups) and picks the one the next level adds.
Level score_level(const Context& cx, Analysis a, const std::vector<std::string>& candidates);

/// Does level L claim a missing effect (its top candidate is significant)?
inline bool claims(const Level& L) { return !L.scores.empty() && L.scores[0].significant; }

/// Residual structure against covariates ("where it fails"): per-pose residuals and partial-F
/// trend tests into `d`.
void where(const Context& cx, const Level& L, Diagnosis& d);

/// The trend of level L's residual at p_adj < alpha/10 that is structure (CovariateTest::
/// structure; the strongest), or none: structure
/// whatever the noise level, where a trend at alpha/10 <= p_adj < alpha is left to chance.
/// `outside_only`: only the trends of mechanisms outside the library (is_outside_library);
/// `level` > 0: that level of p_adj instead of alpha/10.
std::optional<CovariateTest> strong_trend(const Context& cx,
                                          const Level& L,
                                          bool outside_only = false,
                                          double level = 0.0);

/// The joint torques J(L)^T W of the measured wrench at the load point [N*m].
inline VectorXd load_torques(const RobotModel& robot,
                             const Measurement& m,
                             const MeasurementContext& c) {
  Eigen::Matrix<double, 6, 1> w;
  w << m.force, m.moment;
  return robot.jacobian_at(c.chain, robot.point_position(c.chain, robot.load_point)).transpose() *
         w;
}

/// The signature of a mechanism outside the library as a group of weighted columns (3n x k,
/// the used rows of an analysis) for the trend tests of "where it fails".
struct OutsideTrend {
  std::string name, description;
  MatrixXd z;
  /// Tested beyond each candidate in turn (the least significant counts): a group flexible
  /// enough to take up what one of the library's laws leaves.
  bool beyond_candidates = false;
  /// Tested with a variance of the residual estimated per row (robust_group below): a group
  /// whose columns are the directions in which the force reading's noise moves the point.
  bool robust = false;
};

/// The groups of every mechanism outside the library at analysis `a` (outside.cpp).
std::vector<OutsideTrend> outside_trends(const Context& cx, const Analysis& a);

/// Is `covariate` the signature of a mechanism outside the library (outside_trends) rather
/// than a generic covariate?
bool is_outside_library(const std::string& covariate);

/// A trend test in words: what the residual follows, with its partial F and adjusted p.
std::string trend_text(const CovariateTest& c);

/// The covariates and axes the residual follows, in one sentence (for `unexplained`).
std::string signature_of(const Diagnosis& d);

/// The levels of the loop: level 0 is the given model, level i+1 adds level i's top effect.
struct Chain {
  const Context* cx;
  std::vector<std::string> candidates;
  std::vector<Level> levels;
  std::vector<std::string> warnings;
  const std::vector<bool>* fixed = nullptr;  ///< outlier flags shared by every level

  /// Level i+1 (computed on demand), or null when level i claims nothing or the re-fit fails.
  const Level* next(size_t i);

  /// Does adding one of the members of level L's ambiguity group lower the validation error?
  /// (A group that does not separate is not followed by the chain; this asks whether what it
  /// takes up on the calibration poses carries over at all.) With `p_calibration` < 1 (the
  /// group's evidence), the fall must also be confirmed() with it.
  bool group_validates(const Level& L, double p_calibration = 1) const;

  /// Do evidence p_calibration on the calibration poses and the validation errors' fall from
  /// `before` to `after` (paired_fall_p) together reach alpha (Fisher's method)?
  bool confirmed(double p_calibration,
                 const std::vector<double>& before,
                 const std::vector<double>& after) const;

  /// The comparable validation RMS of level L's model with `g` added (INFINITY when the re-fit
  /// fails or there are no validation poses); `errors`: that model's validation errors.
  double step_validation(const Level& L,
                         const std::string& g,
                         std::vector<double>* errors = nullptr) const;

  /// The mechanism outside the library (outside_trends) that is significant at level i and
  /// explains away the evidence of its pick: the data cannot tell the pick from an effect no
  /// candidate has. A flexible group (tested beyond each candidate) counts only when the pick
  /// does not explain it away in turn. Null when none.
  std::optional<OutsideTrend> outside_rival(size_t i) const;

  /// The member of level L's ambiguity group whose single step predicts the validation poses
  /// significantly better than every other member's (F test of the validation mean squares at
  /// alpha), or empty: the calibration poses cannot tell the members apart, the new poses can.
  /// `top_errors`: the validation errors of the step with the group's first member (the top).
  std::string validation_separates(const Level& L,
                                   std::string* why,
                                   std::vector<double>* top_errors) const;

  /// Is the residual of level L at the noise floor? With a stated noise: the chi-square test,
  /// allowing for the uncertainty of the stated level. Without: a model that explains the data
  /// predicts the validation poses about as well as it fits (F test of the two mean squares),
  /// and its residual has no structure left against the covariates of "where it fails"
  /// (partial F-tests, Holm across them: no sigma needed). A chain of candidates that mimics
  /// an effect outside the library fits and predicts alike, but leaves the part it cannot
  /// mimic as a trend in the load torques or directions.
  /// `weak`: every piece of evidence against the floor is marginal (alpha / 10 <= p < alpha).
  bool at_floor(const Level& L, std::string* why, bool* weak) const;

  /// Does adding one of level i's significant candidates (the top and the next ones by rank,
  /// kAlternatives in all) and, while the evidence holds, the following ones bring the
  /// residual to the noise floor, with the validation error falling at every step? The
  /// calibration data ranks the candidates; when several chains explain it, the one that
  /// predicts the validation poses best is kept (out-of-sample choice; the first that explains
  /// without validation data). On success levels[i].pick is its candidate; on failure `why` is
  /// the top's reason, and `weak` says whether the evidence against the top's chain is only
  /// marginal (the validation error not significantly worse, or structure left at
  /// alpha / 10 <= p < alpha): not refuted, only not confirmed.
  bool explained_by_chain(
      size_t i, int depth, std::string* why, std::string* top_why = nullptr, bool* weak = nullptr);

  /// explained_by_chain for level i's pick (sets levels[i].validated).
  bool explained_by(size_t i, int depth, std::string* why, bool* weak);

  /// Verdict of level i.
  std::string decide(size_t i, std::string* why);
};

}  // namespace stiff::diagnose_detail
