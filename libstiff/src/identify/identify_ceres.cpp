// Nonlinear identification of any effect model (identify.hpp): validation, the identifiable
// set, the solve rounds (ceres_solve.hpp over the cached evaluations of evaluations.hpp),
// robust weights and outliers, covariance and the fit's statistics.
#include <ceres/ceres.h>

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <map>
#include <memory>
#include <numeric>
#include <sstream>

#include "identify/ceres_quiet.hpp"
#include "identify/ceres_solve.hpp"
#include "identify/evaluations.hpp"
#include "identify/identifiability.hpp"
#include "identify/robust.hpp"
#include "stiff/error.hpp"
#include "stiff/identify/identify.hpp"

namespace stiff {
namespace detail {
// validate_dataset(data, dof, true) without strings per row (identify_linear.cpp).
void validate_identification_data(const Dataset& data, int dof);
}  // namespace detail
using detail::check_identifiability;
using detail::Evaluations;
using detail::gram_of;
using detail::held_has_effect;
using detail::Identifiability;
using detail::known_losses;
using detail::make_loss;
using detail::num;
using detail::qualified;
using detail::Setup;
using detail::solve;
using detail::SolveOutcome;
using detail::Visible;
using detail::weighted_jacobian;
using detail::weighted_residuals;

std::vector<std::string> loss_names() { return known_losses(); }

void check_identify_options(const IdentifyOptions& opt) {
  // Everything is validated before Ceres sees it (Ceres CHECK-aborts on misuse).
  const auto& losses = known_losses();
  if (std::find(losses.begin(), losses.end(), opt.loss) == losses.end()) {
    std::string k;
    for (const auto& l : losses) k += " " + l;
    throw InvalidArgument("identify: unknown loss '" + opt.loss + "'; known losses:" + k);
  }
  if (!std::isfinite(opt.loss_scale_m) || opt.loss_scale_m < 0)
    throw InvalidArgument("identify: loss_scale_m must be finite and >= 0 [m] (got " +
                          std::to_string(opt.loss_scale_m) + ")");
  if (opt.max_iterations <= 0) throw InvalidArgument("identify: max_iterations must be > 0");
  if (!(opt.outlier_weight > 0 && opt.outlier_weight <= 1))
    throw InvalidArgument("identify: outlier_weight must be in (0, 1]");
  if (!(opt.rank_tolerance > 0 && opt.rank_tolerance < 0.1))
    throw InvalidArgument("identify: rank_tolerance must be in (0, 0.1)");
  if (!(opt.max_relative_se >= 0) || !std::isfinite(opt.max_relative_se))
    throw InvalidArgument("identify: max_relative_se must be a finite value >= 0");
  if (!(opt.orientation_length_m >= 0) || !std::isfinite(opt.orientation_length_m))
    throw InvalidArgument(
        "identify: orientation_length_m must be a finite length >= 0 [m] (0: estimated)");
}

namespace {
/// identify() with the effects that decide parameters from the data deciding them at
/// `decide_at` (DeflectionModel; null: the other effects at their start values).
FitResult identify_at(const RobotModel& robot,
                      const Dataset& data,
                      const std::vector<std::string>& effects,
                      const IdentifyOptions& opt,
                      const std::map<std::string, double>* decide_at) {
  check_identify_options(opt);
  detail::validate_identification_data(data, robot.dof());
  // Unknown effects, missing masses.
  const DeflectionModel model(robot, effects, &data, {}, decide_at);
  const int n = static_cast<int>(data.rows.size());
  const int p = model.parameter_count();
  if (p == 0)
    throw InvalidArgument("identify: model '" + model.model_string() + "' has no parameters");
  const bool weighted = opt.use_sigma && (data.has_sigma || data.has_sigma_p);
  if (weighted)
    for (int r = 0; r < n; ++r)
      if (!(data.rows[r].sigma() > 0))
        throw InvalidArgument("identify: measurement " + std::to_string(r + 1) + " (id '" +
                              data.rows[r].id + "') has " +
                              (data.rows[r].absolute ? "sigma_p" : "sigma_d") +
                              " = 0; give every row a standard deviation > 0 "
                              "or identify without sigma weighting");
  // Orientation residuals: absolute rows with a measured orientation (options permitting).
  int oriented = 0;
  for (const auto& m : data.rows) oriented += m.absolute && m.has_orientation;
  std::string unused_orientation;
  if (oriented > 0 && !model.predicts_orientation())
    unused_orientation = "the data hold " + std::to_string(oriented) +
                         " measured orientations, which this model does not use: it does not "
                         "model the probe's frame on the flange (add tool_orientation)";
  if (!model.predicts_orientation() || !opt.use_orientation) oriented = 0;
  // A refit from a start fit (a new placement registered to a calibrated robot) weighs the
  // orientations as the calibration did: its estimate comes from the full model and many rows,
  // and the two fits then minimise the same error model.
  const double given_length =
      opt.orientation_length_m > 0
          ? opt.orientation_length_m
          : (opt.start && !opt.refit.empty() ? opt.start->orientation_length_m : 0.0);
  const bool estimate_o = !(given_length > 0);
  const bool weighted_o = weighted && data.has_sigma_o && estimate_o;
  if (weighted_o && oriented > 0)
    for (int r = 0; r < n; ++r)
      if (data.rows[r].absolute && data.rows[r].has_orientation && !(data.rows[r].sigma_o > 0))
        throw InvalidArgument("identify: measurement " + std::to_string(r + 1) + " (id '" +
                              data.rows[r].id +
                              "') has sigma_o = 0; give every row with an orientation a "
                              "standard deviation > 0 or identify without sigma weighting");
  const bool absolute = data.absolute_rows() > 0;
  if (absolute) check_absolute_data(robot, data, model.find("registration") >= 0);
  for (int k = 0; k < p; ++k) {
    const auto& sp = model.spec(k);
    if (!(sp.lower <= sp.upper) || !std::isfinite(sp.start))
      throw InvalidArgument("identify: parameter " + qualified(model, k) + " has an invalid spec");
  }

  // A start fit: parameters matched by effect and name; with `refit`, the others are given.
  std::vector<int> from_start(p, -1);  // index into opt.start->parameters
  std::vector<bool> given(p, false);
  if (!opt.refit.empty() && !opt.start)
    throw InvalidArgument("identify: refitting some effects (" + opt.refit.front() +
                          "...) needs the fit that gives the others (start)");
  if (opt.start) {
    if (!opt.start->robot_digest.empty() && opt.start->robot_digest != kinematics_digest(robot))
      throw InvalidArgument("identify: the start fit was made for robot '" + opt.start->robot_name +
                            "', whose kinematics differ from '" + robot.name + "'");
    for (const auto& e : opt.refit)
      if (model.find(e) < 0)
        throw InvalidArgument("identify: effect '" + e + "' to refit is not in the model '" +
                              model.model_string() + "'");
    for (int k = 0; k < p; ++k) {
      for (size_t i = 0; i < opt.start->parameters.size(); ++i) {
        const FitParameter& q = opt.start->parameters[i];
        if (q.effect == model.owner(k).name() && q.name == model.spec(k).name)
          from_start[k] = static_cast<int>(i);
      }
      const bool refitted =
          opt.refit.empty() ||
          std::find(opt.refit.begin(), opt.refit.end(), model.owner(k).name()) != opt.refit.end();
      if (refitted) continue;
      if (from_start[k] < 0)
        throw InvalidArgument("identify: " + qualified(model, k) +
                              " is neither in the start fit nor refitted (add its effect to the "
                              "effects to refit)");
      const double v = opt.start->parameters[from_start[k]].value;
      if (!std::isfinite(v) || v < model.spec(k).lower || v > model.spec(k).upper)
        throw InvalidArgument("identify: the start fit's " + qualified(model, k) + " = " + num(v) +
                              " is outside its range");
      given[k] = true;
    }
  }

  FitResult f;
  if (!unused_orientation.empty()) f.warnings.push_back(unused_orientation);
  Setup s;
  s.model = &model;
  s.data = &data;
  s.ctx = model.contexts(data);
  s.dim = oriented > 0 ? 6 : 3;
  s.typical.resize(p);
  for (int k = 0; k < p; ++k) {
    const double t = std::abs(model.spec(k).typical);
    s.typical(k) = t > 0 && std::isfinite(t) ? t : 1.0;
  }
  // The orientation residual is not affine in theta: the linear model's shortcut is for d.
  s.eval.init(&s, n, p, model.linear() && s.dim == 3);
  const int dim = s.dim;

  // ---- start: linear least squares for the joint compliances, spec start for the rest.
  Eigen::VectorXd theta = model.start_parameters();
  const int je = model.find("joint");
  if (je >= 0 && !absolute) {  // the linear start reads loaded-minus-unloaded rows
    try {
      LinearOptions lo;
      lo.use_sigma = opt.use_sigma;
      const FitResult lin = identify_joint_linear(robot, data, lo);
      for (int j = 0; j < robot.dof(); ++j) {
        const int k = model.offset(je) + j;
        if (lin.parameters[j].identified && lin.parameters[j].value > 0)
          theta(k) = lin.parameters[j].value;
        else if (!lin.parameters[j].identified)
          // Where the check below will most likely hold it: its Jacobian is then the solver's
          // first (a joint that other effects make visible is freed from there as usual).
          theta(k) = model.spec(k).null_value;
      }
    } catch (const NumericalError&) {
      f.warnings.push_back(
          "the linear start of the joint compliances failed; started from the "
          "default compliances");
    }
  }
  for (int k = 0; k < p; ++k)
    if (from_start[k] >= 0) {
      const double v = opt.start->parameters[from_start[k]].value;
      if (std::isfinite(v)) theta(k) = v;
    }
  for (int k = 0; k < p; ++k)
    theta(k) = std::min(std::max(theta(k), model.spec(k).lower), model.spec(k).upper);

  const Eigen::VectorXd theta_start = theta;  // (a re-weighted fit starts again from here)

  // ---- noise scale and row weights.
  const double stated = stated_noise_m(data);
  s.row_weight.resize(n);
  Eigen::VectorXd raw(3 * n);  // positions or displacements [m]: the noise scale
  const Evaluations::Key start_key = s.eval.key(theta.data());
  for (int r = 0; r < n; ++r) {
    const double* d = nullptr;
    s.eval.get(r, start_key, nullptr, &d, nullptr, nullptr);
    raw.segment<3>(3 * r) = data.rows[r].observed() - Eigen::Map<const Eigen::Vector3d>(d);
  }
  double robust_sigma = 0;
  { robust_sigma = robust::mad_sigma(std::vector<double>(raw.data(), raw.data() + raw.size())); }
  const double noise = stated > 0 ? stated : (robust_sigma > 0 ? robust_sigma : 1e-6);
  for (int r = 0; r < n; ++r) s.row_weight(r) = 1.0 / (weighted ? data.rows[r].sigma() : noise);
  // Orientation: the position weight of the error an orientation error makes at
  // orientation_length_m from the probe; estimated (below) from 1/sigma_o when stated and
  // weighted, else from 1 m.
  s.orient_weight = Eigen::VectorXd::Zero(n);
  if (dim == 6)
    for (int r = 0; r < n; ++r)
      if (data.rows[r].absolute && data.rows[r].has_orientation)
        s.orient_weight(r) = weighted_o ? 1.0 / data.rows[r].sigma_o
                                        : (estimate_o ? 1.0 : given_length) * s.row_weight(r);
  int components = 0;  // residual components that carry data
  for (int r = 0; r < n; ++r) components += s.components(r);
  // Robust threshold on each row's residual norm, in that row's sigma units: 3 sigma for the
  // monotone losses. Tukey's biweight gets the same Gaussian efficiency as Huber's: the classical
  // constants for 95 % are 1.345 sigma (Huber) and 4.685 sigma (Tukey) (Holland & Welsch 1977),
  // so 3 * 4.685 / 1.345 = 10.4 sigma; at 3 sigma it gives clean rows weights below one half.
  const double c_sigma = opt.loss == "tukey" ? 3.0 * 4.685 / 1.345 : 3.0;
  const double scale_m = opt.loss_scale_m > 0 ? opt.loss_scale_m : c_sigma * noise;
  // A row with orientation has 6 components: its clean norm grows by sqrt(2), and so does its
  // threshold (the same rate of clean rows down-weighted).
  Eigen::VectorXd loss_scale(n);
  for (int r = 0; r < n; ++r)
    loss_scale(r) =
        (opt.loss_scale_m > 0 ? opt.loss_scale_m * s.row_weight(r)
                              : (weighted ? c_sigma : c_sigma * noise * s.row_weight(r))) *
        std::sqrt(s.components(r) / 3.0);

  // The robust weight rho'(|e_r|^2) in [0, 1] of row r at the weighted residuals e (1 without a
  // loss): a row the loss down-weights counts that much in the scales and statistics below.
  auto robust_weight = [&](const Eigen::VectorXd& e, int r) {
    std::unique_ptr<ceres::LossFunction> loss(make_loss(opt.loss, loss_scale(r)));
    if (!loss) return 1.0;
    double rho[3];
    loss->Evaluate(e.segment(dim * r, dim).squaredNorm(), rho);
    return std::min(1.0, std::max(0.0, rho[1]));
  };

  // ---- identifiability, solve, re-check at the solution (offsets can make c6 visible).
  Identifiability idf;
  std::vector<bool> left_out;  ///< per parameter: an optional term the data do not support
  std::vector<int> free;
  int iterations = 0;
  const IdentifyOptions* solving = &opt;
  SolveOutcome last;
  Eigen::MatrixXd last_jacobian;
  Eigen::VectorXd last_jacobian_theta;
  Eigen::MatrixXd last_gram;    // its J^T J, for the checks at the solution and the statistics
  double residual_sigma = 0.0;  // 0: the structural test only (the passes)
  // The statistical test judges only values a solve fitted (`free`): a value held at its
  // null so far is not evidence either way.
  // Parameters decided already (given by the start fit; on absolute data, those held at the
  // start): their columns take no part in the decision `run` makes about the others, and they
  // keep their own decision.
  // A start fit's identified parameters claim first what the data show (priority_order).
  std::vector<bool> start_identified(p, false);
  for (int k = 0; k < p; ++k)
    start_identified[k] = from_start[k] >= 0 && opt.start->parameters[from_start[k]].identified;
  const std::vector<bool>* first = opt.start ? &start_identified : nullptr;
  Identifiability given_idf;
  given_idf.fixed = given;
  given_idf.statistical.assign(p, false);
  given_idf.reason.assign(p, "");
  for (int k = 0; k < p; ++k)
    if (given[k]) given_idf.reason[k] = "given by the start fit";
  // `gram`: J^T J of jac when known (null: formed by check_identifiability).
  auto apart = [&](const Eigen::MatrixXd& jac, const Eigen::MatrixXd* gram,
                   const Identifiability& decided, auto&& run) {
    const bool any =
        std::find(decided.fixed.begin(), decided.fixed.end(), true) != decided.fixed.end();
    Eigen::MatrixXd rest, rest_gram;
    if (any) {
      rest = jac;
      if (gram) rest_gram = *gram;
      for (int k = 0; k < p; ++k)
        if (decided.fixed[k]) {
          rest.col(k).setZero();
          if (gram) {
            rest_gram.col(k).setZero();
            rest_gram.row(k).setZero();
          }
        }
    }
    Identifiability out = run(any ? rest : jac, any && gram ? &rest_gram : gram);
    for (int k = 0; k < p; ++k)
      if (decided.fixed[k]) {
        out.fixed[k] = true;
        out.statistical[k] = decided.statistical[k];
        out.reason[k] = decided.reason[k];
      }
    return out;
  };
  auto check = [&](const Eigen::MatrixXd& jac, const Eigen::VectorXd& at,
                   const Eigen::MatrixXd* gram = nullptr) {
    std::vector<bool> fitted(p, false);
    for (int k : free) fitted[k] = true;
    return apart(jac, gram, given_idf, [&](const Eigen::MatrixXd& j, const Eigen::MatrixXd* g) {
      return check_identifiability(model, j, s.typical, opt.rank_tolerance, residual_sigma,
                                   opt.max_relative_se, &at, &fitted, nullptr, first, nullptr, g);
    });
  };
  // The Jacobian at the solve's solution and its J^T J.
  auto keep_last_jacobian = [&]() {
    last_jacobian = weighted_jacobian(s, theta);
    last_jacobian_theta = theta;
    last_gram = gram_of(last_jacobian);
  };
  // Residual standard deviation of the weighted fit at theta, as the statistics below: rows
  // down-weighted by the robust loss count that much.
  auto robust_residual_sigma = [&]() {
    const Eigen::VectorXd e = weighted_residuals(s, theta);
    double wsum = 0, wrss = 0;
    for (int r = 0; r < n; ++r) {
      const double w = robust_weight(e, r);
      wsum += s.components(r) * w;
      wrss += w * w * e.segment(dim * r, dim).squaredNorm();
    }
    const double dof_left = wsum - static_cast<double>(free.size());
    return dof_left > 0 ? std::sqrt(wrss / dof_left) : 1.0;
  };
  // Before a geometric solve, a parameter the data determine only to more than ten times its
  // typical magnitude (its standard error on the linearised start, where absolute rows are
  // close to linear: the registration starts from a Kabsch fit of the nominal chain) is held:
  // free, it drifts along a near-null direction to its bound, to values without meaning, and
  // costs the solver most of its iterations (docs/identifiability.md). Ten, not the
  // max_relative_se of the solution's test, because this one cannot weigh a fitted value.
  constexpr double kStartRelativeSe = 10.0;
  // `structure`: the structural decision check() made on jac (the same columns); `gram` its
  // J^T J.
  auto prescreen = [&](const Eigen::MatrixXd& jac, const Eigen::MatrixXd& gram,
                       const Identifiability& structure) {
    const std::vector<bool> fitted(p, true);
    const Eigen::VectorXd e = weighted_residuals(s, theta);
    const Identifiability stat =
        apart(jac, &gram, given_idf, [&](const Eigen::MatrixXd& j, const Eigen::MatrixXd* g) {
          return check_identifiability(model, j, s.typical, opt.rank_tolerance, 0.0,
                                       std::min(kStartRelativeSe, opt.max_relative_se), &theta,
                                       &fitted, &e, first, &structure, g);
        });
    if (std::find(stat.statistical.begin(), stat.statistical.end(), true) != stat.statistical.end())
      idf = stat;
  };
  // The free set from idf (held parameters back to their null value) and one more solve.
  auto resolve_free = [&](const char* what) {
    free.clear();
    for (int k = 0; k < p; ++k) {
      if (!idf.fixed[k])
        free.push_back(k);
      else if (!given[k])
        theta(k) =
            std::min(std::max(model.spec(k).null_value, model.spec(k).lower), model.spec(k).upper);
    }
    if (free.empty())
      throw NumericalError("identify: no parameter of model '" + model.model_string() + "' " +
                           what);
    last = solve(s, free, theta, opt, loss_scale, nullptr);
    iterations += last.iterations;
    keep_last_jacobian();
  };
  // Optional terms (ParameterSpec::optional_term: members of a family of forms that overlap
  // each other) stay only when the data support them: backward elimination by the Bayesian
  // information criterion (Schwarz 1978), BIC = m ln(RSS) + k ln(m) over the m weighted
  // residual components (no stated noise needed). Each round drops the optional term that pays
  // least beyond its price (ln m, more for a rare term: below), while m ln(RSS_without / RSS) is
  // below that price; the RSS and the other parameters follow the removal on the linearisation
  // at the solution (exact for a model linear in its parameters). Terms that overlap are judged one
  // at a time, so that one of two collinear terms stays when together they matter. The dropped
  // terms are held at their null value and the rest solved again.
  left_out.assign(p, false);
  auto select_terms = [&]() {
    std::fill(left_out.begin(), left_out.end(), false);
    if (!opt.select_terms) return;
    std::vector<int> cur = free;
    auto optional = [&](int k) { return model.spec(k).optional_term && !given[k]; };
    if (std::none_of(cur.begin(), cur.end(), optional) &&
        std::none_of(model.effects().begin(), model.effects().end(),
                     [](const auto& e) { return e->alternative_forms(); }))
      return;
    const Eigen::MatrixXd& jac = last_jacobian;  // at theta (the last solve's)
    Eigen::VectorXd e = weighted_residuals(s, theta);
    Eigen::MatrixXd js(jac.rows(), p);
    for (int k = 0; k < p; ++k) js.col(k) = jac.col(k) * s.typical(k);
    // Rows a robust loss down-weights count that much (as in the residual scale above).
    for (int r = 0; r < n; ++r) {
      const double w = std::sqrt(robust_weight(e, r));
      e.segment(dim * r, dim) *= w;
      js.middleRows(dim * r, dim) *= w;
    }
    const double m = static_cast<double>(components);
    // The price of a term: ln m (BIC); a term outside its family's common sub-forms
    // (Effect::sub_forms, e.g. a coupling of joints that are not neighbours) also pays for the
    // size of the space it is chosen from, 2 ln(number of such terms) (the extended BIC of
    // Chen & Chen 2008, gamma = 1), so that the rare terms are not picked up by chance.
    Eigen::VectorXd price = Eigen::VectorXd::Constant(p, std::log(m));
    for (size_t ei = 0; ei < model.effects().size(); ++ei) {
      const Effect& eff = *model.effects()[ei];
      const std::vector<bool> common = eff.common_terms();
      const auto rare = std::count(common.begin(), common.end(), false);
      if (rare < 2) continue;
      for (int k = 0; k < eff.size(); ++k)
        if (!common[k]) price(model.offset(static_cast<int>(ei)) + k) += 2.0 * std::log(rare);
    }
    // Sub-forms that are alternatives (Effect::alternative_forms) may also go as a whole: a
    // block's rise is z_B^T cov_BB^-1 z_B, its price the sum of its terms'.
    // Its terms need not be optional one by one; one alternative of each effect always stays.
    std::vector<std::vector<int>> blocks;
    std::vector<size_t> block_effect;
    for (size_t ei = 0; ei < model.effects().size(); ++ei) {
      const Effect& eff = *model.effects()[ei];
      if (!eff.alternative_forms()) continue;
      for (const auto& form : eff.sub_forms()) {
        std::vector<int> b;
        for (int k : form)
          if (!given[model.offset(static_cast<int>(ei)) + k])
            b.push_back(model.offset(static_cast<int>(ei)) + k);
        blocks.push_back(b);
        block_effect.push_back(ei);
      }
    }
    auto block_free = [&](size_t bi, const std::vector<int>& cur) {
      std::vector<int> at;  // positions in cur
      for (int k : blocks[bi]) {
        const auto it = std::find(cur.begin(), cur.end(), k);
        if (it != cur.end()) at.push_back(static_cast<int>(it - cur.begin()));
      }
      return at;
    };
    double rss = e.squaredNorm();  // only grows as terms are dropped
    if (!(rss > 0)) return;
    Eigen::VectorXd z(p);  // distance from the null value in typical magnitudes
    for (int k = 0; k < p; ++k) z(k) = (theta(k) - model.spec(k).null_value) / s.typical(k);
    bool dropped = false;
    while (cur.size() > 1) {
      const int nc = static_cast<int>(cur.size());
      Eigen::MatrixXd g(nc, nc);
      for (int a = 0; a < nc; ++a)
        for (int b = 0; b <= a; ++b) g(a, b) = g(b, a) = js.col(cur[a]).dot(js.col(cur[b]));
      const Eigen::VectorXd d = g.diagonal().cwiseSqrt().cwiseMax(1e-300).cwiseInverse();
      const Eigen::MatrixXd cov =
          d.asDiagonal() *
          (d.asDiagonal() * g * d.asDiagonal()).ldlt().solve(Eigen::MatrixXd::Identity(nc, nc)) *
          d.asDiagonal();
      int worst = -1;
      double rise = INFINITY, margin = INFINITY;  // margin: what the term pays beyond its price
      for (int a = 0; a < nc; ++a) {
        if (!optional(cur[a]) || !(cov(a, a) > 0)) continue;
        const double r = z(cur[a]) * z(cur[a]) / cov(a, a);  // RSS rise when it is dropped
        const double over = m * std::log1p(r / rss) - price(cur[a]);
        if (over < margin) {
          margin = over;
          rise = r;
          worst = a;
        }
      }
      // cov_BB^-1 z_B for the terms at positions `at` of cur (empty when cov_BB is singular).
      auto block_weights = [&](const std::vector<int>& at, Eigen::VectorXd* zb) {
        const int nb = static_cast<int>(at.size());
        Eigen::MatrixXd cbb(nb, nb);
        zb->resize(nb);
        for (int a = 0; a < nb; ++a) {
          (*zb)(a) = z(cur[at[a]]);
          for (int c = 0; c < nb; ++c) cbb(a, c) = cov(at[a], at[c]);
        }
        const Eigen::LDLT<Eigen::MatrixXd> f(cbb);
        if (f.info() != Eigen::Success || !(f.vectorD().minCoeff() > 0)) return Eigen::VectorXd();
        return Eigen::VectorXd(f.solve(*zb));
      };
      std::vector<int> best_block;
      for (size_t bi = 0; bi < blocks.size(); ++bi) {
        const std::vector<int> at = block_free(bi, cur);
        // A sub-form with two or more terms still free, beside another of its effect.
        bool other = false;
        for (size_t bj = 0; bj < blocks.size(); ++bj)
          other = other || (bj != bi && block_effect[bj] == block_effect[bi] &&
                            !block_free(bj, cur).empty());
        if (!other || at.size() < 2) continue;
        Eigen::VectorXd zb;
        const Eigen::VectorXd w = block_weights(at, &zb);
        if (w.size() == 0) continue;
        double cost = 0.0;
        for (int a : at) cost += price(cur[a]);
        const double r = zb.dot(w);
        const double over = m * std::log1p(r / rss) - cost;
        if (over < margin) {
          margin = over;
          rise = r;
          best_block = at;
        }
      }
      if (margin >= 0 || (worst < 0 && best_block.empty())) break;
      std::vector<int> gone = best_block;  // positions in cur
      if (gone.empty()) gone = {worst};
      {
        // The other terms follow the removal: z_rest -= cov_rB cov_BB^-1 z_B.
        Eigen::VectorXd zb;
        const Eigen::VectorXd w = block_weights(gone, &zb);
        for (int a = 0; a < nc; ++a) {
          if (std::find(gone.begin(), gone.end(), a) != gone.end()) continue;
          for (int c = 0; c < static_cast<int>(w.size()); ++c) z(cur[a]) -= cov(a, gone[c]) * w(c);
        }
      }
      double cost = 0.0;
      for (int g : gone) cost += price(cur[g]);
      for (int g : gone) {
        const int k = cur[g];
        z(k) = 0.0;
        idf.fixed[k] = true;
        idf.statistical[k] = true;
        idf.reason[k] =
            std::string(gone.size() > 1 ? "the data do not support this alternative form of "
                                          "its effect: its terms lower"
                                        : "the data do not support this optional term: it "
                                          "lowers") +
            " the residual sum of squares by " + num(100.0 * rise / (rss + rise)) +
            " %, less than the Bayesian information criterion asks of " +
            (gone.size() > 1 ? std::to_string(gone.size()) + " more parameters ("
                             : std::string("one more parameter (")) +
            num(100.0 * (1.0 - std::exp(-cost / m))) + " %)";
        left_out[k] = true;
      }
      rss += rise;
      std::sort(gone.begin(), gone.end(), std::greater<int>());
      for (int g : gone) cur.erase(cur.begin() + g);
      dropped = true;
    }
    if (dropped) resolve_free("is left after the optional terms the data do not support");
  };
  auto fit_passes = [&]() {
    // theta as the solver will see it, (theta / typical) * typical, so that the Jacobian of
    // this check is the one of the solver's first iteration (Evaluations cache).
    for (int k = 0; k < p; ++k) theta(k) = theta(k) / s.typical(k) * s.typical(k);
    {
      const Eigen::MatrixXd jac = weighted_jacobian(s, theta);
      const Eigen::MatrixXd gram = gram_of(jac);  // for both tests below
      idf = check(jac, theta, &gram);
      if (absolute && opt.max_relative_se > 0) prescreen(jac, gram, idf);
    }
    for (int pass = 0;; ++pass) {
      free.clear();
      for (int k = 0; k < p; ++k) {
        if (!idf.fixed[k])
          free.push_back(k);
        else if (!given[k])  // a given parameter keeps the start fit's value
          theta(k) = std::min(std::max(model.spec(k).null_value, model.spec(k).lower),
                              model.spec(k).upper);
      }
      if (free.empty())
        throw NumericalError("identify: no parameter of model '" + model.model_string() +
                             "' is identifiable from this data (are there loads?)");
      if (components <= static_cast<int>(free.size()))
        throw InvalidArgument("identify: " + std::to_string(n) + " measurements give " +
                              std::to_string(components) + " equations for " +
                              std::to_string(free.size()) + " parameters; at least " +
                              std::to_string(free.size() / 3 + 1) + " measurements are needed");
      // Watch for a held parameter becoming identifiable while solving (not in the last pass,
      // which must converge); cheap when the cached Jacobians hold every column.
      const Visible visible = [&](const Eigen::VectorXd& t) {
        if (model.linear() || (p + kJetStride - 1) / kJetStride >
                                  (static_cast<int>(free.size()) + kJetStride - 1) / kJetStride)
          return false;  // a constant Jacobian, or columns the cache does not hold
        if (!held_has_effect(s, t, idf.fixed)) return false;
        const Identifiability a = check(weighted_jacobian(s, t), t);
        for (int k = 0; k < p; ++k)
          if (idf.fixed[k] && !a.fixed[k]) return true;
        return false;
      };
      // The identifiable set of a geometric calibration is decided at the start, where the
      // model is linearised (prescreen): a combination of parameters stays a combination to
      // first order, and a member that the solution's curvature makes faintly visible is
      // determined by nothing but that curvature. Loads are different: a point offset found
      // by the solve can make a compliance visible, so a displacement fit watches for it.
      const bool watch = !absolute && pass < 2;
      last = solve(s, free, theta, *solving, loss_scale, watch ? &visible : nullptr);
      iterations += last.iterations;
      keep_last_jacobian();
      if (absolute) break;  // its set stays the start's (below): no structural re-check
      Identifiability again = check(last_jacobian, theta, &last_gram);
      if (again == idf || pass == 2) break;
      // A parameter held so far became visible (or the reverse): solve again from here, a
      // freed parameter from the value it was held at (theta unchanged: the Jacobians cached
      // at this point serve the next solve's first iteration).
      idf = again;
    }
    // The statistical test, once, at the solution of the structurally identifiable model;
    // what it holds goes back to its null value and the rest is solved once more.
    residual_sigma = robust_residual_sigma();
    // On absolute data the set decided at the start stays: a held column judged again at the
    // solution, where the curvature breaks its exact dependencies by a hair, would only blur
    // its partners.
    const Identifiability stat =
        absolute ? apart(last_jacobian, &last_gram, idf,
                         [&](const Eigen::MatrixXd& j, const Eigen::MatrixXd* g) {
                           return check(j, theta, g);
                         })
                 : check(last_jacobian, theta, &last_gram);
    residual_sigma = 0.0;
    if (!(absolute ? stat == idf
                   : std::find(stat.statistical.begin(), stat.statistical.end(), true) ==
                         stat.statistical.end())) {
      idf = stat;
      resolve_free("is determined by this data");
    }
    select_terms();
  };
  // A redescending loss (Tukey) has many local minima and gives zero weight beyond its scale:
  // from the least-squares start, whose residuals carry the outliers' pull, it can stop where it
  // started with every row rejected. Start it from the Huber fit (convex: one minimum).
  auto fit_from_start = [&]() {
    if (opt.loss == "tukey") {
      IdentifyOptions huber = opt;
      huber.loss = "huber";
      const Eigen::VectorXd tukey_scale = loss_scale;
      loss_scale *= 1.345 / 4.685;
      solving = &huber;
      fit_passes();
      solving = &opt;
      loss_scale = tukey_scale;
    }
    fit_passes();
  };
  fit_from_start();
  // Without a stated noise the robust scale comes from the residuals; the start's residuals
  // are inflated by the outliers' pull, so re-estimate it from the robust fit (MAD) and refit.
  double scale_used_m = scale_m;
  if (opt.loss != "none" && opt.loss_scale_m == 0 && stated == 0) {
    for (int round = 0; round < 3; ++round) {
      const Eigen::VectorXd e = weighted_residuals(s, theta) * noise;  // metres
      std::vector<double> position;  // the noise scale is the positions' (as at the start)
      for (int r = 0; r < n; ++r)
        for (int k = 0; k < 3; ++k) position.push_back(e(dim * r + k));
      const double sigma = robust::mad_sigma(position);
      if (!(sigma > 0) || std::abs(c_sigma * sigma - scale_used_m) < 0.05 * scale_used_m) break;
      scale_used_m = c_sigma * sigma;
      for (int r = 0; r < n; ++r)
        loss_scale(r) = scale_used_m * s.row_weight(r) * std::sqrt(s.components(r) / 3.0);
      fit_passes();
    }
  }
  // The model's error as a variance component of its own (Paule & Mandel 1982; Rukhin, Biggerstaff
  // & Vangel 2000): a tracker states each row's noise, but on a real arm the model's errors are
  // tens of times larger and do not shrink where the instrument happened to be more precise.
  // Weighting by the stated sigma alone lets the few rows with the smallest stated sigma decide
  // the fit (the registration of a new placement from 15 poses then followed 2-3 of them). Each
  // absolute row's variance is therefore sigma_r^2 + s^2, one s^2 per group (positions,
  // orientations with a stated sigma_o), the smallest s^2 >= 0 at which the group's weighted
  // squares match its redundancy, and the fit is made again from its start. Where the stated
  // noise explains the residuals, s = 0 and the weights are the stated ones.
  double excess_p2 = 0, excess_o2 = 0;
  if (weighted && absolute) {
    const double share = 1.0 - static_cast<double>(free.size()) / std::max(1, components);
    // Smallest s2 >= 0 with sum_r w_r u_r^2 / (v_r + s2) <= red (the left side falls with s2).
    auto excess = [](const std::vector<double>& u2, const std::vector<double>& v,
                     const std::vector<double>& w, double red) {
      auto lhs = [&](double s2) {
        double t = 0;
        for (size_t i = 0; i < u2.size(); ++i) t += w[i] * u2[i] / (v[i] + s2);
        return t;
      };
      if (!(red > 0) || lhs(0.0) <= red) return 0.0;
      double lo = 0, hi = 0;
      for (size_t i = 0; i < u2.size(); ++i) hi += w[i] * u2[i];
      hi /= red;  // every term <= w u2 / hi, so the sum <= red
      for (int it = 0; it < 100 && hi - lo > 1e-9 * hi; ++it) {
        const double mid = 0.5 * (lo + hi);
        (lhs(mid) > red ? lo : hi) = mid;
      }
      return hi;
    };
    for (int round = 0; round < 4; ++round) {
      const Eigen::VectorXd e = weighted_residuals(s, theta);
      std::vector<double> up, vp, wp, uo, vo, wo;
      for (int r = 0; r < n; ++r) {
        if (!data.rows[r].absolute) continue;
        const double w = robust_weight(e, r);
        const double sp = data.rows[r].sigma();
        up.push_back((e.segment<3>(dim * r) / s.row_weight(r)).squaredNorm() / 3.0);
        vp.push_back(sp * sp);
        wp.push_back(3.0 * w);
        if (weighted_o && s.orient_weight(r) > 0) {
          const double so = data.rows[r].sigma_o;
          uo.push_back((e.segment<3>(dim * r + 3) / s.orient_weight(r)).squaredNorm() / 3.0);
          vo.push_back(so * so);
          wo.push_back(3.0 * w);
        }
      }
      const double sp2 = excess(up, vp, wp, share * std::accumulate(wp.begin(), wp.end(), 0.0));
      const double so2 =
          uo.empty() ? 0.0 : excess(uo, vo, wo, share * std::accumulate(wo.begin(), wo.end(), 0.0));
      // Refit only when a weight moves by more than 5 % (then from the start, as below).
      double change = 0;
      Eigen::VectorXd rw = s.row_weight, ow = s.orient_weight;
      for (int r = 0; r < n; ++r) {
        if (!data.rows[r].absolute) continue;
        const double sp = data.rows[r].sigma();
        rw(r) = 1.0 / std::sqrt(sp * sp + sp2);
        if (ow(r) > 0)
          ow(r) = weighted_o ? 1.0 / std::sqrt(std::pow(data.rows[r].sigma_o, 2) + so2)
                             : s.orient_weight(r) / s.row_weight(r) * rw(r);
        change = std::max(change, std::abs(rw(r) / s.row_weight(r) - 1.0));
        if (ow(r) > 0) change = std::max(change, std::abs(ow(r) / s.orient_weight(r) - 1.0));
      }
      excess_p2 = sp2;
      excess_o2 = so2;
      if (change < 0.05) break;
      s.row_weight = rw;
      s.orient_weight = ow;
      theta = theta_start;
      fit_from_start();
    }
  }
  // The orientation weight as a variance component (Helmert; Koch, Parameter Estimation and
  // Hypothesis Testing in Linear Models, 1999, ch. 3.6): the position and the orientation
  // residuals are two groups whose scales the data estimate. Where the model's errors, not the
  // instrument's noise, make the residuals, a stated sigma_o or a fixed length weighs one group
  // against the other by a ratio the residuals do not have, and the fit trades orientation for
  // position (or the reverse) in the directions both see, e.g. the registration's rotation on
  // a small set of poses. The orientation weights are scaled until both groups' weighted mean
  // squares agree (to 5 %), each time fitted again from the start (so that the identifiable set
  // is decided, as in any fit, on the linearised start with the final weights); the
  // redundancy of each group is taken as its count (first order in parameters / residuals),
  // rows a robust loss down-weights count that much.
  if (dim == 6 && estimate_o) {
    for (int round = 0; round < 4; ++round) {
      const Eigen::VectorXd e = weighted_residuals(s, theta);
      double sp = 0, np = 0, so = 0, no = 0;
      for (int r = 0; r < n; ++r) {
        const double w = robust_weight(e, r);
        sp += w * e.segment<3>(dim * r).squaredNorm();
        np += 3.0 * w;
        if (s.orient_weight(r) > 0) {
          so += w * e.segment<3>(dim * r + 3).squaredNorm();
          no += 3.0 * w;
        }
      }
      const double kappa = std::sqrt((sp / np) / (so / no));
      if (!std::isfinite(kappa) || !(kappa > 0) || std::abs(kappa - 1.0) < 0.05) break;
      s.orient_weight *= kappa;
      theta = theta_start;
      fit_from_start();
    }
  }
  for (int k = 0; k < p; ++k)
    theta(k) = std::min(std::max(theta(k), model.spec(k).lower), model.spec(k).upper);

  // ---- statistics at the solution.
  const Eigen::VectorXd e = weighted_residuals(s, theta);
  f.weights = Eigen::VectorXd::Ones(n);
  for (int r = 0; r < n; ++r) f.weights(r) = robust_weight(e, r);
  const int nf = static_cast<int>(free.size());
  // The Jacobian of the last identifiability check is the one at the solution unless the
  // clamping above moved theta.
  const bool at_last = last_jacobian_theta.size() == theta.size() && last_jacobian_theta == theta;
  const Eigen::MatrixXd jall = at_last ? std::move(last_jacobian) : weighted_jacobian(s, theta);
  // Residual variance of the (robustly) weighted problem: sum w^2 |e|^2 / (sum 3 w - p), which
  // is the usual RSS / (3N - p) without a loss and bounded for down-weighted rows.
  double wsum = 0, wrss = 0;
  for (int r = 0; r < n; ++r) {
    const double w = f.weights(r);
    wsum += s.components(r) * w;
    wrss += w * w * e.segment(dim * r, dim).squaredNorm();
  }
  const double s2 = wsum > nf ? wrss / (wsum - nf) : NAN;
  // The free columns, rows scaled by the root of their robust weight, and normalised (js):
  // their Gram matrix from the solution's J^T J when no row is down-weighted, the tall js
  // itself only when needed.
  const bool from_gram = at_last && (f.weights.array() == 1.0).all();
  Eigen::VectorXd norms(nf);
  Eigen::MatrixXd gf(nf, nf);
  if (from_gram) {
    for (int a = 0; a < nf; ++a)
      for (int b = 0; b < nf; ++b) gf(a, b) = last_gram(free[a], free[b]);
    norms = gf.diagonal().cwiseSqrt();
  }
  Eigen::MatrixXd js;
  auto tall = [&]() {
    Eigen::MatrixXd jf(dim * n, nf);
    for (int i = 0; i < nf; ++i) jf.col(i) = jall.col(free[i]);
    for (int r = 0; r < n; ++r) jf.middleRows(dim * r, dim) *= std::sqrt(f.weights(r));
    if (!from_gram) norms = jf.colwise().norm().transpose();
    for (int i = 0; i < nf; ++i)
      if (!(norms(i) > 0)) norms(i) = 1.0;
    js = jf * norms.cwiseInverse().asDiagonal();
  };
  if (from_gram) {
    for (int i = 0; i < nf; ++i)
      if (!(norms(i) > 0)) norms(i) = 1.0;
  } else {
    tall();
  }
  // Singular values and V of the tall js: from the eigen-decomposition of js^T js when it is
  // well conditioned (cond(js) < 1e5, far from the rank threshold below and within the
  // normal equations' accuracy), else from its QR: js = Q R, R = U S V^T.
  Eigen::VectorXd sv;
  Eigen::MatrixXd v;
  {
    Eigen::MatrixXd gs = Eigen::MatrixXd::Zero(nf, nf);
    if (from_gram)
      gs = norms.cwiseInverse().asDiagonal() * gf * norms.cwiseInverse().asDiagonal();
    else
      gs.selfadjointView<Eigen::Lower>().rankUpdate(js.transpose());
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(gs, Eigen::ComputeEigenvectors);
    const Eigen::VectorXd lam = es.eigenvalues();  // ascending
    if (nf > 0 && jall.rows() >= nf && lam(0) > 1e-10 * lam(nf - 1)) {
      sv = lam.reverse().cwiseSqrt();
      v = es.eigenvectors().rowwise().reverse();
    }
  }
  if (sv.size() == 0) {
    if (js.size() == 0) tall();
    Eigen::MatrixXd rs = Eigen::MatrixXd::Zero(nf, nf);
    if (js.rows() >= nf) {
      Eigen::HouseholderQR<Eigen::MatrixXd> qr(js);
      rs = qr.matrixQR().topRows(nf).triangularView<Eigen::Upper>();
    } else {
      rs = js;
    }
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(rs, Eigen::ComputeThinV);
    sv = svd.singularValues();
    v = svd.matrixV();
  }
  int rank = 0;
  for (int i = 0; i < sv.size(); ++i)
    if (sv(i) > 1e-12 * sv(0)) ++rank;
  Eigen::VectorXd inv_sv2 = Eigen::VectorXd::Zero(sv.size());
  for (int i = 0; i < rank; ++i) inv_sv2(i) = 1.0 / (sv(i) * sv(i));
  const Eigen::MatrixXd cov_s = v * inv_sv2.asDiagonal() * v.transpose();

  // A fit that identified nothing, or a robust fit that rejected most of the data, is a failure:
  // its parameters are the start, not an estimate (an M-estimator breaks down beyond half).
  if (rank == 0)
    throw NumericalError(
        "identify: the fit identified no parameter (the Jacobian at the "
        "solution has rank 0); check the loads and the units");
  if (opt.loss != "none") {
    int rejected = 0;
    for (int r = 0; r < n; ++r) rejected += f.weights(r) < opt.outlier_weight;
    if (2 * rejected > n)
      throw NumericalError("identify: the " + opt.loss + " loss rejected " +
                           std::to_string(rejected) + " of " + std::to_string(n) +
                           " measurements; a robust fit needs most rows to be good (check the "
                           "units, or give --loss-scale-um)");
  }
  f.robot_name = robot.name;
  f.robot_digest = kinematics_digest(robot);
  f.robot_path = robot.source_path;
  f.model = model.effect_names();
  if (data.has_session) f.sessions = model.session_labels();
  f.method = "ceres";
  f.loss = opt.loss;
  f.loss_scale_m = opt.loss == "none" ? 0.0 : scale_used_m;
  f.measurements = n;
  f.rank = rank;
  f.dof = components - rank;
  f.condition_number = rank > 0 ? sv(0) / sv(rank - 1) : INFINITY;
  f.covariance = Eigen::MatrixXd::Constant(p, p, NAN);
  for (int a = 0; a < nf; ++a)
    for (int b = 0; b < nf; ++b)
      f.covariance(free[a], free[b]) = s2 * cov_s(a, b) / (norms(a) * norms(b));
  std::vector<bool> reported(p, false);  // folded into an earlier warning line
  // A parameter's value with its unit, a dimensionless one ("1") bare.
  auto value_of = [&](int k) {
    const std::string& unit = model.spec(k).unit;
    return num(theta(k)) + (unit == "1" ? std::string() : " " + unit);
  };
  for (int k = 0; k < p; ++k) {
    const auto& sp = model.spec(k);
    FitParameter fp;
    fp.effect = model.owner(k).name();
    fp.name = sp.name;
    fp.unit = sp.unit;
    fp.meaning = sp.meaning;
    fp.value = theta(k);
    fp.identified = !idf.fixed[k];
    fp.standard_error = fp.identified ? std::sqrt(f.covariance(k, k)) : NAN;
    if (given[k]) {  // kept as the start fit has it
      const FitParameter& q = opt.start->parameters[from_start[k]];
      fp.identified = q.identified;
      fp.held = q.held;
      fp.standard_error = q.standard_error;
      f.covariance(k, k) = q.standard_error * q.standard_error;
      f.parameters.push_back(fp);
      continue;
    }
    if (!fp.identified)
      fp.held = sp.spread || sp.from_data ? "decided" : left_out[k] ? "left_out" : "undetermined";
    f.parameters.push_back(fp);
    if (!fp.identified && sp.spread) {
      // A block of spread values (backlash's mass covariance): one line for the block.
      if (k > 0 && model.spec(k - 1).spread) continue;
      int block_end = k;
      while (block_end + 1 < model.parameter_count() && model.spec(block_end + 1).spread)
        ++block_end;
      f.warnings.push_back(qualified(model, k) + " to " + qualified(model, block_end) +
                           " are decided from the data, not fitted: what the data leave open, "
                           "which spreads the prediction of new poses");
    } else if (!fp.identified && sp.from_data) {
      // Decided by the effect from the data before the fit (no derivative): not a failure.
      f.warnings.push_back(qualified(model, k) +
                           " is decided from the data, not fitted: " + value_of(k) +
                           (std::isfinite(sp.confidence_lower) && std::isfinite(sp.confidence_upper)
                                ? " (the data do not exclude " + num(sp.confidence_lower) + " to " +
                                      num(sp.confidence_upper) + ")"
                                : std::string()));
    } else if (!fp.identified && (left_out[k] || reported[k])) {
      // A sub-form left out whole (an alternative frame of force_frame): one line for its
      // terms, which share the reason, and for the terms of that sub-form held before the
      // selection (the frame's gauge gain), which mean nothing without it.
      if (reported[k]) continue;
      std::vector<int> members{k};
      const Effect& e = model.owner(k);
      for (int j = k + 1; j < p; ++j)
        if (left_out[j] && &model.owner(j) == &e && idf.reason[j] == idf.reason[k])
          members.push_back(j);
      if (members.size() > 1 && e.alternative_forms()) {
        const int first = model.offset(model.find(e.name()));
        for (const std::vector<int>& form : e.sub_forms()) {
          if (std::find(form.begin(), form.end(), k - first) == form.end()) continue;
          for (const int local : form) {
            const int j = first + local;
            if (j > k && idf.fixed[j] && !left_out[j] && !model.spec(j).from_data)
              members.push_back(j);
          }
        }
        std::sort(members.begin(), members.end());
      }
      // "a, b and c are left out, with d": the terms the selection dropped, then those held before.
      auto list = [&](bool dropped) {
        std::vector<std::string> n;
        for (const int j : members)
          if (left_out[j] == dropped)
            n.push_back(j == k ? qualified(model, j) : model.spec(j).name);
        std::string out;
        for (size_t i = 0; i < n.size(); ++i)
          out += (i == 0 ? "" : i + 1 == n.size() ? " and " : ", ") + n[i];
        return out;
      };
      bool zero = true;
      for (const int j : members) {
        reported[j] = true;
        zero = zero && theta(j) == 0.0;
      }
      const std::string with = list(false);
      const bool one = members.size() == 1;
      const std::string held = one    ? value_of(k)
                               : zero ? std::string("0")
                                      : std::string("their values without the effect");
      const bool several =
          std::count_if(members.begin(), members.end(), [&](int j) { return left_out[j]; }) > 1;
      f.warnings.push_back(list(true) + (several ? " are" : " is") + " left out" +
                           (with.empty() ? "" : ", with " + with) + ": " + idf.reason[k] +
                           "; held at " + held);
    } else if (!fp.identified) {
      f.warnings.push_back(qualified(model, k) + " is not identifiable from this data: " +
                           idf.reason[k] + "; held at " + value_of(k));
    } else if (sp.lower > -1e299 && sp.lower != sp.null_value &&
               theta(k) <= sp.lower + 1e-9 * s.typical(k)) {
      f.warnings.push_back(qualified(model, k) + " ended at its lower bound " + num(sp.lower) +
                           " " + sp.unit + "; its standard error is not meaningful");
    } else if (sp.upper < 1e299 && theta(k) >= sp.upper - 1e-9 * s.typical(k)) {
      f.warnings.push_back(qualified(model, k) + " ended at its upper bound " + num(sp.upper) +
                           " " + sp.unit + "; its standard error is not meaningful");
    }
  }
  if (rank < nf)
    f.warnings.push_back("the Jacobian at the solution has rank " + std::to_string(rank) + " < " +
                         std::to_string(nf) +
                         " free parameters; some standard errors are not "
                         "meaningful");
  if (!last.converged)
    f.warnings.push_back("the solver stopped before convergence after " +
                         std::to_string(iterations) + " iterations: " + last.message);

  f.residuals.resize(3 * n);
  for (int r = 0; r < n; ++r)
    f.residuals.segment<3>(3 * r) = e.segment<3>(dim * r) / s.row_weight(r);
  f.rms_m = std::sqrt(f.residuals.squaredNorm() / (3 * n));
  if (dim == 6) {
    f.oriented_rows = oriented;
    f.orientation_residuals = Eigen::VectorXd::Constant(3 * n, NAN);
    double sq = 0, sum = 0, worst = 0;
    for (int r = 0; r < n; ++r) {
      if (!(s.orient_weight(r) > 0)) continue;
      const Eigen::Vector3d o = e.segment<3>(dim * r + 3) / s.orient_weight(r);
      f.orientation_residuals.segment<3>(3 * r) = o;
      sq += o.squaredNorm();
      sum += o.norm();
      worst = std::max(worst, o.norm());
    }
    f.orientation_rms_rad = std::sqrt(sq / (3.0 * oriented));
    f.orientation_mean_rad = sum / oriented;
    f.orientation_max_rad = worst;
    std::vector<double> length;
    for (int r = 0; r < n; ++r)
      if (s.orient_weight(r) > 0) length.push_back(s.orient_weight(r) / s.row_weight(r));
    f.orientation_length_m = robust::median(length);
  }
  f.noise_floor_m = stated;
  f.model_error_m = std::sqrt(excess_p2);
  f.model_error_rad = std::sqrt(excess_o2);
  // Metres per residual unit (typical): the stated noise, with the model's error when estimated.
  const double resid_scale = weighted ? std::sqrt(stated * stated + excess_p2) : noise;
  f.sigma_hat_m = std::sqrt(std::max(0.0, s2)) * resid_scale;
  if (weighted) {
    // Against the stated noise alone (the model's error is what chi2 measures).
    f.chi2 = 0;
    for (int r = 0; r < n; ++r) {
      const double ws = 1.0 / data.rows[r].sigma();  // the stated position weight
      f.chi2 += e.segment<3>(dim * r).squaredNorm() * std::pow(ws / s.row_weight(r), 2);
      if (dim == 6 && s.orient_weight(r) > 0) {
        const double wo =
            weighted_o ? 1.0 / data.rows[r].sigma_o : s.orient_weight(r) / s.row_weight(r) * ws;
        f.chi2 += e.segment<3>(dim * r + 3).squaredNorm() * std::pow(wo / s.orient_weight(r), 2);
      }
    }
  } else if (stated > 0)
    f.chi2 = f.residuals.squaredNorm() / (stated * stated);

  // ---- outliers: rows inconsistent with the rest. Least squares judges them against the
  // residual's robust scale at the solution (MAD of the weighted components), never below a
  // stated noise: when the model does not reach the stated noise, most rows exceed a few of its
  // sigmas, and that is a missing effect or an understated noise, not outliers.
  const bool stated_unit = weighted || stated > 0;
  std::vector<double> carried;  // the components that carry data (not a missing orientation)
  for (int r = 0; r < n; ++r)
    for (int k = 0; k < s.components(r); ++k) carried.push_back(e(dim * r + k));
  const double bulk = robust::mad_sigma(carried);
  const double unit_scale = stated_unit ? std::max(1.0, bulk) : (bulk > 0 ? bulk : 1.0);
  if (stated_unit && 3 * n >= 30 && bulk > 2.0)
    f.warnings.push_back(
        "the residuals are " + num(bulk, 3) + " times the stated noise (robust scale of " +
        std::to_string(n) + " rows): the model misses an effect (stiff diagnose) or the stated " +
        "sigma is too small; outliers are judged against the residuals' own scale");
  // The unit of the norms below: the stated sigma, unless least squares counts in the
  // residuals' own scale (or there is no stated noise).
  const double unit_used = opt.loss == "none" ? unit_scale : 1.0;
  const std::string unit = stated_unit && unit_used == 1.0 ? " sigma" : " robust sigma";
  for (int r = 0; r < n; ++r) {
    Outlier o;
    o.row = r;
    o.id = data.rows[r].id;
    o.residual_m = f.residuals.segment<3>(3 * r).norm();
    o.weight = f.weights(r);
    const double norm_sigma = e.segment(dim * r, dim).norm() / unit_used;
    // A row with orientation has 6 components: its clean norm is sqrt(2) larger.
    const double limit = 5.0 * std::sqrt(s.components(r) / 3.0);
    if (opt.loss != "none") {
      if (o.weight >= opt.outlier_weight) continue;
      o.reason = "robust weight " + num(o.weight, 2) + " < " + num(opt.outlier_weight, 2) +
                 ": residual " + num(o.residual_m * 1e6) + " um = " + num(norm_sigma) + unit +
                 " (clean rows stay below ~3.4)";
    } else {
      if (norm_sigma <= limit) continue;
      o.reason = "residual " + num(o.residual_m * 1e6) + " um = " + num(norm_sigma) + unit +
                 " (> " + num(limit, 2) +
                 "); least squares does not down-weight it: use a robust loss";
    }
    f.outliers.push_back(o);
  }
  if (!f.outliers.empty())
    f.warnings.push_back(std::to_string(f.outliers.size()) + " of " + std::to_string(n) +
                         " measurements look like outliers (see the outlier list)");
  return f;
}

}  // namespace

FitResult identify(const RobotModel& robot,
                   const Dataset& data,
                   const std::vector<std::string>& effects,
                   const IdentifyOptions& opt) {
  FitResult fit = identify_at(robot, data, effects, opt, nullptr);
  // An effect that decides parameters from the data (backlash's link masses, by the sign of
  // each joint's preload plus load torque) decided them with the model's other effects at
  // their start values. An effect that moves the points or the wrench (a point offset, a
  // force-sensor frame) then fitted changes the lever arms and load torques those decisions
  // rest on: a few centimetres of SMR offset turn the wrist joints' load torques. So the
  // decision is taken again at the fit and the model refitted from it, until the parameters
  // that move the points and the wrench change by less than 3 % of their typical size (a
  // millimetre of point offset), at most kRedecide times. Not for a refit from a given start
  // (its decisions are the caller's).
  constexpr int kRedecide = 2;
  if (opt.start || !opt.refit.empty()) return fit;
  // Built as identify_at built it (the search's result is cached): the fit's parameter order.
  const DeflectionModel bare(robot, effects, &data);
  std::vector<int> moving;  // parameters of effects with a wrench stage
  bool decides = false;
  for (size_t e = 0; e < bare.effects().size(); ++e) {
    const Effect& eff = *bare.effects()[e];
    for (int k = 0; k < eff.size(); ++k) {
      decides = decides || eff.parameters()[k].from_data;
      if (eff.stages() & kWrenchStage) moving.push_back(bare.offset(static_cast<int>(e)) + k);
    }
  }
  if (!decides || moving.empty() ||
      static_cast<int>(fit.parameters.size()) != bare.parameter_count())
    return fit;
  Eigen::VectorXd at = bare.start_parameters();
  for (int pass = 0; pass < kRedecide; ++pass) {
    double moved = 0;
    for (int k : moving)
      moved = std::max(moved, std::abs(fit.parameters[k].value - at(k)) /
                                  std::max(std::abs(bare.spec(k).typical), 1e-300));
    if (!(moved > 0.03)) break;
    const std::map<std::string, double> values = fit.values();
    for (int k : moving) at(k) = fit.parameters[k].value;
    // The refit starts from the fit, but for what the new decision gives.
    FitResult start = fit;
    start.parameters.clear();
    for (int k = 0; k < bare.parameter_count(); ++k)
      if (!bare.spec(k).from_data) start.parameters.push_back(fit.parameters[k]);
    IdentifyOptions o = opt;
    o.start = &start;
    try {
      fit = identify_at(robot, data, effects, o, &values);
    } catch (const NumericalError& e) {
      // The fit with the first decision stands; say why it was not taken again.
      fit.warnings.push_back(std::string("the decisions of the effects that decide from the "
                                         "data were not taken again at the fit: ") +
                             e.what());
      break;
    }
  }
  return fit;
}

}  // namespace stiff
