// The identifiability decision of every fit (identifiability.hpp, docs/identifiability.md).
#include "identify/identifiability.hpp"

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include "stiff/error.hpp"
#include "stiff/model/effect.hpp"

namespace stiff::detail {

Eigen::MatrixXd gram_of(const Eigen::MatrixXd& j) {
  Eigen::MatrixXd g = Eigen::MatrixXd::Zero(j.cols(), j.cols());
  g.selfadjointView<Eigen::Lower>().rankUpdate(j.transpose());
  g.triangularView<Eigen::StrictlyUpper>() = g.transpose();
  return g;
}

std::string qualified(const DeflectionModel& model, int k) {
  return model.owner(k).name() + "." + model.spec(k).name;
}

namespace {

/// Which parameters the data cannot identify at theta. Columns are taken in priority order
/// (joint compliances first, then the effects in model order), normalised, and a column is
/// accepted when its component orthogonal to the accepted ones has relative norm above
/// `tolerance`; otherwise it is named with the parameters it is confounded with.
/// The order in which parameters claim what the data show: the joint compliances first (the
/// deflection model's core), then the effects in model order; on a geometric model (an effect
/// that corrects the chain or registers the instrument) the model order alone, so that the
/// registration, tool and geometry the user lists first keep what the compliances share.
/// Parameters marked in `first` (those a start fit identified) go before all others, in the
/// same order among themselves: the data decided once which of a confounded set carries it,
/// and a refit from that solution keeps the decision (at another linearisation point the
/// order alone would pick another member, held at its null value while its partners keep
/// values fitted with it free).
std::vector<int> priority_order(const DeflectionModel& model, const std::vector<bool>* first) {
  const int p = model.parameter_count();
  bool geometric = false;
  for (const auto& e : model.effects())
    geometric = geometric || (e->stages() & kGeometryStage) || e->name() == "registration";
  std::vector<int> order;
  const int je = model.find("joint");
  if (je >= 0 && !geometric)
    for (int k = 0; k < model.effects()[je]->size(); ++k) order.push_back(model.offset(je) + k);
  for (int k = 0; k < p; ++k)
    if (std::find(order.begin(), order.end(), k) == order.end()) order.push_back(k);
  if (first && static_cast<int>(first->size()) == p)
    std::stable_partition(order.begin(), order.end(), [&](int k) { return (*first)[k]; });
  return order;
}

/// R (p x p, upper triangular) of a tall J = Q R, by a Householder QR of each block of rows and
/// one of the blocks' stacked triangles (tall-skinny QR, Demmel, Grigori, Hoemmen & Langou,
/// SIAM J. Sci. Comput. 34(1), 2012): R^T R = J^T J as from one QR of J (rows of R may differ
/// in sign), with the same backward stability, but each block's QR runs in cache, where a
/// panel of the whole J (its height times a few dozen columns) does not fit.
Eigen::MatrixXd tall_triangle(const Eigen::MatrixXd& j) {
  const int m = static_cast<int>(j.rows()), p = static_cast<int>(j.cols());
  const int block = std::max(1024, 4 * p);
  Eigen::MatrixXd stacked(((m + block - 1) / block) * p, p);
  int rows = 0;
  for (int first = 0; first < m; first += block) {
    const int count = std::min(block, m - first);
    const Eigen::HouseholderQR<Eigen::MatrixXd> qr(j.middleRows(first, count));
    const int k = std::min(count, p);
    stacked.middleRows(rows, k) = qr.matrixQR().topRows(k).triangularView<Eigen::Upper>();
    rows += k;
  }
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(stacked.topRows(rows));
  return qr.matrixQR().topRows(p).triangularView<Eigen::Upper>();
}

Identifiability structural(const DeflectionModel& model,
                           const Eigen::MatrixXd& j,
                           const Eigen::MatrixXd& g,
                           const Eigen::VectorXd& typical,
                           double tolerance,
                           const std::vector<bool>* first) {
  const int p = model.parameter_count();
  Identifiability out;
  out.fixed.assign(p, false);
  out.reason.assign(p, "");
  const std::vector<int> order = priority_order(model, first);
  // The last gain of each frame of the load is held whatever the data seem to see of it (a
  // force reference alone can tell a common gain; ParameterSpec::gauge).
  std::vector<bool> gauge_last(p, false);
  {
    std::map<std::pair<const Effect*, int>, int> last;
    for (int k : order)
      if (model.spec(k).gauge > 0) last[{&model.owner(k), model.spec(k).gauge}] = k;
    for (const auto& entry : last) gauge_last[entry.second] = true;
  }

  // The same decisions on the p x p Gram matrix J^T J (Cholesky of the normalised columns in
  // this order: the squared orthogonal rest is 1 - |L^-1 c|^2), which costs a third of the
  // Gram-Schmidt below on tall J; taken only when every column is clearly accepted (its
  // rest^2 is resolved to ~1e-15), else the exact path decides.
  {
    Eigen::MatrixXd l = Eigen::MatrixXd::Zero(p, p);  // rows: accepted columns' factor
    std::vector<int> acc;
    Identifiability fast = out;
    bool clear = true;
    for (int k : order) {
      const double norm = std::sqrt(g(k, k));
      if (!(norm * typical(k) > 1e-9)) {
        fast.fixed[k] = true;
        fast.reason[k] = "it has no effect on any of these measurements";
        continue;
      }
      if (gauge_last[k]) {  // decided, with its reason, by the exact path below
        clear = false;
        break;
      }
      const int a = static_cast<int>(acc.size());
      Eigen::VectorXd y(a);
      for (int i = 0; i < a; ++i) {
        const int c = acc[i];
        double v = (c > k ? g(c, k) : g(k, c)) / (std::sqrt(g(c, c)) * norm);
        for (int m = 0; m < i; ++m) v -= l(i, m) * y(m);
        y(i) = v / l(i, i);
      }
      const double rest2 = 1.0 - y.squaredNorm();
      if (!(rest2 > 100.0 * tolerance * tolerance)) {
        clear = false;
        break;
      }
      l.row(a).head(a) = y.transpose();
      l(a, a) = std::sqrt(rest2);
      acc.push_back(k);
    }
    if (clear) return fast;
  }

  // Column norms, inner products, orthogonal rests and least-squares coefficients are the same
  // for J and for R of J = Q R (Q with orthonormal columns spanning J's range): on tall J the
  // exact test runs on the p x p triangle of Householder QRs.
  Eigen::MatrixXd r;
  if (j.rows() > 2 * j.cols()) r = tall_triangle(j);
  const Eigen::MatrixXd& jr = r.size() ? r : j;
  std::vector<Eigen::VectorXd> basis;
  std::vector<int> accepted;
  for (int k : order) {
    const double norm = jr.col(k).norm();
    // Moving the parameter by its typical magnitude changes the residuals by less than 1e-9
    // of one noise sigma in total: it has no effect on these measurements.
    if (!(norm * typical(k) > 1e-9)) {
      out.fixed[k] = true;
      out.reason[k] = "it has no effect on any of these measurements";
      continue;
    }
    Eigen::VectorXd v = jr.col(k) / norm;
    for (int pass = 0; pass < 2; ++pass)
      for (const auto& b : basis) v -= b.dot(v) * b;
    const double rest = v.norm();
    if (rest > tolerance && !gauge_last[k]) {
      basis.push_back(v / rest);
      accepted.push_back(k);
      continue;
    }
    out.fixed[k] = true;
    if (rest > tolerance) {
      out.reason[k] =
          "it is the last gain of its frame, and the frame's common gain is a scale of every "
          "compliance that only an independent force reference can tell (the other gains are "
          "relative to it)";
      continue;
    }
    if (accepted.empty()) {
      out.reason[k] = "it has no effect on any of these measurements";
      continue;
    }
    // Name the combination: least-squares coefficients on the accepted (normalised) columns.
    Eigen::MatrixXd a(jr.rows(), accepted.size());
    for (size_t i = 0; i < accepted.size(); ++i)
      a.col(i) = jr.col(accepted[i]) / jr.col(accepted[i]).norm();
    const Eigen::VectorXd beta = a.colPivHouseholderQr().solve(jr.col(k) / norm);
    const double big = beta.cwiseAbs().maxCoeff();
    std::string with;
    for (size_t i = 0; i < accepted.size(); ++i)
      if (std::abs(beta(i)) > 0.1 * big)
        with += (with.empty() ? "" : ", ") + qualified(model, accepted[i]);
    out.reason[k] = "its effect on the measurements is a combination of " + with +
                    " (the data see only the combination)";
  }
  return out;
}

}  // namespace

Identifiability check_identifiability(const DeflectionModel& model,
                                      const Eigen::MatrixXd& j,
                                      const Eigen::VectorXd& typical,
                                      double tolerance,
                                      double residual_sigma,
                                      double max_relative_se,
                                      const Eigen::VectorXd* theta,
                                      const std::vector<bool>* fitted,
                                      const Eigen::VectorXd* residuals,
                                      const std::vector<bool>* first,
                                      const Identifiability* structure,
                                      const Eigen::MatrixXd* gram) {
  // Finite but absurd data (a displacement of 1e308 m) overflow the Jacobian; the rank test
  // would then run a QR on an empty matrix.
  if (!j.allFinite())
    throw NumericalError(
        "identify: the Jacobian is not finite (overflow): check the units and sizes of the loads "
        "and displacements (N, N*m, m)");
  const bool statistical =
      max_relative_se > 0 && theta && (residual_sigma > 0 || residuals != nullptr);
  // J^T J once for both tests.
  Eigen::MatrixXd own;
  if (!gram && (!structure || statistical)) {
    own = gram_of(j);
    gram = &own;
  }
  Identifiability out =
      structure ? *structure : structural(model, j, *gram, typical, tolerance, first);
  out.statistical.assign(out.fixed.size(), false);
  if (!statistical) return out;
  const int p = model.parameter_count();
  // Gram matrix of the scaled columns once; each round inverts its free block.
  const Eigen::MatrixXd g = typical.asDiagonal() * *gram * typical.asDiagonal();
  // With the residuals at theta, the residual scale is that of the linear least-squares step
  // over each round's free set.
  Eigen::VectorXd jtr;  // J^T r of the scaled columns
  if (residuals) jtr = typical.cwiseProduct(j.transpose() * *residuals);
  std::vector<int> rank(p);  // position in the priority order
  {
    const std::vector<int> order = priority_order(model, first);
    for (int i = 0; i < p; ++i) rank[order[i]] = i;
  }
  while (true) {
    std::vector<int> free;
    for (int k = 0; k < p; ++k)
      if (!out.fixed[k]) free.push_back(k);
    const int nf = static_cast<int>(free.size());
    if (nf == 0) break;
    Eigen::MatrixXd gf(nf, nf);
    for (int a = 0; a < nf; ++a)
      for (int b = 0; b < nf; ++b) gf(a, b) = g(free[a], free[b]);
    // Equilibrate so that the inverse is accurate for columns of very different norms.
    const Eigen::VectorXd d = gf.diagonal().cwiseSqrt().cwiseMax(1e-300).cwiseInverse();
    const Eigen::MatrixXd ge = d.asDiagonal() * gf * d.asDiagonal();
    const Eigen::MatrixXd cov =
        d.asDiagonal() * ge.ldlt().solve(Eigen::MatrixXd::Identity(nf, nf)) * d.asDiagonal();
    if (residuals) {
      Eigen::VectorXd bf(nf);
      for (int a = 0; a < nf; ++a) bf(a) = jtr(free[a]);
      const Eigen::VectorXd z = cov * bf;  // step in units of the typical magnitudes
      const double rss = std::max(0.0, residuals->squaredNorm() - bf.dot(z));
      const double dof = static_cast<double>(residuals->size() - nf);
      residual_sigma = dof > 0 ? std::sqrt(rss / dof) : 0.0;
      if (!(residual_sigma > 0)) break;
    }
    // se in units of the typical magnitude. Determined: to within max_relative_se typical
    // magnitudes, or its value three standard errors from the null (t >= 3; before a solve
    // there is no value to test). Of the parameters that fail, the last in priority order is
    // held (in a correlated group the others then become determined, as in the structural
    // test).
    int worst = -1;
    double worst_se = 0.0;
    for (int a = 0; a < nf; ++a) {
      const double se = residual_sigma * std::sqrt(std::max(0.0, cov(a, a)));
      const int k = free[a];
      if (fitted && !(*fitted)[k]) continue;
      const double from_null = std::abs((*theta)(k)-model.spec(k).null_value);
      const bool determined =
          se <= max_relative_se || (!residuals && 3.0 * se < from_null / typical(k));
      if (determined) continue;  // NaN fails
      if (worst < 0 || rank[free[a]] > rank[free[worst]]) {
        worst = a;
        worst_se = std::isfinite(se) ? se : INFINITY;
      }
    }
    if (worst < 0) break;
    const int k = free[worst];
    int partner = -1;
    double corr = 0.0;
    for (int b = 0; b < nf; ++b) {
      if (b == worst) continue;
      const double c = cov(worst, b) / std::sqrt(cov(worst, worst) * cov(b, b));
      if (std::abs(c) > std::abs(corr)) {
        corr = c;
        partner = free[b];
      }
    }
    const auto& sp = model.spec(k);
    out.fixed[k] = true;
    out.statistical[k] = true;
    const std::string limit =
        residuals ? num(max_relative_se) + " times its typical magnitude " + num(typical(k)) + " " +
                        sp.unit + " (linearised at the start)"
                  : (max_relative_se != 1.0 ? num(max_relative_se) + " times " : "") +
                        "its typical magnitude " + num(typical(k)) + " " + sp.unit +
                        " and a third of its distance " + num(std::abs((*theta)(k)-sp.null_value)) +
                        " " + sp.unit + " from its null value";
    out.reason[k] = "the data determine it only to +-" + num(worst_se * typical(k)) + " " +
                    sp.unit + " (standard error), more than " + limit +
                    (partner >= 0 && std::abs(corr) > 0.5
                         ? "; it is correlated " + num(corr) + " with " + qualified(model, partner)
                         : std::string());
  }
  return out;
}

}  // namespace stiff::detail
