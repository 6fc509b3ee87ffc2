// Scores of the candidate effects at one model: group score / partial-F tests on the
// regressors each candidate adds, ambiguity groups and the experiment that separates them
// (docs/diagnosis.md, section 3).
#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>

#include "diagnose/analysis.hpp"
#include "diagnose/text.hpp"
#include "stiff/error.hpp"
#include "stiff/model/effect.hpp"

namespace stiff::diagnose_detail {
namespace {

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
        a.W[i] * mg.displacement_jacobian(theta, a.used.rows[i], ctx[i], pc).rightCols(pg);
  typical->resize(pg);
  for (int k = 0; k < pg; ++k) {
    const double t = std::abs(mg.spec(pc + k).typical);
    (*typical)(k) = t > 0 && std::isfinite(t) ? t : 1.0;
  }
  return z;
}

/// The partial F of g's drop in the residual sum of squares taken as df fitted parameters,
/// and its log p; false when no degree of freedom is left.
bool partial_f(const Analysis& a, int df, GroupScore* g) {
  const int dof2 = a.n - a.p - df;
  if (dof2 <= 0) return false;
  g->f = (g->drss / df) / (std::max(a.rss - g->drss, 1e-300) / dof2);
  g->log_p = stats::log_f_sf(g->f, df, dof2);
  return true;
}

}  // namespace

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
  if (!partial_f(a, g.df, &g)) g.df = 0;
  return g;
}

void robust_group(const Analysis& a, GroupScore* g) {
  const int df = g->df, rows = a.n / 3;
  if (df == 0) return;
  if (rows < df + 2 || a.n <= a.p) {
    g->df = 0;
    return;
  }
  const VectorXd s = g->u.transpose() * a.r;
  MatrixXd v = MatrixXd::Zero(df, df);
  for (int i = 0; i < rows; ++i) {
    const VectorXd si = g->u.middleRows(3 * i, 3).transpose() * a.r.segment(3 * i, 3);
    v += si * si.transpose();
  }
  v *= (rows / (rows - 1.0)) * ((a.n - 1.0) / (a.n - a.p));
  const Eigen::LDLT<MatrixXd> ldlt(v);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0)) {
    g->df = 0;
    return;
  }
  g->f = s.dot(ldlt.solve(s)) / df;
  g->log_p = stats::log_f_sf(g->f, df, rows - 1);
  g->robust = true;
}

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

bool explains_away(
    const Analysis& a, const MatrixXd& ut, const MatrixXd& ug, double alpha, double rank_tol) {
  const VectorXd rg = a.r - ug * (ug.transpose() * a.r);
  const MatrixXd utg = ut - ug * (ug.transpose() * ut);
  const MatrixXd b = orthonormal_basis(utg, rank_tol, nullptr, nullptr, 1.0);
  if (b.cols() == 0) return true;  // g spans t
  const double d = (b.transpose() * rg).squaredNorm();
  const int dof2 = a.n - a.p - static_cast<int>(ug.cols() + b.cols());
  if (dof2 <= 0) return true;
  const double f = (d / b.cols()) / (std::max(rg.squaredNorm() - d, 1e-300) / dof2);
  return stats::f_sf(f, b.cols(), dof2) >= alpha;
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
    if ((eg.requirements() & kNeedsOrientation) && !a.used.has_orientation) {
      c.testable = false;
      c.identifiable = false;
      c.reason = "untestable: it is identified from measured orientations and the data have none";
      untestable.push_back(c);
      continue;
    }
    VectorXd typical;
    const MatrixXd z = candidate_regressors(a, *mg, &typical);
    GroupScore g = score_group(a, z, typical, opt.rank_tolerance);
    // The whole effect decides what is identifiable; the test takes the best of it and its
    // common sub-forms and its other forms (Effect::score_forms), Bonferroni-corrected for the
    // forms tried.
    GroupScore best = g;
    const std::vector<std::vector<int>> forms = eg.score_forms();
    size_t form = 0;
    for (size_t f = 0; f < forms.size(); ++f) {
      MatrixXd zf(z.rows(), forms[f].size());
      VectorXd tf(forms[f].size());
      for (size_t k = 0; k < forms[f].size(); ++k) {
        zf.col(k) = z.col(forms[f][k]);
        tf(k) = typical(forms[f][k]);
      }
      GroupScore gf = score_group(a, zf, tf, opt.rank_tolerance);
      if (gf.df > 0 && (best.df == 0 || gf.log_p < best.log_p)) {
        best = std::move(gf);
        form = f + 1;
      }
    }
    // Parameters the effect decided from these data by a search (backlash's link masses) were
    // fitted too: the F test counts them, or the search's freedom reads as evidence. A spread
    // (what the search left open) is no freedom of its own.
    int decided = 0;
    for (const auto& ps : eg.parameters())
      decided += ps.from_data && !ps.spread && ps.null_value != 0.0;
    if (decided > 0 && best.df > 0) partial_f(a, best.df + decided, &best);
    best.log_p = std::min(0.0, best.log_p + std::log(static_cast<double>(forms.size() + 1)));
    for (int k : g.null_columns) c.unidentifiable.push_back(eg.parameters()[k].name);
    std::sort(c.unidentifiable.begin(), c.unidentifiable.end());
    c.df = best.df;  // the form tested; identifiability is the whole effect's (g)
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
    if (form > 0) {
      std::vector<std::string> names;
      for (int k : forms[form - 1]) names.push_back(eg.parameters()[k].name);
      c.reason += std::string(c.reason.empty() ? "" : "; ") + "scored as its sub-form " +
                  join(names, ", ") + " (the best of " + std::to_string(forms.size() + 1) +
                  " forms, Bonferroni-corrected)";
    }
    c.statistic = best.f;
    c.delta_rss = best.drss;
    c.lm = cx.noise->known ? best.drss : NAN;
    c.log_p = best.log_p;
    c.p_value = std::exp(best.log_p);
    const double s2 =
        cx.noise->known ? 1.0 : std::max(a.rss - best.drss, 0.0) / std::max(1, a.n - a.p - best.df);
    const double metres2 = cx.noise->known ? cx.noise->floor_m * cx.noise->floor_m : 1.0;
    c.expected_rms_drop_m = std::sqrt(std::max(0.0, best.drss - best.df * s2) * metres2 / a.n);
    const double rms2 = a.quality.fit_rms_m * a.quality.fit_rms_m;
    c.fit_rms_after_m =
        std::sqrt(std::max(0.0, rms2 * (1.0 - best.drss / std::max(a.rss, 1e-300))));
    const double excess = a.rss - (a.n - a.p);
    c.excess_explained = cx.noise->known && excess > 0 ? std::min(1.0, best.drss / excess) : NAN;
    testable.push_back(c);
    bases.push_back(best.u);
    fitted.push_back(best.fitted);
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
      for (int row = 0; row < a.n / 3; ++row) {
        const Eigen::Vector3d fm = a.cov_factor[row] * f.segment<3>(3 * row);
        const Eigen::Vector3d rm = a.cov_factor[row] * a.r.segment<3>(3 * row);
        c.av_fitted_m.insert(c.av_fitted_m.end(), fm.data(), fm.data() + 3);
        c.av_residual_m.insert(c.av_residual_m.end(), rm.data(), rm.data() + 3);
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
      const bool explained_away = explains_away(a, ut, ug, opt.alpha, opt.rank_tolerance);
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

}  // namespace stiff::diagnose_detail
