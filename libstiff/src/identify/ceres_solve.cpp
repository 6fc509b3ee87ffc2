#include "identify/ceres_solve.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "identify/ceres_quiet.hpp"
#include "identify/identifiability.hpp"
#include "identify/robust.hpp"
#include "stiff/error.hpp"

namespace stiff::detail {

const std::vector<std::string>& known_losses() {
  static const std::vector<std::string> names = {"none", "huber", "cauchy", "soft_l1", "tukey"};
  return names;
}

ceres::LossFunction* make_loss(const std::string& name, double a) {
  if (name == "huber") return new ceres::HuberLoss(a);
  if (name == "cauchy") return new ceres::CauchyLoss(a);
  if (name == "soft_l1") return new ceres::SoftLOneLoss(a);
  if (name == "tukey") return new ceres::TukeyLoss(a);
  return nullptr;
}

namespace {

/// What the residual blocks of one solve share: the free parameters (the held ones come from
/// `held`), their typical magnitudes and each row's robust loss.
struct ResidualSetup {
  const Setup* setup;
  const std::vector<int>* free;
  const Eigen::VectorXd* held;
  const std::vector<double>* free_typical;
  const std::vector<const ceres::LossFunction*>* losses;  ///< per row, may be null
};

/// Residuals of measurements first .. first + count - 1 over the free parameters in scaled
/// form: e_r = (measured - predicted) / sigma for each measurement r and, with a robust loss
/// rho on |e_r|^2 = s, the scaled residual sqrt(rho(s) / s) e_r, so that 1/2 |residuals|^2 is
/// the robust cost 1/2 sum_r rho(s_r) with the exact derivative (Gauss-Newton on the scaled
/// residuals instead of Ceres's per-block Triggs correction; the cost and hence the minimum
/// are the same). Each row has D = Setup::dim components (position, and orientation with
/// 6-D data). Writes r (D count) and, when `jac` is not null, their derivatives (D count x
/// free, row-major). Model values and derivatives from the cached Evaluations. False when a
/// value is not finite.
bool chunk_residuals(
    const ResidualSetup& rs, int first, int count, const double* z, double* r, double* jac) {
  const Setup& s = *rs.setup;
  const std::vector<int>& free = *rs.free;
  const int p = s.model->parameter_count();
  const int nf = static_cast<int>(free.size());
  auto& theta = s.theta_double;
  theta.assign(rs.held->data(), rs.held->data() + p);
  for (int f = 0; f < nf; ++f) theta[free[f]] = z[f] * s.typical(free[f]);
  const Evaluations::Key key = s.eval.key(theta.data());
  const int dim = s.dim;
  for (int i = 0; i < count; ++i) {
    const int row = first + i;
    double w[6];
    for (int k = 0; k < dim; ++k) w[k] = s.weight(row, k);
    const double *d = nullptr, *jrow = nullptr;
    const std::vector<int>* jcols = nullptr;
    s.eval.get(row, key, jac ? &free : nullptr, &d, &jrow, &jcols);
    double* ri = r + dim * i;
    double sq = 0.0;
    for (int k = 0; k < dim; ++k) {
      ri[k] = (s.observed(row, k) - d[k]) * w[k];
      sq += ri[k] * ri[k];
    }
    // Non-finite values make Ceres log to stderr; returning false rejects the point quietly.
    if (!std::isfinite(sq)) return false;
    // Robust scaling a = sqrt(rho(s) / s) and da/ds (limits at s = 0).
    double a = 1.0, da = 0.0;
    const ceres::LossFunction* loss = (*rs.losses)[row];
    if (loss) {
      double rho[3];
      loss->Evaluate(sq, rho);
      if (sq > 0) {
        a = std::sqrt(rho[0] / sq);
        da = a > 0 ? (rho[1] * sq - rho[0]) / (2.0 * sq * sq * a) : 0.0;
      } else {
        a = std::sqrt(rho[1]);
        da = a > 0 ? 0.25 * rho[2] / a : 0.0;
      }
    }
    double* ji = jac ? jac + dim * i * nf : nullptr;
    if (ji) {
      const bool every = jcols == &s.eval.all();
      for (int f = 0; f < nf; ++f) {
        const double* col = jrow + dim * (every ? free[f] : f);
        const double scale = -(*rs.free_typical)[f];
        for (int k = 0; k < dim; ++k) ji[k * nf + f] = col[k] * w[k] * scale;
      }
      if (a != 1.0 || da != 0.0) {
        // d(a e) = a de + e (da/ds) 2 e^T de
        for (int f = 0; f < nf; ++f) {
          double g = 0.0;
          for (int k = 0; k < dim; ++k) g += ri[k] * ji[k * nf + f];
          g *= 2.0 * da;
          for (int k = 0; k < dim; ++k) ji[k * nf + f] = a * ji[k * nf + f] + ri[k] * g;
        }
      }
      double nan_if_not_finite = 0.0;  // 0 * x is NaN for an infinite or NaN x
      for (int k = 0; k < dim * nf; ++k) nan_if_not_finite += 0.0 * ji[k];
      if (nan_if_not_finite != 0.0) return false;
    }
    if (loss) {
      double sa = 0.0;
      for (int k = 0; k < dim; ++k) {
        ri[k] *= a;
        sa += ri[k] * ri[k];
      }
      if (!std::isfinite(sa)) return false;
    }
  }
  return true;
}

/// The residuals of a chunk of measurements as one residual block: chunks of many
/// measurements spare Ceres's per-residual-block work, which outweighs the model on small
/// models.
class Residual final : public ceres::CostFunction {
 public:
  Residual(const ResidualSetup& rs, int first, int count) : rs_(rs), first_(first), count_(count) {
    set_num_residuals(rs.setup->dim * count);
    mutable_parameter_block_sizes()->push_back(static_cast<int>(rs.free->size()));
  }
  bool Evaluate(double const* const* z, double* r, double** jacobians) const override {
    return chunk_residuals(rs_, first_, count_, z[0], r,
                           jacobians && jacobians[0] ? jacobians[0] : nullptr);
  }

 private:
  ResidualSetup rs_;
  int first_, count_;
};

/// Every measurement as one block of nf + 1 residuals r' with Jacobian J' (nf + 1 x nf) such
/// that J'^T J' = J^T J, J'^T r' = J^T r and |r'|^2 = |r|^2 for the D N residuals r and their
/// Jacobian J of chunk_residuals: the cost, its gradient and the Gauss-Newton model of every
/// Levenberg-Marquardt step are those of the full problem, so the iterates are the same, but
/// Ceres's passes over the tall Jacobian (copies, validity checks, column scaling, products)
/// become passes over nf + 1 rows. From the eigen-decomposition J^T J = V L V^T: J' = [L^1/2
/// V^T; 0], r' = [L^-1/2 V^T J^T r; sqrt(|r|^2 - |that|^2)] (directions of eigenvalue below
/// 1e-13 of the largest, round-off of J^T J, are left out of r'). Without the Jacobian, r' =
/// (0, .., 0, |r|). For tall problems only, where Ceres would form J^T J anyway.
class CompressedResidual final : public ceres::CostFunction {
 public:
  static constexpr int kChunk = 256;  ///< measurements per pass of chunk_residuals
  CompressedResidual(const ResidualSetup& rs, int rows) : rs_(rs), rows_(rows) {
    const int nf = static_cast<int>(rs.free->size());
    set_num_residuals(nf + 1);
    mutable_parameter_block_sizes()->push_back(nf);
    r_.resize(rs.setup->dim * kChunk);
    j_.resize(rs.setup->dim * kChunk, nf);
  }
  bool Evaluate(double const* const* z, double* r, double** jacobians) const override {
    const int nf = static_cast<int>(rs_.free->size());
    double* jac = jacobians && jacobians[0] ? jacobians[0] : nullptr;
    Eigen::MatrixXd gram = Eigen::MatrixXd::Zero(nf, nf);
    Eigen::VectorXd grad = Eigen::VectorXd::Zero(nf);
    double sq = 0.0;
    for (int first = 0; first < rows_; first += kChunk) {
      const int count = std::min(kChunk, rows_ - first);
      if (!chunk_residuals(rs_, first, count, z[0], r_.data(), jac ? j_.data() : nullptr))
        return false;
      const auto rc = r_.head(rs_.setup->dim * count);
      sq += rc.squaredNorm();
      if (!jac) continue;
      const auto jc = j_.topRows(rs_.setup->dim * count);
      gram.selfadjointView<Eigen::Lower>().rankUpdate(jc.transpose());
      grad.noalias() += jc.transpose() * rc;
    }
    Eigen::Map<Eigen::VectorXd> out(r, nf + 1);
    out.setZero();
    if (!jac) {
      out(nf) = std::sqrt(sq);
      return std::isfinite(out(nf));
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(gram);
    if (es.info() != Eigen::Success) return false;
    const Eigen::VectorXd& lam = es.eigenvalues();  // ascending
    const Eigen::MatrixXd& v = es.eigenvectors();
    Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> jout(
        jac, nf + 1, nf);
    jout.setZero();
    double top = 0.0;
    int rank = 0;
    for (int i = 0; i < nf; ++i) {
      if (!(lam(i) > 1e-13 * lam(nf - 1))) continue;
      ++rank;
      const double root = std::sqrt(lam(i));
      jout.row(i) = root * v.col(i).transpose();
      out(i) = v.col(i).dot(grad) / root;
      top += out(i) * out(i);
    }
    // |r'|^2 = |r|^2 also when round-off puts the projection above the norm.
    if (top > sq) out.head(nf) *= std::sqrt(sq / top);
    out(nf) = std::sqrt(std::max(0.0, sq - top));
    // The relative offset at this point (see RelativeOffset): the part of the residual in the
    // tangent plane, per direction, over the residual's scale in the others.
    const double m = static_cast<double>(rs_.setup->dim) * rows_;
    const double rest = sq - top;
    offset_ = rank > 0 && m > rank && rest > 0 ? std::sqrt((top / rank) / (rest / (m - rank)))
                                               : std::numeric_limits<double>::infinity();
    return std::isfinite(top) && std::isfinite(sq);
  }
  /// The relative offset at the point of the last Jacobian evaluation (infinite before one,
  /// or without a residual to compare with).
  double offset() const { return offset_; }

 private:
  ResidualSetup rs_;
  int rows_;
  mutable Eigen::VectorXd r_;
  mutable Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> j_;
  mutable double offset_ = std::numeric_limits<double>::infinity();
};

/// Stops the minimizer once the iterate is statistically converged: the relative offset of
/// Bates & Watts (1981, Technometrics 23:179), sqrt((|Q1^T r|^2 / p) / (|Q2^T r|^2 / (m - p)))
/// with Q1 the tangent plane of the p parameter directions, is below kTolerance. It compares
/// what one more Gauss-Newton step can still gain with the residual scale, so below 0.001 the
/// iterate lies within a thousandth of the radius of any confidence region of the parameters
/// from the least-squares solution; the steps that Ceres's relative cost tolerance (1e-12)
/// would still take change nothing a user can see. A problem without residual (noise-free
/// data) or with a parameter on its bound, where the offset does not vanish, keeps Ceres's
/// own tolerances.
class RelativeOffset : public ceres::IterationCallback {
 public:
  static constexpr double kTolerance = 1e-3;
  explicit RelativeOffset(const CompressedResidual& r) : r_(r) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& it) override {
    if (!it.step_is_successful || it.iteration == 0 || !(r_.offset() < kTolerance))
      return ceres::SOLVER_CONTINUE;
    fired = true;
    return ceres::SOLVER_TERMINATE_SUCCESSFULLY;
  }
  bool fired = false;

 private:
  const CompressedResidual& r_;
};

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

/// Stops the minimizer when free parameters have sat on a bound for kPinAfter successful
/// iterations: projected Levenberg-Marquardt then converges only linearly (a step computed as
/// if the parameter could cross the bound is clipped every iteration), so the caller holds
/// them at the bound and solves for the rest (an active set, checked at the end).
class BoundWatch : public ceres::IterationCallback {
 public:
  static constexpr int kPinAfter = 3;
  BoundWatch(const double* z, const std::vector<double>& lower, const std::vector<double>& upper)
      : z_(z), lower_(lower), upper_(upper), count_(lower.size(), 0) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& it) override {
    if (!it.step_is_successful || it.iteration == 0) return ceres::SOLVER_CONTINUE;
    for (size_t f = 0; f < count_.size(); ++f) {
      count_[f] = (z_[f] == lower_[f] || z_[f] == upper_[f]) ? count_[f] + 1 : 0;
      if (count_[f] >= kPinAfter) pinned.push_back(static_cast<int>(f));
    }
    return pinned.empty() ? ceres::SOLVER_CONTINUE : ceres::SOLVER_TERMINATE_SUCCESSFULLY;
  }
  std::vector<int> pinned;  ///< indices into the solve's parameters

 private:
  const double* z_;
  const std::vector<double>& lower_;
  const std::vector<double>& upper_;
  std::vector<int> count_;
};

/// Stops the minimizer as soon as a held parameter becomes identifiable at an accepted
/// iterate (point_offset makes c6 visible once the offsets move): the caller re-solves with
/// it free from there instead of first converging without it.
class VisibleWatch : public ceres::IterationCallback {
 public:
  VisibleWatch(const Setup& s,
               const double* z,
               const std::vector<int>& free,
               const Eigen::VectorXd& held,
               const Visible& visible)
      : s_(s), z_(z), free_(free), theta_(held), visible_(visible) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& it) override {
    if (!it.step_is_successful || it.iteration == 0) return ceres::SOLVER_CONTINUE;
    for (size_t f = 0; f < free_.size(); ++f) theta_(free_[f]) = z_[f] * s_.typical(free_[f]);
    try {
      fired = visible_(theta_);
    } catch (...) {
      fired = false;  // decided at the solution instead
    }
    return fired ? ceres::SOLVER_TERMINATE_SUCCESSFULLY : ceres::SOLVER_CONTINUE;
  }
  bool fired = false;

 private:
  const Setup& s_;
  const double* z_;
  const std::vector<int>& free_;
  Eigen::VectorXd theta_;
  const Visible& visible_;
};

/// One Ceres solve over `free` (the rest of theta held); theta is updated in place. With
/// `pinned`, parameters found sitting on a bound stop the solve and are returned there; with
/// `visible`, a held parameter becoming identifiable stops it (out.restart).
SolveOutcome solve_once(const Setup& s,
                        const std::vector<int>& free,
                        Eigen::VectorXd& theta,
                        const IdentifyOptions& opt,
                        const Eigen::VectorXd& loss_scale,
                        std::vector<int>* pinned,
                        const Visible* visible) {
  SolveOutcome out;
  const int nf = static_cast<int>(free.size());
  if (nf == 0) return out;
  const DeflectionModel& model = *s.model;
  std::vector<double> z(nf), lower(nf, -INFINITY), upper(nf, INFINITY);
  for (int f = 0; f < nf; ++f) {
    const auto& spec = model.spec(free[f]);
    const double t = std::min(std::max(theta(free[f]), spec.lower), spec.upper);
    z[f] = t / s.typical(free[f]);
    theta(free[f]) = z[f] * s.typical(free[f]);  // the point the residuals see (cache key)
  }
  std::vector<double> free_typical(nf);
  for (int f = 0; f < nf; ++f) free_typical[f] = s.typical(free[f]);
  ceres::Problem problem;
  const int n = static_cast<int>(s.data->rows.size());
  // One loss per distinct scale, shared by its rows (no object per row to fetch).
  std::vector<std::unique_ptr<ceres::LossFunction>> owned;
  std::map<double, const ceres::LossFunction*> by_scale;
  std::vector<const ceres::LossFunction*> losses(n);
  for (int r = 0; r < n; ++r) {
    auto it = by_scale.find(loss_scale(r));
    if (it == by_scale.end()) {
      owned.emplace_back(make_loss(opt.loss, loss_scale(r)));
      it = by_scale.emplace(loss_scale(r), owned.back().get()).first;
    }
    losses[r] = it->second;
  }
  const ResidualSetup rs{&s, &free, &theta, &free_typical, &losses};
  // Tall problems as one compressed block (Ceres would take the normal equations anyway);
  // else chunks of 64 measurements, solved by QR.
  const bool tall = s.dim * n >= 10 * nf;
  CompressedResidual* compressed = nullptr;  // owned by `problem`
  if (tall) {
    compressed = new CompressedResidual(rs, n);
    problem.AddResidualBlock(compressed, nullptr, z.data());
  } else {
    constexpr int kChunk = 64;  // measurements per residual block
    for (int r = 0; r < n; r += kChunk)
      problem.AddResidualBlock(new Residual(rs, r, std::min(kChunk, n - r)), nullptr, z.data());
  }
  for (int f = 0; f < nf; ++f) {
    const auto& spec = model.spec(free[f]);
    if (spec.lower > -1e299) {
      lower[f] = spec.lower / s.typical(free[f]);
      problem.SetParameterLowerBound(z.data(), f, lower[f]);
    }
    if (spec.upper < 1e299) {
      upper[f] = spec.upper / s.typical(free[f]);
      problem.SetParameterUpperBound(z.data(), f, upper[f]);
    }
  }
  ceres::Solver::Options so;
  // QR: of the nf + 1 compressed rows of a tall problem (whose J^T J is formed once per
  // Jacobian, as the normal equations would), of the chunks' rows otherwise.
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = opt.max_iterations;
  so.logging_type = ceres::SILENT;
  so.minimizer_progress_to_stdout = false;
  so.num_threads = 1;
  so.function_tolerance = 1e-12;
  so.gradient_tolerance = 1e-14;
  so.parameter_tolerance = 1e-12;
  // The projected line search of a bounded problem: backtracking by bisection needs no
  // Jacobian at the trial point (cubic interpolation evaluates one, wasted whenever the step
  // is rejected or ends the solve).
  so.line_search_interpolation_type = ceres::BISECTION;
  Progress progress(opt.progress);
  if (opt.progress) so.callbacks.push_back(&progress);
  BoundWatch watch(z.data(), lower, upper);
  if (pinned) {
    so.callbacks.push_back(&watch);
    so.update_state_every_iteration = true;  // the watch reads z
  }
  std::unique_ptr<VisibleWatch> seen;
  if (visible && *visible) {
    seen = std::make_unique<VisibleWatch>(s, z.data(), free, theta, *visible);
    so.callbacks.push_back(seen.get());
    so.update_state_every_iteration = true;
  }
  std::unique_ptr<RelativeOffset> settled;
  if (compressed) {
    settled = std::make_unique<RelativeOffset>(*compressed);
    so.callbacks.push_back(settled.get());
  }
  ceres::Solver::Summary summary;
  std::string why;
  if (!so.IsValid(&why)) throw InvalidArgument("identify: invalid solver options: " + why);
  double start_cost = 0;
  if (!problem.Evaluate(ceres::Problem::EvaluateOptions(), &start_cost, nullptr, nullptr,
                        nullptr) ||
      !std::isfinite(start_cost))
    throw NumericalError(
        "identify: the residuals overflow: check the units and sizes of the loads and "
        "displacements (N, N*m, m)");
  ceres_quiet::InvalidStepGuard guard;  // Ceres must not print (ceres_quiet.hpp)
  ceres_quiet::install(so, guard);
  ceres::Solve(so, &problem, &summary);
  if (progress.cancelled) throw Cancelled("identify: cancelled by the progress callback");
  ceres_quiet::check(guard, "identify");
  if (!summary.IsSolutionUsable())
    throw NumericalError("identify: the solver failed: " + summary.message);
  for (int f = 0; f < nf; ++f) theta(free[f]) = z[f] * s.typical(free[f]);
  if (pinned)
    for (int f : watch.pinned) pinned->push_back(free[f]);
  out.restart = seen && seen->fired;
  out.iterations = static_cast<int>(summary.iterations.size());
  out.converged = summary.termination_type == ceres::CONVERGENCE || (settled && settled->fired);
  out.message = summary.message;
  return out;
}

/// Derivative of the cost 1/2 sum_r rho(|e_r|^2) with respect to theta(k) * typical(k) for
/// k in `cols` (at most kJetStride), at theta.
Eigen::VectorXd cost_gradient(const Setup& s,
                              const Eigen::VectorXd& theta,
                              const std::vector<int>& cols,
                              const IdentifyOptions& opt,
                              const Eigen::VectorXd& loss_scale) {
  const int nc = static_cast<int>(cols.size());
  std::vector<double> scale(nc);
  for (int i = 0; i < nc; ++i) scale[i] = s.typical(cols[i]);
  Eigen::VectorXd g = Eigen::VectorXd::Zero(nc);
  const int dim = s.dim;
  Eigen::MatrixXd blk(dim, nc);
  double d[6];
  for (int r = 0; r < static_cast<int>(s.data->rows.size()); ++r) {
    displacement_and_jacobian(s, r, theta.data(), cols, scale.data(), false, d, blk.data());
    Eigen::VectorXd e(dim), w(dim);
    for (int k = 0; k < dim; ++k) {
      w(k) = s.weight(r, k);
      e(k) = (s.observed(r, k) - d[k]) * w(k);
    }
    double rho[3] = {0, 1, 0};
    std::unique_ptr<ceres::LossFunction> loss(make_loss(opt.loss, loss_scale(r)));
    if (loss) loss->Evaluate(e.squaredNorm(), rho);
    g -= rho[1] * (blk.transpose() * w.cwiseProduct(e));
  }
  return g;
}

}  // namespace

SolveOutcome solve(const Setup& s,
                   const std::vector<int>& free,
                   Eigen::VectorXd& theta,
                   const IdentifyOptions& opt,
                   const Eigen::VectorXd& loss_scale,
                   const Visible* visible) {
  constexpr int kRounds = 4;
  SolveOutcome out;
  std::vector<int> pinned;
  for (int round = 0;; ++round) {
    const bool last = round == kRounds;
    if (last) pinned.clear();
    std::vector<int> active;
    for (int k : free)
      if (std::find(pinned.begin(), pinned.end(), k) == pinned.end()) active.push_back(k);
    std::vector<int> fresh;
    const SolveOutcome o =
        solve_once(s, active, theta, opt, loss_scale, last ? nullptr : &fresh, visible);
    out.iterations += o.iterations;
    out.converged = o.converged;
    out.message = o.message;
    if (o.restart) {
      out.restart = true;
      break;
    }
    if (!fresh.empty()) {
      pinned.insert(pinned.end(), fresh.begin(), fresh.end());
      continue;
    }
    if (pinned.empty() || last) break;
    std::vector<int> release;
    for (size_t first = 0; first < pinned.size(); first += kJetStride) {
      const std::vector<int> cols(pinned.begin() + first,
                                  pinned.begin() + std::min(pinned.size(), first + kJetStride));
      const Eigen::VectorXd g = cost_gradient(s, theta, cols, opt, loss_scale);
      for (size_t i = 0; i < cols.size(); ++i) {
        // Into the range is up from a lower bound, down from an upper one.
        const bool at_lower = theta(cols[i]) <= s.model->spec(cols[i]).lower;
        if ((at_lower ? -g(i) : g(i)) > 1e-9 * (1.0 + g.cwiseAbs().maxCoeff()))
          release.push_back(cols[i]);
      }
    }
    if (release.empty()) break;
    for (int k : release) pinned.erase(std::find(pinned.begin(), pinned.end(), k));
  }
  return out;
}

}  // namespace stiff::detail
