/// \file identify.hpp
/// Identification of the compliance model from measurements.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "stiff/identify/fit.hpp"

namespace stiff {

/// Default statistical identifiability limit (IdentifyOptions::max_relative_se): a standard
/// error two orders of magnitude above a parameter's typical size is beyond any physically
/// plausible value.
inline constexpr double kDefaultMaxRelativeSe = 100.0;

/// Options of the linear least-squares identification (Jiang & Fang 2023).
struct LinearOptions {
  /// Relative tolerance on the column-scaled pivoted QR diagonal below which a direction is
  /// declared unidentifiable.
  double rank_tolerance = 1e-8;
  /// Weight rows by 1/sigma_d when the data has sigma_d.
  bool use_sigma = true;
  /// The statistical identifiability limit, as IdentifyOptions::max_relative_se.
  double max_relative_se = kDefaultMaxRelativeSe;
};

/// Least-squares identification of the diagonal joint compliances (`joint` model), c =
/// argmin ||A c - X||, with the rank decision of the column-pivoted QR of the column-scaled A
/// (taken on the small normal matrix when no pivot is near the tolerance, else by the QR
/// itself) and the solution at QR accuracy. Joints whose columns the
/// data cannot identify (zero or dependent) are named in `warnings`, held at 0 and marked
/// unidentified. Throws InvalidArgument for bad data and NumericalError when nothing is
/// identifiable.
FitResult identify_joint_linear(const RobotModel& robot,
                                const Dataset& data,
                                const LinearOptions& options = {});

/// Options of the nonlinear (Ceres) identification of any effect model.
struct IdentifyOptions {
  /// Robust loss on the norm of each measurement's 3-vector residual (in units of its sigma):
  /// "none" (least squares), "huber", "cauchy", "soft_l1" or "tukey".
  std::string loss = "none";
  /// Residual norm [m] at which the loss starts to down-weight a measurement. 0: three times
  /// the stated noise (sigma_d column or `# tracker_sigma_m`), else three times a robust
  /// (MAD) estimate of the residual scale of the start model.
  double loss_scale_m = 0.0;
  int max_iterations = 200;
  /// A measurement whose robust weight rho'(s) falls below this is listed as an outlier.
  double outlier_weight = 0.5;
  /// Weight rows by 1/sigma_d (sigma_p, sigma_o) when the data has them.
  bool use_sigma = true;
  /// Absolute rows with a measured orientation add its residual, the rotation vector of
  /// R_measured R_predicted^T [rad], when the model has the probe's frame
  /// (DeflectionModel::predicts_orientation); false fits the positions alone.
  bool use_orientation = true;
  /// Weight of the orientation residuals (docs/identifiability.md): > 0, an orientation error
  /// weighs as the position error it makes this far from the probe [m] (1 m: 1 mrad counts as
  /// 1 mm). 0 (default): estimated from the fit's residuals, the orientation and the position
  /// residuals as two variance components (Helmert), started from 1/sigma_o (rows weighted by
  /// their stated sigmas) or from 1 m; each row keeps its stated relative weight.
  double orientation_length_m = 0.0;
  /// Sine of the angle below which a (column-scaled) Jacobian column counts as lying in the
  /// span of the columns before it: that parameter is not identifiable and is held fixed.
  double rank_tolerance = 1e-6;
  /// A parameter whose standard error at the solution exceeds this many times its typical
  /// magnitude (ParameterSpec::typical; two orders of magnitude: beyond any physically
  /// plausible value) and a third of its distance from its null value is not determined by
  /// the data: it is held at its null value, named in `warnings`, and the rest solved again
  /// (docs/identifiability.md). 0 turns the statistical test off (structural rank only).
  double max_relative_se = kDefaultMaxRelativeSe;
  /// Keep an optional term (ParameterSpec::optional_term) only when it lowers the Bayesian
  /// information criterion of the fit; false keeps every identifiable term
  /// (docs/identifiability.md).
  bool select_terms = true;
  /// Called after every Ceres iteration with (iteration, cost); return false to cancel (the
  /// call then throws Cancelled).
  std::function<bool(int, double)> progress;
  /// A previous fit of the same robot (not owned; may be null): every parameter of the model
  /// that it holds (same effect and name) starts from its value.
  const FitResult* start = nullptr;
  /// With `start`: the effects to fit; every other parameter of the model is given by the
  /// start fit and kept (value, identified flag, standard error), e.g. {"registration"} to
  /// register a new placement of the instrument to a calibrated robot. Empty: fit everything.
  std::vector<std::string> refit;
};

/// Throws InvalidArgument, with the message every surface shows, for options identify() cannot
/// use (unknown loss, negative or non-finite loss scale or max_relative_se, max_iterations <= 0,
/// outlier_weight or rank_tolerance out of range). identify() runs it first; callers that pick
/// the linear method run it too, so that a bad value is refused whichever method solves.
void check_identify_options(const IdentifyOptions& options);

/// Checks of absolute rows against the nominal robot that the file alone cannot make
/// (identify() runs them): without a `registration` effect (`registered` false) the measured
/// positions must lie near where the nominal robot puts the target (else the instrument frame
/// is metres away from the base, and the message says by how much); orientations, where
/// given, must turn between the poses of one session by the angles the robot's flange turns
/// (this is independent of the registration and the tool, and catches an Euler convention
/// or an angle unit mixed up). Throws InvalidArgument naming the session and the sizes.
void check_absolute_data(const RobotModel& robot, const Dataset& data, bool registered);

/// Names of the robust losses identify() accepts.
std::vector<std::string> loss_names();

/// Nonlinear identification of the effect model `effects` (e.g. {"joint", "force_frame"}) by
/// Ceres: 3 residuals per measurement weighted by 1/sigma_d (docs/effects.md, solver details),
/// automatic derivatives, bounds from each ParameterSpec, the joint compliances started from the
/// linear least-squares solution and every other parameter from its spec start. Parameters (or
/// combinations) the data cannot separate are found on the column-scaled Jacobian, held at
/// their null value, marked unidentified and named in `warnings`; on displacement data the
/// check is repeated at the solution (a parameter such as c6 can become visible once offsets
/// are known), on absolute data the set is decided on the linearised start and kept
/// (docs/identifiability.md).
/// Standard errors from the final Jacobian, scaled by the residual variance; robust weights
/// and an outlier list. Throws InvalidArgument for bad data, unknown effects or losses,
/// effects whose requirements the robot lacks; NumericalError when nothing is identifiable;
/// Cancelled when `progress` returns false. Never prints, never aborts.
FitResult identify(const RobotModel& robot,
                   const Dataset& data,
                   const std::vector<std::string>& effects,
                   const IdentifyOptions& options = {});

}  // namespace stiff
