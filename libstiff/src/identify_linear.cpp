// Linear least-squares identification of joint compliances, method.md eqs. 4-5.
//
// Performance notes (issue 4): the observation matrix A (3N x n) is built in one pass with a
// forward kinematics specialised once per robot (no 4x4 products, no allocations per row),
// and the normal matrix A^T W^2 A and A^T W^2 x are accumulated on the way. The rank decision,
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
#include <functional>
#include <string_view>
#include <vector>

#include "stiff/error.hpp"
#include "stiff/identify.hpp"

namespace stiff {
namespace detail {

/// validate_dataset(data, dof, true) for the identification, without building strings or a
/// std::set per row: a fast scan that, on finding any problem, lets validate_dataset throw its
/// (identical) error. Also checks what check_joint_vector checks (q size and finiteness).
void validate_identification_data(const Dataset& data, int dof) {
  if (data.rows.empty() || !data.has_displacement) validate_dataset(data, dof, true);
  const size_t n = data.rows.size();
  // Duplicate ids: open addressing on the ids' hashes (no allocation per row).
  size_t cap = 16;
  while (cap < 2 * n) cap *= 2;
  std::vector<int> table(cap, -1);
  const std::hash<std::string_view> hash;
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
    for (size_t h = hash(m.id) & (cap - 1);; h = (h + 1) & (cap - 1)) {
      if (table[h] < 0) {
        table[h] = static_cast<int>(r);
        break;
      }
      if (data.rows[table[h]].id == m.id) {
        bad = true;
        break;
      }
    }
  }
  if (bad) validate_dataset(data, dof, true);  // throws the exact message
}

/// Forward kinematics of a RobotModel specialised once: the joints' constant transforms as
/// rotation + translation with identity / zero parts skipped and unit joint axes applied as
/// plane rotations. Gives the joint axes, the points on them and the flange pose, equal to
/// RobotModel::chain up to round-off.
class FastChain {
 public:
  explicit FastChain(const RobotModel& robot) {
    for (const auto& j : robot.joints) {
      Step s;
      s.pre = rigid(j.pre);
      s.post = rigid(j.post);
      s.axis = j.axis;
      s.unit = -1;
      for (int k = 0; k < 3; ++k) {
        Eigen::Vector3d e = Eigen::Vector3d::Zero();
        e(k) = 1.0;
        if (j.axis == e) s.unit = k, s.sign = 1.0;
        if (j.axis == -e) s.unit = k, s.sign = -1.0;
      }
      // A modified-DH joint (Craig: RotX(alpha) TransX(a) TransZ(d) RotZ(offset + q)) is applied
      // as two plane rotations and one translation; cos/sin of alpha snapped to 0 / +-1 when
      // they are round-off of a multiple of 90 degrees.
      const Joint dh = modified_dh_joint(j.dh[0], j.dh[1], j.dh[2], j.dh[3]);
      if (j.axis == Eigen::Vector3d::UnitZ() && s.post.r_identity && s.post.p_zero &&
          dh.pre == j.pre) {
        s.dh = true;
        s.ca = std::cos(j.dh[0]);
        s.sa = std::sin(j.dh[0]);
        if (std::abs(s.ca) < 1e-15) s.ca = 0.0, s.sa = s.sa > 0 ? 1.0 : -1.0;
        if (std::abs(s.sa) < 1e-15) s.sa = 0.0, s.ca = s.ca > 0 ? 1.0 : -1.0;
        s.a = j.dh[1];
        s.d = j.dh[2];
        s.offset = j.dh[3];
      }
      steps_.push_back(s);
    }
  }

  /// z (3 x n) axes, o (3 x n) points on them, flange rotation and position.
  void operator()(const Eigen::VectorXd& q,
                  Eigen::Matrix3Xd& z,
                  Eigen::Matrix3Xd& o,
                  Eigen::Matrix3d& r,
                  Eigen::Vector3d& p) const {
    r.setIdentity();
    p.setZero();
    for (size_t i = 0; i < steps_.size(); ++i) {
      const Step& s = steps_[i];
      if (s.dh) {
        // r <- r RotX(alpha)
        if (s.sa != 0.0 || s.ca != 1.0) {
          const Eigen::Vector3d c1 = r.col(1), c2 = r.col(2);
          if (s.ca == 0.0) {
            r.col(1) = c2 * s.sa;
            r.col(2) = c1 * -s.sa;
          } else {
            r.col(1) = c1 * s.ca + c2 * s.sa;
            r.col(2) = c2 * s.ca - c1 * s.sa;
          }
        }
        if (s.a != 0.0) p += r.col(0) * s.a;
        if (s.d != 0.0) p += r.col(2) * s.d;
        o.col(i) = p;
        z.col(i) = r.col(2);
        rotate(r, 2, s.offset == 0.0 ? q(i) : q(i) + s.offset, 1.0);
        continue;
      }
      apply(s.pre, r, p);
      o.col(i) = p;
      if (s.unit >= 0) {
        z.col(i) = s.sign * r.col(s.unit);
        rotate(r, s.unit, q(i), s.sign);
      } else {
        z.col(i) = r * s.axis;
        const Eigen::Matrix3d rot = Eigen::AngleAxisd(q(i), s.axis).toRotationMatrix();
        r = (r * rot).eval();
      }
      apply(s.post, r, p);
    }
  }

 private:
  struct Rigid {
    Eigen::Matrix3d r;
    Eigen::Vector3d p;
    bool r_identity;
    bool p_zero;
  };
  struct Step {
    Rigid pre, post;
    Eigen::Vector3d axis;
    int unit;  ///< axis = sign * e_unit, or -1 for a general axis
    double sign = 1.0;
    bool dh = false;  ///< modified DH joint: the fields below
    double ca = 1, sa = 0, a = 0, d = 0, offset = 0;
  };
  /// r <- r Rot(sign e_unit, angle)
  static void rotate(Eigen::Matrix3d& r, int unit, double angle, double sign) {
    const double c = std::cos(angle), sn = sign * std::sin(angle);
    const int a = (unit + 1) % 3, b = (unit + 2) % 3;
    const Eigen::Vector3d ca = r.col(a), cb = r.col(b);
    r.col(a) = ca * c + cb * sn;
    r.col(b) = cb * c - ca * sn;
  }
  static Rigid rigid(const Eigen::Matrix4d& t) {
    Rigid g;
    g.r = t.block<3, 3>(0, 0);
    g.p = t.block<3, 1>(0, 3);
    g.r_identity = g.r == Eigen::Matrix3d::Identity();
    g.p_zero = g.p.isZero(0.0);
    return g;
  }
  /// (r, p) <- (r, p) * g
  static void apply(const Rigid& g, Eigen::Matrix3d& r, Eigen::Vector3d& p) {
    if (!g.p_zero) {
      Eigen::Vector3d dp = Eigen::Vector3d::Zero();
      for (int k = 0; k < 3; ++k)
        if (g.p(k) != 0.0) dp += r.col(k) * g.p(k);
      p += dp;
    }
    if (!g.r_identity) r = (r * g.r).eval();
  }
  std::vector<Step> steps_;
};

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
    const double f0 = m.force(0), f1 = m.force(1), f2 = m.force(2);
    const double m0 = m.moment(0), m1 = m.moment(1), m2 = m.moment(2);
    for (int j = 0; j < n; ++j) {
      const double* zj = z.data() + 3 * j;
      const double* oj = o.data() + 3 * j;
      // lever arm at L: z x (L - o), torque tau = lever . F + z . M
      const double lx = pl(0) - oj[0], ly = pl(1) - oj[1], lz = pl(2) - oj[2];
      const double wl0 = zj[1] * lz - zj[2] * ly, wl1 = zj[2] * lx - zj[0] * lz,
                   wl2 = zj[0] * ly - zj[1] * lx;
      const double tau = wl0 * f0 + wl1 * f1 + wl2 * f2 + (zj[0] * m0 + zj[1] * m1 + zj[2] * m2);
      double* col = blk.data() + 3 * j;
      if (same_point) {
        col[0] = wl0 * tau, col[1] = wl1 * tau, col[2] = wl2 * tau;
      } else {
        const double px = pm(0) - oj[0], py = pm(1) - oj[1], pz = pm(2) - oj[2];
        col[0] = (zj[1] * pz - zj[2] * py) * tau;
        col[1] = (zj[2] * px - zj[0] * pz) * tau;
        col[2] = (zj[0] * py - zj[1] * px) * tau;
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

FitResult identify_joint_linear(const RobotModel& robot,
                                const Dataset& data,
                                const LinearOptions& options) {
  detail::validate_identification_data(data, robot.dof());
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
    if (norms(j) > 1e-12 * max_norm)
      candidates.push_back(j);
    else
      f.warnings.push_back("joint " + std::to_string(j + 1) +
                           " is not identifiable: its column of A is zero for every measurement "
                           "(the load and the measured point give it no torque or no motion); "
                           "held at c = 0");
  }
  const int nc = static_cast<int>(candidates.size());
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
    if (fp.value <= 0)
      f.warnings.push_back("joint " + std::to_string(ident[k] + 1) +
                           ": identified compliance is not positive (" + std::to_string(fp.value) +
                           " rad/(N*m)); the data cannot resolve this joint's stiffness");
  }
  f.weights = Eigen::VectorXd::Ones(N);
  f.rms_m = std::sqrt(f.residuals.squaredNorm() / m);
  f.noise_floor_m = stated_noise_m(data);
  f.sigma_hat_m = weighted ? std::sqrt(s2) * f.noise_floor_m : std::sqrt(s2);
  if (weighted)
    f.chi2 = rss_w;
  else if (f.noise_floor_m > 0)
    f.chi2 = f.residuals.squaredNorm() / (f.noise_floor_m * f.noise_floor_m);
  return f;
}

}  // namespace stiff
