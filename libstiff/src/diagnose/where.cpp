// Where the model fails: per-pose residuals and trend tests of the residual against the
// covariates (docs/diagnosis.md, section 4).
#include <algorithm>
#include <cmath>

#include "diagnose/analysis.hpp"
#include "diagnose/text.hpp"

namespace stiff::diagnose_detail {

namespace {
/// A significant trend that takes up enough of the residual to be structure.
bool is_structure(const CovariateTest& c) {
  // A trend that takes up less than a tenth of the residual sum of squares moves the residual
  // RMS by less than 5 %: with many rows such a trend is significant, yet no model predicts new
  // poses noticeably better for it (a law of the library in a slightly other form, a chance
  // pattern among the dozens of covariates tested). Effects that small are the candidates'
  // F tests' to find, not evidence of a mechanism outside the list.
  constexpr double kShare = 0.1;
  return c.significant && c.share >= kShare;
}
}  // namespace

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
  // Per-axis RMS and chi2 (used rows), of the residual in metres (em) over its variance.
  const int nu = static_cast<int>(a.used_rows.size());
  std::vector<Eigen::Vector3d> em(nu);
  for (int i = 0; i < nu; ++i) em[i] = a.cov_factor[i] * a.r.segment<3>(3 * i);
  for (int k = 0; k < 3; ++k) {
    double ss_w = 0, ss_m = 0;
    for (int i = 0; i < nu; ++i) {
      ss_w += em[i](k) * em[i](k) / a.cov_factor[i].row(k).squaredNorm();
      ss_m += em[i](k) * em[i](k);
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
    const VectorXd tau = load_torques(robot, m, c);
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
  // A test of the residual against a group, kept when the group survives projection.
  auto record_score = [&](const std::string& name, const std::string& desc,
                          const GroupScore& g) -> CovariateTest* {
    if (g.df == 0) return nullptr;
    CovariateTest ct;
    ct.covariate = name;
    ct.description = desc;
    ct.df = g.df;
    ct.test = g.robust ? "cluster_robust_F" : "partial_F";
    ct.statistic = g.f;
    ct.p_value = std::exp(g.log_p);
    ct.share = a.rss > 0 ? g.drss / a.rss : 0.0;
    tests.push_back(ct);
    lps.push_back(g.log_p);
    return &tests.back();
  };
  auto group_score = [&](const MatrixXd& z) {
    return score_group(a, z, VectorXd::Ones(z.cols()), 1e-6);
  };
  auto record = [&](const std::string& name, const std::string& desc, const MatrixXd& z) {
    return record_score(name, desc, group_score(z));
  };
  // The group's test with each candidate's directions taken out as well, the least significant
  // (none when a candidate spans the group): a trend one candidate explains is that
  // candidate's evidence, which the candidates' own tests weigh.
  // Only a group significant on its own is asked further: the least significant p can only be
  // larger, and a p above alpha is not significant after Holm whatever its value.
  auto beyond_candidates = [&](const MatrixXd& z) {
    GroupScore weakest = group_score(z);
    if (!(std::exp(weakest.log_p) < cx.opt->alpha)) return weakest;
    for (const MatrixXd& b : L.bases) {
      if (weakest.df == 0) break;
      if (b.cols() == 0) continue;
      GroupScore g = group_score(z - b * (b.transpose() * z));
      if (g.df == 0 || g.log_p > weakest.log_p) weakest = std::move(g);
    }
    return weakest;
  };
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
      z.block<3, 3>(3 * i, 0) = c * a.W[i];
    }
    if (!(var > 1e-24)) continue;
    CovariateTest* ct = record(names[t].first, names[t].second, z);
    if (!ct) continue;
    for (int k = 0; k < 3; ++k) {
      if (constant) {
        double s = 0, ss = 0;
        for (int i = 0; i < nu; ++i) {
          const double y = em[i](k) / a.cov_factor[i].row(k).norm();  // in its sigma
          s += y;
          ss += y * y;
        }
        ct->correlation[k] = ss > 0 ? s / std::sqrt(nu * ss) : 0.0;
        continue;
      }
      double sxy = 0, syy = 0, sxx = 0, ym = 0;
      for (int i = 0; i < nu; ++i) ym += em[i](k);
      ym /= nu;
      for (int i = 0; i < nu; ++i) {
        const double y = em[i](k) - ym;
        const double x = v[i] - mean;
        sxy += x * y;
        sxx += x * x;
        syy += y * y;
      }
      ct->correlation[k] = sxx > 0 && syy > 0 ? sxy / std::sqrt(sxx * syy) : 0.0;
    }
  }
  // The signatures of mechanisms outside the library (outside.cpp).
  for (const OutsideTrend& o : outside_trends(cx, a)) {
    GroupScore g = o.beyond_candidates ? beyond_candidates(o.z) : group_score(o.z);
    if (o.robust) robust_group(a, &g);
    record_score(o.name, o.description, g);
  }
  const auto adj = stats::holm_adjust(lps);
  for (size_t t = 0; t < tests.size(); ++t) {
    tests[t].p_adjusted = adj[t];
    tests[t].significant = adj[t] < cx.opt->alpha;
    tests[t].structure = is_structure(tests[t]);
  }
  std::stable_sort(tests.begin(), tests.end(), [](const CovariateTest& x, const CovariateTest& y) {
    return x.p_value < y.p_value;
  });
  d.covariates = tests;
}

std::optional<CovariateTest> strong_trend(const Context& cx,
                                          const Level& L,
                                          bool outside_only,
                                          double level) {
  Diagnosis d;
  where(cx, L, d);
  const double at = level > 0 ? level : cx.opt->alpha / 10;
  for (const auto& c : d.covariates)  // sorted by p
    if (c.structure && c.p_adjusted < at && (!outside_only || is_outside_library(c.covariate)))
      return c;
  return std::nullopt;
}

std::string trend_text(const CovariateTest& c) {
  return c.description + " (partial F = " + num(c.statistic, 3) +
         ", p_adj = " + num(c.p_adjusted, 2) + ")";
}

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

}  // namespace stiff::diagnose_detail
