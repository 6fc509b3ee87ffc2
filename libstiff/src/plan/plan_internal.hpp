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

/// std::mt19937_64 re-implemented header-only so that the annealing's draws inline (the
/// standard engine's operator() is an out-of-line call): the same algorithm, seeding and
/// tempering, hence exactly the same stream as Rng(seed).engine() (tested). index(), uniform()
/// and fast_index() map it exactly as Rng does.
class FastRng {
 public:
  explicit FastRng(uint64_t seed) {
    x_[0] = seed;
    for (int i = 1; i < kN; ++i)
      x_[i] = 6364136223846793005ULL * (x_[i - 1] ^ (x_[i - 1] >> 62)) + i;
    i_ = kN;
  }
#if defined(__GNUC__)
  __attribute__((always_inline))
#endif
  uint64_t
  operator()() {
    if (i_ >= kN) twist();
    uint64_t z = x_[i_++];
    z ^= (z >> 29) & 0x5555555555555555ULL;
    z ^= (z << 17) & 0x71d67fffeda60000ULL;
    z ^= (z << 37) & 0xfff7eee000000000ULL;
    z ^= z >> 43;
    return z;
  }
  /// Uniform in [0, 1) with 53 random bits (as Rng::uniform).
  double uniform() { return static_cast<double>((*this)() >> 11) * 0x1.0p-53; }
  /// Uniform integer in [0, n) by rejection (as Rng::index).
  uint64_t index(uint64_t n) {
    const uint64_t limit = UINT64_MAX - UINT64_MAX % n;
    uint64_t x;
    do x = (*this)();
    while (x >= limit);
    return x % n;
  }

 private:
  static constexpr int kN = 312, kM = 156;
  static constexpr uint64_t kUpper = ~uint64_t(0) << 31, kLower = ~kUpper;
  static constexpr uint64_t kA = 0xb5026f5aa96619e9ULL;
#if defined(__GNUC__)
  __attribute__((noinline))
#endif
  void
  twist() {
    int k = 0;
    for (; k < kN - kM; ++k) {
      const uint64_t y = (x_[k] & kUpper) | (x_[k + 1] & kLower);
      x_[k] = x_[k + kM] ^ (y >> 1) ^ ((y & 1) ? kA : 0);
    }
    for (; k < kN - 1; ++k) {
      const uint64_t y = (x_[k] & kUpper) | (x_[k + 1] & kLower);
      x_[k] = x_[k + (kM - kN)] ^ (y >> 1) ^ ((y & 1) ? kA : 0);
    }
    const uint64_t y = (x_[kN - 1] & kUpper) | (x_[0] & kLower);
    x_[kN - 1] = x_[kM - 1] ^ (y >> 1) ^ ((y & 1) ? kA : 0);
    i_ = 0;
  }
  uint64_t x_[kN];
  int i_;
};

/// fast_index on FastRng: the same mapping, hence the same integers for the same stream.
#if defined(__GNUC__)
__attribute__((always_inline))
#endif
inline uint32_t
fast_index(FastRng& rng, uint32_t n) {
  uint64_t x = rng() >> 32;
  uint64_t prod = x * n;
  uint32_t low = static_cast<uint32_t>(prod);
  if (low < n) {
    const uint32_t threshold = static_cast<uint32_t>(-n) % n;
    while (low < threshold) {
      x = rng() >> 32;
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
  double L[kSize] = {};  // (only the lower triangle is used; silences -Wmaybe-uninitialized)
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

// ------------------------------------------------------------------------------------------
// Packed kernels: the fast path of the set optimizers. A symmetric m x m matrix is its packed
// lower triangle, row-major ((k, l), l <= k, at k (k + 1) / 2 + l): 15 doubles for m = 5.
// Every function does the same floating-point operations in the same order as its full-storage
// counterpart above (add_element, cholesky, invert_lower, ...), so both paths give the same
// values bit for bit (tests/unit/plan/plan_test.cpp, PlanFastPath).
// ------------------------------------------------------------------------------------------

constexpr int packed_size(int m) { return m * (m + 1) / 2; }

/// Largest per-element table finalize() stores (CandidatePool::packed_element_information).
/// A cache budget rather than a memory one: the annealing reads about two random elements per
/// step, and once the table no longer fits in the L2 cache these reads miss, so computing the
/// element from the per-pose data (which stays cached) is faster. Measured on a 2-core Xeon VM
/// (2 MB L2 per core), m = 5: 1e4 elements (1.2 MB): 7.1e6 swaps/s with the table, 5.1e6
/// without; 1e5 elements (12 MB): 3.0e6 with, 4.6e6 without (docs/benchmarks.md).
constexpr double kElementTableBudgetBytes = 4.0 * 1024 * 1024;

/// Packed A_e^T A_e / sigma_e^2 of element e, computed as add_element does.
template <int MC>
inline void element_information(const CandidatePool& p, int e, double* G) {
  const int m = dim<MC>(p.identified_count());
  const int pose = p.element_pose[e];
  const double* jl = p.packed_load_jacobian.data() + static_cast<size_t>(pose) * 3 * m;
  const double* f = p.packed_force.data() + 3 * static_cast<size_t>(p.element_load[e]);
  const double* g = p.packed_gram.data() + static_cast<size_t>(pose) * m * m;
  double t[kMaxM];
  for (int k = 0; k < m; ++k) t[k] = jl[3 * k] * f[0] + jl[3 * k + 1] * f[1] + jl[3 * k + 2] * f[2];
  const double s = p.weight2[pose];
  int idx = 0;
  for (int k = 0; k < m; ++k) {
    const double sk = s * t[k];
    for (int l = 0; l <= k; ++l) G[idx++] = sk * t[l] * g[k * m + l];
  }
}

/// Packed Jp^T Jp of element e's pose (kappa_j), as add_jacobian adds it.
template <int MC>
inline void element_jacobian_information(const CandidatePool& p, int e, double* G) {
  const int m = dim<MC>(p.identified_count());
  const double* g = p.packed_gram.data() + static_cast<size_t>(p.element_pose[e]) * m * m;
  int idx = 0;
  for (int k = 0; k < m; ++k)
    for (int l = 0; l <= k; ++l) G[idx++] = g[k * m + l];
}

template <int MC>
inline bool cholesky_packed(const double* M, double* L, int m_runtime) {
  const int m = dim<MC>(m_runtime);
#pragma GCC unroll 16
  for (int j = 0; j < m; ++j) {
    const int rj = j * (j + 1) / 2;
    double d = M[rj + j];
#pragma GCC unroll 16
    for (int k = 0; k < j; ++k) d -= L[rj + k] * L[rj + k];
    // = !(d > 1e-14 |M_jj|) || !isfinite(d)
    if (!(d > 1e-14 * std::abs(M[rj + j]) && d < kInf)) return false;
    const double inv = 1.0 / std::sqrt(d);
    L[rj + j] = inv;
#pragma GCC unroll 16
    for (int i = j + 1; i < m; ++i) {
      const int ri = i * (i + 1) / 2;
      double s = M[ri + j];
#pragma GCC unroll 16
      for (int k = 0; k < j; ++k) s -= L[ri + k] * L[rj + k];
      L[ri + j] = s * inv;
    }
  }
  return true;
}

template <int MC>
inline void invert_lower_packed(const double* L, double* Li, int m_runtime) {
  const int m = dim<MC>(m_runtime);
#pragma GCC unroll 16
  for (int j = 0; j < m; ++j) {
    Li[j * (j + 1) / 2 + j] = L[j * (j + 1) / 2 + j];
#pragma GCC unroll 16
    for (int i = j + 1; i < m; ++i) {
      const int ri = i * (i + 1) / 2;
      double s = 0.0;
#pragma GCC unroll 16
      for (int k = j; k < i; ++k) s -= L[ri + k] * Li[k * (k + 1) / 2 + j];
      Li[ri + j] = s * L[ri + i];
    }
  }
}

template <int MC>
inline double trace_inverse_packed(const double* Li, int m_runtime) {
  const int n = packed_size(dim<MC>(m_runtime));
  double s = 0.0;
#pragma GCC unroll 136
  for (int i = 0; i < n; ++i) s += Li[i] * Li[i];
  return s;
}

template <int MC>
inline double log_det_packed(const double* L, int m_runtime) {
  const int m = dim<MC>(m_runtime);
  double prod = 1.0;
  for (int i = 0; i < m; ++i) prod *= L[i * (i + 1) / 2 + i];
  if (std::isfinite(prod) && prod > 0) return -2.0 * std::log(prod);
  double s = 0.0;
  for (int i = 0; i < m; ++i) s -= std::log(L[i * (i + 1) / 2 + i]);
  return 2.0 * s;
}

template <int MC>
inline double kappa_inverse_packed(const double* M, int m_runtime) {
  const int m = dim<MC>(m_runtime);
  constexpr int kT = packed_size(MC > 0 ? MC : kMaxM);
  double L[kT], Li[kT];
  if (!cholesky_packed<MC>(M, L, m)) return 0.0;
  invert_lower_packed<MC>(L, Li, m);
  double tr = 0.0;
  for (int i = 0; i < m; ++i) tr += M[i * (i + 1) / 2 + i];
  return m / std::sqrt(tr * trace_inverse_packed<MC>(Li, m));
}

/// score<MC> on a packed matrix X: M, or MJ for kappa_j (the annealing keeps only the one the
/// criterion needs). The criterion is a template argument: no dispatch in the inner loop.
template <int MC, Crit C>
inline double score_packed(const Context& c, const double* X) {
  const int m = dim<MC>(c.m);
  constexpr int kT = packed_size(MC > 0 ? MC : kMaxM);
  if constexpr (C == Crit::kappa_a || C == Crit::kappa_j) {
    return kappa_inverse_packed<MC>(X, m);
  } else if constexpr (C == Crit::d_opt || C == Crit::o1 || C == Crit::a_opt) {
    double L[kT];
    const bool ok = cholesky_packed<MC>(X, L, m);
    if constexpr (C == Crit::d_opt) {
      return ok ? log_det_packed<MC>(L, m) : -kInf;
    } else if constexpr (C == Crit::o1) {
      return ok ? std::exp(log_det_packed<MC>(L, m) / (2.0 * m)) /
                      std::sqrt(static_cast<double>(c.count))
                : 0.0;
    } else {
      if (!ok) return -kInf;
      double Li[kT];
      invert_lower_packed<MC>(L, Li, m);
      return -trace_inverse_packed<MC>(Li, m);
    }
  } else {
    // e_opt, task: full storage and the generic score (an eigensolver or m^3 work anyway).
    constexpr int kSize = MC > 0 ? MC * MC : kMaxM * kMaxM;
    double full[kSize];
    for (int i = 0, idx = 0; i < m; ++i)
      for (int j = 0; j <= i; ++j) full[i * m + j] = X[idx++];
    return score<MC>(c, full, full);
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
