// Kernels of measurement planning: rank-3 updates of the small information matrix and the
// criteria on it. Each criterion is written once here (score<MC>), used by the registry (with
// MC = 0, runtime size) and by the optimizers (MC = m, fixed size, for speed).
#pragma once

#include <Eigen/Eigenvalues>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "stiff/plan.hpp"
#include "stiff/random.hpp"

namespace stiff::plan_detail {

constexpr int kMaxM = 16;
constexpr double kInf = std::numeric_limits<double>::infinity();

enum class Crit { kappa_a, kappa_j, d_opt, a_opt, e_opt, o1, task };

/// Registry name -> id; throws InvalidArgument listing the names.
Crit criterion_id(const std::string& name);

/// What score<MC> needs besides M and MJ.
struct Context {
  Crit id = Crit::kappa_a;
  int m = 0;
  int count = 0;
  const double* task = nullptr;  // S, row-major m x m (full), or null
  bool needs_a() const { return id != Crit::kappa_j; }
  bool needs_j() const { return id == Crit::kappa_j; }
};

template <int MC>
inline int dim(int m) {
  return MC > 0 ? MC : m;
}

// M += sign * w^2 * diag(t) (Jp^T Jp) diag(t), t = Jl^T F: the element's A_e^T A_e / sigma^2
// (method.md eq. 3: A[r, k] = Jp[r, k] t_k). Lower triangle of row-major m x m only.
template <int MC>
inline void add_element(const CandidatePool& p, int e, double sign, double* M) {
  const int m = dim<MC>(p.identified_count());
  const int pose = p.element_pose[e];
  const double* jl = p.packed_load_jacobian.data() + static_cast<size_t>(pose) * 3 * m;
  const double* f = p.packed_force.data() + 3 * static_cast<size_t>(p.element_load[e]);
  const double* g = p.packed_gram.data() + static_cast<size_t>(pose) * m * m;
  double t[kMaxM];
  for (int k = 0; k < m; ++k) t[k] = jl[3 * k] * f[0] + jl[3 * k + 1] * f[1] + jl[3 * k + 2] * f[2];
  const double s = sign * p.weight2[pose];
  for (int k = 0; k < m; ++k) {
    const double sk = s * t[k];
    for (int l = 0; l <= k; ++l) M[k * m + l] += sk * t[l] * g[k * m + l];
  }
}

// MJ += sign * Jp^T Jp (pose only, unweighted).
template <int MC>
inline void add_jacobian(const CandidatePool& p, int e, double sign, double* MJ) {
  const int m = dim<MC>(p.identified_count());
  const double* g = p.packed_gram.data() + static_cast<size_t>(p.element_pose[e]) * m * m;
  for (int k = 0; k < m; ++k)
    for (int l = 0; l <= k; ++l) MJ[k * m + l] += sign * g[k * m + l];
}

/// Unbiased integer in [0, n), n < 2^32, from the Rng's engine (Lemire's multiply-shift with
/// rejection): exact and platform independent like Rng::index, without a 64-bit division.
inline uint32_t fast_index(Rng& rng, uint32_t n) {
  uint64_t x = rng.engine()() >> 32;
  uint64_t prod = x * n;
  uint32_t low = static_cast<uint32_t>(prod);
  if (low < n) {
    const uint32_t threshold = static_cast<uint32_t>(-n) % n;
    while (low < threshold) {
      x = rng.engine()() >> 32;
      prod = x * n;
      low = static_cast<uint32_t>(prod);
    }
  }
  return static_cast<uint32_t>(prod >> 32);
}

// Cholesky M = L L^T from the lower triangle; false when not numerically positive definite.
// The diagonal of L is stored inverted (1 / L_jj): the triangular solves then multiply.
template <int MC>
inline bool cholesky(const double* M, double* L, int m_runtime) {
  const int m = dim<MC>(m_runtime);
  for (int j = 0; j < m; ++j) {
    double d = M[j * m + j];
    for (int k = 0; k < j; ++k) d -= L[j * m + k] * L[j * m + k];
    if (!(d > 1e-14 * std::abs(M[j * m + j])) || !std::isfinite(d)) return false;
    const double inv = 1.0 / std::sqrt(d);
    L[j * m + j] = inv;
    for (int i = j + 1; i < m; ++i) {
      double s = M[i * m + j];
      for (int k = 0; k < j; ++k) s -= L[i * m + k] * L[j * m + k];
      L[i * m + j] = s * inv;
    }
  }
  return true;
}

// Li = L^-1 (lower triangular), forward substitution (L with inverted diagonal).
template <int MC>
inline void invert_lower(const double* L, double* Li, int m_runtime) {
  const int m = dim<MC>(m_runtime);
  for (int j = 0; j < m; ++j) {
    Li[j * m + j] = L[j * m + j];
    for (int i = j + 1; i < m; ++i) {
      double s = 0.0;
      for (int k = j; k < i; ++k) s -= L[i * m + k] * Li[k * m + j];
      Li[i * m + j] = s * L[i * m + i];
    }
  }
}

// tr(M^-1) = ||L^-1||_F^2.
template <int MC>
inline double trace_inverse(const double* Li, int m_runtime) {
  const int m = dim<MC>(m_runtime);
  double s = 0.0;
  for (int i = 0; i < m; ++i)
    for (int j = 0; j <= i; ++j) s += Li[i * m + j] * Li[i * m + j];
  return s;
}

template <int MC>
inline double log_det(const double* L, int m_runtime) {
  const int m = dim<MC>(m_runtime);
  double prod = 1.0;  // of 1 / L_ii
  for (int i = 0; i < m; ++i) prod *= L[i * m + i];
  if (std::isfinite(prod) && prod > 0) return -2.0 * std::log(prod);
  double s = 0.0;
  for (int i = 0; i < m; ++i) s -= std::log(L[i * m + i]);
  return 2.0 * s;
}

template <int MC>
inline double kappa_inverse(const double* M, int m_runtime) {
  const int m = dim<MC>(m_runtime);
  double L[(MC > 0 ? MC * MC : kMaxM * kMaxM)] = {};
  double Li[(MC > 0 ? MC * MC : kMaxM * kMaxM)];
  if (!cholesky<MC>(M, L, m)) return 0.0;
  invert_lower<MC>(L, Li, m);
  double tr = 0.0;
  for (int i = 0; i < m; ++i) tr += M[i * m + i];
  return m / std::sqrt(tr * trace_inverse<MC>(Li, m));
}

// Score (larger is better) of a set with information M (and MJ for kappa_j): the criterion's
// value, negated for the criteria to be minimised; the worst value when M is singular.
template <int MC>
inline double score(const Context& c, const double* M, const double* MJ) {
  const int m = dim<MC>(c.m);
  constexpr int kSize = MC > 0 ? MC * MC : kMaxM * kMaxM;
  switch (c.id) {
    case Crit::kappa_a:
      return kappa_inverse<MC>(M, m);
    case Crit::kappa_j:
      return kappa_inverse<MC>(MJ, m);
    case Crit::e_opt: {
      Eigen::MatrixXd a(m, m);
      for (int i = 0; i < m; ++i)
        for (int j = 0; j <= i; ++j) a(i, j) = a(j, i) = M[i * m + j];
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(a, Eigen::EigenvaluesOnly);
      const double v = es.eigenvalues()(0);
      return std::isfinite(v) ? std::max(v, 0.0) : 0.0;
    }
    default:
      break;
  }
  double L[kSize];
  const bool ok = cholesky<MC>(M, L, m);
  switch (c.id) {
    case Crit::d_opt:
      return ok ? log_det<MC>(L, m) : -kInf;
    case Crit::o1:
      return ok ? std::exp(log_det<MC>(L, m) / (2.0 * m)) / std::sqrt(static_cast<double>(c.count))
                : 0.0;
    case Crit::a_opt: {
      if (!ok) return -kInf;
      double Li[kSize];
      invert_lower<MC>(L, Li, m);
      return -trace_inverse<MC>(Li, m);
    }
    case Crit::task: {
      if (!ok || !c.task) return -kInf;
      double Li[kSize];
      invert_lower<MC>(L, Li, m);
      // tr(M^-1 S) = sum_ij (Li^T Li)_ij S_ij
      double s = 0.0;
      for (int i = 0; i < m; ++i)
        for (int j = 0; j < m; ++j) {
          double inv = 0.0;
          for (int k = std::max(i, j); k < m; ++k) inv += Li[k * m + i] * Li[k * m + j];
          s += inv * c.task[i * m + j];
        }
      return -std::sqrt(std::max(s, 0.0) / 3.0);
    }
    default:
      return -kInf;
  }
}

/// Annealing cost: the paper's kappa_F(A) = 1 / kappa_F^-1(A) for the kappa criteria,
/// -score for the others.
inline double cost_of(Crit id, double s) {
  if (id == Crit::kappa_a || id == Crit::kappa_j) return s > 0 ? 1.0 / s : kInf;
  return std::isfinite(s) ? -s : kInf;
}

/// Task information S = mean_t B_t^T B_t in the identified columns (row-major m x m).
std::vector<double> task_information(const RobotModel& robot,
                                     const Dataset& task,
                                     const std::vector<int>& identified);

/// CriterionInput of explicit measurements (q, F, moment) for the identified joints.
struct Row {
  Eigen::VectorXd q;
  Eigen::Vector3d force = Eigen::Vector3d::Zero();
  Eigen::Vector3d moment = Eigen::Vector3d::Zero();
};
CriterionInput criterion_input(const RobotModel& robot,
                               const std::vector<Row>& rows,
                               const std::vector<int>& identified,
                               const NoiseModel& noise,
                               const std::vector<double>& task);

/// Planned measurements of pool elements (ids p01.., forces in base and flange frame).
std::vector<PlannedMeasurement> to_measurements(const CandidatePool& pool,
                                                const std::vector<int>& set);
/// Fill a PlanResult's criteria, value, contributions and pool record from measurements.
void finish_result(const RobotModel& robot,
                   const CandidatePool& pool,
                   const PlanOptions& o,
                   std::vector<PlannedMeasurement> ms,
                   PlanResult& r);

/// Copy the lower triangle of an Eigen matrix into a row-major array, and back (symmetric).
void to_array(const Eigen::MatrixXd& a, double* out);
Eigen::MatrixXd from_lower(const double* lower, int m);

}  // namespace stiff::plan_detail
