// Linear least-squares identification of joint compliances, Jiang & Fang 2023.
//
// Performance notes: the observation matrix A (3N x n) is built in one pass with a
// forward kinematics specialised once per robot (fast_chain.hpp: no 4x4 products, no
// allocations per row; for modified-DH chains eight measurements at a time in vectorised loops
// with a branch-free polynomial sincos), and the normal matrix A^T W^2 A and A^T W^2 x are
// accumulated on the way. The rank decision,
// the solution, the conditioning and the covariance then come from the small n x n problem:
// a pivoted Cholesky of the column-scaled normal matrix takes the same pivots as the
// column-pivoted QR of the scaled A (its pivots are the squared QR diagonal), and when every
// pivot is clearly above the rank tolerance the solution is the normal-equation solution
// refined once with the explicit residual (QR accuracy), the conditioning and covariance from
// the eigen-decomposition of the small matrix (= singular values and V of the scaled A). Only
// data close to a rank decision take the exact path: column-pivoted QR of the scaled A and the
// SVD of the identified columns.
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "identify/identifiability.hpp"
#include "kinematics/fast_chain.hpp"
#include "stiff/error.hpp"
#include "stiff/identify/identify.hpp"
#include "stiff/kinematics/joint_torque.hpp"

namespace stiff {
namespace detail {

/// validate_dataset(data, dof, true) for the identification, without building strings or a
/// std::set per row: a fast scan that, on finding any problem, lets validate_dataset throw its
/// (identical) error. Also checks what check_joint_vector checks (q size and finiteness).
void validate_identification_data(const Dataset& data, int dof) {
  if (data.rows.empty() || !data.has_displacement || data.has_position) {
    validate_dataset(data, dof, true);  // the full check (absolute rows have more columns)
    if (data.has_position) return;
  }
  const size_t n = data.rows.size();
  // Duplicate ids: open addressing on the ids' hashes (FNV-1a, inline: ids are short), the
  // full hash kept beside the row so that only equal hashes compare the strings.
  size_t cap = 16;
  while (cap < 2 * n) cap *= 2;
  struct Slot {
    std::uint64_t hash;
    int row;
  };
  std::vector<Slot> table(cap, Slot{0, -1});
  bool bad = false;
  for (size_t r = 0; r < n && !bad; ++r) {
    const auto& m = data.rows[r];
    if (m.q.size() != dof || !m.q.allFinite() || !m.force.allFinite() || !m.moment.allFinite() ||
        !m.displacement.allFinite() || !m.rotation.allFinite() || !std::isfinite(m.sigma_d) ||
        !std::isfinite(m.time) || m.sigma_d < 0) {
      bad = true;
      break;
    }
    if (m.id.empty()) continue;
    std::uint64_t hv = 1469598103934665603ull;
    for (const char ch : m.id) hv = (hv ^ static_cast<unsigned char>(ch)) * 1099511628211ull;
    for (size_t h = (hv ^ (hv >> 29)) & (cap - 1);; h = (h + 1) & (cap - 1)) {
      if (table[h].row < 0) {
        table[h] = Slot{hv, static_cast<int>(r)};
        break;
      }
      if (table[h].hash == hv && data.rows[table[h].row].id == m.id) {
        bad = true;
        break;
      }
    }
  }
  if (bad) validate_dataset(data, dof, true);  // throws the exact message
  // An uncertainty beyond a metre is no tracker's: a unit mistake (um read as m). It would
  // weight every row to nothing and read as "no load".
  if (data.has_sigma)
    for (size_t r = 0; r < n; ++r)
      if (data.rows[r].sigma_d > 1.0)
        throw InvalidArgument("measurement " + std::to_string(r + 1) + " (id '" + data.rows[r].id +
                              "'): sigma_d = " + std::to_string(data.rows[r].sigma_d) +
                              " m is larger than any robot; check the unit of the sigma_d column");
}

}  // namespace detail

namespace {

/// Unit-free weighted observation rows: A (3N x n, unweighted), x, the row weights and the
/// normal equations G = A^T W^2 A, b = A^T W^2 x accumulated in the same pass.
struct Observations {
  Eigen::MatrixXd a;
  Eigen::VectorXd x;
  Eigen::VectorXd w;  ///< weight of each measurement (1 / sigma_d or 1)
  Eigen::MatrixXd g;
  Eigen::VectorXd b;
};

// Compiled twice, AVX2 chosen at load time where the processor has it (the lanes' arithmetic
// is the same, in the same order, so are the results).
// (Not under ThreadSanitizer: the ifunc resolver runs before its runtime is initialised.)
#if defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define STIFF_NO_IFUNC 1
#endif
#endif
#if defined(__SANITIZE_THREAD__)
#define STIFF_NO_IFUNC 1
#endif
#if defined(__x86_64__) && defined(__GNUC__) && !defined(STIFF_NO_IFUNC)
#define STIFF_AVX2_CLONE __attribute__((target_clones("avx2", "default")))
#else
#define STIFF_AVX2_CLONE
#endif

/// observe() for an all-DH chain: FastChain::kLanes measurements at a time, one per lane of
/// structure-of-arrays loops that the compiler vectorises; the normal equations are summed per
/// lane and the lanes added at the end.
STIFF_AVX2_CLONE bool observe_batched(const RobotModel& robot,
                                      const Dataset& data,
                                      bool weighted,
                                      const detail::FastChain& fk,
                                      Observations& ob) {
  constexpr int L = detail::FastChain::kLanes;
  constexpr int kMaxJ = 12;
  const int n = robot.dof();
  if (!fk.all_dh() || n > kMaxJ) return false;
  const int N = static_cast<int>(data.rows.size());
  double c[kMaxJ][L], sn[kMaxJ][L], z[kMaxJ][3][L], o[kMaxJ][3][L], rf[3][3][L], pf[3][L];
  double col[kMaxJ][3][L], pm[3][L], pl[3][L], f[3][L], mo[3][L], x[3][L], w2[L];
  double gacc[kMaxJ][kMaxJ][L] = {}, bacc[kMaxJ][L] = {};
  const Eigen::Vector3d rp = robot.measured_point, rl = robot.load_point;
  const bool same_point = rp == rl;
  double* a = ob.a.data();
  const size_t rows = 3 * static_cast<size_t>(N);
  double angle[kMaxJ][L];
  for (int r0 = 0; r0 < N; r0 += L) {
    const int nb = std::min(L, N - r0);
    bool small = true;
    for (int l = 0; l < L; ++l) {
      const Measurement* m = l < nb ? &data.rows[r0 + l] : nullptr;
      for (int j = 0; j < n; ++j) {
        const double off = fk.offset(j);
        const double q = m ? m->q(j) : 0.0;
        angle[j][l] = off == 0.0 ? q : q + off;
        small = small && std::abs(angle[j][l]) < 1e5;
      }
      for (int k = 0; k < 3; ++k) {
        f[k][l] = m ? m->force(k) : 0.0;
        mo[k][l] = m ? m->moment(k) : 0.0;
        x[k][l] = m ? m->displacement(k) : 0.0;
      }
      const double w = m && weighted ? 1.0 / m->sigma_d : 1.0;
      w2[l] = m ? w * w : 0.0;
      if (m) ob.w(r0 + l) = w;
    }
    for (int j = 0; j < n; ++j) {
      if (small)
        detail::sincos_lanes(angle[j], sn[j], c[j], L);
      else
        for (int l = 0; l < L; ++l) detail::sincos_fast(angle[j][l], &sn[j][l], &c[j][l]);
    }
    fk.batch(c, sn, z, o, rf, pf);
    for (int k = 0; k < 3; ++k)
      for (int l = 0; l < L; ++l) {
        pm[k][l] = rf[k][0][l] * rp(0) + rf[k][1][l] * rp(1) + rf[k][2][l] * rp(2) + pf[k][l];
        pl[k][l] = rf[k][0][l] * rl(0) + rf[k][1][l] * rl(1) + rf[k][2][l] * rl(2) + pf[k][l];
      }
    for (int j = 0; j < n; ++j) {
      const double(*zj)[L] = z[j];
      const double(*oj)[L] = o[j];
      for (int l = 0; l < L; ++l) {
        const Lane<L> zl{zj, l}, ol{oj, l};
        double wl[3];
        lever_arm(zl, ol, Lane<L>{pl, l}, wl);
        const double tau = joint_torque(wl, zl, Lane<L>{f, l}, Lane<L>{mo, l});
        if (same_point) {
          col[j][0][l] = wl[0] * tau, col[j][1][l] = wl[1] * tau, col[j][2][l] = wl[2] * tau;
        } else {
          double wm[3];
          lever_arm(zl, ol, Lane<L>{pm, l}, wm);
          col[j][0][l] = wm[0] * tau, col[j][1][l] = wm[1] * tau, col[j][2][l] = wm[2] * tau;
        }
      }
    }
    for (int j = 0; j < n; ++j)
      for (int l = 0; l < L; ++l) {
        const double c0 = col[j][0][l] * w2[l], c1 = col[j][1][l] * w2[l],
                     c2 = col[j][2][l] * w2[l];
        for (int k = 0; k <= j; ++k)
          gacc[j][k][l] += c0 * col[k][0][l] + c1 * col[k][1][l] + c2 * col[k][2][l];
        bacc[j][l] += c0 * x[0][l] + c1 * x[1][l] + c2 * x[2][l];
      }
    for (int l = 0; l < nb; ++l) {
      const size_t row = 3 * static_cast<size_t>(r0 + l);
      for (int j = 0; j < n; ++j)
        for (int k = 0; k < 3; ++k) a[j * rows + row + k] = col[j][k][l];
      for (int k = 0; k < 3; ++k) ob.x(row + k) = x[k][l];
    }
  }
  for (int j = 0; j < n; ++j) {
    for (int k = 0; k <= j; ++k) {
      double sum = 0.0;
      for (int l = 0; l < L; ++l) sum += gacc[j][k][l];
      ob.g(j, k) = ob.g(k, j) = sum;
    }
    double sum = 0.0;
    for (int l = 0; l < L; ++l) sum += bacc[j][l];
    ob.b(j) = sum;
  }
  return true;
}

Observations observe(const RobotModel& robot, const Dataset& data, bool weighted) {
  const int n = robot.dof();
  const int N = static_cast<int>(data.rows.size());
  Observations ob;
  ob.a.resize(3 * N, n);
  ob.x.resize(3 * N);
  ob.w.resize(N);
  ob.g = Eigen::MatrixXd::Zero(n, n);
  ob.b = Eigen::VectorXd::Zero(n);
  const detail::FastChain fk(robot);
  if (observe_batched(robot, data, weighted, fk, ob)) return ob;
  Eigen::Matrix3Xd z(3, n), o(3, n), blk(3, n);
  Eigen::Matrix3d rf;
  Eigen::Vector3d pf;
  const bool same_point = robot.measured_point == robot.load_point;
  double* g = ob.g.data();
  for (int r = 0; r < N; ++r) {
    const Measurement& m = data.rows[r];
    fk(m.q, z, o, rf, pf);
    const Eigen::Vector3d pm = rf * robot.measured_point + pf;
    const Eigen::Vector3d pl = rf * robot.load_point + pf;
    for (int j = 0; j < n; ++j) {
      const double* zj = z.data() + 3 * j;
      const double* oj = o.data() + 3 * j;
      double wl[3];
      lever_arm(zj, oj, pl, wl);
      const double tau = joint_torque(wl, zj, m.force, m.moment);
      double* col = blk.data() + 3 * j;
      if (same_point) {
        col[0] = wl[0] * tau, col[1] = wl[1] * tau, col[2] = wl[2] * tau;
      } else {
        double wm[3];
        lever_arm(zj, oj, pm, wm);
        col[0] = wm[0] * tau, col[1] = wm[1] * tau, col[2] = wm[2] * tau;
      }
    }
    ob.a.middleRows<3>(3 * r) = blk;
    ob.x.segment<3>(3 * r) = m.displacement;
    const double w = weighted ? 1.0 / m.sigma_d : 1.0;
    ob.w(r) = w;
    const double w2 = w * w;
    const double* b3 = blk.data();
    const double x0 = m.displacement(0), x1 = m.displacement(1), x2 = m.displacement(2);
    for (int j = 0; j < n; ++j) {
      const double c0 = b3[3 * j] * w2, c1 = b3[3 * j + 1] * w2, c2 = b3[3 * j + 2] * w2;
      for (int k = 0; k <= j; ++k)
        g[j + n * k] += c0 * b3[3 * k] + c1 * b3[3 * k + 1] + c2 * b3[3 * k + 2];
      ob.b(j) += c0 * x0 + c1 * x1 + c2 * x2;
    }
  }
  ob.g.triangularView<Eigen::StrictlyUpper>() = ob.g.transpose();
  return ob;
}

/// Pivoted Cholesky of a symmetric positive semi-definite matrix with unit diagonal: the
/// square roots of its pivots (in pivot order) equal |diag R| of the column-pivoted QR of a
/// matrix whose Gram matrix it is.
Eigen::VectorXd pivoted_cholesky_diagonal(Eigen::MatrixXd g) {
  const int p = static_cast<int>(g.rows());
  Eigen::VectorXd out(p);
  std::vector<int> left(p);
  for (int k = 0; k < p; ++k) left[k] = k;
  for (int k = 0; k < p; ++k) {
    int best = k;
    for (int i = k + 1; i < p; ++i)
      if (g(left[i], left[i]) > g(left[best], left[best])) best = i;
    std::swap(left[k], left[best]);
    const int c = left[k];
    const double d = g(c, c);
    out(k) = d > 0 ? std::sqrt(d) : 0.0;
    if (!(d > 0)) {
      for (int i = k + 1; i < p; ++i) out(i) = 0.0;
      break;
    }
    for (int i = k + 1; i < p; ++i)
      for (int l = k + 1; l < p; ++l) g(left[i], left[l]) -= g(left[i], c) * g(c, left[l]) / d;
  }
  return out;
}

}  // namespace

namespace {

/// The linear fit with the compliances in `held` held at 0 (named in warnings by the caller).
FitResult linear_fit(const RobotModel& robot,
                     const Dataset& data,
                     const LinearOptions& options,
                     const std::vector<bool>& held,
                     Eigen::MatrixXd* weighted_a,
                     double* residual_sigma);

}  // namespace

FitResult identify_joint_linear(const RobotModel& robot,
                                const Dataset& data,
                                const LinearOptions& options) {
  // The rank decision inside the fit, then the statistical test of every fit
  // (identifiability.hpp): a compliance the data do not determine is held at 0 and the rest
  // fitted again.
  const int n = robot.dof();
  std::vector<bool> held(n, false);
  std::vector<std::string> reasons(n);
  std::vector<bool> below(n, false);  // held at the bound 0, not for want of data
  bool significantly_below = false;   // one of them by more than 3 standard errors
  const DeflectionModel model(robot, {"joint"});
  Eigen::VectorXd typical(n);
  for (int j = 0; j < n; ++j) typical(j) = model.spec(j).typical;
  for (int round = 0; round <= n; ++round) {
    Eigen::MatrixXd aw;
    double sigma = 0.0;  // residual standard deviation in the rows' weighted units
    FitResult f;
    try {
      f = linear_fit(robot, data, options, held, &aw, &sigma);
    } catch (const NumericalError&) {
      // Nothing left after the statistical test: say why, not only that.
      const auto why = std::find_if(reasons.begin(), reasons.end(),
                                    [](const std::string& r) { return !r.empty(); });
      if (why == reasons.end()) throw;
      std::string below_list, other;
      for (int j = 0; j < n; ++j) {
        if (below[j])
          below_list += (below_list.empty() ? "" : ", ") + std::to_string(j + 1);
        else if (other.empty() && !reasons[j].empty())
          other = "joint " + std::to_string(j + 1) + ": " + reasons[j];
      }
      // Noise pulls a loosely determined compliance below 0 by a standard error or two; a
      // fit that loses every compliance to the bound, one of them far below 0, has data whose
      // displacements oppose their loads.
      if (significantly_below)
        throw NumericalError(
            "identify: the measured displacements go against the loads: least squares puts the "
            "compliance of joint(s) " +
            below_list + " below 0, held at 0" +
            (other.empty() ? std::string()
                           : ", and the data do not determine the others (" + other + ")") +
            ", which leaves no compliance to fit. Check the sign conventions: a displacement is "
            "loaded minus unloaded, and the force and moment are those applied to the robot at "
            "the load point (not the sensor's reaction)");
      throw NumericalError(
          "identify: no joint compliance is determined by this data (joint " +
          std::to_string(why - reasons.begin() + 1) + ": " + *why +
          "): the deflections the loads cause are not resolved against the residual scatter "
          "(loads too small for the noise, too few poses, or displacements in a wrong unit)");
    }
    const Eigen::VectorXd theta = f.theta();
    std::vector<bool> fitted(n);
    for (int j = 0; j < n; ++j) fitted[j] = f.parameters[j].identified;
    const detail::Identifiability idf =
        detail::check_identifiability(model, aw, typical, options.rank_tolerance, sigma,
                                      options.max_relative_se, &theta, &fitted);
    bool more = false;
    for (int j = 0; j < n; ++j)
      if (idf.statistical[j]) {
        held[j] = true;
        reasons[j] = idf.reason[j];
        more = true;
      }
    // A compliance is not negative: where least squares puts one below 0 (the data pull that
    // joint against its load, noise or an effect the model lacks), the bounded solution holds
    // it at its bound 0 and fits the rest again, as the nonlinear identification's bounds do
    // (the most negative in standard errors first, one per round, as an active-set solver of
    // non-negative least squares proceeds: Lawson & Hanson 1974, ch. 23). A fit with a negative
    // compliance would predict the joint deflecting against its load, and no model can be
    // built from it.
    if (!more) {
      int worst = -1;
      double worst_t = 0;
      for (int j = 0; j < n; ++j) {
        const FitParameter& fp = f.parameters[j];
        const double t = fp.value / fp.standard_error;
        if (fp.identified && fp.value < 0 && (worst < 0 || t < worst_t)) {
          worst = j;
          worst_t = t;
        }
      }
      if (worst >= 0) {
        const FitParameter& fp = f.parameters[worst];
        held[worst] = true;
        below[worst] = true;
        significantly_below = significantly_below || worst_t < -3.0;
        reasons[worst] = "least squares puts its compliance below 0 (" + detail::num(fp.value) +
                         " +- " + detail::num(fp.standard_error) + " " + fp.unit +
                         "), which no joint has: held at its bound c = 0 (infinitely stiff), as "
                         "a bounded fit does; several standard errors below 0 mean the model "
                         "misses an effect (stiff diagnose) or a sign convention is crossed";
        more = true;
      }
    }
    if (!more) {
      for (int j = 0; j < n; ++j)
        if (!f.parameters[j].identified) f.parameters[j].held = below[j] ? "bound" : "undetermined";
      for (int j = 0; j < n; ++j)
        if (below[j])
          f.warnings.push_back("joint " + std::to_string(j + 1) + " (joint.c" +
                               std::to_string(j + 1) + "): " + reasons[j]);
        else if (!reasons[j].empty())
          f.warnings.push_back(
              "joint " + std::to_string(j + 1) + " is not identifiable from this data (joint.c" +
              std::to_string(j + 1) + "): " + reasons[j] + "; held at c = 0 (infinitely stiff)");
      return f;
    }
  }
  throw NumericalError("identify: no joint compliance is identifiable");
}

namespace {

FitResult linear_fit(const RobotModel& robot,
                     const Dataset& data,
                     const LinearOptions& options,
                     const std::vector<bool>& held,
                     Eigen::MatrixXd* weighted_a,
                     double* residual_sigma) {
  detail::validate_identification_data(data, robot.dof());
  if (data.absolute_rows() > 0)
    throw InvalidArgument(
        "the linear identification takes loaded-minus-unloaded rows only; absolute rows need "
        "the nonlinear identification (with geometric effects such as registration+tool)");
  const int n = robot.dof();
  const int N = static_cast<int>(data.rows.size());
  const int m = 3 * N;
  DeflectionModel model(robot, {"joint"});

  bool weighted = options.use_sigma && data.has_sigma;
  for (const auto& row : data.rows) weighted = weighted && row.sigma_d > 0;
  const Observations ob = observe(robot, data, weighted);
  const Eigen::MatrixXd& a = ob.a;
  const Eigen::VectorXd& x = ob.x;

  // Column scaling makes the rank decision independent of units and lever arms.
  Eigen::VectorXd norms = ob.g.diagonal().cwiseMax(0.0).cwiseSqrt();
  const double max_norm = norms.maxCoeff();
  if (!(max_norm > 0))
    throw NumericalError("identify: every observation column is zero (no load?)");
  // Finite but absurd inputs (loads or displacements near 1e308) overflow the normal equations.
  if (!std::isfinite(max_norm) || !ob.g.allFinite() || !ob.b.allFinite())
    throw NumericalError(
        "identify: the normal equations overflow: check the units and sizes of the loads and "
        "displacements (N, N*m, m)");
  std::vector<int> candidates;
  FitResult f;
  for (int j = 0; j < n; ++j) {
    if (held[j]) continue;  // named by the caller
    if (norms(j) > 1e-12 * max_norm)
      candidates.push_back(j);
    else
      f.warnings.push_back("joint " + std::to_string(j + 1) +
                           " is not identifiable: its column of A is zero for every measurement "
                           "(the load and the measured point give it no torque or no motion); "
                           "held at c = 0");
  }
  const int nc = static_cast<int>(candidates.size());
  // Every compliance held (by the caller's statistical test or a zero column): nothing to fit.
  if (nc == 0) throw NumericalError("identify: no joint compliance is identifiable from this data");
  Eigen::MatrixXd gs(nc, nc);
  for (int k = 0; k < nc; ++k)
    for (int l = 0; l < nc; ++l)
      gs(k, l) = ob.g(candidates[k], candidates[l]) / (norms(candidates[k]) * norms(candidates[l]));
  // Fast path when no pivot is near the rank tolerance (the pivots' round-off from the normal
  // equations, ~1e-15 / pivot, is then far below the margin): every candidate is identified.
  const Eigen::VectorXd piv = pivoted_cholesky_diagonal(gs);
  const bool clear = nc > 0 && piv.minCoeff() > std::max(1e-5, 1e3 * options.rank_tolerance);

  std::vector<int> ident;
  Eigen::VectorXd cs, sv;
  Eigen::MatrixXd inv;
  if (clear) {
    ident = candidates;
  } else {
    // Exact path: column-pivoted QR of the scaled, weighted A for the rank decision.
    Eigen::MatrixXd as(m, nc);
    for (int k = 0; k < nc; ++k)
      for (int r = 0; r < N; ++r)
        as.block<3, 1>(3 * r, k) =
            a.block<3, 1>(3 * r, candidates[k]) * (ob.w(r) / norms(candidates[k]));
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(as);
    qr.setThreshold(options.rank_tolerance);
    const int rank = static_cast<int>(qr.rank());
    const auto& perm = qr.colsPermutation().indices();
    for (int k = 0; k < nc; ++k) {
      if (k < rank)
        ident.push_back(candidates[perm(k)]);
      else
        f.warnings.push_back("joint " + std::to_string(candidates[perm(k)] + 1) +
                             " is not identifiable from this data: its column of A depends on the "
                             "others; held at c = 0 (add poses or loads that move it)");
    }
    std::sort(ident.begin(), ident.end());
  }
  if (ident.empty()) throw NumericalError("identify: no joint compliance is identifiable");
  if (m <= static_cast<int>(ident.size()))
    throw InvalidArgument("identify: " + std::to_string(N) + " measurements give " +
                          std::to_string(m) + " equations for " + std::to_string(ident.size()) +
                          " compliances; at least " + std::to_string(ident.size() / 3 + 1) +
                          " measurements are needed");

  const int p = static_cast<int>(ident.size());
  Eigen::VectorXd scale(p);
  for (int k = 0; k < p; ++k) scale(k) = norms(ident[k]);
  // Weighted residual of the scaled solution cs: w (x - A_ident cs / scale).
  auto residual = [&](const Eigen::VectorXd& c_scaled) {
    Eigen::VectorXd c = Eigen::VectorXd::Zero(n);
    for (int k = 0; k < p; ++k) c(ident[k]) = c_scaled(k) / scale(k);
    Eigen::VectorXd rw = x - a * c;
    for (int r = 0; r < N; ++r) rw.segment<3>(3 * r) *= ob.w(r);
    return rw;
  };
  if (clear) {
    // Scaled normal matrix of the identified columns: its eigen-decomposition gives the
    // singular values (sqrt) and V of the scaled A, hence (A^T A)^-1 = V S^-2 V^T.
    Eigen::MatrixXd gi(p, p);
    Eigen::VectorXd bi(p);
    for (int k = 0; k < p; ++k) {
      bi(k) = ob.b(ident[k]) / scale(k);
      for (int l = 0; l < p; ++l) gi(k, l) = ob.g(ident[k], ident[l]) / (scale(k) * scale(l));
    }
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(gi);
    const Eigen::VectorXd lam = es.eigenvalues();  // ascending
    sv.resize(p);
    for (int k = 0; k < p; ++k) sv(k) = std::sqrt(std::max(lam(p - 1 - k), 0.0));
    inv = es.eigenvectors() * lam.cwiseInverse().asDiagonal() * es.eigenvectors().transpose();
    cs = inv * bi;
    // The normal equations lose accuracy as cond^2: for a less than well-conditioned problem,
    // one step of refinement with the explicit residual restores QR accuracy.
    if (sv(0) > 30.0 * sv(p - 1)) {
      const Eigen::VectorXd r0 = residual(cs);
      Eigen::VectorXd grad = Eigen::VectorXd::Zero(p);
      for (int r = 0; r < N; ++r)
        for (int k = 0; k < p; ++k)
          grad(k) += a.block<3, 1>(3 * r, ident[k]).dot(r0.segment<3>(3 * r)) * ob.w(r) / scale(k);
      cs += inv * grad;
    }
  } else {
    Eigen::MatrixXd ai(m, p);
    for (int k = 0; k < p; ++k)
      for (int r = 0; r < N; ++r)
        ai.block<3, 1>(3 * r, k) = a.block<3, 1>(3 * r, ident[k]) * (ob.w(r) / scale(k));
    Eigen::VectorXd xw(m);
    for (int r = 0; r < N; ++r) xw.segment<3>(3 * r) = x.segment<3>(3 * r) * ob.w(r);
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(ai, Eigen::ComputeThinU | Eigen::ComputeThinV);
    sv = svd.singularValues();
    cs = svd.solve(xw);
    // (A^T A)^-1 of the scaled system from the SVD: V S^-2 V^T.
    inv = svd.matrixV() * sv.cwiseInverse().cwiseAbs2().asDiagonal() * svd.matrixV().transpose();
  }
  Eigen::VectorXd theta = Eigen::VectorXd::Zero(n);
  for (int k = 0; k < p; ++k) theta(ident[k]) = cs(k) / scale(k);
  f.residuals = x - a * theta;
  double rss_w = 0;
  for (int r = 0; r < N; ++r)
    rss_w += f.residuals.segment<3>(3 * r).squaredNorm() * (ob.w(r) * ob.w(r));
  const int dof = m - p;
  const double s2 = rss_w / dof;

  f.robot_name = robot.name;
  f.robot_digest = kinematics_digest(robot);
  f.robot_path = robot.source_path;
  f.model = {"joint"};
  f.method = "linear_least_squares";
  f.measurements = N;
  f.rank = p;
  f.dof = dof;
  f.condition_number = sv(0) / sv(p - 1);
  f.covariance = Eigen::MatrixXd::Constant(n, n, NAN);
  for (int j = 0; j < n; ++j) {
    FitParameter fp;
    const auto& spec = model.spec(j);
    fp.effect = "joint";
    fp.name = spec.name;
    fp.unit = spec.unit;
    fp.meaning = spec.meaning;
    fp.value = 0.0;
    fp.standard_error = NAN;
    fp.identified = false;
    f.parameters.push_back(fp);
  }
  for (int k = 0; k < p; ++k) {
    auto& fp = f.parameters[ident[k]];
    fp.value = theta(ident[k]);
    fp.identified = true;
    for (int l = 0; l < p; ++l)
      f.covariance(ident[k], ident[l]) = s2 * inv(k, l) / (scale(k) * scale(l));
    fp.standard_error = std::sqrt(f.covariance(ident[k], ident[k]));
  }
  f.weights = Eigen::VectorXd::Ones(N);
  f.rms_m = std::sqrt(f.residuals.squaredNorm() / m);
  f.noise_floor_m = stated_noise_m(data);
  f.sigma_hat_m = weighted ? std::sqrt(s2) * f.noise_floor_m : std::sqrt(s2);
  if (weighted)
    f.chi2 = rss_w;
  else if (f.noise_floor_m > 0)
    f.chi2 = f.residuals.squaredNorm() / (f.noise_floor_m * f.noise_floor_m);
  *weighted_a = a;
  for (int r = 0; r < N; ++r) weighted_a->middleRows<3>(3 * r) *= ob.w(r);
  *residual_sigma = std::sqrt(s2);
  return f;
}

}  // namespace

}  // namespace stiff
