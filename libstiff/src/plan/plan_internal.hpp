// Kernels of measurement planning: rank-3 updates of the small information matrix and the
// criteria on it. Each criterion is written once here (score<MC>), used by the registry (with
// MC = 0, runtime size) and by the optimizers (MC = m, fixed size, for speed).
#pragma once

#include <Eigen/Eigenvalues>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "stiff/kinematics/joint_torque.hpp"
#include "stiff/plan/plan.hpp"
#include "stiff/random.hpp"

#if defined(__GNUC__)
#define STIFF_UNLIKELY(x) __builtin_expect(!!(x), 0)
#define STIFF_ALWAYS_INLINE __attribute__((always_inline))
#define STIFF_NOINLINE __attribute__((noinline))
#else
#define STIFF_UNLIKELY(x) (x)
#define STIFF_ALWAYS_INLINE
#define STIFF_NOINLINE
#endif

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

/// Blocks on 64-byte cache lines; blocks of 2 MB and more on 2 MB boundaries, and on Linux
/// marked for transparent huge pages (a random read of a large table then misses the TLB far
/// less often).
void* allocate_table(std::size_t bytes);
void free_table(void* p, std::size_t bytes) noexcept;

/// std::allocator for the planning tables: see allocate_table.
template <class T>
struct TableAllocator {
  using value_type = T;
  TableAllocator() = default;
  template <class U>
  TableAllocator(const TableAllocator<U>&) {}
  T* allocate(std::size_t n) { return static_cast<T*>(allocate_table(n * sizeof(T))); }
  void deallocate(T* p, std::size_t n) noexcept { free_table(p, n * sizeof(T)); }
  template <class U>
  bool operator==(const TableAllocator<U>&) const {
    return true;
  }
  template <class U>
  bool operator!=(const TableAllocator<U>&) const {
    return false;
  }
};

/// What CandidatePool::finalize() packs for the kernels: per pose the m x m Gram matrix
/// Jp_I^T Jp_I (row-major), the 3 x m load Jacobian Jl_I (column-major) and 1/sigma^2, per
/// load F; and, below a memory budget, per element the packed lower triangle of
/// A_e^T A_e / sigma_e^2 (packed_size(m) doubles in the kernels' order, 2 x 2 diagonal blocks
/// first; rows start on cache lines and are padded to whole lines). Without the table the
/// kernels compute the rows from the per-pose data, with the same values bit for bit.
struct KernelData {
  std::vector<double> packed_gram;
  std::vector<double> packed_load_jacobian;
  std::vector<double> weight2;
  std::vector<double> packed_force;
  std::vector<double, TableAllocator<double>> element_table_storage;
  int element_table_stride = 0;
  /// Row e of the element table at element_table() + e * element_table_stride; nullptr when
  /// the table is not stored.
  const double* element_table() const {
    return element_table_storage.empty() ? nullptr : element_table_storage.data();
  }
};

/// The kernel data of a finalized pool (InvalidArgument otherwise).
const KernelData& kernel_of(const CandidatePool& p);

// M += sign * w^2 * diag(t) (Jp^T Jp) diag(t), t = Jl^T F: the element's A_e^T A_e / sigma^2
// (Jiang & Fang 2023: A[r, k] = Jp[r, k] t_k). Lower triangle of row-major m x m only.
template <int MC>
inline void add_element(const CandidatePool& p, int e, double sign, double* M) {
  const int m = dim<MC>(p.identified_count());
  const int pose = p.element_pose[e];
  const double* jl = p.kernel->packed_load_jacobian.data() + static_cast<size_t>(pose) * 3 * m;
  const double* f = p.kernel->packed_force.data() + 3 * static_cast<size_t>(p.element_load[e]);
  const double* g = p.kernel->packed_gram.data() + static_cast<size_t>(pose) * m * m;
  double t[kMaxM];
  for (int k = 0; k < m; ++k) t[k] = force_torque(jl + 3 * k, f);
  const double s = sign * p.kernel->weight2[pose];
  for (int k = 0; k < m; ++k) {
    const double sk = s * t[k];
    for (int l = 0; l <= k; ++l) M[k * m + l] += sk * t[l] * g[k * m + l];
  }
}

// MJ += sign * Jp^T Jp (pose only, unweighted).
template <int MC>
inline void add_jacobian(const CandidatePool& p, int e, double sign, double* MJ) {
  const int m = dim<MC>(p.identified_count());
  const double* g = p.kernel->packed_gram.data() + static_cast<size_t>(p.element_pose[e]) * m * m;
  for (int k = 0; k < m; ++k)
    for (int l = 0; l <= k; ++l) MJ[k * m + l] += sign * g[k * m + l];
}

/// Uniform integer in [0, n) from a 64-bit engine by rejection (as Rng::index).
template <class Engine>
inline uint64_t rejection_index(Engine& engine, uint64_t n) {
  const uint64_t limit = UINT64_MAX - UINT64_MAX % n;
  uint64_t x;
  do x = engine();
  while (x >= limit);
  return x % n;
}

/// std::mt19937_64 re-implemented header-only so that the exchange's draws inline (the
/// standard engine's operator() is an out-of-line call): the same algorithm, seeding and
/// tempering, hence exactly the same stream as Rng(seed).engine() (tested). index() maps it
/// exactly as Rng does.
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
  /// Uniform integer in [0, n) by rejection (as Rng::index).
  uint64_t index(uint64_t n) { return rejection_index(*this, n); }

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

/// xoshiro256++ (Blackman & Vigna, "Scrambled linear pseudorandom number generators", ACM TOMS
/// 2021), seeded by splitmix64: the annealing's engine. Four words of state and a handful of
/// instructions per draw (std::mt19937_64 costs about 40 with its twist), which matters at
/// 1e7 draws per second; the statistical quality is ample for Metropolis proposals.
class Xoshiro256pp {
 public:
  explicit Xoshiro256pp(uint64_t seed) {
    uint64_t z = seed;
    for (auto& w : s_) {
      z += 0x9E3779B97F4A7C15ULL;
      uint64_t x = z;
      x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
      x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
      w = x ^ (x >> 31);
    }
  }
  STIFF_ALWAYS_INLINE uint64_t operator()() {
    const uint64_t result = rotl(s_[0] + s_[3], 23) + s_[0];
    const uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = rotl(s_[3], 45);
    return result;
  }
  /// Uniform in (0, 1] with 53 random bits (never 0: its logarithm is finite).
  double uniform_open() { return static_cast<double>(((*this)() >> 11) + 1) * 0x1.0p-53; }
  /// Uniform integer in [0, n) by rejection.
  uint64_t index(uint64_t n) { return rejection_index(*this, n); }
  /// Advance by 2^128 draws (the authors' jump polynomial): a stream that does not overlap
  /// this one's next 2^128 draws.
  void jump() {
    static constexpr uint64_t kJump[4] = {0x180ec6d33cfd0aba, 0xd5a61266f0c9392c,
                                          0xa9582618e03fc9aa, 0x39abdc4529b1661c};
    uint64_t t[4] = {0, 0, 0, 0};
    for (uint64_t word : kJump)
      for (int b = 0; b < 64; ++b) {
        if (word & (uint64_t{1} << b))
          for (int i = 0; i < 4; ++i) t[i] ^= s_[i];
        (*this)();
      }
    for (int i = 0; i < 4; ++i) s_[i] = t[i];
  }

 private:
  static uint64_t rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
  uint64_t s_[4];
};

/// Standard exponential variates by the ziggurat method (Marsaglia & Tsang, "The ziggurat
/// method for generating random variables", J. Stat. Softw. 5(8), 2000), 256 layers: one
/// draw, a table look-up, a multiplication and a comparison in 98.9 % of the calls, where
/// -ln(u) costs a call to log. The Metropolis test Delta <= -T ln u is Delta <= T E with
/// E = -ln u ~ Exp(1), so the annealing draws E directly.
struct ExponentialZiggurat {
  static constexpr double r = 7.69711747013104972;   // start of the tail
  static constexpr double v = 3.949659822581572e-3;  // area of each layer
  double x[257], f[257];  // layer edges, decreasing from x[0] = v e^r to x[256] = 0; f = e^-x
  ExponentialZiggurat() {
    x[0] = v * std::exp(r);
    x[1] = r;
    for (int i = 1; i < 255; ++i) x[i + 1] = -std::log(v / x[i] + std::exp(-x[i]));
    x[256] = 0.0;
    for (int i = 0; i < 257; ++i) f[i] = std::exp(-x[i]);
  }
};
inline const ExponentialZiggurat kExponentialZiggurat;

/// One draw of the ziggurat: layer i from the low 8 bits, abscissa x = u x_i from the high 53.
struct ZigguratPoint {
  int i;
  double x;
  /// Inside the layer's rectangle, under the density: x is the variate.
  bool inside() const { return x < kExponentialZiggurat.x[i + 1]; }
};
STIFF_ALWAYS_INLINE inline ZigguratPoint ziggurat_point(Xoshiro256pp& rng) {
  const uint64_t bits = rng();
  const int i = static_cast<int>(bits & 0xff);
  return {i, static_cast<double>(bits >> 11) * 0x1.0p-53 * kExponentialZiggurat.x[i]};
}

// The tail (memoryless: r + E) and the wedges of the ziggurat.
STIFF_NOINLINE inline double exponential_slow(Xoshiro256pp& rng, ZigguratPoint z) {
  const ExponentialZiggurat& t = kExponentialZiggurat;
  for (;;) {
    if (z.i == 0) return t.r - std::log(rng.uniform_open());
    const double y = t.f[z.i] + (t.f[z.i + 1] - t.f[z.i]) * (1.0 - rng.uniform_open());
    if (y < std::exp(-z.x)) return z.x;
    z = ziggurat_point(rng);
    if (z.inside()) return z.x;
  }
}

/// E ~ Exp(1).
STIFF_ALWAYS_INLINE inline double standard_exponential(Xoshiro256pp& rng) {
  const ZigguratPoint z = ziggurat_point(rng);
  return z.inside() ? z.x : exponential_slow(rng, z);
}

// The rare rejection branch of fast_index, out of line so that its division is not hoisted.
STIFF_NOINLINE inline uint64_t fast_index_reject(Xoshiro256pp& rng, uint32_t n, uint64_t prod) {
  const uint32_t threshold = static_cast<uint32_t>(-n) % n;
  while (static_cast<uint32_t>(prod) < threshold) prod = (rng() >> 32) * n;
  return prod;
}

/// Unbiased integer in [0, n), n < 2^32, from the high half of one draw (Lemire's
/// multiply-shift; the rejection, and its division, are taken with probability n / 2^32).
STIFF_ALWAYS_INLINE inline uint32_t fast_index(Xoshiro256pp& rng, uint32_t n) {
  uint64_t prod = (rng() >> 32) * n;
  if (STIFF_UNLIKELY(static_cast<uint32_t>(prod) < n)) prod = fast_index_reject(rng, n, prod);
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
// lower triangle, m (m + 1) / 2 doubles (15 for m = 5), in "bound-first" order: first the 2 x 2
// diagonal blocks {0, 1}, {2, 3}, ... (a last 1 x 1 block for odd m), each as (2b, 2b),
// (2b + 1, 2b), (2b + 1, 2b + 1); then every other entry (r, c), c < r, row by row. The
// annealing's bound (bound_rejects) reads only those blocks, the first packed_bound_size(m)
// entries (7 of 15 for m = 5): a proposal the bound rejects, most of them, updates only those
// and reads one cache line of each table row. Every function does the same floating-point
// operations in the same order as its full-storage counterpart above (add_element, cholesky,
// invert_lower, ...), so both paths give the same values bit for bit
// (tests/unit/plan/plan_test.cpp, PlanFastPath).
// ------------------------------------------------------------------------------------------

constexpr int packed_size(int m) { return m * (m + 1) / 2; }
constexpr int packed_bound_size(int m) { return 3 * (m / 2) + m % 2; }
/// Position of entry (r, c), c <= r, of a packed m x m matrix.
constexpr int packed_index(int m, int r, int c) {
  return r / 2 == c / 2 ? 3 * (r / 2) + (r % 2) + (c % 2)
                        : packed_bound_size(m) + packed_size(r) + c - (r + r / 2);
}
/// Entry (r, c), c <= r, of a packed MC x MC matrix.
template <int MC>
STIFF_ALWAYS_INLINE inline double packed_at(const double* X, int r, int c) {
  return X[packed_index(MC, r, c)];
}

/// Largest per-element table finalize() stores (KernelData::element_table()): 64 MB, a
/// 1e5-element pool up to m = 10. Beyond the L2 cache the annealing's random reads of the table
/// miss, but it draws its candidates ahead and prefetches their rows, so the table still beats
/// computing elements from the per-pose data (measured in bench/, docs/benchmarks.md).
constexpr double kElementTableBudgetBytes = 64.0 * 1024 * 1024;
/// Cache line of x86-64 and AArch64: the element table's rows start on one and are padded to
/// whole lines; the annealing prefetches them line by line.
constexpr int kCacheLineBytes = 64;
constexpr int kCacheLineDoubles = kCacheLineBytes / static_cast<int>(sizeof(double));

/// Packed A_e^T A_e / sigma_e^2 of element e, computed as add_element does.
template <int MC>
inline void element_information(const CandidatePool& p, int e, double* G) {
  const int m = dim<MC>(p.identified_count());
  const int pose = p.element_pose[e];
  const double* jl = p.kernel->packed_load_jacobian.data() + static_cast<size_t>(pose) * 3 * m;
  const double* f = p.kernel->packed_force.data() + 3 * static_cast<size_t>(p.element_load[e]);
  const double* g = p.kernel->packed_gram.data() + static_cast<size_t>(pose) * m * m;
  double t[kMaxM];
  for (int k = 0; k < m; ++k) t[k] = force_torque(jl + 3 * k, f);
  const double s = p.kernel->weight2[pose];
  for (int k = 0; k < m; ++k) {
    const double sk = s * t[k];
    for (int l = 0; l <= k; ++l) G[packed_index(m, k, l)] = sk * t[l] * g[k * m + l];
  }
}

/// Packed Jp^T Jp of element e's pose (kappa_j), as add_jacobian adds it.
template <int MC>
inline void element_jacobian_information(const CandidatePool& p, int e, double* G) {
  const int m = dim<MC>(p.identified_count());
  const double* g = p.kernel->packed_gram.data() + static_cast<size_t>(p.element_pose[e]) * m * m;
  for (int k = 0; k < m; ++k)
    for (int l = 0; l <= k; ++l) G[packed_index(m, k, l)] = g[k * m + l];
}

// M packed (packed_index); L and its inverse Li packed row-major ((i, j) at i (i + 1) / 2 + j).
template <int MC>
inline bool cholesky_packed(const double* M, double* L, int m_runtime) {
  const int m = dim<MC>(m_runtime);
#pragma GCC unroll 16
  for (int j = 0; j < m; ++j) {
    const int rj = j * (j + 1) / 2;
    const double mjj = M[packed_index(m, j, j)];
    double d = mjj;
#pragma GCC unroll 16
    for (int k = 0; k < j; ++k) d -= L[rj + k] * L[rj + k];
    // = !(d > 1e-14 |M_jj|) || !isfinite(d)
    if (!(d > 1e-14 * std::abs(mjj) && d < kInf)) return false;
    const double inv = 1.0 / std::sqrt(d);
    L[rj + j] = inv;
#pragma GCC unroll 16
    for (int i = j + 1; i < m; ++i) {
      const int ri = i * (i + 1) / 2;
      double s = M[packed_index(m, i, j)];
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
  for (int i = 0; i < m; ++i) tr += M[packed_index(m, i, i)];
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
    for (int i = 0; i < m; ++i)
      for (int j = 0; j <= i; ++j) full[i * m + j] = X[packed_index(m, i, j)];
    return score<MC>(c, full, full);
  }
}

/// Annealing cost: the paper's kappa_F(A) = 1 / kappa_F^-1(A) for the kappa criteria,
/// -score for the others.
inline double cost_of(Crit id, double s) {
  if (id == Crit::kappa_a || id == Crit::kappa_j) return s > 0 ? 1.0 / s : kInf;
  return std::isfinite(s) ? -s : kInf;
}

// ------------------------------------------------------------------------------------------
// Closed form for the annealing's serial loop, where the criterion is evaluated once per step:
// the Cholesky above is a chain of m square roots and m divisions and about twice the
// instructions. For m <= 6 the closed form below splits M = [A B; B^T D] with blocks of at
// most 3 x 3 and uses the Schur complement S = D - B^T A^-1 B (block inversion; Golub & Van
// Loan, Matrix Computations, 4th ed., section 3.2.11; Horn & Johnson, Matrix Analysis, 0.8.5):
//   det M = det A det S,   tr M^-1 = tr A^-1 + tr S^-1 + tr(Q S^-1 Q^T),   Q = A^-1 B.
// With a = det A, Q' = adj(A) B and the scaled complement S' = a S = a D - B^T Q' (ns x ns):
//   det M = det S' / a^(ns - 1),
//   tr M^-1 = (tr adj(A) det S' + a^2 tr adj(S') + sum_ij (Q'^T Q')_ij adj(S')_ij) / (a det S')
// so both come as fractions with positive denominators and the Metropolis test compares
// products: no division, square root or logarithm on the serial path. Adjugates lose accuracy
// as a block nears singularity, so the closed form declines (returns false) when
// det / prod(diag) of a block is below kClosedFormHadamard or a value overflows; the caller then
// uses the Cholesky path, which also decides singularity exactly as before.
// ------------------------------------------------------------------------------------------

constexpr double kClosedFormHadamard = 1e-9;

template <int MC>
constexpr bool has_closed_form() {
  return MC >= 1 && MC <= 6;
}

// adj(a) of a symmetric n x n block (n <= 3; lower triangle of a read, adj filled in full);
// returns det(a).
template <int N>
STIFF_ALWAYS_INLINE inline double adjugate_sym(const double (&a)[3][3], double (&adj)[3][3]) {
  if constexpr (N == 1) {
    adj[0][0] = 1.0;
    return a[0][0];
  } else if constexpr (N == 2) {
    adj[0][0] = a[1][1];
    adj[1][1] = a[0][0];
    adj[1][0] = adj[0][1] = -a[1][0];
    return a[0][0] * a[1][1] - a[1][0] * a[1][0];
  } else {
    adj[0][0] = a[1][1] * a[2][2] - a[2][1] * a[2][1];
    adj[1][1] = a[0][0] * a[2][2] - a[2][0] * a[2][0];
    adj[2][2] = a[0][0] * a[1][1] - a[1][0] * a[1][0];
    adj[1][0] = adj[0][1] = a[2][0] * a[2][1] - a[1][0] * a[2][2];
    adj[2][0] = adj[0][2] = a[1][0] * a[2][1] - a[2][0] * a[1][1];
    adj[2][1] = adj[1][2] = a[2][0] * a[1][0] - a[0][0] * a[2][1];
    return a[0][0] * adj[0][0] + a[1][0] * adj[1][0] + a[2][0] * adj[2][0];
  }
}

/// a[0] + ... + a[N-1] as a balanced tree (depth log2 N instead of N - 1 dependent additions);
/// 0 for N = 0.
template <int N>
STIFF_ALWAYS_INLINE inline double pairwise_sum(const double* a) {
  if constexpr (N == 0)
    return 0.0;
  else if constexpr (N == 1)
    return a[0];
  else
    return pairwise_sum<N / 2>(a) + pairwise_sum<N - N / 2>(a + N / 2);
}

template <int N>
STIFF_ALWAYS_INLINE inline double diagonal_product(const double (&a)[3][3]) {
  double prod = a[0][0];
  for (int i = 1; i < N; ++i) prod *= a[i][i];
  return prod;
}

/// The closed form of a packed symmetric positive definite m x m matrix (m <= 6) as fractions:
/// tr M, tr M^-1 = num / den, det M = det_num / det_den (denominators > 0). False when a block
/// is too close to singular or a value overflows (use the Cholesky path).
struct ClosedForm {
  double tr, num, den, det_num, det_den;
};

template <int MC>
STIFF_ALWAYS_INLINE inline bool closed_form(const double* X, ClosedForm& f) {
  static_assert(has_closed_form<MC>(), "closed form for m = 1..6 only");
  constexpr int na = MC <= 3 ? MC : MC / 2, ns = MC - na;
  // Inlined, so that packed_index folds to a constant for the unrolled indices.
  auto at = [X](int r, int c) STIFF_ALWAYS_INLINE { return packed_at<MC>(X, r, c); };
  double a[3][3], adja[3][3];
  f.tr = 0.0;
#pragma GCC unroll 8
  for (int i = 0; i < MC; ++i) f.tr += at(i, i);
#pragma GCC unroll 8
  for (int i = 0; i < na; ++i)
#pragma GCC unroll 8
    for (int j = 0; j <= i; ++j) a[i][j] = at(i, j);
  const double deta = adjugate_sym<na>(a, adja);
  double tra = adja[0][0];
#pragma GCC unroll 8
  for (int i = 1; i < na; ++i) tra += adja[i][i];
  const bool a_regular = deta > kClosedFormHadamard * diagonal_product<na>(a);
  if constexpr (ns == 0) {
    f.num = tra;
    f.den = deta;
    f.det_num = deta;
    f.det_den = 1.0;
    return a_regular && deta < kInf;
  } else {
    double b[3][3], q[3][3], s[3][3], adjs[3][3];
#pragma GCC unroll 8
    for (int i = 0; i < na; ++i)
#pragma GCC unroll 8
      for (int j = 0; j < ns; ++j) b[i][j] = at(na + j, i);
#pragma GCC unroll 8
    for (int i = 0; i < na; ++i)
#pragma GCC unroll 8
      for (int j = 0; j < ns; ++j) {
        double v = adja[i][0] * b[0][j];
#pragma GCC unroll 8
        for (int k = 1; k < na; ++k) v += adja[i][k] * b[k][j];
        q[i][j] = v;
      }
      // S' = a D - B^T Q' (lower triangle)
#pragma GCC unroll 8
    for (int i = 0; i < ns; ++i)
#pragma GCC unroll 8
      for (int j = 0; j <= i; ++j) {
        double v = b[0][i] * q[0][j];
#pragma GCC unroll 8
        for (int k = 1; k < na; ++k) v += b[k][i] * q[k][j];
        s[i][j] = deta * at(na + i, na + j) - v;
      }
    const double dets = adjugate_sym<ns>(s, adjs);
    // sum_ij (Q'^T Q')_ij adj(S')_ij over the lower triangle, off-diagonal terms twice. The
    // terms are summed pairwise, not in a chain: this sum ends the annealing step's critical
    // path (its decision waits on it).
    double diag[3], off[3], trs[3];
    int no = 0;
#pragma GCC unroll 8
    for (int i = 0; i < ns; ++i) {
      trs[i] = adjs[i][i];
#pragma GCC unroll 8
      for (int j = 0; j <= i; ++j) {
        double v = q[0][i] * q[0][j];
#pragma GCC unroll 8
        for (int k = 1; k < na; ++k) v += q[k][i] * q[k][j];
        if (i == j)
          diag[i] = v * adjs[i][i];
        else
          off[no++] = v * adjs[i][j];
      }
    }
    const double sum_diag = pairwise_sum<ns>(diag), sum_trs = pairwise_sum<ns>(trs);
    const double sum_off = pairwise_sum<ns*(ns - 1) / 2>(off);
    f.num = (tra * dets + deta * deta * sum_trs) + (sum_diag + 2.0 * sum_off);
    f.den = deta * dets;
    f.det_num = dets;  // det S' = a^ns det S
    f.det_den = ns == 1 ? 1.0 : (ns == 2 ? deta : deta * deta);
    const bool s_regular = dets > kClosedFormHadamard * diagonal_product<ns>(s);
    return a_regular && s_regular && f.den < kInf && f.num < kInf;
  }
}

/// The criteria whose annealing decisions use the closed form. Their raw value v = p / q
/// (q > 0) is tr M tr M^-1 for kappa_a and kappa_j (cost = kappa_F = sqrt(v) / m), tr M^-1
/// for a_opt (cost = v) and det M for d_opt (cost = -log v).
template <int MC, Crit C>
constexpr bool uses_closed_form() {
  return has_closed_form<MC>() &&
         (C == Crit::kappa_a || C == Crit::kappa_j || C == Crit::a_opt || C == Crit::d_opt);
}

template <int MC, Crit C>
STIFF_ALWAYS_INLINE inline bool raw_fraction(const double* X, double& p, double& q) {
  ClosedForm f;
  if (!closed_form<MC>(X, f)) return false;
  if constexpr (C == Crit::d_opt) {
    p = f.det_num;
    q = f.det_den;
  } else if constexpr (C == Crit::a_opt) {
    p = f.num;
    q = f.den;
  } else {
    p = f.tr * f.num;
    q = f.den;
  }
  return p < kInf;
}

// ------------------------------------------------------------------------------------------
// A cheap bound that rejects a proposal before the closed form. For a positive definite M and
// a partition of its indices into blocks, (M^-1)_BB >= (M_BB)^-1 for every diagonal block B
// (the inverse of a Schur complement; inversion reverses the Loewner order: Horn & Johnson,
// Matrix Analysis, 2nd ed., 0.7.3 and 7.7), hence
//   tr M^-1 >= sum_B tr (M_BB)^-1   and (Fischer's inequality)   det M <= prod_B det M_BB.
// With blocks {0,1}, {2,3}, ... (a last 1 x 1 block for odd m) this costs a few products of the
// diagonal and first sub-diagonal, and on the paper's set-up it decides about two thirds of the
// rejections of an annealing run (the raw value is dominated by the smallest eigenvalue, which
// the pairs see). A rejection by the bound is a rejection by the exact criterion, so the chain
// is unchanged; the closed form then runs only for proposals the bound cannot decide.
// ------------------------------------------------------------------------------------------

/// True when the bound proves that the exact test within<C>(p, q, threshold) fails for the
/// packed matrix X (m <= 6, closed-form criteria only). False when it cannot tell, including for
/// a block that is not positive definite (the exact path decides those).
template <int MC, Crit C>
STIFF_ALWAYS_INLINE inline bool bound_rejects(const double* X, double threshold) {
  static_assert(uses_closed_form<MC, C>(), "the bound serves the closed-form criteria");
  // Inlined, so that packed_index folds to a constant for the unrolled indices.
  auto at = [X](int r, int c) STIFF_ALWAYS_INLINE { return packed_at<MC>(X, r, c); };
  // sum_B tr(M_BB)^-1 = num / den: a pair's tr inverse is its trace over its determinant.
  double num = 0.0, den = 1.0, tr = 0.0;
  bool positive = true;
#pragma GCC unroll 8
  for (int b = 0; b < MC; b += 2) {
    double bn, bd;
    if (b + 1 < MC) {
      bn = at(b, b) + at(b + 1, b + 1);
      bd = at(b, b) * at(b + 1, b + 1) - at(b + 1, b) * at(b + 1, b);
    } else {
      bn = 1.0;
      bd = at(b, b);
    }
    tr += b + 1 < MC ? bn : at(b, b);
    positive = positive && bd > 0.0;
    num = b == 0 ? bn : num * bd + bn * den;
    den = b == 0 ? bd : den * bd;
  }
  // A relative margin far above the round-off of these few operations keeps the bound a bound.
  constexpr double kMargin = 1e-12;
  if constexpr (C == Crit::d_opt) {
    return positive && den * (1.0 + kMargin) < threshold;
  } else if constexpr (C == Crit::a_opt) {
    return positive && num > threshold * den * (1.0 + kMargin);
  } else {
    return positive && tr * num > threshold * den * (1.0 + kMargin);
  }
}

template <Crit C>
inline double cost_from_raw(double v, int m) {
  if constexpr (C == Crit::d_opt)
    return -std::log(v);
  else if constexpr (C == Crit::a_opt)
    return v;
  else
    return std::sqrt(v) / m;
}

/// Score (larger is better) from the annealing cost (inverse of cost_of).
inline double score_of(Crit id, double cost) {
  if (id == Crit::kappa_a || id == Crit::kappa_j) return cost < kInf ? 1.0 / cost : 0.0;
  return -cost;
}

/// Metropolis test on the fraction: raw_threshold(c) is the raw value whose cost is c, and
/// within(p, q, t) says whether cost(p / q) <= c (the cost falls with v for d_opt and rises
/// with it for the others).
template <Crit C>
inline double raw_threshold(double cost, int m) {
  if constexpr (C == Crit::d_opt) {
    return std::exp(-cost);
  } else if constexpr (C == Crit::a_opt) {
    return cost;
  } else {
    const double c = m * cost;
    return c * c;
  }
}

template <Crit C>
STIFF_ALWAYS_INLINE inline bool within(double p, double q, double threshold) {
  if constexpr (C == Crit::d_opt)
    return p >= threshold * q;
  else
    return p <= threshold * q;
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
