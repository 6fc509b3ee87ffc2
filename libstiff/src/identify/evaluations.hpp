// The identification's model evaluations: the per-row cache of predictions and derivatives
// that the Ceres residuals, the identifiability check and the statistics share, and the
// weighted residuals and Jacobian at a parameter vector (private to identify/).
#pragma once

#include <Eigen/Core>
#include <vector>

#include "stiff/io/dataset.hpp"
#include "stiff/model/model.hpp"

namespace stiff::detail {

struct Setup;

/// Model evaluations per measurement, cached: the trust-region minimizer evaluates the
/// Jacobian at a trial point in its line search and again when it accepts it, the cost there
/// in between, and the identifiability check and the statistics want the Jacobian at the
/// solution, where the minimizer last evaluated it. Each row keeps its last two evaluations
/// (d and, when asked for, dd/dtheta for every parameter or for one column set), tagged with
/// the key of their theta (Setup::dim values and dim x P derivatives per entry): the recent
/// distinct thetas get keys (key()), so that a row stores
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
  int dim_ = 3;  ///< Setup::dim
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
/// Each row has `dim` residual components: its position or displacement (3) and, when the
/// data hold absolute rows with orientation (dim 6), the orientation residual (3, zero with
/// zero weight on rows without one): Log(R_measured R_predicted^T) [rad]
/// (orientation_discrepancy, observed as zero).
struct Setup {
  const DeflectionModel* model = nullptr;
  const Dataset* data = nullptr;
  std::vector<MeasurementContext> ctx;
  int dim = 3;                    ///< residual components per row: 3, or 6 with orientation
  Eigen::VectorXd row_weight;     ///< 1 / (sigma of the row) [1/m]
  Eigen::VectorXd orient_weight;  ///< 1 / (sigma of the row's orientation) [1/rad]; 0: none
  /// Weight of component k of row r.
  double weight(int r, int k) const { return k < 3 ? row_weight(r) : orient_weight(r); }
  /// Observed value of component k of row r (the orientation's is zero).
  double observed(int r, int k) const { return k < 3 ? data->rows[r].observed()(k) : 0.0; }
  /// Residual components that carry data in row r: 3, or 6 for a row with orientation.
  int components(int r) const { return dim == 6 && orient_weight(r) > 0 ? 6 : 3; }
  Eigen::VectorXd typical;  ///< parameter scaling: theta_k = typical_k * z_k
  /// Scratch of the evaluations (Ceres runs single-threaded here: num_threads = 1).
  mutable EvalState<Jet> scratch;
  mutable EvalState<double> dscratch;
  mutable std::vector<Jet> theta_jet;
  mutable std::vector<double> theta_double;
  mutable Evaluations eval;
};

/// Derivatives of the predicted displacement (and orientation discrepancy when s.dim is 6) of
/// measurement `row` with respect to theta(cols[i]) * scale[i] (scale null: ones), by
/// kJetStride parameters per pass of DeflectionModel::evaluate_jet; `theta` is the full
/// parameter vector. Writes d (s.dim) and the s.dim x cols.size() derivatives (column-major,
/// leading dimension s.dim) into `out`. With `every`
/// (cols lists every parameter, no scale) of an analytic model, the passes differentiate only
/// its jet_parameters() and the other columns come from DeflectionModel::analytic_columns; an
/// absolute row of an analytic_absolute() model takes DeflectionModel::absolute_jacobian.
void displacement_and_jacobian(const Setup& s,
                               int row,
                               const double* theta,
                               const std::vector<int>& cols,
                               const double* scale,
                               bool every,
                               double* d,
                               double* out);

/// Weighted residuals e (dim N, sigma units) at theta.
Eigen::VectorXd weighted_residuals(const Setup& s, const Eigen::VectorXd& theta);

/// Jacobian of the predicted, weighted displacement with respect to theta (dim N x P).
Eigen::MatrixXd weighted_jacobian(const Setup& s, const Eigen::VectorXd& theta);

/// Whether any parameter marked in `held` moves the weighted predictions at theta (column
/// norm times its typical magnitude above 1e-9, the identifiability check's first test).
bool held_has_effect(const Setup& s, const Eigen::VectorXd& theta, const std::vector<bool>& held);

}  // namespace stiff::detail
