// Model diagnosis: goodness of fit, residual structure, group score / partial-F tests of the
// candidate effects, verdict and the forward-stepwise loop (diagnose.hpp, docs/diagnosis.md).
#include "stiff/diagnose/diagnose.hpp"

#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>

#include "diagnose/noise.hpp"
#include "diagnose/text.hpp"
#include "identify/robust.hpp"
#include "stiff/error.hpp"
#include "stiff/identify/fit.hpp"
#include "stiff/identify/identify.hpp"
#include "stiff/model/model.hpp"

namespace stiff {
namespace {

using diagnose_detail::join;
using diagnose_detail::Noise;
using diagnose_detail::noise_of;
using diagnose_detail::num;
using diagnose_detail::um;
using Eigen::MatrixXd;
using Eigen::VectorXd;

/// Orthonormal basis of the column space of `a` (columns scaled to unit norm first); columns
/// whose relative singular value is below `tol` are dropped. `v_null` (optional) receives the
/// right singular vectors of the dropped directions.
MatrixXd orthonormal_basis(const MatrixXd& a,
                           double tol,
                           VectorXd* sv = nullptr,
                           MatrixXd* v_null = nullptr,
                           double scale_ref = 0.0) {
  if (a.cols() == 0) return MatrixXd(a.rows(), 0);
  Eigen::JacobiSVD<MatrixXd> svd(a, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const VectorXd s = svd.singularValues();
  const double ref = scale_ref > 0 ? scale_ref : (s.size() ? s(0) : 0.0);
  int rank = 0;
  for (int i = 0; i < s.size(); ++i)
    if (s(i) > tol * ref) ++rank;
  if (sv) *sv = s;
  if (v_null) *v_null = svd.matrixV().rightCols(s.size() - rank);
  return svd.matrixU().leftCols(rank);
}

/// A fitted model on the calibration rows that are not outliers, with everything the tests need.
struct Analysis {
  std::vector<std::string> effects;
  Dataset used;                ///< inlier rows (times kept)
  std::vector<int> used_rows;  ///< their index in the calibration data
  std::vector<bool> outlier;   ///< per calibration row
  std::unique_ptr<DeflectionModel> model;
  std::vector<MeasurementContext> ctx;  ///< of `used`
  VectorXd theta;
  std::vector<bool> identified;
  VectorXd w;         ///< 1/sigma per used row
  MatrixXd qx;        ///< orthonormal basis of the weighted Jacobian (3n x p)
  VectorXd r;         ///< weighted residual of the used rows (3n)
  MatrixXd pred_all;  ///< predicted d of every calibration row (N x 3)
  double rss = 0;     ///< ||r||^2
  int n = 0, p = 0;   ///< equations, rank
  ModelQuality quality;
  std::vector<std::string> warnings;
};

/// The calibration data with its time axis made explicit (row index when it has no `t`), so
/// that subsets keep each row's time.
Dataset with_explicit_time(const Dataset& d) {
  Dataset out = d;
  if (!d.has_time) {
    for (size_t r = 0; r < out.rows.size(); ++r) out.rows[r].time = static_cast<double>(r);
    out.has_time = true;
  }
  return out;
}

Dataset subset(const Dataset& d, const std::vector<int>& rows) {
  Dataset out = d;
  out.rows.clear();
  for (int r : rows) out.rows.push_back(d.rows[r]);
  return out;
}

/// Fit `effects` to `data` (linear least squares for the joint model, else Ceres).
FitResult fit_model(const RobotModel& robot,
                    const Dataset& data,
                    const std::vector<std::string>& effects) {
  if (effects.size() == 1 && effects[0] == "joint") return identify_joint_linear(robot, data);
  IdentifyOptions o;
  o.max_iterations = 100;
  return identify(robot, data, effects, o);
}

struct Context {
  const RobotModel* robot;
  const Dataset* calib;  ///< with explicit time
  const Dataset* validation;
  const Noise* noise;
  const Noise* vnoise;
  const DiagnosisOptions* opt;
  bool had_time = true;  ///< the calibration data has a `t` column
};

/// Rows improbable under the linear model y ~ M beta (weighted, 3 rows per measurement):
/// least squares on the rows not yet flagged, robust scale (MAD of the residual components,
/// never below 1 when the noise is stated), flag rows with P(chi2_3 > |r_i|^2/s^2) < alpha/N;
/// repeat until stable. More than N/5 flagged rows are structure, not outliers: none flagged.
std::vector<bool> improbable_rows(
    const MatrixXd& m, const VectorXd& y, double alpha, bool known, int* too_many) {
  const int rows = static_cast<int>(y.size() / 3);
  std::vector<bool> flag(rows, false);
  for (int round = 0; round < 4; ++round) {
    std::vector<int> in;
    for (int r = 0; r < rows; ++r)
      if (!flag[r]) in.push_back(r);
    MatrixXd ms(3 * in.size(), m.cols());
    VectorXd ys(3 * in.size());
    for (size_t i = 0; i < in.size(); ++i) {
      ms.middleRows(3 * i, 3) = m.middleRows(3 * in[i], 3);
      ys.segment<3>(3 * i) = y.segment<3>(3 * in[i]);
    }
    VectorXd beta = VectorXd::Zero(m.cols());
    if (m.cols() > 0) {
      VectorXd norms = ms.colwise().norm().transpose();
      for (int k = 0; k < norms.size(); ++k) norms(k) = norms(k) > 0 ? 1.0 / norms(k) : 0.0;
      Eigen::CompleteOrthogonalDecomposition<MatrixXd> cod(ms * norms.asDiagonal());
      cod.setThreshold(1e-8);
      beta = norms.asDiagonal() * cod.solve(ys);
    }
    const VectorXd res = y - m * beta;
    std::vector<double> comps;
    for (int r : in)
      for (int k = 0; k < 3; ++k) comps.push_back(res(3 * r + k));
    double scale = robust::mad_sigma(comps);
    if (known) scale = std::max(1.0, scale);
    if (!(scale > 0)) break;
    std::vector<bool> next(rows, false);
    int flagged = 0;
    for (int r = 0; r < rows; ++r)
      if (stats::log_chi2_sf(res.segment<3>(3 * r).squaredNorm() / (scale * scale), 3.0) <
          std::log(alpha / rows)) {
        next[r] = true;
        ++flagged;
      }
    if (flagged > rows / 5) {
      *too_many = std::max(*too_many, flagged);
      return std::vector<bool>(rows, false);
    }
    if (next == flag) break;
    flag = next;
  }
  return flag;
}

/// `fixed` (may be null): use these outlier flags instead of detecting them. Otherwise a row
/// is an outlier only when it is improbable under the current model AND under the current
/// model plus each candidate (linearised about the current fit): rows that an effect
/// explains are that effect's evidence, not outliers.
Analysis analyse(const Context& cx,
                 const std::vector<std::string>& effects,
                 const std::vector<bool>* fixed = nullptr,
                 const std::vector<std::string>& candidates = {}) {
  const Dataset& calib = *cx.calib;
  const int rows = static_cast<int>(calib.rows.size());
  const Noise& noise = *cx.noise;
  Analysis a;
  a.effects = effects;
  a.outlier.assign(rows, false);
  if (fixed) a.outlier = *fixed;
  FitResult fit;
  for (int round = 0; round < 2; ++round) {
    a.used_rows.clear();
    for (int r = 0; r < rows; ++r)
      if (!a.outlier[r]) a.used_rows.push_back(r);
    a.used = subset(calib, a.used_rows);
    fit = fit_model(*cx.robot, a.used, effects);
    a.model = std::make_unique<DeflectionModel>(*cx.robot, effects, &a.used);
    a.theta = fit.theta();
    const auto ctx_all = a.model->contexts(calib);
    a.pred_all.resize(rows, 3);
    VectorXd y(3 * rows);
    MatrixXd x(3 * rows, a.model->parameter_count());
    for (int r = 0; r < rows; ++r) {
      const Eigen::Vector3d d = a.model->predict(a.theta, calib.rows[r], ctx_all[r]).head<3>();
      a.pred_all.row(r) = d.transpose();
      y.segment<3>(3 * r) = (calib.rows[r].observed() - d) / noise.sigma(r);
      if (round == 0 && !fixed)
        x.middleRows(3 * r, 3) =
            a.model->displacement_jacobian(a.theta, calib.rows[r], ctx_all[r]) / noise.sigma(r);
    }
    if (round > 0 || fixed || !(cx.opt->outlier_alpha > 0)) break;
    int too_many = 0;
    std::vector<bool> flag = improbable_rows(x, y, cx.opt->outlier_alpha, noise.known, &too_many);
    for (const auto& name : candidates) {
      if (std::none_of(flag.begin(), flag.end(), [](bool b) { return b; })) break;
      std::vector<std::string> eff = effects;
      eff.push_back(name);
      std::unique_ptr<DeflectionModel> mg;
      try {
        mg = std::make_unique<DeflectionModel>(*cx.robot, eff, &calib);
      } catch (const InvalidArgument&) {
        continue;  // untestable here (no masses, no sessions)
      }
      const int pc = a.model->parameter_count(), pg = mg->parameter_count() - pc;
      VectorXd theta(mg->parameter_count());
      theta.head(pc) = a.theta;
      for (int k = 0; k < pg; ++k) theta(pc + k) = mg->spec(pc + k).null_value;
      const auto ctx = mg->contexts(calib);
      MatrixXd xz(3 * rows, pc + pg);
      xz.leftCols(pc) = x;
      for (int r = 0; r < rows; ++r)
        xz.block(3 * r, pc, 3, pg) =
            mg->displacement_jacobian(theta, calib.rows[r], ctx[r]).rightCols(pg) / noise.sigma(r);
      const std::vector<bool> fg =
          improbable_rows(xz, y, cx.opt->outlier_alpha, noise.known, &too_many);
      for (int r = 0; r < rows; ++r) flag[r] = flag[r] && fg[r];
    }
    if (too_many > 0)
      a.warnings.push_back(std::to_string(too_many) +
                           " measurements have improbably large residuals under some model: too "
                           "many to be outliers, kept (heavy tails: structure)");
    if (flag == a.outlier) break;
    a.outlier = flag;
  }
  for (const auto& w : fit.warnings)
    if (w.find("outlier") == std::string::npos) a.warnings.push_back(w);

  const int nu = static_cast<int>(a.used_rows.size());
  a.n = 3 * nu;
  a.ctx = a.model->contexts(a.used);
  a.identified.resize(fit.parameters.size());
  for (size_t k = 0; k < fit.parameters.size(); ++k) a.identified[k] = fit.parameters[k].identified;
  a.w.resize(nu);
  for (int i = 0; i < nu; ++i) a.w(i) = 1.0 / noise.sigma(a.used_rows[i]);
  // Weighted Jacobian of the identified parameters, and the weighted residual.
  const int pc = a.model->parameter_count();
  MatrixXd x(a.n, pc);
  a.r.resize(a.n);
  double ss_m = 0;
  for (int i = 0; i < nu; ++i) {
    const auto& m = a.used.rows[i];
    x.middleRows(3 * i, 3) = a.model->displacement_jacobian(a.theta, m, a.ctx[i]) * a.w(i);
    const Eigen::Vector3d e = m.observed() - a.pred_all.row(a.used_rows[i]).transpose();
    a.r.segment<3>(3 * i) = e * a.w(i);
    ss_m += e.squaredNorm();
  }
  std::vector<int> cols;
  for (int k = 0; k < pc; ++k)
    if (a.identified[k] && x.col(k).norm() > 0) cols.push_back(k);
  MatrixXd xs(a.n, cols.size());
  for (size_t i = 0; i < cols.size(); ++i) xs.col(i) = x.col(cols[i]) / x.col(cols[i]).norm();
  a.qx = orthonormal_basis(xs, 1e-8);
  a.p = static_cast<int>(a.qx.cols());
  // A nonlinear fit leaves r orthogonal to X only approximately: remove the rest so that the
  // tests see what the current model cannot absorb.
  a.r -= a.qx * (a.qx.transpose() * a.r);
  a.rss = a.r.squaredNorm();

  ModelQuality& q = a.quality;
  q.model = join(effects, "+");
  q.measurements = rows;
  q.used = nu;
  q.parameters = a.p;
  q.fit_rms_m = std::sqrt(ss_m / a.n);
  q.dof = a.n - a.p;
  q.chi2 = noise.known ? a.rss : 0.0;
  q.chi2_p = noise.known && q.dof > 0 ? stats::chi2_sf(a.rss, q.dof) : 1.0;
  q.sigma_hat_m = q.dof > 0 ? std::sqrt(a.rss / q.dof) * (noise.known ? noise.floor_m : 1.0) : 0.0;
  if (noise.known && q.dof > 0) {
    const double u = 1.0 + cx.opt->noise_uncertainty;
    q.residual_to_floor = std::sqrt(a.rss / q.dof);
    q.floor_p = stats::chi2_sf(a.rss / (u * u), q.dof);
  }
  for (int k = 0; k < pc; ++k) {
    q.parameter_names.push_back(a.model->owner(k).name() + "." + a.model->spec(k).name);
    q.parameter_values.push_back(a.theta(k));
  }
  if (cx.validation) {
    const Dataset& v = *cx.validation;
    const auto vctx = a.model->contexts(v);
    double ss = 0;
    for (size_t r = 0; r < v.rows.size(); ++r) {
      const Eigen::Vector3d e =
          v.rows[r].observed() - a.model->predict(a.theta, v.rows[r], vctx[r]).head<3>();
      q.validation_error_m.push_back(e.norm());
      ss += e.squaredNorm();
    }
    q.has_validation = true;
    q.validation_rms_m = std::sqrt(ss / (3.0 * v.rows.size()));
    const double vs = cx.vnoise->known ? cx.vnoise->floor_m : noise.floor_m;  // RMS sigma
    q.validation_floor_m = vs * std::sqrt(1.0 + static_cast<double>(a.p) / a.n);
    // Prediction error of new poses expected from the fit residual alone: E[RSS] = s^2 (n - p)
    // and E[validation SS] = s^2 3m (1 + p/n) for a right model (mean leverage p/n), so the
    // ratio of the two mean squares is ~ F(3m, n - p) (unweighted: no stated noise needed).
    if (q.dof > 0 && ss_m > 0) {
      const double fit_ms = ss_m / q.dof;
      const double f = (ss / (3.0 * v.rows.size())) / (fit_ms * (1.0 + double(a.p) / a.n));
      q.validation_to_fit = std::sqrt(f);
      // A validation session's noise is not the calibration's (another day, another thermal
      // state): allowed to differ by the same relative uncertainty as a stated noise level.
      const double u = 1.0 + cx.opt->noise_uncertainty;
      q.validation_to_fit_p = stats::f_sf(f / (u * u), 3.0 * v.rows.size(), q.dof);
    }
  }
  return a;
}

/// Score of one regressor group Z (weighted, 3n x k) against an analysis.
struct GroupScore {
  int columns = 0, df = 0;
  double drss = 0, f = 0, log_p = 0, surviving = 0;
  MatrixXd u;                     ///< basis of the projected group
  std::vector<int> null_columns;  ///< columns with no (surviving) effect
  VectorXd fitted;                ///< projection of r on the group (weighted)
};

GroupScore score_group(const Analysis& a, const MatrixXd& z, const VectorXd& typical, double tol) {
  GroupScore g;
  g.columns = static_cast<int>(z.cols());
  std::vector<int> live;
  for (int k = 0; k < z.cols(); ++k) {
    // Moving the parameter by its typical size changes the residuals by < 1e-9 sigma in
    // total: no effect on these measurements.
    if (z.col(k).norm() * typical(k) > 1e-9)
      live.push_back(k);
    else
      g.null_columns.push_back(k);
  }
  MatrixXd zn(a.n, live.size());
  for (size_t i = 0; i < live.size(); ++i) zn.col(i) = z.col(live[i]) / z.col(live[i]).norm();
  MatrixXd zt = zn - a.qx * (a.qx.transpose() * zn);
  zt -= a.qx * (a.qx.transpose() * zt);
  g.surviving = zn.cols() ? zt.norm() / zn.norm() : 0.0;
  MatrixXd v_null;
  g.u = orthonormal_basis(zt, tol, nullptr, &v_null, 1.0);
  for (int j = 0; j < v_null.cols(); ++j) {
    int best = 0;
    v_null.col(j).cwiseAbs().maxCoeff(&best);
    if (std::find(g.null_columns.begin(), g.null_columns.end(), live[best]) == g.null_columns.end())
      g.null_columns.push_back(live[best]);
  }
  g.df = static_cast<int>(g.u.cols());
  if (g.df == 0) return g;
  const VectorXd proj = g.u.transpose() * a.r;
  g.drss = proj.squaredNorm();
  g.fitted = g.u * proj;
  const int dof2 = a.n - a.p - g.df;
  if (dof2 <= 0) {
    g.df = 0;
    return g;
  }
  const double rss1 = std::max(a.rss - g.drss, 1e-300);
  g.f = (g.drss / g.df) / (rss1 / dof2);
  g.log_p = stats::log_f_sf(g.f, g.df, dof2);
  return g;
}

/// Candidate group regressors: d(prediction)/d(theta_g) at theta_g = null, current
/// parameters at their fitted values (model current+g), weighted.
MatrixXd candidate_regressors(const Analysis& a, const DeflectionModel& mg, VectorXd* typical) {
  const int pc = a.model->parameter_count();
  const int pg = mg.parameter_count() - pc;
  VectorXd theta(mg.parameter_count());
  theta.head(pc) = a.theta;
  for (int k = 0; k < pg; ++k) theta(pc + k) = mg.spec(pc + k).null_value;
  const auto ctx = mg.contexts(a.used);
  MatrixXd z(a.n, pg);
  for (size_t i = 0; i < a.used.rows.size(); ++i)
    z.middleRows(3 * i, 3) =
        mg.displacement_jacobian(theta, a.used.rows[i], ctx[i]).rightCols(pg) * a.w(i);
  typical->resize(pg);
  for (int k = 0; k < pg; ++k) {
    const double t = std::abs(mg.spec(pc + k).typical);
    (*typical)(k) = t > 0 && std::isfinite(t) ? t : 1.0;
  }
  return z;
}

/// Everything known about the candidates at one model.
struct Level {
  Analysis a;
  std::vector<CandidateScore> scores;  ///< testable by rank, then untestable
  std::vector<MatrixXd> bases;         ///< projected basis per score (testable)
  std::vector<std::string> group;      ///< ambiguity set around the top (incl. top)
  size_t pick = 0;                     ///< the candidate the next level adds (index in scores)
  std::string rival;      ///< a group member whose chain explains the data as well as the pick
  bool separable = true;  ///< the top is separable from every group member
  std::string experiment;
};

/// The experiments that would separate the effects of an ambiguous group: each effect's own
/// hints (Effect::experiment_hints), once each, then the planner's model-discriminating design.
std::string experiment_for(const Context& cx, const std::vector<std::string>& group) {
  EffectSetup setup;
  setup.robot = cx.robot;
  setup.data = cx.calib;
  std::vector<std::string> tips;
  for (const auto& name : group) {
    std::vector<std::string> hints;
    try {
      hints = make_effect(name, setup)->experiment_hints();
    } catch (const InvalidArgument&) {
      continue;  // an effect the data cannot host gives no advice
    }
    for (auto& h : hints)
      if (std::find(tips.begin(), tips.end(), h) == tips.end()) tips.push_back(std::move(h));
  }
  tips.push_back(
      "poses from the planner (stiff plan) that maximise the difference between the "
      "candidates' re-fitted predictions (T-optimal design, Atkinson & Fedorov 1975)");
  return join(tips, "; ");
}

Level score_level(const Context& cx, Analysis a, const std::vector<std::string>& candidates) {
  const DiagnosisOptions& opt = *cx.opt;
  Level L;
  std::vector<CandidateScore> testable, untestable;
  std::vector<MatrixXd> bases;
  std::vector<VectorXd> fitted;
  const std::string model = join(a.effects, "+");
  for (const auto& name : candidates) {
    CandidateScore c;
    c.effect = name;
    c.command = opt.command_prefix + " --model " + model + "+" + name;
    std::vector<std::string> eff = a.effects;
    eff.push_back(name);
    std::unique_ptr<DeflectionModel> mg;
    try {
      mg = std::make_unique<DeflectionModel>(*cx.robot, eff, &a.used);
    } catch (const InvalidArgument& e) {
      c.testable = false;
      c.identifiable = false;
      c.reason = std::string("untestable: ") + e.what();
      untestable.push_back(c);
      continue;
    }
    const Effect& eg = *mg->effects().back();
    c.parameters = eg.size();
    if ((eg.requirements() & kNeedsAbsolute) && a.used.absolute_rows() == 0) {
      c.testable = false;
      c.identifiable = false;
      c.reason = "untestable: it is identified from absolute positions and the data have none";
      untestable.push_back(c);
      continue;
    }
    VectorXd typical;
    const MatrixXd z = candidate_regressors(a, *mg, &typical);
    GroupScore g = score_group(a, z, typical, opt.rank_tolerance);
    for (int k : g.null_columns) c.unidentifiable.push_back(eg.parameters()[k].name);
    std::sort(c.unidentifiable.begin(), c.unidentifiable.end());
    c.df = g.df;
    c.identifiable = g.df == c.parameters;
    c.surviving_fraction = g.surviving;
    if (g.df == 0) {
      c.testable = false;
      c.identifiable = false;
      c.reason =
          "untestable: no direction of it is identifiable from this data (the current "
          "model absorbs it, or it has no effect on these measurements)";
      untestable.push_back(c);
      continue;
    }
    if (!c.identifiable)
      c.reason = std::to_string(c.parameters - g.df) + " of " + std::to_string(c.parameters) +
                 " directions are not identifiable from this data (" +
                 join(c.unidentifiable, ", ") + "); tested on the other " + std::to_string(g.df);
    if ((eg.requirements() & kNeedsTime) && !cx.had_time)
      c.reason += std::string(c.reason.empty() ? "" : "; ") +
                  "the data has no time column: the row order is taken as time";
    c.statistic = g.f;
    c.delta_rss = g.drss;
    c.lm = cx.noise->known ? g.drss : NAN;
    c.log_p = g.log_p;
    c.p_value = std::exp(g.log_p);
    const double s2 =
        cx.noise->known ? 1.0 : std::max(a.rss - g.drss, 0.0) / std::max(1, a.n - a.p - g.df);
    const double metres2 = cx.noise->known ? cx.noise->floor_m * cx.noise->floor_m : 1.0;
    c.expected_rms_drop_m = std::sqrt(std::max(0.0, g.drss - g.df * s2) * metres2 / a.n);
    const double rms2 = a.quality.fit_rms_m * a.quality.fit_rms_m;
    c.fit_rms_after_m = std::sqrt(std::max(0.0, rms2 * (1.0 - g.drss / std::max(a.rss, 1e-300))));
    const double excess = a.rss - (a.n - a.p);
    c.excess_explained = cx.noise->known && excess > 0 ? std::min(1.0, g.drss / excess) : NAN;
    testable.push_back(c);
    bases.push_back(g.u);
    fitted.push_back(g.fitted);
  }
  // Holm across the testable groups; rank by log p, then statistic.
  std::vector<double> lp;
  for (const auto& c : testable) lp.push_back(c.log_p);
  const std::vector<double> adj = stats::holm_adjust(lp);
  for (size_t i = 0; i < testable.size(); ++i) {
    testable[i].p_adjusted = adj[i];
    testable[i].significant = adj[i] < opt.alpha;
  }
  std::vector<size_t> order(testable.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](size_t x, size_t y) {
    if (testable[x].log_p != testable[y].log_p) return testable[x].log_p < testable[y].log_p;
    return testable[x].statistic > testable[y].statistic;
  });
  for (size_t i = 0; i < order.size(); ++i) {
    CandidateScore c = testable[order[i]];
    c.rank = static_cast<int>(i) + 1;
    if (i < 3) {
      // Added-variable plot data, in metres.
      const VectorXd& f = fitted[order[i]];
      for (int k = 0; k < a.n; ++k) {
        c.av_fitted_m.push_back(f(k) / a.w(k / 3));
        c.av_residual_m.push_back(a.r(k) / a.w(k / 3));
      }
    }
    L.scores.push_back(c);
    L.bases.push_back(bases[order[i]]);
  }
  // Ambiguity around the top: canonical correlation and conditional tests.
  if (!L.scores.empty() && L.scores[0].significant) {
    const MatrixXd& ut = L.bases[0];
    L.group.push_back(L.scores[0].effect);
    for (size_t i = 1; i < L.scores.size(); ++i) {
      const MatrixXd& ug = L.bases[i];
      Eigen::JacobiSVD<MatrixXd> svd(ut.transpose() * ug);
      const double rho = svd.singularValues().size() ? svd.singularValues()(0) : 0.0;
      L.scores[i].max_correlation = std::min(1.0, rho);
      if (!L.scores[i].significant && rho <= opt.ambiguity_correlation) continue;
      // Does g explain the top's evidence away? Test top | (current + g).
      const VectorXd rg = a.r - ug * (ug.transpose() * a.r);
      MatrixXd utg = ut - ug * (ug.transpose() * ut);
      const MatrixXd b = orthonormal_basis(utg, opt.rank_tolerance, nullptr, nullptr, 1.0);
      bool explained_away = true;
      if (b.cols() > 0) {
        const double d = (b.transpose() * rg).squaredNorm();
        const int dof2 = a.n - a.p - static_cast<int>(ug.cols() + b.cols());
        if (dof2 > 0) {
          const double f = (d / b.cols()) / (std::max(rg.squaredNorm() - d, 1e-300) / dof2);
          explained_away = stats::f_sf(f, b.cols(), dof2) >= opt.alpha;
        }
      }
      if (rho > opt.ambiguity_correlation || (explained_away && L.scores[i].significant)) {
        L.group.push_back(L.scores[i].effect);
        if (explained_away) L.separable = false;
      }
    }
    if (L.group.size() > 1) {
      for (auto& c : L.scores)
        if (std::find(L.group.begin(), L.group.end(), c.effect) != L.group.end()) c.group = L.group;
      L.experiment = experiment_for(cx, L.group);
    } else {
      L.scores[0].group = L.group;
    }
  }
  for (auto& c : untestable) L.scores.push_back(c);
  L.a = std::move(a);
  return L;
}

bool claims(const Level& L) { return !L.scores.empty() && L.scores[0].significant; }

/// Residual structure against covariates ("where it fails").
void where(const Context& cx, const Level& L, Diagnosis& d) {
  const Analysis& a = L.a;
  const Dataset& calib = *cx.calib;
  const Noise& noise = *cx.noise;
  const RobotModel& robot = *cx.robot;
  const int rows = static_cast<int>(calib.rows.size());
  // Per-pose residuals.
  for (int r = 0; r < rows; ++r) {
    PoseResidual p;
    p.row = r;
    p.id = calib.rows[r].id;
    const Eigen::Vector3d e = calib.rows[r].observed() - a.pred_all.row(r).transpose();
    for (int k = 0; k < 3; ++k) {
      p.residual_m[k] = e(k);
      p.predicted_m[k] = a.pred_all(r, k);
    }
    p.norm_m = e.norm();
    p.norm_sigma = noise.known ? e.norm() / noise.sigma(r) : NAN;
    p.outlier = a.outlier[r];
    d.residuals.push_back(p);
  }
  std::vector<PoseResidual> sorted = d.residuals;
  std::stable_sort(sorted.begin(), sorted.end(), [&](const PoseResidual& x, const PoseResidual& y) {
    const double sx = noise.known ? x.norm_m / noise.sigma(x.row) : x.norm_m;
    const double sy = noise.known ? y.norm_m / noise.sigma(y.row) : y.norm_m;
    return sx > sy;
  });
  for (int i = 0; i < std::min<int>(cx.opt->worst_poses, rows); ++i) d.worst.push_back(sorted[i]);
  // Per-axis RMS and chi2 (used rows).
  const int nu = static_cast<int>(a.used_rows.size());
  for (int k = 0; k < 3; ++k) {
    double ss_w = 0, ss_m = 0;
    for (int i = 0; i < nu; ++i) {
      ss_w += a.r(3 * i + k) * a.r(3 * i + k);
      ss_m += std::pow(a.r(3 * i + k) / a.w(i), 2);
    }
    d.axis_rms_m[k] = std::sqrt(ss_m / nu);
    const double dof = nu * static_cast<double>(a.n - a.p) / a.n;
    d.axis_chi2_p[k] = noise.known && dof > 0 ? stats::chi2_sf(ss_w, dof) : 1.0;
  }
  // Covariates per used row.
  const int dof = robot.dof();
  std::vector<std::pair<std::string, std::string>> names;
  std::vector<std::vector<double>> values;
  auto add = [&](const std::string& n, const std::string& desc, std::vector<double> v) {
    names.emplace_back(n, desc);
    values.push_back(std::move(v));
  };
  std::vector<std::vector<double>> q(dof), tl(dof), tg(dof);
  std::vector<double> fx, fy, fz, level, pred, time, ones;
  bool any_gravity = false;
  for (int i = 0; i < nu; ++i) {
    const auto& m = a.used.rows[i];
    const auto& c = a.ctx[i];
    const Matrix6X<double> jl =
        robot.jacobian_at(c.chain, robot.point_position(c.chain, robot.load_point));
    Eigen::Matrix<double, 6, 1> wr;
    wr << m.force, m.moment;
    const VectorXd tau = jl.transpose() * wr;
    for (int j = 0; j < dof; ++j) {
      q[j].push_back(m.q(j));
      tl[j].push_back(tau(j));
      const double g = c.tau_gravity.size() > j ? c.tau_gravity(j) : 0.0;
      tg[j].push_back(g);
      if (std::abs(g) > 1e-9) any_gravity = true;
    }
    const double f = m.force.norm();
    fx.push_back(f > 0 ? m.force.x() / f : 0.0);
    fy.push_back(f > 0 ? m.force.y() / f : 0.0);
    fz.push_back(f > 0 ? m.force.z() / f : 0.0);
    level.push_back(f);
    pred.push_back(a.pred_all.row(a.used_rows[i]).norm());
    time.push_back(c.time);
    ones.push_back(1.0);
  }
  add("offset", "constant (mean residual different from zero)", ones);
  for (int j = 0; j < dof; ++j)
    add("q" + std::to_string(j + 1), "joint angle " + std::to_string(j + 1), q[j]);
  for (int j = 0; j < dof; ++j)
    add("tau_load_" + std::to_string(j + 1),
        "load torque of joint " + std::to_string(j + 1) + " (J^T W)", tl[j]);
  if (any_gravity)
    for (int j = 0; j < dof; ++j)
      add("tau_gravity_" + std::to_string(j + 1),
          "gravity torque of joint " + std::to_string(j + 1), tg[j]);
  add("load_dir_x", "load direction, base x (F_x/|F|)", fx);
  add("load_dir_y", "load direction, base y (F_y/|F|)", fy);
  add("load_dir_z", "load direction, base z (F_z/|F|)", fz);
  add("load_level", "load level |F|", level);
  add("predicted", "predicted deflection |d|", pred);
  add("time", cx.had_time ? "measurement time" : "measurement order", time);
  std::vector<CovariateTest> tests;
  std::vector<double> lps;
  for (size_t t = 0; t < names.size(); ++t) {
    const auto& v = values[t];
    double mean = 0;
    for (double x : v) mean += x;
    mean /= nu;
    const bool constant = names[t].first == "offset";
    MatrixXd z = MatrixXd::Zero(a.n, 3);
    double var = 0;
    for (int i = 0; i < nu; ++i) {
      const double c = constant ? 1.0 : v[i] - mean;
      var += c * c;
      for (int k = 0; k < 3; ++k) z(3 * i + k, k) = c * a.w(i);
    }
    if (!(var > 1e-24)) continue;
    const GroupScore g = score_group(a, z, VectorXd::Ones(3), 1e-6);
    CovariateTest ct;
    ct.covariate = names[t].first;
    ct.description = names[t].second;
    ct.df = g.df;
    if (g.df == 0) continue;
    ct.statistic = g.f;
    ct.p_value = std::exp(g.log_p);
    for (int k = 0; k < 3; ++k) {
      if (constant) {
        double s = 0, ss = 0;
        for (int i = 0; i < nu; ++i) {
          s += a.r(3 * i + k);
          ss += a.r(3 * i + k) * a.r(3 * i + k);
        }
        ct.correlation[k] = ss > 0 ? s / std::sqrt(nu * ss) : 0.0;
        continue;
      }
      double sxy = 0, syy = 0, sxx = 0, ym = 0;
      for (int i = 0; i < nu; ++i) ym += a.r(3 * i + k) / a.w(i);
      ym /= nu;
      for (int i = 0; i < nu; ++i) {
        const double y = a.r(3 * i + k) / a.w(i) - ym;
        const double x = v[i] - mean;
        sxy += x * y;
        sxx += x * x;
        syy += y * y;
      }
      ct.correlation[k] = sxx > 0 && syy > 0 ? sxy / std::sqrt(sxx * syy) : 0.0;
    }
    tests.push_back(ct);
    lps.push_back(g.log_p);
  }
  const auto adj = stats::holm_adjust(lps);
  for (size_t t = 0; t < tests.size(); ++t) {
    tests[t].p_adjusted = adj[t];
    tests[t].significant = adj[t] < cx.opt->alpha;
  }
  std::stable_sort(tests.begin(), tests.end(), [](const CovariateTest& x, const CovariateTest& y) {
    return x.p_value < y.p_value;
  });
  d.covariates = tests;
}

/// The levels of the loop: level 0 is the given model, level i+1 adds level i's top effect.
struct Chain {
  const Context* cx;
  std::vector<std::string> candidates;
  std::vector<Level> levels;
  std::vector<std::string> warnings;
  const std::vector<bool>* fixed = nullptr;  ///< outlier flags shared by every level

  /// Level i+1 (computed on demand), or null when level i claims nothing or the re-fit fails.
  const Level* next(size_t i) {
    if (!claims(levels[i])) return nullptr;
    if (levels.size() <= i + 1) {
      std::vector<std::string> eff = levels[i].a.effects;
      const std::string top = levels[i].scores[levels[i].pick].effect;
      eff.push_back(top);
      std::vector<std::string> rest;
      for (const auto& c : candidates)
        if (std::find(eff.begin(), eff.end(), c) == eff.end()) rest.push_back(c);
      try {
        Analysis a = analyse(*cx, eff, fixed, rest);
        levels.push_back(score_level(*cx, std::move(a), rest));
      } catch (const NumericalError& e) {
        warnings.push_back("re-fit with " + top + " failed: " + e.what());
        return nullptr;
      }
    }
    return &levels[i + 1];
  }

  /// Is the residual of level L at the noise floor? With a stated noise: the chi-square test,
  /// allowing for the uncertainty of the stated level. Without: a model that explains the data
  /// predicts the validation poses about as well as it fits (F test of the two mean squares),
  /// and its residual has no structure left against the covariates of "where it fails"
  /// (partial F-tests, Holm across them: no sigma needed). A chain of candidates that mimics
  /// an effect outside the library fits and predicts alike, but leaves the part it cannot
  /// mimic as a trend in the load torques or directions.
  bool at_floor(const Level& L, std::string* why) const {
    const ModelQuality& q = L.a.quality;
    const double alpha = cx->opt->alpha;
    if (cx->noise->known) {
      if (q.floor_p >= alpha) return true;
      *why = "the residual is " + num(q.residual_to_floor, 3) + " times the stated noise floor (" +
             "improbable even for a noise " + num(100 * cx->opt->noise_uncertainty, 2) +
             " % above the stated one, p = " + num(q.floor_p, 2) + ")";
      return false;
    }
    if (q.has_validation && q.validation_to_fit_p < alpha) {
      *why = "it predicts the validation poses " + num(q.validation_to_fit, 3) +
             " times worse than its fit residual allows (p = " + num(q.validation_to_fit_p, 2) +
             " allowing " + num(100 * cx->opt->noise_uncertainty, 2) +
             " % between sessions): structure remains";
      return false;
    }
    Diagnosis d;
    where(*cx, L, d);
    for (const auto& c : d.covariates)
      if (c.significant) {
        *why = "its residual still follows " + c.description +
               " (partial F = " + num(c.statistic, 3) + ", p_adj = " + num(c.p_adjusted, 2) +
               "): structure remains that no candidate explains";
        return false;
      }
    return true;
  }

  /// Does adding one of level i's significant candidates (the top and the next ones by rank,
  /// kAlternatives in all) and, while the evidence holds, the following ones bring the
  /// residual to the noise floor, with the validation error falling at every step? The
  /// calibration data ranks the candidates; when several chains explain it, the one that
  /// predicts the validation poses best is kept (out-of-sample choice; the first that explains
  /// without validation data). On success levels[i].pick is its candidate; on failure `why` is
  /// the top's reason.
  bool explained_by_chain(size_t i, int depth, std::string* why, std::string* top_why = nullptr) {
    static constexpr size_t kAlternatives = 3;
    std::string first;
    size_t best = SIZE_MAX;
    double best_rms = INFINITY, top_rms = INFINITY;
    const size_t tries = std::min(kAlternatives, levels[i].scores.size());
    const auto& group = levels[i].group;
    for (size_t k = 0; k < tries; ++k) {
      if (!levels[i].scores[k].significant) break;
      // Candidates outside the top's ambiguity group explain another part of the residual:
      // tried only when nothing in the group explains it.
      const bool rival = k == 0 || std::find(group.begin(), group.end(),
                                             levels[i].scores[k].effect) != group.end();
      if (!rival && best != SIZE_MAX) break;
      levels.resize(i + 1);
      levels[i].pick = k;
      std::string w;
      if (explained_by(i, depth, &w)) {
        const ModelQuality& end = levels.back().a.quality;
        const double rms = end.has_validation ? end.validation_rms_m : 0.0;
        if (k == 0) top_rms = end.has_validation ? rms : INFINITY;
        if (rms < best_rms) {
          best_rms = rms;
          best = k;
        }
        if (!end.has_validation) break;
      } else if (k == 0) {
        first = w;
      }
    }
    levels.resize(i + 1);
    levels[i].rival.clear();
    if (best == SIZE_MAX) {
      levels[i].pick = 0;
      *why = first;
      return false;
    }
    // The top keeps its place unless a rival chain predicts the validation poses significantly
    // better (F test of the two validation mean squares, 3m dof each); a rival that is not
    // significantly better or worse leaves the data unable to choose (ambiguous).
    if (best != 0 && top_rms < INFINITY) {
      const double m3 = 3.0 * cx->validation->rows.size();
      const double ratio = (top_rms * top_rms) / (best_rms * best_rms);
      if (stats::f_sf(ratio, m3, m3) >= cx->opt->alpha) {
        levels[i].rival = levels[i].scores[best].effect;
        best = 0;
      }
    }
    levels[i].pick = best;
    std::string w;
    explained_by(i, depth, &w);  // rebuild the chosen chain's levels
    if (top_why)
      *top_why =
          best == 0 ? ""
                    : (first.empty() ? "predicts the validation poses significantly worse" : first);
    return true;
  }

  /// explained_by_chain for level i's pick.
  bool explained_by(size_t i, int depth, std::string* why) {
    const std::string added = levels[i].scores[levels[i].pick].effect;
    const Level* n = next(i);
    if (!n) {
      *why = "the re-fit with " + added + " failed";
      return false;
    }
    const ModelQuality& q = levels[i].a.quality;
    const ModelQuality& nq = n->a.quality;
    if (q.has_validation && nq.validation_rms_m >= q.validation_rms_m) {
      *why = "adding " + added + " does not improve the validation error (" +
             um(q.validation_rms_m) + " -> " + um(nq.validation_rms_m) + ")";
      return false;
    }
    // Explained: the residual is at the floor and no candidate finds structure in it (the
    // partial F-tests do not depend on the stated noise, so they also catch a residual that
    // the noise allowance would let pass).
    std::string floor_why;
    const bool floor = at_floor(*n, &floor_why);
    if (floor && !claims(*n)) return true;
    // At the floor with a marginal candidate left (p_adj > alpha/10, the rule of decide()) that
    // does not validate: not structure.
    const bool marginal = n->scores[0].p_adjusted > cx->opt->alpha / 10;
    if (claims(*n) && n->separable && depth > 1) {
      std::string deeper;
      if (explained_by_chain(i + 1, depth - 1, &deeper)) return true;
      if (floor && levels[i + 1].scores[0].p_adjusted > cx->opt->alpha / 10) return true;
      *why = "after adding " + added + ": " + deeper;
      return false;
    }
    if (floor && marginal) return true;
    n = &levels[i + 1];
    if (floor)
      floor_why = "structure remains (" + n->scores[0].effect +
                  " is significant, p_adj = " + num(n->scores[0].p_adjusted, 2) +
                  (n->separable ? "" : ", not separable from " + join(n->group, ", ")) + ")";
    *why = "after adding " + added + " " + floor_why +
           (depth > 1 ? " and no further candidate explains the rest" : "");
    return false;
  }

  /// Verdict of level i.
  std::string decide(size_t i, std::string* why) {
    const Level& L = levels[i];
    const double alpha = cx->opt->alpha;
    const ModelQuality& q = L.a.quality;
    const bool known = cx->noise->known;
    const bool omnibus = known && q.floor_p < alpha;
    const std::string chi = "chi2 = " + num(q.chi2, 4) + " for " + std::to_string(q.dof) +
                            " dof, residual " + num(q.residual_to_floor, 3) +
                            " times the floor, p = " + num(q.floor_p, 2) + " allowing " +
                            num(100 * cx->opt->noise_uncertainty, 2) + " % noise uncertainty";
    auto nothing = [&](const std::string& extra) {
      if (omnibus) {
        *why = "the residual is above the noise floor (" + chi + ") but no candidate effect " +
               "explains it" + extra;
        return std::string("unexplained");
      }
      *why =
          known
              ? "the residuals are at the noise floor (" + chi + ") and no candidate " +
                    "effect is significant" + extra
              : "no candidate effect is significant (the noise level is unknown: give "
                "sigma_d or sigma_p, # tracker_sigma_m or replicated measurements for an absolute "
                "check)" +
                    extra;
      return std::string("adequate");
    };
    if (!claims(L)) return nothing("");
    const CandidateScore& top = L.scores[0];
    if (!L.separable) {
      *why =
          "these candidates explain the same part of the residual and this data cannot tell "
          "them apart: " +
          join(L.group, ", ");
      return "ambiguous";
    }
    std::string reason, top_reason;
    if (!explained_by_chain(i, cx->opt->max_steps, &reason, &top_reason)) {
      // A marginal candidate that does not validate on a model at the noise floor: no claim.
      if (!omnibus && top.p_adjusted > alpha / 10)
        return nothing(" (" + top.effect + " reached p_adj = " + num(top.p_adjusted, 2) + " but " +
                       reason + ")");
      *why = top.effect + " explains part of the misfit (partial F = " + num(top.statistic, 4) +
             ", p_adj = " + num(top.p_adjusted, 2) + ") but " + reason +
             ": the missing effect is probably not in the candidate list";
      return "unexplained";
    }
    if (!L.rival.empty()) {
      levels[i].group = {top.effect, L.rival};
      levels[i].experiment = experiment_for(*cx, levels[i].group);
      *why = top.effect + " and " + L.rival +
             " each explain the misfit and predict the validation poses equally well: this data "
             "cannot tell them apart";
      return "ambiguous";
    }
    const CandidateScore& pick = L.scores[L.pick];
    *why = pick.effect + " is missing (partial F = " + num(pick.statistic, 4) +
           ", Holm-adjusted p = " + num(pick.p_adjusted, 2) + ", expected RMS drop " +
           um(pick.expected_rms_drop_m) + ")";
    if (L.pick > 0)
      *why += "; " + top.effect + " fits the calibration data as well or better but " + top_reason;
    return "missing_effect";
  }
};

std::string signature_of(const Diagnosis& d) {
  std::vector<std::string> parts;
  for (const auto& c : d.covariates)
    if (c.significant && parts.size() < 4)
      parts.push_back(c.covariate + " (F = " + num(c.statistic, 3) +
                      ", p_adj = " + num(c.p_adjusted, 2) + ")");
  const char* ax = "xyz";
  for (int k = 0; k < 3; ++k)
    if (d.axis_chi2_p[k] < d.alpha)
      parts.push_back(std::string("axis ") + ax[k] + " (RMS " + um(d.axis_rms_m[k]) + ")");
  if (parts.empty()) return "no significant trend against the covariates tested";
  return "the residual correlates with " + join(parts, ", ");
}

}  // namespace

Diagnosis diagnose(const RobotModel& robot,
                   const Dataset& calibration,
                   const Dataset* validation,
                   const std::vector<std::string>& model,
                   const DiagnosisOptions& options) {
  if (!(options.alpha > 0 && options.alpha < 1))
    throw InvalidArgument("diagnose: alpha must be in (0, 1)");
  if (!(options.ambiguity_correlation > 0 && options.ambiguity_correlation <= 1))
    throw InvalidArgument("diagnose: ambiguity_correlation must be in (0, 1]");
  if (!(options.rank_tolerance > 0 && options.rank_tolerance < 0.1))
    throw InvalidArgument("diagnose: rank_tolerance must be in (0, 0.1)");
  if (!(options.outlier_alpha >= 0 && options.outlier_alpha < 1))
    throw InvalidArgument("diagnose: outlier_alpha must be in [0, 1)");
  if (!(options.noise_uncertainty >= 0 && options.noise_uncertainty < 1))
    throw InvalidArgument("diagnose: noise_uncertainty must be in [0, 1)");
  if (options.max_steps < 0 || options.max_steps > 20)
    throw InvalidArgument("diagnose: max_steps must be in [0, 20]");
  if (model.empty()) throw InvalidArgument("diagnose: the model has no effect (e.g. 'joint')");
  validate_dataset(calibration, robot.dof(), true);
  if (calibration.rows.size() < 4)
    throw InvalidArgument("diagnose: needs at least 4 calibration measurements");
  if (validation) {
    validate_dataset(*validation, robot.dof(), true);
    if (validation->rows.empty()) throw InvalidArgument("diagnose: the validation data is empty");
  }
  { const DeflectionModel check(robot, model, &calibration); }  // names, requirements
  std::vector<std::string> candidates = options.candidates;
  const auto all = effect_names();
  if (candidates.empty()) {
    for (const auto& e : all)
      if (std::find(model.begin(), model.end(), e) == model.end()) candidates.push_back(e);
  } else {
    std::set<std::string> seen;
    std::vector<std::string> keep;
    for (const auto& c : candidates) {
      if (std::find(all.begin(), all.end(), c) == all.end())
        throw InvalidArgument("diagnose: unknown candidate effect '" + c +
                              "'; known effects: " + join(all, " "));
      if (!seen.insert(c).second) continue;
      if (std::find(model.begin(), model.end(), c) == model.end()) keep.push_back(c);
    }
    candidates = keep;
  }

  Dataset calib = with_explicit_time(calibration);
  const Noise noise = noise_of(calibration);
  const Noise vnoise = validation ? noise_of(*validation) : Noise{};
  Context cx{&robot, &calib, validation, &noise, &vnoise, &options, calibration.has_time};

  Diagnosis d;
  d.robot = robot.name;
  d.model = model;
  d.alpha = options.alpha;
  d.noise_floor_m = noise.floor_m;
  d.noise_source = noise.source;
  if (!noise.known)
    d.warnings.push_back(
        "the noise level is unknown (no sigma_d or sigma_p, no # tracker_sigma_m, no replicated "
        "measurements): tests use the residual variance; the absolute (chi2) check is skipped");

  Chain chain{&cx, candidates, {}, {}};
  // decide() holds references into `levels` while the chain grows it: never reallocate (the
  // loop's last step looks max_steps further).
  chain.levels.reserve(2 * static_cast<size_t>(options.max_steps) + 2);
  chain.levels.push_back(score_level(cx, analyse(cx, model, nullptr, candidates), candidates));
  std::string why;
  d.verdict = chain.decide(0, &why);
  // Outliers are judged under the best explanation found: rows the given model calls outliers
  // only because an effect is missing are not outliers. Redo the chain with the last level's
  // flags, shared by every level (so that the steps compare like with like).
  std::vector<bool> final_flags = chain.levels.back().a.outlier;
  if (final_flags != chain.levels[0].a.outlier || chain.levels.size() > 1) {
    chain.levels.clear();
    chain.fixed = &final_flags;
    chain.levels.push_back(score_level(cx, analyse(cx, model, &final_flags), candidates));
    d.verdict = chain.decide(0, &why);
  }
  const Level* next = chain.next(0);
  const Level& L0 = chain.levels[0];
  d.fit = L0.a.quality;
  d.omnibus_rejects = noise.known && d.fit.floor_p < options.alpha;
  d.candidates = L0.scores;
  d.warnings.insert(d.warnings.end(), L0.a.warnings.begin(), L0.a.warnings.end());
  where(cx, L0, d);
  if (next) {
    d.after = next->a.quality;
    d.after_valid = true;
  }
  if (claims(L0)) {
    d.suggested_model = join(model, "+") + "+" + L0.scores[L0.pick].effect;
    d.suggested_command = L0.scores[L0.pick].command;
  }
  if (d.verdict == "ambiguous") {
    d.ambiguous_group = L0.group;
    d.experiment = L0.experiment;
  }
  if (d.verdict == "unexplained") d.unexplained_signature = signature_of(d);
  int outliers = 0;
  for (bool o : L0.a.outlier) outliers += o;
  d.summary = "model " + d.fit.model + ": fit RMS " + um(d.fit.fit_rms_m) +
              (noise.known ? " vs noise floor " + um(noise.floor_m) + " (" +
                                 num(d.fit.residual_to_floor, 3) + " times the floor)"
                           : "") +
              (d.fit.has_validation ? ", validation RMS " + um(d.fit.validation_rms_m) : "") +
              (outliers ? ", " + std::to_string(outliers) + " outlier(s) excluded" : "") +
              ". Verdict: " + d.verdict + " - " + why + ".";
  if (d.verdict == "ambiguous") d.summary += " Discriminating experiment: " + d.experiment + ".";
  if (d.verdict == "unexplained") d.summary += " Signature: " + d.unexplained_signature + ".";

  // Step 0 and the loop.
  auto step_of = [&](size_t i, const std::string& added, const std::string& verdict) {
    const Level& L = chain.levels[i];
    DiagnosisStep s;
    s.step = static_cast<int>(i);
    s.added = added;
    s.quality = L.a.quality;
    s.verdict = verdict;
    if (claims(L)) {
      s.top = L.scores[L.pick].effect;
      s.top_p_adjusted = L.scores[L.pick].p_adjusted;
      s.top_expected_rms_drop_m = L.scores[L.pick].expected_rms_drop_m;
    }
    return s;
  };
  d.steps.push_back(step_of(0, "", d.verdict));
  d.final_model = d.fit.model;
  d.final_verdict = d.verdict;
  if (options.auto_loop) {
    // On absolute data the loop is also a calibration: a residual that no candidate explains
    // completely (unexplained), or that two candidates explain equally well (ambiguous, e.g. a
    // joint offset and a tilt of the same axis), still gets the top candidate when the held-out
    // poses confirm it, i.e. their squared errors fall (paired one-sided t test at alpha): the
    // model grows while the evidence holds, and the last step says what is left. Displacement
    // data stop there: their verdicts name a physical effect, not an accuracy.
    const bool absolute = std::any_of(calibration.rows.begin(), calibration.rows.end(),
                                      [](const Measurement& m) { return m.absolute; });
    auto validates = [&](size_t i) {
      const Level* n = claims(chain.levels[i]) ? chain.next(i) : nullptr;
      if (!n || !validation) return false;
      const std::vector<double>& a = chain.levels[i].a.quality.validation_error_m;
      const std::vector<double>& b = n->a.quality.validation_error_m;
      const size_t m = a.size();
      if (m < 3 || b.size() != m) return false;
      double mean = 0, sq = 0;
      for (size_t r = 0; r < m; ++r) mean += (a[r] * a[r] - b[r] * b[r]) / m;
      for (size_t r = 0; r < m; ++r) {
        const double e = a[r] * a[r] - b[r] * b[r] - mean;
        sq += e * e;
      }
      const double se = std::sqrt(sq / (m - 1) / m);
      if (!(mean > 0)) return false;
      if (!(se > 0)) return true;
      const double t = mean / se;
      return 0.5 * stats::f_sf(t * t, 1.0, static_cast<double>(m - 1)) < options.alpha;
    };
    std::string verdict = d.verdict;
    for (size_t i = 0;
         (verdict == "missing_effect" ||
          (absolute && (verdict == "unexplained" || verdict == "ambiguous") && validates(i))) &&
         static_cast<int>(i) < options.max_steps;
         ++i) {
      if (!chain.next(i)) break;
      const std::string added = chain.levels[i].scores[chain.levels[i].pick].effect;
      std::string w2;
      verdict = chain.decide(i + 1, &w2);
      d.steps.push_back(step_of(i + 1, added, verdict));
      d.final_model = chain.levels[i + 1].a.quality.model;
      d.final_verdict = verdict;
    }
  }
  d.warnings.insert(d.warnings.end(), chain.warnings.begin(), chain.warnings.end());
  return d;
}

}  // namespace stiff
