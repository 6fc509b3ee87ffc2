// Set optimizers of measurement planning: the paper's simulated annealing (Jiang & Fang 2023,
// section 2.2), a modified Fedorov exchange (Cook & Nachtsheim 1980) and the plan driver.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "plan_internal.hpp"
#include "stiff/error.hpp"
#include "stiff/random.hpp"

namespace stiff {

using namespace plan_detail;

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

Context make_context(const RobotModel& robot,
                     const CandidatePool& pool,
                     const PlanOptions& o,
                     std::vector<double>* task) {
  Context c;
  c.id = criterion_id(o.criterion);
  c.m = pool.identified_count();
  c.count = o.count;
  if (c.id == Crit::task) {
    if (o.task.rows.empty())
      throw InvalidArgument(
          "plan: criterion 'task' needs task poses and loads (PlanOptions::task)");
    *task = task_information(robot, o.task, pool.identified_joints);
    c.task = task->data();
  }
  return c;
}

void validate(const CandidatePool& pool, const PlanOptions& o) {
  criterion_id(o.criterion);
  const int m = pool.identified_count();
  if (pool.size() == 0 || m == 0 || !pool.kernel)
    throw InvalidArgument("plan: the pool is empty or not finalized");
  if (o.count < 1) throw InvalidArgument("plan: count must be >= 1");
  if (o.count > pool.size())
    throw InvalidArgument("plan: count " + std::to_string(o.count) + " is larger than the pool (" +
                          std::to_string(pool.size()) + " elements)");
  if (3 * o.count < m)
    throw InvalidArgument("plan: count " + std::to_string(o.count) + " is too small to identify " +
                          std::to_string(m) +
                          " compliances (need 3N >= m, N >= " + std::to_string((m + 2) / 3) + ")");
  if (o.progress_interval < 1) throw InvalidArgument("plan: progress_interval must be >= 1");
}

void report(const PlanOptions& o, const PlanProgress& p) {
  if (o.progress && !o.progress(p))
    throw Cancelled("plan: cancelled by the progress callback during " + p.optimizer);
}

template <class R>
std::vector<int> random_subset(R& rng, int pool_size, int count, std::vector<uint8_t>& in) {
  std::vector<int> set;
  set.reserve(count);
  while (static_cast<int>(set.size()) < count) {
    const int e = static_cast<int>(rng.index(static_cast<uint64_t>(pool_size)));
    if (in[e]) continue;
    in[e] = 1;
    set.push_back(e);
  }
  return set;
}

// The optimizers keep one packed m x m matrix X: M, or MJ for kappa_j (the criteria need one or
// the other, never both). An element's packed contribution comes from the pool's per-element
// table when finalize() stored it, else it is computed from the per-pose data (same values).
template <int MC>
struct PackedKernel {
  static constexpr int kT = packed_size(MC > 0 ? MC : kMaxM);
  const CandidatePool& pool;
  const int t;
  const bool jac;
  const double* table;
  const int stride;
  PackedKernel(const CandidatePool& p, const Context& c)
      : pool(p),
        t(packed_size(c.m)),
        jac(c.id == Crit::kappa_j),
        table(jac ? nullptr : kernel_of(p).element_table()),
        stride(kernel_of(p).element_table_stride) {}
  int size() const { return MC > 0 ? packed_size(MC) : t; }
  // Element e's packed matrix: a pointer into the table, or `scratch` filled.
  const double* element(int e, double* scratch) const {
    if (table) return table + static_cast<size_t>(e) * stride;
    if (jac)
      element_jacobian_information<MC>(pool, e, scratch);
    else
      element_information<MC>(pool, e, scratch);
    return scratch;
  }
  // Start loading element e's table row: its first cache line and the line `last` bytes
  // into the row (rows of m <= 5 span at most two lines); longer rows whole.
  void prefetch(int e, int last) const {
#if defined(__GNUC__)
    if (!table) return;
    const char* row = reinterpret_cast<const char*>(table + static_cast<size_t>(e) * stride);
    if (size() > 2 * kCacheLineDoubles) {
      for (int b = 0; b < size(); b += kCacheLineDoubles)
        __builtin_prefetch(row + b * sizeof(double));
      return;
    }
    __builtin_prefetch(row);
    __builtin_prefetch(row + last);
#else
    (void)e;
    (void)last;
#endif
  }
  void copy_element(int e, double* out) const {
    const double* g = element(e, out);
    if (g != out) std::copy(g, g + size(), out);
  }
  // X = sum over positions of gset (in position order, as a rebuild from scratch).
  void rebuild(const std::vector<double>& gset, int count, double* X) const {
    const int T = size();
    std::fill(X, X + T, 0.0);
    for (int i = 0; i < count; ++i) {
      const double* g = gset.data() + static_cast<size_t>(i) * T;
      for (int q = 0; q < T; ++q) X[q] += g[q];
    }
  }
};

// The paper's simulated annealing over sets of N pool elements, on the packed information
// matrix X: k-element swap proposals, Metropolis acceptance, a linear cooling schedule and a
// swap count k(t) that falls from k0 to 1.
template <int MC, Crit C>
class Anneal {
 public:
  static SetSearchResult run(const CandidatePool& pool, const PlanOptions& o, const Context& ctx) {
    const auto t0 = Clock::now();
    Anneal a(pool, o, ctx);
    SetSearchResult r = a.search();
    r.trace.seconds = seconds_since(t0);
    return r;
  }

 private:
  static constexpr bool kClosed = uses_closed_form<MC, C>();
  using K_t = PackedKernel<MC>;
  // Candidate elements are drawn kAhead draws before they are used and their table rows
  // prefetched meanwhile: on pools whose table exceeds the cache (1e5 elements: 13 MB for
  // m = 5) the row arrives while earlier steps run. A candidate is uniform over the pool and
  // independent of the state, and one already in the set is skipped when used, so the
  // proposals are distributed exactly as with drawing at the time of use. They come from a
  // stream of their own, so that the look-ahead distance does not change which draws become
  // candidates (the result is the same for any kAhead).
  static constexpr int kAhead = 8;  // a power of two

  Anneal(const CandidatePool& pool, const PlanOptions& o, const Context& ctx)
      : o_(o),
        ctx_(ctx),
        K(pool, ctx),
        N(o.count),
        P(pool.size()),
        T(K.size()),
        m(ctx.m),
        rng(o.seed),
        in(P, 0),
        set(random_subset(rng, P, N, in)),
        gset(static_cast<size_t>(N) * T),
        TB(kClosed ? packed_bound_size(MC) : T),
        last_bound((TB - 1) / kCacheLineDoubles * kCacheLineBytes),
        last_row((T - 1) / kCacheLineDoubles * kCacheLineBytes),
        last(last_bound) {
    // Per position of the set, its element's packed matrix (the "out" side of a swap).
    for (int i = 0; i < N; ++i) K.copy_element(set[i], gset.data() + static_cast<size_t>(i) * T);
    K.rebuild(gset, N, X);
    cost = cost_of_matrix(X);
    const AnnealingOptions& ao = o.annealing;
    k0 = ao.initial_swap_count > 0 ? ao.initial_swap_count : std::max(1, N / 3);
    k0 = std::min({k0, N, P - N});
    const int kmax = std::max(k0, 1);
    pos.resize(N);
    new_e.resize(kmax);
    gin.resize(kmax);
    gout.resize(kmax);
    scratch.resize(static_cast<size_t>(kmax) * T);
    for (int i = 0; i < N; ++i) pos[i] = i;
    candidate_rng = rng;
    candidate_rng.jump();
    for (uint32_t& a : ahead) draw_ahead(a);
  }

  // Cost of a packed matrix: the closed form when it applies, else the Cholesky path.
  double cost_of_matrix(const double* Y) const {
    if constexpr (kClosed) {
      double p, q;
      if (raw_fraction<MC, C>(Y, p, q)) return cost_from_raw<C>(p / q, m);
    }
    return cost_of(C, score_packed<MC, C>(ctx_, Y));
  }

  void draw_ahead(uint32_t& slot) {
    slot = fast_index(candidate_rng, static_cast<uint32_t>(P));
    K.prefetch(static_cast<int>(slot), last);
  }
  int next_candidate() {
    const int e = static_cast<int>(ahead[ahead_at]);
    draw_ahead(ahead[ahead_at]);
    ahead_at = (ahead_at + 1) & (kAhead - 1);
    return e;
  }

  // One k-element swap proposal: Xn = X + sum (G_in - G_out), no rebuild of A; only the first
  // TB entries of Xn, those the bound reads (packed_bound_size).
  void propose(int k) {
    for (int s = 0; s < k; ++s) {
      const int j = s + static_cast<int>(fast_index(rng, static_cast<uint32_t>(N - s)));
      std::swap(pos[s], pos[j]);
      int e;
      do e = next_candidate();
      while (in[e]);
      in[e] = 2;
      new_e[s] = e;
      const double* gi = K.element(e, scratch.data() + static_cast<size_t>(s) * T);
      const double* go = gset.data() + static_cast<size_t>(pos[s]) * T;
      gin[s] = gi;
      gout[s] = go;
      const double* from = s == 0 ? X : Xn;
      for (int q = 0; q < TB; ++q) Xn[q] = (from[q] + gi[q]) - go[q];
    }
  }
  // The other entries of Xn, each summed in the same order as in propose.
  void complete(int k) {
    for (int s = 0; s < k; ++s) {
      const double* from = s == 0 ? X : Xn;
      for (int q = TB; q < T; ++q) Xn[q] = (from[q] + gin[s][q]) - gout[s][q];
    }
  }
  void reject(int k) {
    for (int s = 0; s < k; ++s) in[new_e[s]] = 0;
  }
  // The proposal becomes the set, at cost cn.
  void accept(int k, double cn) {
    for (int s = 0; s < k; ++s) {
      in[set[pos[s]]] = 0;
      set[pos[s]] = new_e[s];
      in[new_e[s]] = 1;
      double* out = gset.data() + static_cast<size_t>(pos[s]) * T;
      for (int q = 0; q < T; ++q) out[q] = gin[s][q];  // fixed size: no memmove call
    }
    for (int q = 0; q < T; ++q) X[q] = Xn[q];
    cost = cn;
  }

  // T0: the user's, or a fraction of the mean uphill cost change of random k0-swaps from the
  // start set. A random set's cost changes are far larger than those that decide near good sets
  // (docs/planning.md, "Initial temperature"), hence the fraction.
  double initial_temperature() {
    const AnnealingOptions& ao = o_.annealing;
    if (ao.initial_temperature < 0 || !std::isfinite(ao.initial_temperature))
      throw InvalidArgument("plan: initial temperature must be finite and >= 0");
    if (ao.iterations < 0) throw InvalidArgument("plan: iterations must be >= 0");
    if (!(ao.automatic_temperature_fraction > 0) ||
        !std::isfinite(ao.automatic_temperature_fraction))
      throw InvalidArgument("plan: automatic_temperature_fraction must be finite and > 0");
    if (k0 == 0 || ao.initial_temperature != 0) return ao.initial_temperature;
    double sum = 0;
    int cnt = 0;
    for (int t = 0; t < 200; ++t) {
      propose(k0);
      complete(k0);
      const double c = cost_of_matrix(Xn);
      reject(k0);
      if (std::isfinite(c) && std::isfinite(cost) && c > cost) {
        sum += c - cost;
        ++cnt;
      }
    }
    return cnt > 0 ? ao.automatic_temperature_fraction * (sum / cnt)
                   : (std::isfinite(cost) ? 1e-3 * std::abs(cost) + 1e-300 : 1.0);
  }

  // Metropolis on the proposal of k swaps: accept when Delta <= dmax (`down`: the raw value of
  // the current cost, for the closed form's bound). Sets *cn to the proposal's cost when
  // accepted.
  bool metropolis(int k, double dmax, double down, double* cn) {
    bool decided = false, ok = false;
    *cn = kInf;
    if constexpr (kClosed) {
      const double threshold = dmax > 0 ? raw_threshold<C>(cost + dmax, m) : down;
      double p, q;
      if (bound_rejects<MC, C>(Xn, threshold)) {
        decided = true;
      } else {
        complete(k);
        ++completed;
        if (raw_fraction<MC, C>(Xn, p, q)) {
          decided = true;
          ok = within<C>(p, q, threshold);
          if (ok) *cn = cost_from_raw<C>(p / q, m);
        }
      }
    } else {
      complete(k);
    }
    if (!decided) {
      *cn = cost_of(C, score_packed<MC, C>(ctx_, Xn));
      ok = *cn < kInf && *cn - cost <= dmax;
    }
    return ok;
  }

  SetSearchResult search() {
    const AnnealingOptions& ao = o_.annealing;
    SetSearchResult r;
    r.trace.optimizer = "annealing";
    r.trace.start_score = score_of(C, cost);
    std::vector<int> best = set;
    double best_cost = cost;
    const double T0 = initial_temperature();
    r.trace.initial_temperature = T0;
    r.trace.initial_swap_count = k0;

    const long iters = k0 > 0 ? ao.iterations : 0;
    const int refresh = std::max(1, ao.refresh_interval);
    long accepted = 0, since_refresh = 0;
    PlanProgress pr;
    pr.optimizer = "annealing";
    pr.total = iters;
    const bool progress = static_cast<bool>(o_.progress);
    // k(t) = max(1, ceil(k0 (1 - t / iterations))) is a step function: evaluated where it steps.
    auto k_at = [&](long it) {
      return std::max(1, static_cast<int>(std::ceil(
                             k0 * (1.0 - static_cast<double>(it) / static_cast<double>(iters)))));
    };
    int k = 0;
    long k_until = 0;  // k holds for it < k_until
    const double inv_iters = iters > 0 ? 1.0 / static_cast<double>(iters) : 0.0;
    double down = kClosed ? raw_threshold<C>(cost, m) : 0.0;  // raw value of the current cost
    for (long it = 0; it < iters; ++it) {
      if (it >= k_until) {
        k = k_at(it);
        long lo = it, hi = iters;  // first iteration with another k: in (lo, hi]
        while (hi - lo > 1) {
          const long mid = lo + (hi - lo) / 2;
          (k_at(mid) == k ? lo : hi) = mid;
        }
        k_until = hi;
      }
      const double temp = T0 * (1.0 - static_cast<double>(it) * inv_iters);
      propose(k);
      // Accept when Delta <= dmax = T E with E ~ Exp(1) (E = -ln u, u uniform in (0, 1]):
      // downhill always, uphill with probability exp(-Delta / T). E is drawn before the
      // evaluation so that one comparison decides (one unpredictable branch per step, not two).
      const double dmax = temp > 0 ? temp * standard_exponential(rng) : 0.0;
      double cn;
      if (metropolis(k, dmax, down, &cn)) {
        accept(k, cn);
        ++accepted;
        if (++since_refresh >= refresh) {
          // Bound the round-off of the rank-3 updates.
          K.rebuild(gset, N, X);
          cost = cost_of_matrix(X);
          since_refresh = 0;
        }
        if constexpr (kClosed) down = raw_threshold<C>(cost, m);
        if (cost < best_cost) {
          best_cost = cost;
          best = set;
        }
      } else {
        reject(k);
      }
      // A proposal reads the first TB entries of a candidate's row, and the rest only when the
      // bound cannot reject it: only those are prefetched while the bound rejects most
      // proposals (a cool chain, the default T0); a hot chain, where most proposals reach the
      // closed form, prefetches whole rows. `last` follows the share of completed proposals
      // over windows of 1024 steps.
      if ((it & 1023) == 1023) {
        last = completed > 512 ? last_row : last_bound;
        completed = 0;
      }
      if (progress && (it + 1) % o_.progress_interval == 0) {
        pr.iteration = it + 1;
        pr.best_score = score_of(C, best_cost);
        pr.current_score = score_of(C, cost);
        pr.temperature = temp;
        report(o_, pr);
      }
    }
    // The reported score of the best set: summed afresh and through the Cholesky path, as
    // set_score() computes it.
    for (int i = 0; i < N; ++i) K.copy_element(best[i], gset.data() + static_cast<size_t>(i) * T);
    K.rebuild(gset, N, X);
    const double best_score = score_packed<MC, C>(ctx_, X);
    r.elements = best;
    r.score = best_score;
    r.trace.best_score = best_score;
    r.trace.iterations = iters;
    r.trace.evaluations = iters;
    r.trace.accepted = accepted;
    return r;
  }

  const PlanOptions& o_;
  const Context& ctx_;
  const K_t K;
  const int N, P, T, m;
  Xoshiro256pp rng, candidate_rng{0};
  std::vector<uint8_t> in;
  std::vector<int> set;
  std::vector<double> gset;  ///< per position of the set, its element's packed matrix
  double X[K_t::kT], Xn[K_t::kT];
  double cost = 0;
  int k0 = 0;
  std::vector<int> pos, new_e;
  std::vector<const double*> gin, gout;
  std::vector<double> scratch;
  uint32_t ahead[kAhead];
  int ahead_at = 0;
  const int TB, last_bound, last_row;  ///< entries the bound reads; prefetch byte offsets
  int last, completed = 0;
};

template <int MC, Crit C>
struct Exchange {
  static SetSearchResult run(const CandidatePool& pool,
                             const PlanOptions& o,
                             const Context& ctx,
                             const std::vector<int>* start) {
    const auto t0 = Clock::now();
    using K_t = PackedKernel<MC>;
    const K_t K(pool, ctx);
    const int N = o.count, P = pool.size(), T = K.size();
    const ExchangeOptions& xo = o.exchange;
    if (xo.max_passes < 0 || xo.max_evaluations_per_pass < N)
      throw InvalidArgument(
          "plan: exchange needs max_passes >= 0 and max_evaluations_per_pass >= N");
    FastRng rng(o.seed ^ 0x9E3779B97F4A7C15ULL);
    std::vector<uint8_t> in(P, 0);
    std::vector<int> set;
    if (start) {
      if (static_cast<int>(start->size()) != N)
        throw InvalidArgument("plan: exchange start set has the wrong size");
      for (int e : *start) {
        if (e < 0 || e >= P || in[e]) throw InvalidArgument("plan: bad exchange start set");
        in[e] = 1;
      }
      set = *start;
    } else {
      set = random_subset(rng, P, N, in);
    }
    std::vector<double> gset(static_cast<size_t>(N) * T);
    for (int i = 0; i < N; ++i) K.copy_element(set[i], gset.data() + static_cast<size_t>(i) * T);
    double X[K_t::kT], Xm[K_t::kT], Xt[K_t::kT], scratch[K_t::kT];
    K.rebuild(gset, N, X);
    double sc = score_packed<MC, C>(ctx, X), cost = cost_of(C, sc);
    SetSearchResult r;
    r.trace.optimizer = "exchange";
    r.trace.start_score = sc;
    const bool all = static_cast<long>(N) * P <= xo.max_evaluations_per_pass;
    const long per_position = all ? P : xo.max_evaluations_per_pass / N;
    long evals = 0, accepted = 0, passes = 0;
    PlanProgress pr;
    pr.optimizer = "exchange";
    const bool progress = static_cast<bool>(o.progress);
    for (; passes < xo.max_passes; ++passes) {
      bool improved = false;
      for (int p = 0; p < N; ++p) {
        const double* go = gset.data() + static_cast<size_t>(p) * T;
        for (int q = 0; q < T; ++q) Xm[q] = X[q] - go[q];
        double best_c = cost;
        int best_e = -1;
        for (long t = 0; t < per_position; ++t) {
          const int e = all ? static_cast<int>(t) : static_cast<int>(rng.index(P));
          if (in[e]) continue;
          const double* g = K.element(e, scratch);
          for (int q = 0; q < T; ++q) Xt[q] = Xm[q] + g[q];
          const double s = score_packed<MC, C>(ctx, Xt);
          const double c = cost_of(C, s);
          ++evals;
          if (c < best_c - 1e-12 * std::abs(best_c)) {
            best_c = c;
            best_e = e;
          }
          if (progress && evals % o.progress_interval == 0) {
            pr.iteration = evals;
            pr.best_score = sc;
            pr.current_score = sc;
            report(o, pr);
          }
        }
        if (best_e >= 0) {
          in[set[p]] = 0;
          set[p] = best_e;
          in[best_e] = 1;
          K.copy_element(best_e, gset.data() + static_cast<size_t>(p) * T);
          K.rebuild(gset, N, X);
          sc = score_packed<MC, C>(ctx, X);
          cost = cost_of(C, sc);
          ++accepted;
          improved = true;
        }
      }
      if (!improved) {
        ++passes;
        break;
      }
    }
    r.elements = set;
    r.score = sc;
    r.trace.best_score = sc;
    r.trace.iterations = passes;
    r.trace.evaluations = evals;
    r.trace.accepted = accepted;
    r.trace.seconds = seconds_since(t0);
    return r;
  }
};

// The criterion is chosen once: the optimizer's loop is compiled per criterion and per m
// (fixed-size code for m = 1..7, runtime size above).
template <template <int, Crit> class F, int MC, typename... Args>
SetSearchResult dispatch_criterion(Crit id, Args&&... args) {
  switch (id) {
    case Crit::kappa_a:
      return F<MC, Crit::kappa_a>::run(std::forward<Args>(args)...);
    case Crit::kappa_j:
      return F<MC, Crit::kappa_j>::run(std::forward<Args>(args)...);
    case Crit::d_opt:
      return F<MC, Crit::d_opt>::run(std::forward<Args>(args)...);
    case Crit::a_opt:
      return F<MC, Crit::a_opt>::run(std::forward<Args>(args)...);
    case Crit::e_opt:
      return F<MC, Crit::e_opt>::run(std::forward<Args>(args)...);
    case Crit::o1:
      return F<MC, Crit::o1>::run(std::forward<Args>(args)...);
    default:
      return F<MC, Crit::task>::run(std::forward<Args>(args)...);
  }
}

template <template <int, Crit> class F, typename... Args>
SetSearchResult dispatch(int m, Crit id, Args&&... args) {
  switch (m) {
    case 1:
      return dispatch_criterion<F, 1>(id, std::forward<Args>(args)...);
    case 2:
      return dispatch_criterion<F, 2>(id, std::forward<Args>(args)...);
    case 3:
      return dispatch_criterion<F, 3>(id, std::forward<Args>(args)...);
    case 4:
      return dispatch_criterion<F, 4>(id, std::forward<Args>(args)...);
    case 5:
      return dispatch_criterion<F, 5>(id, std::forward<Args>(args)...);
    case 6:
      return dispatch_criterion<F, 6>(id, std::forward<Args>(args)...);
    case 7:
      return dispatch_criterion<F, 7>(id, std::forward<Args>(args)...);
    default:
      return dispatch_criterion<F, 0>(id, std::forward<Args>(args)...);
  }
}

void finish_trace(OptimizerTrace& t, const Context& ctx) {
  const bool larger = ctx.id != Crit::a_opt && ctx.id != Crit::task;
  t.best_value = larger ? t.best_score : -t.best_score;
}

}  // namespace

// ---------------------------------------------------------------------------------------------

IncrementalInformation::IncrementalInformation(const CandidatePool& pool, std::vector<int> elements)
    : pool_(&pool), elements_(std::move(elements)) {
  if (!pool.kernel) throw InvalidArgument("plan: the pool is not finalized");
  for (int e : elements_)
    if (e < 0 || e >= pool.size()) throw InvalidArgument("plan: element index out of range");
  refresh();
}

void IncrementalInformation::replace(int position, int element) {
  if (position < 0 || position >= static_cast<int>(elements_.size()) || element < 0 ||
      element >= pool_->size())
    throw InvalidArgument("plan: replace: index out of range");
  add_element<0>(*pool_, element, 1.0, m_.data());
  add_element<0>(*pool_, elements_[position], -1.0, m_.data());
  elements_[position] = element;
}

Eigen::MatrixXd IncrementalInformation::information() const {
  return from_lower(m_.data(), pool_->identified_count());
}

Eigen::MatrixXd IncrementalInformation::recomputed_information() const {
  const int m = pool_->identified_count();
  std::vector<double> a(m * m, 0.0);
  for (int e : elements_) add_element<0>(*pool_, e, 1.0, a.data());
  return from_lower(a.data(), m);
}

void IncrementalInformation::refresh() {
  const int m = pool_->identified_count();
  m_.assign(m * m, 0.0);
  for (int e : elements_) add_element<0>(*pool_, e, 1.0, m_.data());
}

SetSearchResult anneal(const RobotModel& robot, const CandidatePool& pool, const PlanOptions& o) {
  validate(pool, o);
  std::vector<double> task;
  const Context ctx = make_context(robot, pool, o, &task);
  SetSearchResult r = dispatch<Anneal>(ctx.m, ctx.id, pool, o, ctx);
  finish_trace(r.trace, ctx);
  return r;
}

SetSearchResult exchange(const RobotModel& robot,
                         const CandidatePool& pool,
                         const PlanOptions& o,
                         const std::vector<int>* start) {
  validate(pool, o);
  std::vector<double> task;
  const Context ctx = make_context(robot, pool, o, &task);
  SetSearchResult r = dispatch<Exchange>(ctx.m, ctx.id, pool, o, ctx, start);
  finish_trace(r.trace, ctx);
  return r;
}

double set_score(const RobotModel& robot,
                 const CandidatePool& pool,
                 const std::vector<int>& elements,
                 const PlanOptions& options) {
  PlanOptions o = options;
  o.count = static_cast<int>(elements.size());
  std::vector<double> task;
  const Context ctx = make_context(robot, pool, o, &task);
  const int m = ctx.m;
  std::vector<double> M(m * m, 0.0), MJ(m * m, 0.0);
  for (int e : elements) {
    if (e < 0 || e >= pool.size()) throw InvalidArgument("plan: element index out of range");
    add_element<0>(pool, e, 1.0, M.data());
    add_jacobian<0>(pool, e, 1.0, MJ.data());
  }
  return score<0>(ctx, M.data(), MJ.data());
}

PlanResult plan_measurements(const RobotModel& robot,
                             const CandidatePool& pool,
                             const PlanOptions& o) {
  validate(pool, o);
  if (!o.annealing.enabled && !o.exchange.enabled)
    throw InvalidArgument("plan: enable annealing and/or exchange");
  if (pool.dof != robot.dof())
    throw InvalidArgument("plan: the pool was built for a " + std::to_string(pool.dof) +
                          "-joint robot");
  PlanResult r;
  std::vector<SetSearchResult> runs;
  if (o.annealing.enabled) runs.push_back(anneal(robot, pool, o));
  if (o.exchange.enabled) runs.push_back(exchange(robot, pool, o));
  size_t best = 0;
  for (size_t i = 0; i < runs.size(); ++i) {
    r.trace.push_back(runs[i].trace);
    if (runs[i].score > runs[best].score) best = i;
  }
  r.found_by = runs[best].trace.optimizer;
  std::vector<PlannedMeasurement> ms = to_measurements(pool, runs[best].elements);
  if (o.refine.enabled) {
    OptimizerTrace t;
    std::vector<PlannedMeasurement> refined = refine_plan(robot, pool, ms, o, &t);
    r.trace.push_back(t);
    if (t.best_score > t.start_score) {
      ms = std::move(refined);
      r.found_by = "nlopt";
    }
  }
  finish_result(robot, pool, o, std::move(ms), r);
  return r;
}

namespace {
std::string got(double v) {
  std::ostringstream s;
  s << " (got " << v << ")";
  return s.str();
}
}  // namespace

void check_plan_options(const PoolOptions& pool, const PlanOptions& plan) {
  criterion_id(plan.criterion);
  if (plan.count < 1) throw InvalidArgument("plan: count must be >= 1" + got(plan.count));
  if (pool.candidate_file.empty() && pool.pose_count < 1)
    throw InvalidArgument("plan: the pool's pose count must be >= 1" + got(pool.pose_count));
  if (pool.load_count < 0)
    throw InvalidArgument("plan: the pool's load count must be >= 0 (0: the whole grid)" +
                          got(static_cast<double>(pool.load_count)));
  if (!(pool.range_fraction > 0 && pool.range_fraction <= 1))
    throw InvalidArgument("plan: range_fraction must be in (0, 1]" + got(pool.range_fraction));
  if (!(pool.load_min_N >= 0 && pool.load_min_N <= pool.load_max_N &&
        std::isfinite(pool.load_max_N))) {
    std::ostringstream range;
    range << "plan: empty load range [" << pool.load_min_N << ", " << pool.load_max_N
          << "] N: the per-axis magnitudes need 0 <= min <= max < inf";
    throw InvalidArgument(range.str());
  }
  if (!(pool.min_sigma_m >= 0 && std::isfinite(pool.min_sigma_m)))
    throw InvalidArgument("plan: min_sigma_m must be finite and >= 0" + got(pool.min_sigma_m));
  if (!(pool.noise.tracker_sigma_m > 0 && std::isfinite(pool.noise.tracker_sigma_m)))
    throw InvalidArgument("plan: the tracker sigma must be finite and > 0" +
                          got(pool.noise.tracker_sigma_m));
  const AnnealingOptions& a = plan.annealing;
  if (a.enabled && a.iterations < 1)
    throw InvalidArgument("plan: the annealing's iteration count must be >= 1" +
                          got(static_cast<double>(a.iterations)));
  if (!(std::isfinite(a.initial_temperature) && a.initial_temperature >= 0))
    throw InvalidArgument(
        "plan: the annealing's initial temperature T0 must be finite and >= 0 (0: automatic)" +
        got(a.initial_temperature));
  if (a.initial_swap_count < 0)
    throw InvalidArgument(
        "plan: the annealing's initial swap count k0 must be >= 0 (0: automatic)" +
        got(a.initial_swap_count));
}

PlanResult plan_measurements(const RobotModel& robot,
                             const PoolOptions& pool_options,
                             const PlanOptions& options) {
  // Every option is checked before the pool (the expensive part) is built, with one message
  // that the C ABI, Python and the command line all show.
  check_plan_options(pool_options, options);
  const CandidatePool pool = build_pool(robot, pool_options);
  return plan_measurements(robot, pool, options);
}

}  // namespace stiff
