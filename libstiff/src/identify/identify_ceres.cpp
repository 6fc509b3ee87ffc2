// Nonlinear identification of any effect model with Ceres: robust losses, identifiability
// check, covariance and outliers (identify.hpp).
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
#include <sstream>

#include "identify/ceres_quiet.hpp"
#include "identify/identifiability.hpp"
#include "identify/robust.hpp"
#include "stiff/error.hpp"
#include "stiff/identify/identify.hpp"

namespace stiff {
namespace detail {
// validate_dataset(data, dof, true) without strings per row (identify_linear.cpp).
void validate_identification_data(const Dataset& data, int dof);
}  // namespace detail
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

struct Setup;

/// Model evaluations per measurement, cached: the trust-region minimizer evaluates the
/// Jacobian at a trial point in its line search and again when it accepts it, the cost there
/// in between, and the identifiability check and the statistics want the Jacobian at the
/// solution, where the minimizer last evaluated it. Each row keeps its last two evaluations
/// (d and, when asked for, dd/dtheta for every parameter or for one column set), tagged with
/// the key of their theta: the recent distinct thetas get keys (key()), so that a row stores
/// and compares one number instead of a copy of theta (rows then stream less memory). A model
/// made only of linear effects (Effect::linear) predicts d affine in theta: after one Jacobian
/// evaluation per row, d and its derivatives follow without the model.
class Evaluations {
 public:
  /// A parameter vector and its key.
  struct Key {
    const double* theta;
    unsigned id;
  };
  void init(const Setup* s, int rows, int p, bool linear);
  /// The key of theta (its contents: equal vectors have equal keys while they are among the
  /// kKeys most recent distinct ones; an older one gets a new key and misses the cache).
  Key key(const double* theta);
  /// d and, with `cols` (a list owned by the caller and stable while cached), the derivatives
  /// dd/dtheta(k) (3 per column, column-major) of row `row` at key.theta. `*jcols` says which
  /// columns `*jac` holds: `cols` itself or all() (every parameter).
  void get(int row,
           const Key& key,
           const std::vector<int>* cols,
           const double** d,
           const double** jac,
           const std::vector<int>** jcols);
  const std::vector<int>& all() const { return all_; }

 private:
  static constexpr int kKeys = 16;
  const Setup* s_ = nullptr;
  int p_ = 0;
  bool linear_ = false;
  std::vector<int> all_;
  std::vector<double> keys_;  ///< kKeys thetas, slot id % kKeys holds key id
  unsigned next_ = 1;         ///< next key (0: empty)
  std::vector<double> d_, jac_;
  std::vector<unsigned> id_;                   ///< per slot: key of its theta, 0 empty
  std::vector<char> used_;                     ///< per slot: 0 empty, else recency 1 or 2
  std::vector<const std::vector<int>*> cols_;  ///< per slot: nullptr (value only), &all_, list
  std::vector<char> ref_;                      ///< per row: linear model's reference present
  std::vector<double> ref_theta_, ref_d_, ref_jac_;
};

/// Everything the residuals need, fixed for one call.
struct Setup {
  const DeflectionModel* model = nullptr;
  const Dataset* data = nullptr;
  std::vector<MeasurementContext> ctx;
  Eigen::VectorXd row_weight;  ///< 1 / (sigma of the row) [1/m]
  Eigen::VectorXd typical;     ///< parameter scaling: theta_k = typical_k * z_k
  /// Scratch of the evaluations (Ceres runs single-threaded here: num_threads = 1).
  mutable EvalState<Jet> scratch;
  mutable EvalState<double> dscratch;
  mutable std::vector<Jet> theta_jet;
  mutable std::vector<double> theta_double;
  mutable Evaluations eval;
};

/// Derivatives of the predicted displacement of measurement `row` with respect to
/// theta(cols[i]) * scale[i] (scale null: ones), by kJetStride parameters per pass of
/// DeflectionModel::evaluate_jet; `theta` is the full parameter vector. Writes d (3) and the
/// 3 x cols.size() derivatives (column-major, leading dimension 3) into `out`. With `every`
/// (cols lists every parameter, no scale) of an analytic model, the passes differentiate only
/// its jet_parameters() and the other columns come from DeflectionModel::analytic_columns.
void displacement_and_jacobian(const Setup& s,
                               int row,
                               const double* theta,
                               const std::vector<int>& cols,
                               const double* scale,
                               bool every,
                               Eigen::Vector3d& d,
                               double* out) {
  const DeflectionModel& model = *s.model;
  const int p = model.parameter_count();
  auto& t = s.theta_jet;
  t.resize(p);
  for (int k = 0; k < p; ++k) t[k] = Jet(theta[k]);
  const bool analytic = every && model.analytic();
  const std::vector<int>& jc = analytic ? model.jet_parameters() : cols;
  const int nc = static_cast<int>(jc.size());
  const Measurement& m = s.data->rows[row];
  Vector3<Jet> dj;
  if (nc == 0) model.evaluate_jet(t.data(), m, s.ctx[row], s.scratch, &dj);
  for (int first = 0; first < nc; first += kJetStride) {
    const int last = std::min(nc, first + kJetStride);
    for (int i = first; i < last; ++i) t[jc[i]].v(i - first) = scale ? scale[i] : 1.0;
    model.evaluate_jet(t.data(), m, s.ctx[row], s.scratch, &dj);
    for (int i = first; i < last; ++i) {
      t[jc[i]].v(i - first) = 0.0;
      double* o = out + 3 * (analytic ? jc[i] : i);
      for (int k = 0; k < 3; ++k) o[k] = dj(k).v(i - first);
    }
  }
  for (int k = 0; k < 3; ++k) d(k) = dj(k).a;
  if (analytic) model.analytic_columns(s.scratch, s.dscratch, out);
}

void Evaluations::init(const Setup* s, int rows, int p, bool linear) {
  s_ = s;
  p_ = p;
  linear_ = linear;
  all_.resize(p);
  for (int k = 0; k < p; ++k) all_[k] = k;
  keys_.assign(static_cast<size_t>(kKeys) * p, 0.0);
  next_ = 1;
  d_.assign(6 * static_cast<size_t>(rows), 0.0);
  jac_.assign(6 * static_cast<size_t>(rows) * p, 0.0);
  id_.assign(2 * static_cast<size_t>(rows), 0);
  used_.assign(2 * static_cast<size_t>(rows), 0);
  cols_.assign(2 * static_cast<size_t>(rows), nullptr);
  if (linear) {
    ref_.assign(rows, 0);
    ref_theta_.assign(static_cast<size_t>(rows) * p, 0.0);
    ref_d_.assign(3 * static_cast<size_t>(rows), 0.0);
    ref_jac_.assign(3 * static_cast<size_t>(rows) * p, 0.0);
  }
}

Evaluations::Key Evaluations::key(const double* theta) {
  const unsigned oldest = next_ > kKeys ? next_ - kKeys : 1;
  for (unsigned id = next_; id-- > oldest;)  // the most recent first
    if (std::memcmp(theta, keys_.data() + (id % kKeys) * p_, p_ * sizeof(double)) == 0)
      return {theta, id};
  const unsigned id = next_++;
  std::copy(theta, theta + p_, keys_.data() + (id % kKeys) * p_);
  return {theta, id};
}

void Evaluations::get(int row,
                      const Key& key,
                      const std::vector<int>* cols,
                      const double** d,
                      const double** jac,
                      const std::vector<int>** jcols) {
  const size_t r2 = 2 * static_cast<size_t>(row);
  const double* theta = key.theta;
  int slot = -1;
  for (int k = 0; k < 2 && slot < 0; ++k)
    if (id_[r2 + k] == key.id && (!cols || cols_[r2 + k] == &all_ || cols_[r2 + k] == cols))
      slot = k;
  if (slot < 0) {
    // Replace the entry at this theta (it lacks the columns) or else the older one.
    if (id_[r2] == key.id)
      slot = 0;
    else if (id_[r2 + 1] == key.id)
      slot = 1;
    else
      slot = used_[r2] <= used_[r2 + 1] ? 0 : 1;
    const size_t i = r2 + slot;
    double* dd = d_.data() + 3 * i;
    double* jj = jac_.data() + 3 * i * p_;
    Eigen::Vector3d dv;
    if (linear_ && ref_[row]) {
      // d = d0 + J (theta - theta0), exact for a model affine in theta.
      const double* t0 = ref_theta_.data() + static_cast<size_t>(row) * p_;
      const double* j0 = ref_jac_.data() + 3 * static_cast<size_t>(row) * p_;
      dv = Eigen::Map<const Eigen::Vector3d>(ref_d_.data() + 3 * static_cast<size_t>(row));
      for (int k = 0; k < p_; ++k)
        if (theta[k] != t0[k])
          dv += Eigen::Map<const Eigen::Vector3d>(j0 + 3 * k) * (theta[k] - t0[k]);
      std::copy(j0, j0 + 3 * p_, jj);
      cols_[i] = &all_;
    } else if (cols || linear_) {
      // Every column when that takes no more passes of the model than the ones asked for.
      const int want = cols ? static_cast<int>(cols->size()) : 0;
      const int passes = static_cast<int>(s_->model->jet_parameters().size()) + kJetStride - 1;
      const bool every = linear_ || passes / kJetStride <= (want + kJetStride - 1) / kJetStride;
      const std::vector<int>& c = every ? all_ : *cols;
      displacement_and_jacobian(*s_, row, theta, c, nullptr, every, dv, jj);
      cols_[i] = every ? &all_ : cols;
      if (linear_) {
        ref_[row] = 1;
        std::copy(theta, theta + p_, ref_theta_.data() + static_cast<size_t>(row) * p_);
        std::copy(dv.data(), dv.data() + 3, ref_d_.data() + 3 * static_cast<size_t>(row));
        std::copy(jj, jj + 3 * p_, ref_jac_.data() + 3 * static_cast<size_t>(row) * p_);
      }
    } else {
      Vector3<double> v;
      s_->model->evaluate_double(theta, s_->data->rows[row], s_->ctx[row], s_->dscratch, &v);
      dv = v;
      cols_[i] = nullptr;
    }
    std::copy(dv.data(), dv.data() + 3, dd);
    id_[i] = key.id;
  }
  const size_t i = r2 + slot;
  used_[i] = 2;
  used_[r2 + (1 - slot)] = used_[r2 + (1 - slot)] ? 1 : 0;
  *d = d_.data() + 3 * i;
  if (jac) *jac = jac_.data() + 3 * i * p_;
  if (jcols) *jcols = cols_[i];
}

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
/// are the same). Writes r (3 count) and, when `jac` is not null, their derivatives (3 count x
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
  for (int i = 0; i < count; ++i) {
    const int row = first + i;
    const Measurement& m = s.data->rows[row];
    const double w = s.row_weight(row);
    const double *d = nullptr, *jrow = nullptr;
    const std::vector<int>* jcols = nullptr;
    s.eval.get(row, key, jac ? &free : nullptr, &d, &jrow, &jcols);
    double* ri = r + 3 * i;
    for (int k = 0; k < 3; ++k) ri[k] = (m.observed()(k) - d[k]) * w;
    const double sq = ri[0] * ri[0] + ri[1] * ri[1] + ri[2] * ri[2];
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
    double* ji = jac ? jac + 3 * i * nf : nullptr;
    if (ji) {
      const bool every = jcols == &s.eval.all();
      for (int f = 0; f < nf; ++f) {
        const double* col = jrow + 3 * (every ? free[f] : f);
        const double scale = -w * (*rs.free_typical)[f];
        for (int k = 0; k < 3; ++k) ji[k * nf + f] = col[k] * scale;
      }
      if (a != 1.0 || da != 0.0) {
        // d(a e) = a de + e (da/ds) 2 e^T de
        for (int f = 0; f < nf; ++f) {
          const double g = 2.0 * da * (ri[0] * ji[f] + ri[1] * ji[nf + f] + ri[2] * ji[2 * nf + f]);
          for (int k = 0; k < 3; ++k) ji[k * nf + f] = a * ji[k * nf + f] + ri[k] * g;
        }
      }
      double nan_if_not_finite = 0.0;  // 0 * x is NaN for an infinite or NaN x
      for (int k = 0; k < 3 * nf; ++k) nan_if_not_finite += 0.0 * ji[k];
      if (nan_if_not_finite != 0.0) return false;
    }
    if (loss) {
      for (int k = 0; k < 3; ++k) ri[k] *= a;
      if (!std::isfinite(ri[0] * ri[0] + ri[1] * ri[1] + ri[2] * ri[2])) return false;
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
    set_num_residuals(3 * count);
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
/// that J'^T J' = J^T J, J'^T r' = J^T r and |r'|^2 = |r|^2 for the 3N residuals r and their
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
    r_.resize(3 * kChunk);
    j_.resize(3 * kChunk, nf);
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
      const auto rc = r_.head(3 * count);
      sq += rc.squaredNorm();
      if (!jac) continue;
      const auto jc = j_.topRows(3 * count);
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
    for (int i = 0; i < nf; ++i) {
      if (!(lam(i) > 1e-13 * lam(nf - 1))) continue;
      const double root = std::sqrt(lam(i));
      jout.row(i) = root * v.col(i).transpose();
      out(i) = v.col(i).dot(grad) / root;
      top += out(i) * out(i);
    }
    // |r'|^2 = |r|^2 also when round-off puts the projection above the norm.
    if (top > sq) out.head(nf) *= std::sqrt(sq / top);
    out(nf) = std::sqrt(std::max(0.0, sq - top));
    return std::isfinite(top) && std::isfinite(sq);
  }

 private:
  ResidualSetup rs_;
  int rows_;
  mutable Eigen::VectorXd r_;
  mutable Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> j_;
};

/// Weighted residuals e (3N, sigma units) at theta.
Eigen::VectorXd weighted_residuals(const Setup& s, const Eigen::VectorXd& theta) {
  const int n = static_cast<int>(s.data->rows.size());
  Eigen::VectorXd e(3 * n);
  const Evaluations::Key key = s.eval.key(theta.data());
  for (int r = 0; r < n; ++r) {
    const double* d = nullptr;
    s.eval.get(r, key, nullptr, &d, nullptr, nullptr);
    e.segment<3>(3 * r) =
        (s.data->rows[r].observed() - Eigen::Map<const Eigen::Vector3d>(d)) * s.row_weight(r);
  }
  return e;
}

/// Jacobian of the predicted, weighted displacement with respect to theta (3N x P).
Eigen::MatrixXd weighted_jacobian(const Setup& s, const Eigen::VectorXd& theta) {
  const int n = static_cast<int>(s.data->rows.size());
  const int p = s.model->parameter_count();
  Eigen::MatrixXd j(3 * n, p);
  const Evaluations::Key key = s.eval.key(theta.data());
  for (int r = 0; r < n; ++r) {
    const double *d = nullptr, *jac = nullptr;
    s.eval.get(r, key, &s.eval.all(), &d, &jac, nullptr);
    j.middleRows(3 * r, 3) =
        Eigen::Map<const Eigen::Matrix<double, 3, Eigen::Dynamic>>(jac, 3, p) * s.row_weight(r);
  }
  return j;
}

/// Whether any parameter marked in `held` moves the weighted predictions at theta (column
/// norm times its typical magnitude above 1e-9, the identifiability check's first test).
bool held_has_effect(const Setup& s, const Eigen::VectorXd& theta, const std::vector<bool>& held) {
  if (std::find(held.begin(), held.end(), true) == held.end()) return false;
  const int p = s.model->parameter_count();
  Eigen::VectorXd sq = Eigen::VectorXd::Zero(p);
  const Evaluations::Key key = s.eval.key(theta.data());
  for (int r = 0; r < static_cast<int>(s.data->rows.size()); ++r) {
    const double *d = nullptr, *jac = nullptr;
    s.eval.get(r, key, &s.eval.all(), &d, &jac, nullptr);
    const double w2 = s.row_weight(r) * s.row_weight(r);
    for (int k = 0; k < p; ++k)
      if (held[k])
        sq(k) += w2 * (jac[3 * k] * jac[3 * k] + jac[3 * k + 1] * jac[3 * k + 1] +
                       jac[3 * k + 2] * jac[3 * k + 2]);
  }
  for (int k = 0; k < p; ++k)
    if (held[k] && std::sqrt(sq(k)) * s.typical(k) > 1e-9) return true;
  return false;
}

using detail::check_identifiability;
using detail::Identifiability;
using detail::qualified;

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
  bool restart = false;  ///< stopped because a held parameter became identifiable
  std::string message;
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

/// True when a parameter held as unidentifiable has become identifiable at theta.
using Visible = std::function<bool(const Eigen::VectorXd& theta)>;

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
  const bool tall = 3 * n >= 10 * nf;
  if (tall) {
    problem.AddResidualBlock(new CompressedResidual(rs, n), nullptr, z.data());
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
  out.converged = summary.termination_type == ceres::CONVERGENCE;
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
  Eigen::Matrix<double, 3, Eigen::Dynamic> blk(3, nc);
  Eigen::Vector3d d;
  for (int r = 0; r < static_cast<int>(s.data->rows.size()); ++r) {
    displacement_and_jacobian(s, r, theta.data(), cols, scale.data(), false, d, blk.data());
    const double w = s.row_weight(r);
    const Eigen::Vector3d e = (s.data->rows[r].observed() - d) * w;
    double rho[3] = {0, 1, 0};
    std::unique_ptr<ceres::LossFunction> loss(make_loss(opt.loss, loss_scale(r)));
    if (loss) loss->Evaluate(e.squaredNorm(), rho);
    g -= rho[1] * w * (blk.transpose() * e);
  }
  return g;
}

/// Minimise over the free parameters within their bounds; theta (full) is updated in place.
/// Parameters that settle on a bound are held there and the rest solved again; at the end a
/// held parameter whose cost derivative points into the feasible range is released (KKT), and
/// after a few rounds the plain bounded solve over every free parameter is the fallback.
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
  if (!(opt.max_relative_se >= 0) || !std::isfinite(opt.max_relative_se))
    throw InvalidArgument("identify: max_relative_se must be a finite value >= 0");
  detail::validate_identification_data(data, robot.dof());
  const DeflectionModel model(robot, effects, &data);  // unknown effects, missing masses
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
  Setup s;
  s.model = &model;
  s.data = &data;
  s.ctx = model.contexts(data);
  s.typical.resize(p);
  for (int k = 0; k < p; ++k) {
    const double t = std::abs(model.spec(k).typical);
    s.typical(k) = t > 0 && std::isfinite(t) ? t : 1.0;
  }
  s.eval.init(&s, n, p, model.linear());

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

  // ---- noise scale and row weights.
  const double stated = stated_noise_m(data);
  s.row_weight.resize(n);
  Eigen::VectorXd raw(3 * n);
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
  // Robust threshold on each row's residual norm, in that row's sigma units: 3 sigma for the
  // monotone losses. Tukey's biweight gets the same Gaussian efficiency as Huber's: the classical
  // constants for 95 % are 1.345 sigma (Huber) and 4.685 sigma (Tukey) (Holland & Welsch 1977),
  // so 3 * 4.685 / 1.345 = 10.4 sigma; at 3 sigma it gives clean rows weights below one half.
  const double c_sigma = opt.loss == "tukey" ? 3.0 * 4.685 / 1.345 : 3.0;
  const double scale_m = opt.loss_scale_m > 0 ? opt.loss_scale_m : c_sigma * noise;
  Eigen::VectorXd loss_scale(n);
  for (int r = 0; r < n; ++r)
    loss_scale(r) = opt.loss_scale_m > 0 ? opt.loss_scale_m * s.row_weight(r)
                                         : (weighted ? c_sigma : c_sigma * noise * s.row_weight(r));

  // ---- identifiability, solve, re-check at the solution (offsets can make c6 visible).
  Identifiability idf;
  std::vector<int> free;
  int iterations = 0;
  const IdentifyOptions* solving = &opt;
  SolveOutcome last;
  Eigen::MatrixXd last_jacobian;
  Eigen::VectorXd last_jacobian_theta;
  double residual_sigma = 0.0;  // 0: the structural test only (the passes)
  // The statistical test judges only values a solve fitted (`free`): a value held at its
  // null so far is not evidence either way.
  // Parameters decided already (given by the start fit; on absolute data, those held at the
  // start): their columns take no part in the decision `run` makes about the others, and they
  // keep their own decision.
  Identifiability given_idf;
  given_idf.fixed = given;
  given_idf.statistical.assign(p, false);
  given_idf.reason.assign(p, "");
  for (int k = 0; k < p; ++k)
    if (given[k]) given_idf.reason[k] = "given by the start fit";
  auto apart = [&](const Eigen::MatrixXd& jac, const Identifiability& decided, auto&& run) {
    const bool any =
        std::find(decided.fixed.begin(), decided.fixed.end(), true) != decided.fixed.end();
    Eigen::MatrixXd rest;
    if (any) {
      rest = jac;
      for (int k = 0; k < p; ++k)
        if (decided.fixed[k]) rest.col(k).setZero();
    }
    Identifiability out = run(any ? rest : jac);
    for (int k = 0; k < p; ++k)
      if (decided.fixed[k]) {
        out.fixed[k] = true;
        out.statistical[k] = decided.statistical[k];
        out.reason[k] = decided.reason[k];
      }
    return out;
  };
  auto check = [&](const Eigen::MatrixXd& jac, const Eigen::VectorXd& at) {
    std::vector<bool> fitted(p, false);
    for (int k : free) fitted[k] = true;
    return apart(jac, given_idf, [&](const Eigen::MatrixXd& j) {
      return check_identifiability(model, j, s.typical, opt.rank_tolerance, residual_sigma,
                                   opt.max_relative_se, &at, &fitted);
    });
  };
  // Residual standard deviation of the weighted fit at theta, as the statistics below: rows
  // down-weighted by the robust loss count that much.
  auto robust_residual_sigma = [&]() {
    const Eigen::VectorXd e = weighted_residuals(s, theta);
    double wsum = 0, wrss = 0;
    for (int r = 0; r < n; ++r) {
      double w = 1.0;
      std::unique_ptr<ceres::LossFunction> loss(make_loss(opt.loss, loss_scale(r)));
      if (loss) {
        double rho[3];
        loss->Evaluate(e.segment<3>(3 * r).squaredNorm(), rho);
        w = std::min(1.0, std::max(0.0, rho[1]));
      }
      wsum += 3.0 * w;
      wrss += w * w * e.segment<3>(3 * r).squaredNorm();
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
  auto prescreen = [&](const Eigen::MatrixXd& jac) {
    const std::vector<bool> fitted(p, true);
    const Eigen::VectorXd e = weighted_residuals(s, theta);
    const Identifiability stat = apart(jac, given_idf, [&](const Eigen::MatrixXd& j) {
      return check_identifiability(model, j, s.typical, opt.rank_tolerance, 0.0,
                                   std::min(kStartRelativeSe, opt.max_relative_se), &theta, &fitted,
                                   &e);
    });
    if (std::find(stat.statistical.begin(), stat.statistical.end(), true) != stat.statistical.end())
      idf = stat;
  };
  auto fit_passes = [&]() {
    // theta as the solver will see it, (theta / typical) * typical, so that the Jacobian of
    // this check is the one of the solver's first iteration (Evaluations cache).
    for (int k = 0; k < p; ++k) theta(k) = theta(k) / s.typical(k) * s.typical(k);
    {
      const Eigen::MatrixXd jac = weighted_jacobian(s, theta);
      idf = check(jac, theta);
      if (absolute && opt.max_relative_se > 0) prescreen(jac);
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
      if (3 * n <= static_cast<int>(free.size()))
        throw InvalidArgument("identify: " + std::to_string(n) + " measurements give " +
                              std::to_string(3 * n) + " equations for " +
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
      last_jacobian = weighted_jacobian(s, theta);
      last_jacobian_theta = theta;
      Identifiability again = check(last_jacobian, theta);
      if (absolute || again == idf || pass == 2) break;
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
        absolute
            ? apart(last_jacobian, idf, [&](const Eigen::MatrixXd& j) { return check(j, theta); })
            : check(last_jacobian, theta);
    residual_sigma = 0.0;
    if (absolute ? stat == idf
                 : std::find(stat.statistical.begin(), stat.statistical.end(), true) ==
                       stat.statistical.end())
      return;
    idf = stat;
    free.clear();
    for (int k = 0; k < p; ++k) {
      if (!idf.fixed[k])
        free.push_back(k);
      else if (!given[k])
        theta(k) =
            std::min(std::max(model.spec(k).null_value, model.spec(k).lower), model.spec(k).upper);
    }
    if (free.empty())
      throw NumericalError("identify: no parameter of model '" + model.model_string() +
                           "' is determined by this data");
    last = solve(s, free, theta, opt, loss_scale, nullptr);
    iterations += last.iterations;
    last_jacobian = weighted_jacobian(s, theta);
    last_jacobian_theta = theta;
  };
  // A redescending loss (Tukey) has many local minima and gives zero weight beyond its scale:
  // from the least-squares start, whose residuals carry the outliers' pull, it can stop where it
  // started with every row rejected. Start it from the Huber fit (convex: one minimum).
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
  // Without a stated noise the robust scale comes from the residuals; the start's residuals
  // are inflated by the outliers' pull, so re-estimate it from the robust fit (MAD) and refit.
  double scale_used_m = scale_m;
  if (opt.loss != "none" && opt.loss_scale_m == 0 && stated == 0) {
    for (int round = 0; round < 3; ++round) {
      const Eigen::VectorXd e = weighted_residuals(s, theta) * noise;  // metres
      const double sigma = robust::mad_sigma(std::vector<double>(e.data(), e.data() + e.size()));
      if (!(sigma > 0) || std::abs(c_sigma * sigma - scale_used_m) < 0.05 * scale_used_m) break;
      scale_used_m = c_sigma * sigma;
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
  // Singular values and V of the tall js: from the eigen-decomposition of js^T js when it is
  // well conditioned (cond(js) < 1e5, far from the rank threshold below and within the
  // normal equations' accuracy), else from its QR: js = Q R, R = U S V^T.
  Eigen::VectorXd sv;
  Eigen::MatrixXd v;
  {
    Eigen::MatrixXd gs = Eigen::MatrixXd::Zero(nf, nf);
    gs.selfadjointView<Eigen::Lower>().rankUpdate(js.transpose());
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(gs, Eigen::ComputeEigenvectors);
    const Eigen::VectorXd lam = es.eigenvalues();  // ascending
    if (nf > 0 && js.rows() >= nf && lam(0) > 1e-10 * lam(nf - 1)) {
      sv = lam.reverse().cwiseSqrt();
      v = es.eigenvectors().rowwise().reverse();
    }
  }
  if (sv.size() == 0) {
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
    if (given[k]) {  // kept as the start fit has it
      const FitParameter& q = opt.start->parameters[from_start[k]];
      fp.identified = q.identified;
      fp.standard_error = q.standard_error;
      f.covariance(k, k) = q.standard_error * q.standard_error;
      f.parameters.push_back(fp);
      continue;
    }
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
