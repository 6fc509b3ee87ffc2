#include "identify/evaluations.hpp"

#include <algorithm>
#include <cstring>

namespace stiff::detail {

void displacement_and_jacobian(const Setup& s,
                               int row,
                               const double* theta,
                               const std::vector<int>& cols,
                               const double* scale,
                               bool every,
                               double* d,
                               double* out) {
  const int dim = s.dim;
  const DeflectionModel& model = *s.model;
  const int p = model.parameter_count();
  auto& t = s.theta_jet;
  const Measurement& m = s.data->rows[row];
  if (every && m.absolute && model.analytic_absolute()) {
    model.absolute_jacobian(theta, m, s.ctx[row], s.scratch, s.dscratch, t, d, out, dim);
    return;
  }
  t.resize(p);
  for (int k = 0; k < p; ++k) t[k] = Jet(theta[k]);
  const bool analytic = every && model.analytic() && dim == 3;
  const std::vector<int>& jc = analytic ? model.jet_parameters() : cols;
  const int nc = static_cast<int>(jc.size());
  Vector3<Jet> dj, oj;
  Vector3<Jet>* op = dim == 6 ? &oj : nullptr;
  if (nc == 0) model.evaluate_jet(t.data(), m, s.ctx[row], s.scratch, &dj, op);
  for (int first = 0; first < nc; first += kJetStride) {
    const int last = std::min(nc, first + kJetStride);
    for (int i = first; i < last; ++i) t[jc[i]].v(i - first) = scale ? scale[i] : 1.0;
    s.scratch.same_values = first > 0;  // the same row and values, other directions
    model.evaluate_jet(t.data(), m, s.ctx[row], s.scratch, &dj, op);
    for (int i = first; i < last; ++i) {
      t[jc[i]].v(i - first) = 0.0;
      double* o = out + dim * (analytic ? jc[i] : i);
      for (int k = 0; k < 3; ++k) o[k] = dj(k).v(i - first);
      if (op)
        for (int k = 0; k < 3; ++k) o[3 + k] = oj(k).v(i - first);
    }
  }
  s.scratch.same_values = false;
  for (int k = 0; k < 3; ++k) d[k] = dj(k).a;
  if (op)
    for (int k = 0; k < 3; ++k) d[3 + k] = oj(k).a;
  // Analytic columns (displacement models of linear effects) have dim 3.
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
  dim_ = s->dim;
  d_.assign(2 * static_cast<size_t>(dim_) * rows, 0.0);
  jac_.assign(2 * static_cast<size_t>(dim_) * rows * p, 0.0);
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
    const int dim = dim_;
    double* dd = d_.data() + dim * i;
    double* jj = jac_.data() + dim * i * p_;
    double dv[6];
    if (linear_ && ref_[row]) {
      // d = d0 + J (theta - theta0), exact for a model affine in theta.
      const double* t0 = ref_theta_.data() + static_cast<size_t>(row) * p_;
      const double* j0 = ref_jac_.data() + 3 * static_cast<size_t>(row) * p_;
      Eigen::Map<Eigen::Vector3d> d3(dv);
      d3 = Eigen::Map<const Eigen::Vector3d>(ref_d_.data() + 3 * static_cast<size_t>(row));
      for (int k = 0; k < p_; ++k)
        if (theta[k] != t0[k])
          d3 += Eigen::Map<const Eigen::Vector3d>(j0 + 3 * k) * (theta[k] - t0[k]);
      std::copy(j0, j0 + 3 * p_, jj);
      cols_[i] = &all_;
    } else if (cols || linear_) {
      // Every column when that takes no more passes of the model than the ones asked for.
      const int want = cols ? static_cast<int>(cols->size()) : 0;
      const DeflectionModel& model = *s_->model;
      const bool absolute = s_->data->rows[row].absolute && model.analytic_absolute();
      const int passes = (absolute ? 3 + static_cast<int>(model.absolute_jet_parameters().size())
                                   : static_cast<int>(model.jet_parameters().size())) +
                         kJetStride - 1;
      const bool every = linear_ || passes / kJetStride <= (want + kJetStride - 1) / kJetStride;
      const std::vector<int>& c = every ? all_ : *cols;
      displacement_and_jacobian(*s_, row, theta, c, nullptr, every, dv, jj);
      cols_[i] = every ? &all_ : cols;
      if (linear_) {
        ref_[row] = 1;
        std::copy(theta, theta + p_, ref_theta_.data() + static_cast<size_t>(row) * p_);
        std::copy(dv, dv + 3, ref_d_.data() + 3 * static_cast<size_t>(row));
        std::copy(jj, jj + 3 * p_, ref_jac_.data() + 3 * static_cast<size_t>(row) * p_);
      }
    } else {
      Vector3<double> v, o;
      s_->model->evaluate_double(theta, s_->data->rows[row], s_->ctx[row], s_->dscratch, &v,
                                 dim == 6 ? &o : nullptr);
      for (int k = 0; k < 3; ++k) dv[k] = v(k);
      if (dim == 6)
        for (int k = 0; k < 3; ++k) dv[3 + k] = o(k);
      cols_[i] = nullptr;
    }
    std::copy(dv, dv + dim, dd);
    id_[i] = key.id;
  }
  const size_t i = r2 + slot;
  used_[i] = 2;
  used_[r2 + (1 - slot)] = used_[r2 + (1 - slot)] ? 1 : 0;
  *d = d_.data() + dim_ * i;
  if (jac) *jac = jac_.data() + dim_ * i * p_;
  if (jcols) *jcols = cols_[i];
}

Eigen::VectorXd weighted_residuals(const Setup& s, const Eigen::VectorXd& theta) {
  const int n = static_cast<int>(s.data->rows.size());
  const int dim = s.dim;
  Eigen::VectorXd e(dim * n);
  const Evaluations::Key key = s.eval.key(theta.data());
  for (int r = 0; r < n; ++r) {
    const double* d = nullptr;
    s.eval.get(r, key, nullptr, &d, nullptr, nullptr);
    for (int k = 0; k < dim; ++k) e(dim * r + k) = (s.observed(r, k) - d[k]) * s.weight(r, k);
  }
  return e;
}

Eigen::MatrixXd weighted_jacobian(const Setup& s, const Eigen::VectorXd& theta) {
  const int n = static_cast<int>(s.data->rows.size());
  const int p = s.model->parameter_count();
  const int dim = s.dim;
  Eigen::MatrixXd j(dim * n, p);
  const Evaluations::Key key = s.eval.key(theta.data());
  for (int r = 0; r < n; ++r) {
    const double *d = nullptr, *jac = nullptr;
    s.eval.get(r, key, &s.eval.all(), &d, &jac, nullptr);
    const Eigen::Map<const Eigen::MatrixXd> jr(jac, dim, p);
    for (int k = 0; k < dim; ++k) j.row(dim * r + k) = jr.row(k) * s.weight(r, k);
  }
  return j;
}

bool held_has_effect(const Setup& s, const Eigen::VectorXd& theta, const std::vector<bool>& held) {
  if (std::find(held.begin(), held.end(), true) == held.end()) return false;
  const int p = s.model->parameter_count();
  Eigen::VectorXd sq = Eigen::VectorXd::Zero(p);
  const Evaluations::Key key = s.eval.key(theta.data());
  for (int r = 0; r < static_cast<int>(s.data->rows.size()); ++r) {
    const double *d = nullptr, *jac = nullptr;
    s.eval.get(r, key, &s.eval.all(), &d, &jac, nullptr);
    const int dim = s.dim;
    for (int k = 0; k < p; ++k)
      if (held[k])
        for (int i = 0; i < dim; ++i) {
          const double v = jac[dim * k + i] * s.weight(r, i);
          sq(k) += v * v;
        }
  }
  for (int k = 0; k < p; ++k)
    if (held[k] && std::sqrt(sq(k)) * s.typical(k) > 1e-9) return true;
  return false;
}

}  // namespace stiff::detail
