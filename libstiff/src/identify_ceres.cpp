// Nonlinear identification of any effect model with Ceres: robust losses, identifiability
// check, covariance and outliers (identify.hpp).
#include <ceres/ceres.h>

#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "stiff/error.hpp"
#include "stiff/identify.hpp"

namespace stiff {
namespace {

const std::vector<std::string>& known_losses() {
  static const std::vector<std::string> names = {"none", "huber", "cauchy", "soft_l1", "tukey"};
  return names;
}

/// Loss on the squared norm s of one measurement's residual (sigma units), scale a.
ceres::LossFunction* make_loss(const std::string& name, double a) {
  if (name == "huber") return new ceres::HuberLoss(a);
  if (name == "cauchy") return new ceres::CauchyLoss(a);
  if (name == "soft_l1") return new ceres::SoftLOneLoss(a);
  if (name == "tukey") return new ceres::TukeyLoss(a);
  return nullptr;
}

std::string num(double v, int precision = 3) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*g", precision, v);
  return b;
}

/// Everything the residuals need, fixed for one call.
struct Setup {
  const DeflectionModel* model = nullptr;
  const Dataset* data = nullptr;
  std::vector<MeasurementContext> ctx;
  Eigen::VectorXd row_weight;  ///< 1 / (sigma of the row) [1/m]
  Eigen::VectorXd typical;     ///< parameter scaling: theta_k = typical_k * z_k
  /// Scratch of the evaluations (Ceres runs single-threaded here: num_threads = 1).
  mutable EvalState<Jet> scratch;
  mutable std::vector<Jet> theta_jet;
  mutable std::vector<double> theta_double;
  mutable std::vector<double> jac_scratch;
};

/// Derivatives of the predicted displacement of measurement `row` with respect to
/// theta(cols[i]) * scale[i], by kJetStride parameters per pass of
/// DeflectionModel::evaluate_jet; `theta` is the full parameter vector. Writes d (3) and the
/// 3 x cols.size() derivatives (column-major, leading dimension 3) into `out`.
void displacement_and_jacobian(const Setup& s,
                               int row,
                               const double* theta,
                               const std::vector<int>& cols,
                               const double* scale,
                               Eigen::Vector3d& d,
                               double* out) {
  const DeflectionModel& model = *s.model;
  const int p = model.parameter_count();
  auto& t = s.theta_jet;
  t.resize(p);
  for (int k = 0; k < p; ++k) t[k] = Jet(theta[k]);
  const int nc = static_cast<int>(cols.size());
  const Measurement& m = s.data->rows[row];
  Vector3<Jet> dj;
  if (nc == 0) {
    model.evaluate_jet(t.data(), m, s.ctx[row], s.scratch, &dj);
    for (int k = 0; k < 3; ++k) d(k) = dj(k).a;
    return;
  }
  for (int first = 0; first < nc; first += kJetStride) {
    const int last = std::min(nc, first + kJetStride);
    for (int i = first; i < last; ++i) t[cols[i]].v(i - first) = scale[i];
    model.evaluate_jet(t.data(), m, s.ctx[row], s.scratch, &dj);
    for (int i = first; i < last; ++i) {
      t[cols[i]].v(i - first) = 0.0;
      for (int k = 0; k < 3; ++k) out[3 * i + k] = dj(k).v(i - first);
    }
    if (first == 0)
      for (int k = 0; k < 3; ++k) d(k) = dj(k).a;
  }
}

/// Residual of one measurement, (measured - predicted) / sigma, over the free parameters in
/// scaled form; the held parameters come from `held`. Derivatives by
/// displacement_and_jacobian (one model pass per kJetStride free parameters).
class Residual final : public ceres::CostFunction {
 public:
  Residual(const Setup* setup,
           int row,
           const std::vector<int>* free,
           const Eigen::VectorXd* held,
           const std::vector<double>* free_typical)
      : setup_(setup), row_(row), free_(free), held_(held), free_typical_(free_typical) {
    set_num_residuals(3);
    mutable_parameter_block_sizes()->push_back(static_cast<int>(free->size()));
  }

  bool Evaluate(double const* const* z, double* r, double** jacobians) const override {
    const Setup& s = *setup_;
    const DeflectionModel& model = *s.model;
    const int p = model.parameter_count();
    const int nf = static_cast<int>(free_->size());
    auto& theta = s.theta_double;
    theta.assign(held_->data(), held_->data() + p);
    for (int f = 0; f < nf; ++f) {
      const int k = (*free_)[f];
      theta[k] = z[0][f] * s.typical(k);
    }
    const Measurement& m = s.data->rows[row_];
    const double w = s.row_weight(row_);
    const bool want_jacobian = jacobians && jacobians[0];
    // The trust-region minimizer evaluates the Jacobian at a trial point in its line search
    // and again when it accepts that point: the second is a copy of the first.
    if (cached_ && std::equal(z[0], z[0] + nf, cache_z_.begin())) {
      for (int k = 0; k < 3; ++k) r[k] = cache_r_[k];
      if (want_jacobian) std::copy(cache_j_.begin(), cache_j_.end(), jacobians[0]);
      return true;
    }
    if (!want_jacobian) {
      Vector3<double> d;
      model.evaluate<double>(theta.data(), m, s.ctx[row_], &d, nullptr);
      for (int k = 0; k < 3; ++k) r[k] = (m.displacement(k) - d(k)) * w;
      return true;
    }
    Eigen::Vector3d d;
    auto& jac = s.jac_scratch;
    jac.resize(3 * nf);
    displacement_and_jacobian(s, row_, theta.data(), *free_, free_typical_->data(), d, jac.data());
    for (int k = 0; k < 3; ++k) {
      r[k] = (m.displacement(k) - d(k)) * w;
      for (int f = 0; f < nf; ++f) jacobians[0][k * nf + f] = -jac[3 * f + k] * w;
    }
    cache_z_.assign(z[0], z[0] + nf);
    cache_r_.assign(r, r + 3);
    cache_j_.assign(jacobians[0], jacobians[0] + 3 * nf);
    cached_ = true;
    return true;
  }

 private:
  const Setup* setup_;
  int row_;
  const std::vector<int>* free_;
  const Eigen::VectorXd* held_;
  const std::vector<double>* free_typical_;
  mutable bool cached_ = false;
  mutable std::vector<double> cache_z_, cache_r_, cache_j_;
};

/// Weighted residuals e (3N, sigma units) at theta.
Eigen::VectorXd weighted_residuals(const Setup& s, const Eigen::VectorXd& theta) {
  const int n = static_cast<int>(s.data->rows.size());
  Eigen::VectorXd e(3 * n);
  for (int r = 0; r < n; ++r) {
    const auto& m = s.data->rows[r];
    e.segment<3>(3 * r) =
        (m.displacement - s.model->predict(theta, m, s.ctx[r]).head<3>()) * s.row_weight(r);
  }
  return e;
}

/// Jacobian of the predicted, weighted displacement with respect to theta (3N x P).
Eigen::MatrixXd weighted_jacobian(const Setup& s, const Eigen::VectorXd& theta) {
  const int n = static_cast<int>(s.data->rows.size());
  const int p = s.model->parameter_count();
  Eigen::MatrixXd j(3 * n, p);
  std::vector<int> all(p);
  for (int k = 0; k < p; ++k) all[k] = k;
  const std::vector<double> ones(p, 1.0);
  Eigen::Matrix<double, 3, Eigen::Dynamic> blk(3, p);
  Eigen::Vector3d d;
  for (int r = 0; r < n; ++r) {
    displacement_and_jacobian(s, r, theta.data(), all, ones.data(), d, blk.data());
    j.middleRows(3 * r, 3) = blk * s.row_weight(r);
  }
  return j;
}

std::string qualified(const DeflectionModel& model, int k) {
  return model.owner(k).name() + "." + model.spec(k).name;
}

/// Which parameters the data cannot identify at theta. Columns are taken in priority order
/// (joint compliances first, then the effects in model order), normalised, and a column is
/// accepted when its component orthogonal to the accepted ones has relative norm above
/// `tolerance`; otherwise it is named with the parameters it is confounded with.
struct Identifiability {
  std::vector<bool> fixed;
  std::vector<std::string> reason;
  bool operator==(const Identifiability& o) const { return fixed == o.fixed; }
};

Identifiability check_identifiability(const DeflectionModel& model,
                                      const Eigen::MatrixXd& j,
                                      const Eigen::VectorXd& typical,
                                      double tolerance) {
  const int p = model.parameter_count();
  // Finite but absurd data (a displacement of 1e308 m) overflow the Jacobian; the rank test
  // below would then run a QR on an empty matrix.
  if (!j.allFinite())
    throw NumericalError(
        "identify: the Jacobian is not finite (overflow): check the units and sizes of the loads "
        "and displacements (N, N*m, m)");
  Identifiability out;
  out.fixed.assign(p, false);
  out.reason.assign(p, "");
  std::vector<int> order;
  const int je = model.find("joint");
  if (je >= 0)
    for (int k = 0; k < model.effects()[je]->size(); ++k) order.push_back(model.offset(je) + k);
  for (int k = 0; k < p; ++k)
    if (std::find(order.begin(), order.end(), k) == order.end()) order.push_back(k);

  std::vector<Eigen::VectorXd> basis;
  std::vector<int> accepted;
  for (int k : order) {
    const double norm = j.col(k).norm();
    // Moving the parameter by its typical magnitude changes the residuals by less than 1e-9
    // of one noise sigma in total: it has no effect on these measurements.
    if (!(norm * typical(k) > 1e-9)) {
      out.fixed[k] = true;
      out.reason[k] = "it has no effect on any of these measurements";
      continue;
    }
    Eigen::VectorXd v = j.col(k) / norm;
    for (int pass = 0; pass < 2; ++pass)
      for (const auto& b : basis) v -= b.dot(v) * b;
    const double rest = v.norm();
    if (rest > tolerance) {
      basis.push_back(v / rest);
      accepted.push_back(k);
      continue;
    }
    out.fixed[k] = true;
    if (accepted.empty()) {
      out.reason[k] = "it has no effect on any of these measurements";
      continue;
    }
    // Name the combination: least-squares coefficients on the accepted (normalised) columns.
    Eigen::MatrixXd a(j.rows(), accepted.size());
    for (size_t i = 0; i < accepted.size(); ++i)
      a.col(i) = j.col(accepted[i]) / j.col(accepted[i]).norm();
    const Eigen::VectorXd beta = a.colPivHouseholderQr().solve(j.col(k) / norm);
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

/// Ceres iteration callback forwarding to the user's progress function.
class Progress : public ceres::IterationCallback {
 public:
  explicit Progress(const std::function<bool(int, double)>& fn) : fn_(fn) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    bool go = false;
    try {
      go = fn_(s.iteration, s.cost);
    } catch (...) {
      go = false;
    }
    if (go) return ceres::SOLVER_CONTINUE;
    cancelled = true;
    return ceres::SOLVER_ABORT;
  }
  bool cancelled = false;

 private:
  const std::function<bool(int, double)>& fn_;
};

struct SolveOutcome {
  int iterations = 0;
  bool converged = true;
  std::string message;
};

/// Minimise over the free parameters; theta (full) is updated in place.
SolveOutcome solve(const Setup& s,
                   const std::vector<int>& free,
                   Eigen::VectorXd& theta,
                   const IdentifyOptions& opt,
                   const Eigen::VectorXd& loss_scale) {
  SolveOutcome out;
  const int nf = static_cast<int>(free.size());
  if (nf == 0) return out;
  const DeflectionModel& model = *s.model;
  std::vector<double> z(nf);
  for (int f = 0; f < nf; ++f) {
    const auto& spec = model.spec(free[f]);
    const double t = std::min(std::max(theta(free[f]), spec.lower), spec.upper);
    z[f] = t / s.typical(free[f]);
  }
  std::vector<double> free_typical(nf);
  for (int f = 0; f < nf; ++f) free_typical[f] = s.typical(free[f]);
  ceres::Problem problem;
  const int n = static_cast<int>(s.data->rows.size());
  for (int r = 0; r < n; ++r)
    problem.AddResidualBlock(new Residual(&s, r, &free, &theta, &free_typical),
                             make_loss(opt.loss, loss_scale(r)), z.data());
  for (int f = 0; f < nf; ++f) {
    const auto& spec = model.spec(free[f]);
    if (spec.lower > -1e299)
      problem.SetParameterLowerBound(z.data(), f, spec.lower / s.typical(free[f]));
    if (spec.upper < 1e299)
      problem.SetParameterUpperBound(z.data(), f, spec.upper / s.typical(free[f]));
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = opt.max_iterations;
  so.logging_type = ceres::SILENT;
  so.minimizer_progress_to_stdout = false;
  so.num_threads = 1;
  so.function_tolerance = 1e-12;
  so.gradient_tolerance = 1e-14;
  so.parameter_tolerance = 1e-12;
  Progress progress(opt.progress);
  if (opt.progress) {
    so.callbacks.push_back(&progress);
    so.update_state_every_iteration = false;
  }
  ceres::Solver::Summary summary;
  std::string why;
  if (!so.IsValid(&why)) throw InvalidArgument("identify: invalid solver options: " + why);
  ceres::Solve(so, &problem, &summary);
  if (progress.cancelled) throw Cancelled("identify: cancelled by the progress callback");
  if (!summary.IsSolutionUsable())
    throw NumericalError("identify: the solver failed: " + summary.message);
  for (int f = 0; f < nf; ++f) theta(free[f]) = z[f] * s.typical(free[f]);
  out.iterations = static_cast<int>(summary.iterations.size());
  out.converged = summary.termination_type == ceres::CONVERGENCE;
  out.message = summary.message;
  return out;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

std::vector<std::string> loss_names() { return known_losses(); }

FitResult identify(const RobotModel& robot,
                   const Dataset& data,
                   const std::vector<std::string>& effects,
                   const IdentifyOptions& opt) {
  // ---- validate everything before Ceres sees it (Ceres CHECK-aborts on misuse).
  const auto& losses = known_losses();
  if (std::find(losses.begin(), losses.end(), opt.loss) == losses.end()) {
    std::string k;
    for (const auto& l : losses) k += " " + l;
    throw InvalidArgument("identify: unknown loss '" + opt.loss + "'; known losses:" + k);
  }
  if (!std::isfinite(opt.loss_scale_m) || opt.loss_scale_m < 0)
    throw InvalidArgument("identify: loss scale must be a finite value >= 0 [m]");
  if (opt.max_iterations <= 0) throw InvalidArgument("identify: max_iterations must be > 0");
  if (!(opt.outlier_weight > 0 && opt.outlier_weight <= 1))
    throw InvalidArgument("identify: outlier_weight must be in (0, 1]");
  if (!(opt.rank_tolerance > 0 && opt.rank_tolerance < 0.1))
    throw InvalidArgument("identify: rank_tolerance must be in (0, 0.1)");
  validate_dataset(data, robot.dof(), true);
  const DeflectionModel model(robot, effects, &data);  // unknown effects, missing masses
  const int n = static_cast<int>(data.rows.size());
  const int p = model.parameter_count();
  if (p == 0)
    throw InvalidArgument("identify: model '" + model.model_string() + "' has no parameters");
  const bool weighted = opt.use_sigma && data.has_sigma;
  if (weighted)
    for (int r = 0; r < n; ++r)
      if (!(data.rows[r].sigma_d > 0))
        throw InvalidArgument("identify: measurement " + std::to_string(r + 1) + " (id '" +
                              data.rows[r].id +
                              "') has sigma_d = 0; give every row a sigma_d > 0 "
                              "or identify without sigma weighting");
  for (int k = 0; k < p; ++k) {
    const auto& sp = model.spec(k);
    if (!(sp.lower <= sp.upper) || !std::isfinite(sp.start))
      throw InvalidArgument("identify: parameter " + qualified(model, k) + " has an invalid spec");
  }

  FitResult f;
  Setup s;
  s.model = &model;
  s.data = &data;
  s.ctx = model.contexts(data);
  s.typical.resize(p);
  for (int k = 0; k < p; ++k) {
    const double t = std::abs(model.spec(k).typical);
    s.typical(k) = t > 0 && std::isfinite(t) ? t : 1.0;
  }

  // ---- start: linear least squares for the joint compliances, spec start for the rest.
  Eigen::VectorXd theta = model.start_parameters();
  const int je = model.find("joint");
  if (je >= 0) {
    try {
      LinearOptions lo;
      lo.use_sigma = opt.use_sigma;
      const FitResult lin = identify_joint_linear(robot, data, lo);
      for (int j = 0; j < robot.dof(); ++j)
        if (lin.parameters[j].identified && lin.parameters[j].value > 0)
          theta(model.offset(je) + j) = lin.parameters[j].value;
    } catch (const NumericalError&) {
      f.warnings.push_back(
          "the linear start of the joint compliances failed; started from the "
          "default compliances");
    }
  }
  for (int k = 0; k < p; ++k)
    theta(k) = std::min(std::max(theta(k), model.spec(k).lower), model.spec(k).upper);

  // ---- noise scale and row weights.
  const double stated = stated_noise_m(data);
  s.row_weight.resize(n);
  Eigen::VectorXd raw(3 * n);
  for (int r = 0; r < n; ++r)
    raw.segment<3>(3 * r) =
        data.rows[r].displacement - model.predict(theta, data.rows[r], s.ctx[r]).head<3>();
  double robust_sigma = 0;
  {
    std::vector<double> a(raw.data(), raw.data() + raw.size());
    const double med = median(a);
    for (auto& v : a) v = std::abs(v - med);
    robust_sigma = 1.4826 * median(a);
  }
  const double noise = stated > 0 ? stated : (robust_sigma > 0 ? robust_sigma : 1e-6);
  for (int r = 0; r < n; ++r) s.row_weight(r) = 1.0 / (weighted ? data.rows[r].sigma_d : noise);
  // Robust threshold on each row's residual norm, in that row's sigma units.
  const double scale_m = opt.loss_scale_m > 0 ? opt.loss_scale_m : 3.0 * noise;
  Eigen::VectorXd loss_scale(n);
  for (int r = 0; r < n; ++r)
    loss_scale(r) = opt.loss_scale_m > 0 ? opt.loss_scale_m * s.row_weight(r)
                                         : (weighted ? 3.0 : 3.0 * noise * s.row_weight(r));

  // ---- identifiability, solve, re-check at the solution (offsets can make c6 visible).
  Identifiability idf;
  std::vector<int> free;
  int iterations = 0;
  SolveOutcome last;
  Eigen::MatrixXd last_jacobian;
  Eigen::VectorXd last_jacobian_theta;
  auto fit_passes = [&]() {
    idf = check_identifiability(model, weighted_jacobian(s, theta), s.typical, opt.rank_tolerance);
    for (int pass = 0;; ++pass) {
      free.clear();
      for (int k = 0; k < p; ++k) {
        if (idf.fixed[k])
          theta(k) = std::min(std::max(model.spec(k).null_value, model.spec(k).lower),
                              model.spec(k).upper);
        else
          free.push_back(k);
      }
      if (free.empty())
        throw NumericalError("identify: no parameter of model '" + model.model_string() +
                             "' is identifiable from this data (are there loads?)");
      if (3 * n <= static_cast<int>(free.size()))
        throw InvalidArgument("identify: " + std::to_string(n) + " measurements give " +
                              std::to_string(3 * n) + " equations for " +
                              std::to_string(free.size()) + " parameters; at least " +
                              std::to_string(free.size() / 3 + 1) + " measurements are needed");
      last = solve(s, free, theta, opt, loss_scale);
      iterations += last.iterations;
      last_jacobian = weighted_jacobian(s, theta);
      last_jacobian_theta = theta;
      Identifiability again =
          check_identifiability(model, last_jacobian, s.typical, opt.rank_tolerance);
      if (again == idf || pass == 2) break;
      // A parameter held so far became visible (or the reverse): solve again from here.
      for (int k = 0; k < p; ++k)
        if (idf.fixed[k] && !again.fixed[k]) theta(k) = std::max(theta(k), model.spec(k).start);
      idf = again;
    }
  };
  fit_passes();
  // Without a stated noise the robust scale comes from the residuals; the start's residuals
  // are inflated by the outliers' pull, so re-estimate it from the robust fit (MAD) and refit.
  double scale_used_m = scale_m;
  if (opt.loss != "none" && opt.loss_scale_m == 0 && stated == 0) {
    for (int round = 0; round < 3; ++round) {
      const Eigen::VectorXd e = weighted_residuals(s, theta) * noise;  // metres
      std::vector<double> a(e.data(), e.data() + e.size());
      const double med = median(a);
      for (auto& v : a) v = std::abs(v - med);
      const double sigma = 1.4826 * median(a);
      if (!(sigma > 0) || std::abs(3.0 * sigma - scale_used_m) < 0.05 * scale_used_m) break;
      scale_used_m = 3.0 * sigma;
      for (int r = 0; r < n; ++r) loss_scale(r) = scale_used_m * s.row_weight(r);
      fit_passes();
    }
  }
  for (int k = 0; k < p; ++k)
    theta(k) = std::min(std::max(theta(k), model.spec(k).lower), model.spec(k).upper);

  // ---- statistics at the solution.
  const Eigen::VectorXd e = weighted_residuals(s, theta);
  f.weights = Eigen::VectorXd::Ones(n);
  for (int r = 0; r < n; ++r) {
    std::unique_ptr<ceres::LossFunction> loss(make_loss(opt.loss, loss_scale(r)));
    if (!loss) continue;
    double rho[3];
    loss->Evaluate(e.segment<3>(3 * r).squaredNorm(), rho);
    f.weights(r) = std::min(1.0, std::max(0.0, rho[1]));
  }
  const int nf = static_cast<int>(free.size());
  // The Jacobian of the last identifiability check is the one at the solution unless the
  // clamping above moved theta.
  const Eigen::MatrixXd jall =
      last_jacobian_theta.size() == theta.size() && last_jacobian_theta == theta
          ? std::move(last_jacobian)
          : weighted_jacobian(s, theta);
  Eigen::MatrixXd jf(3 * n, nf);
  for (int i = 0; i < nf; ++i) jf.col(i) = jall.col(free[i]);
  // Residual variance of the (robustly) weighted problem: sum w^2 |e|^2 / (sum 3 w - p), which
  // is the usual RSS / (3N - p) without a loss and bounded for down-weighted rows.
  double wsum = 0, wrss = 0;
  for (int r = 0; r < n; ++r) {
    const double w = f.weights(r);
    jf.middleRows(3 * r, 3) *= std::sqrt(w);
    wsum += 3.0 * w;
    wrss += w * w * e.segment<3>(3 * r).squaredNorm();
  }
  const double s2 = wsum > nf ? wrss / (wsum - nf) : NAN;
  Eigen::VectorXd norms = jf.colwise().norm().transpose();
  for (int i = 0; i < nf; ++i)
    if (!(norms(i) > 0)) norms(i) = 1.0;
  const Eigen::MatrixXd js = jf * norms.cwiseInverse().asDiagonal();
  // Singular values and V of the tall js from its QR: js = Q R, R = U S V^T.
  Eigen::MatrixXd rs = Eigen::MatrixXd::Zero(nf, nf);
  if (js.rows() >= nf) {
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(js);
    rs = qr.matrixQR().topRows(nf).triangularView<Eigen::Upper>();
  } else {
    rs = js;
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(rs, Eigen::ComputeThinV);
  const Eigen::VectorXd sv = svd.singularValues();
  int rank = 0;
  for (int i = 0; i < sv.size(); ++i)
    if (sv(i) > 1e-12 * sv(0)) ++rank;
  Eigen::VectorXd inv_sv2 = Eigen::VectorXd::Zero(sv.size());
  for (int i = 0; i < rank; ++i) inv_sv2(i) = 1.0 / (sv(i) * sv(i));
  const Eigen::MatrixXd cov_s = svd.matrixV() * inv_sv2.asDiagonal() * svd.matrixV().transpose();

  f.robot_name = robot.name;
  f.robot_path = robot.source_path;
  f.model = model.effect_names();
  f.method = "ceres";
  f.loss = opt.loss;
  f.loss_scale_m = opt.loss == "none" ? 0.0 : scale_used_m;
  f.measurements = n;
  f.rank = rank;
  f.dof = 3 * n - rank;
  f.condition_number = rank > 0 ? sv(0) / sv(rank - 1) : INFINITY;
  f.covariance = Eigen::MatrixXd::Constant(p, p, NAN);
  for (int a = 0; a < nf; ++a)
    for (int b = 0; b < nf; ++b)
      f.covariance(free[a], free[b]) = s2 * cov_s(a, b) / (norms(a) * norms(b));
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
    f.parameters.push_back(fp);
    if (!fp.identified) {
      f.warnings.push_back(qualified(model, k) + " is not identifiable from this data: " +
                           idf.reason[k] + "; held at " + num(theta(k)) + " " + sp.unit);
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
  for (int r = 0; r < n; ++r) f.residuals.segment<3>(3 * r) = e.segment<3>(3 * r) / s.row_weight(r);
  f.rms_m = std::sqrt(f.residuals.squaredNorm() / (3 * n));
  f.noise_floor_m = stated;
  const double resid_scale = weighted ? stated : noise;  // metres per residual unit (typical)
  f.sigma_hat_m = std::sqrt(std::max(0.0, s2)) * resid_scale;
  if (weighted)
    f.chi2 = e.squaredNorm();
  else if (stated > 0)
    f.chi2 = f.residuals.squaredNorm() / (stated * stated);

  // ---- outliers.
  for (int r = 0; r < n; ++r) {
    const double norm_sigma = e.segment<3>(3 * r).norm();
    Outlier o;
    o.row = r;
    o.id = data.rows[r].id;
    o.residual_m = f.residuals.segment<3>(3 * r).norm();
    o.weight = f.weights(r);
    const std::string unit = (weighted || stated > 0) ? " sigma" : " robust sigma";
    if (opt.loss != "none") {
      if (o.weight >= opt.outlier_weight) continue;
      o.reason = "robust weight " + num(o.weight, 2) + " < " + num(opt.outlier_weight, 2) +
                 ": residual " + num(o.residual_m * 1e6) + " um = " + num(norm_sigma) + unit +
                 " (clean rows stay below ~3.4)";
    } else {
      if (norm_sigma <= 5.0) continue;
      o.reason = "residual " + num(o.residual_m * 1e6) + " um = " + num(norm_sigma) + unit +
                 " (> 5); least squares does not down-weight it: use a robust loss";
    }
    f.outliers.push_back(o);
  }
  if (!f.outliers.empty())
    f.warnings.push_back(std::to_string(f.outliers.size()) + " of " + std::to_string(n) +
                         " measurements look like outliers (see the outlier list)");
  return f;
}

}  // namespace stiff
