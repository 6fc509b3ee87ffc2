// Inverse kinematics: analytic wrist-centre decoupling for 6R arms with a spherical wrist and
// parallel axes 2, 3; damped least squares for other chains (ik.hpp).
#include "stiff/compensate/ik.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <random>

#include "stiff/error.hpp"

namespace stiff {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kTwoPi = 2.0 * kPi;

using Mat3 = Eigen::Matrix3d;
using Vec3 = Eigen::Vector3d;
using Mat4 = Eigen::Matrix4d;

Mat3 rot(const Vec3& axis, double q) { return Eigen::AngleAxisd(q, axis).toRotationMatrix(); }
Mat3 R(const Mat4& t) { return t.block<3, 3>(0, 0); }
Vec3 P(const Mat4& t) { return t.block<3, 1>(0, 3); }
Vec3 apply(const Mat4& t, const Vec3& p) { return R(t) * p + P(t); }
Mat4 inverse(const Mat4& t) {
  Mat4 r = Mat4::Identity();
  r.block<3, 3>(0, 0) = R(t).transpose();
  r.block<3, 1>(0, 3) = -R(t).transpose() * P(t);
  return r;
}

/// Solutions of A cos q + B sin q = C: the two branches (equal at a tangency); none when
/// |C| > hypot(A, B) beyond rounding; `degenerate` when A = B = 0.
struct Trig {
  int count = 0;
  double q[2] = {0, 0};
  bool degenerate = false;
};
Trig solve_trig(double a, double b, double c) {
  Trig t;
  const double r = std::hypot(a, b);
  if (r < 1e-12 * std::max(1.0, std::abs(c))) {
    t.degenerate = true;
    return t;
  }
  double ratio = c / r;
  if (std::abs(ratio) > 1.0 + 1e-9) return t;
  ratio = std::clamp(ratio, -1.0, 1.0);
  const double phi = std::atan2(b, a);
  const double d = std::acos(ratio);
  t.count = 2;
  t.q[0] = phi + d;
  t.q[1] = phi - d;
  return t;
}

/// Coefficients of n . Rot(a, q) x = A cos q + B sin q + K.
void rot_coeffs(const Vec3& n, const Vec3& a, const Vec3& x, double* ca, double* cb, double* k) {
  *ca = n.dot(x) - n.dot(a) * a.dot(x);
  *cb = n.dot(a.cross(x));
  *k = n.dot(a) * a.dot(x);
}

/// Angle q with Rot(a, q) x = y (components perpendicular to a); false if x or y lies on a.
bool planar_angle(const Vec3& a, const Vec3& x, const Vec3& y, double* q) {
  const Vec3 xp = x - a * a.dot(x);
  const Vec3 yp = y - a * a.dot(y);
  if (xp.norm() < 1e-9 || yp.norm() < 1e-9) return false;
  *q = std::atan2(a.dot(xp.cross(yp)), xp.dot(yp));
  return true;
}

double wrap(double q) { return q - kTwoPi * std::floor((q + kPi) / kTwoPi); }

/// Point nearest to the lines (o_k, d_k) in the least-squares sense and its largest distance.
Vec3 nearest_point(const std::vector<Vec3>& o, const std::vector<Vec3>& d, double* worst) {
  Mat3 a = Mat3::Zero();
  Vec3 b = Vec3::Zero();
  for (size_t k = 0; k < o.size(); ++k) {
    const Mat3 proj = Mat3::Identity() - d[k] * d[k].transpose();
    a += proj;
    b += proj * o[k];
  }
  const Vec3 c = a.completeOrthogonalDecomposition().solve(b);
  *worst = 0;
  for (size_t k = 0; k < o.size(); ++k) {
    const Vec3 r = c - o[k];
    *worst = std::max(*worst, (r - d[k] * d[k].dot(r)).norm());
  }
  return c;
}

}  // namespace

Eigen::Matrix<double, 6, 1> pose_error(const Mat4& target, const Mat4& actual) {
  Eigen::Matrix<double, 6, 1> e;
  e.head<3>() = P(target) - P(actual);
  const Eigen::AngleAxisd aa(Mat3(R(target) * R(actual).transpose()));
  e.tail<3>() = aa.angle() * aa.axis();
  return e;
}

WristStructure analyse_wrist(const RobotModel& robot) {
  WristStructure w;
  if (robot.dof() != 6) {
    w.reason = "the analytic solver needs 6 joints, the robot has " + std::to_string(robot.dof());
    return w;
  }
  const ChainState s = robot.chain(Eigen::VectorXd::Zero(6));
  double reach = 0.1;
  for (int j = 0; j < 6; ++j) reach = std::max(reach, s.origin.col(j).norm());
  double worst = 0;
  const Vec3 c = nearest_point({s.origin.col(3), s.origin.col(4), s.origin.col(5)},
                               {s.axis.col(3), s.axis.col(4), s.axis.col(5)}, &worst);
  // Axes 4 and 6 parallel at q = 0 make the point ill-defined: try a bent wrist.
  Eigen::VectorXd q = Eigen::VectorXd::Zero(6);
  q(4) = 0.7;
  q(3) = 0.3;
  const ChainState s2 = robot.chain(q);
  double worst2 = 0;
  const Vec3 c2 = nearest_point({s2.origin.col(3), s2.origin.col(4), s2.origin.col(5)},
                                {s2.axis.col(3), s2.axis.col(4), s2.axis.col(5)}, &worst2);
  if (worst2 > 1e-9 * reach) {
    w.reason = "the last three axes do not intersect in one point (no spherical wrist)";
    return w;
  }
  (void)c;
  (void)worst;
  w.spherical = true;
  w.centre_link3 = apply(inverse(s2.link[2]), c2);
  w.centre_tool = apply(inverse(robot.tool_pose(q)), c2);
  const auto& j = robot.joints;
  const Vec3 a1 = j[1].axis.normalized();
  // Axis 3 seen in the frame of joint 2's rotation: R(post2) R(pre3) a3.
  const Vec3 a2in = (R(j[1].post) * R(j[2].pre) * j[2].axis.normalized());
  if (std::abs(std::abs(a1.dot(a2in)) - 1.0) > 1e-9) {
    w.reason = "axes 2 and 3 are not parallel";
    return w;
  }
  const Vec3 a0in = R(j[0].post) * R(j[1].pre) * a1;  // axis 2 in joint 1's rotation frame
  if (std::abs(std::abs(j[0].axis.normalized().dot(a0in)) - 1.0) < 1e-6) {
    w.reason = "axes 1 and 2 are parallel";
    return w;
  }
  w.analytic = true;
  return w;
}

InverseKinematics::InverseKinematics(const RobotModel& robot, const IkOptions& options)
    : robot_(robot), options_(options), wrist_(analyse_wrist(robot)) {
  if (robot_.dof() < 1) throw InvalidArgument("inverse kinematics: the robot has no joints");
  if (!(options_.tolerance > 0)) throw InvalidArgument("inverse kinematics: tolerance must be > 0");
}

double InverseKinematics::sigma_min(const Eigen::VectorXd& q) const {
  const Eigen::MatrixXd jac = robot_.jacobian(q);
  if (jac.cols() == 6) {
    const Eigen::Matrix<double, 6, 6> j6 = jac;
    // Eigenvalues of J^T J (cheaper than an SVD, accurate enough for a threshold).
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> es(j6.transpose() * j6,
                                                                  Eigen::EigenvaluesOnly);
    return std::sqrt(std::max(0.0, es.eigenvalues()(0)));
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(jac);
  return svd.singularValues()(svd.singularValues().size() - 1);
}

bool InverseKinematics::fit_limits(Eigen::VectorXd* q, const Eigen::VectorXd& seed) const {
  for (int j = 0; j < robot_.dof(); ++j) {
    const double lo = robot_.joints[j].lower, hi = robot_.joints[j].upper;
    const double base = wrap((*q)(j));
    double best = NAN;
    // Representations base + 2 pi k inside the limits (with a rounding margin).
    const double margin = 1e-12;
    const double kmin = std::ceil((lo - margin - base) / kTwoPi);
    const double kmax = std::floor((hi + margin - base) / kTwoPi);
    for (double k = kmin; k <= kmax; k += 1.0) {
      const double v = std::clamp(base + k * kTwoPi, lo, hi);
      if (std::isnan(best) || std::abs(v - seed(j)) < std::abs(best - seed(j))) best = v;
    }
    if (std::isnan(best)) {
      if (options_.respect_limits) return false;
      best = base;
    }
    (*q)(j) = best;
  }
  return true;
}

bool InverseKinematics::solve_numerical(const Mat4& pose,
                                        const Eigen::VectorXd& start,
                                        Eigen::VectorXd* q_out) const {
  const int n = robot_.dof();
  Eigen::VectorXd q = start;
  double lambda = 1e-3;
  Eigen::Matrix<double, 6, 1> e = pose_error(pose, robot_.tool_pose(q));
  double err = e.norm();
  for (int it = 0; it < options_.max_iterations && err > options_.tolerance * 0.1; ++it) {
    const Eigen::MatrixXd jac = robot_.jacobian(q);
    const Eigen::MatrixXd jjt = jac * jac.transpose();
    bool improved = false;
    for (int tries = 0; tries < 12; ++tries) {
      const Eigen::Matrix<double, 6, 6> a =
          jjt + lambda * lambda * Eigen::Matrix<double, 6, 6>::Identity();
      Eigen::VectorXd qn = q + jac.transpose() * a.ldlt().solve(e);
      if (options_.respect_limits)
        for (int j = 0; j < n; ++j)
          qn(j) = std::clamp(qn(j), robot_.joints[j].lower, robot_.joints[j].upper);
      const Eigen::Matrix<double, 6, 1> en = pose_error(pose, robot_.tool_pose(qn));
      if (en.norm() < err) {
        q = qn;
        e = en;
        err = en.norm();
        lambda = std::max(lambda * 0.1, 1e-12);
        improved = true;
        break;
      }
      lambda *= 10.0;
    }
    if (!improved) break;
  }
  *q_out = q;
  return err <= options_.tolerance && q.allFinite();
}

std::vector<IkSolution> InverseKinematics::analytic_all(const Mat4& pose) const {
  const auto& jt = robot_.joints;
  std::vector<IkSolution> out;
  const Vec3 a0 = jt[0].axis.normalized(), a1 = jt[1].axis.normalized(),
             a2 = jt[2].axis.normalized();
  // Wrist centre target in the base frame.
  const Vec3 p = apply(pose, wrist_.centre_tool);
  const Vec3 pp = apply(inverse(jt[0].pre), p);  // in joint 1's rotation frame
  const Mat4 g = inverse(jt[1].pre) * inverse(jt[0].post);
  const Mat4 k = jt[1].post * jt[2].pre;
  const Vec3 u = apply(jt[2].post, wrist_.centre_link3);
  // Height of the wrist centre along axis 2 (constant: axes 2 and 3 are parallel).
  const Vec3 v0 = apply(k, u);
  const double h = a1.dot(v0);
  const Vec3 n1 = R(g).transpose() * a1;
  double ca, cb, kk;
  // (Rot(a0, q1) n1) . pp = h - a1 . t_g  <=>  n1 . Rot(a0, -q1) pp ... write as pp . Rot n1.
  rot_coeffs(pp, a0, n1, &ca, &cb, &kk);
  const Trig t1 = solve_trig(ca, cb, h - a1.dot(P(g)) - kk);
  std::vector<std::pair<double, bool>> q1s;  // value, singular
  if (t1.degenerate) {
    q1s = {{0.0, true}, {0.0, true}};  // on axis 1: any q1 (shoulder singularity)
  } else {
    for (int i = 0; i < t1.count; ++i) q1s.push_back({t1.q[i], false});
  }
  for (size_t i1 = 0; i1 < q1s.size(); ++i1) {
    const double q1 = q1s[i1].first;
    const Vec3 p2 = apply(g, rot(a0, q1).transpose() * pp);
    // |v(q3)|^2 = |p2|^2 with v = R_k Rot(a2, q3) u + t_k.
    const Vec3 m = R(k).transpose() * P(k);
    rot_coeffs(m, a2, u, &ca, &cb, &kk);
    const double rhs = 0.5 * (p2.squaredNorm() - u.squaredNorm() - P(k).squaredNorm()) - kk;
    const Trig t3 = solve_trig(ca, cb, rhs);
    if (t3.degenerate || t3.count == 0) continue;
    for (int i3 = 0; i3 < 2; ++i3) {
      const double q3 = t3.q[i3];
      const Vec3 v = R(k) * (rot(a2, q3) * u) + P(k);
      double q2 = 0;
      bool sing = q1s[i1].second;
      if (!planar_angle(a1, v, p2, &q2)) sing = true;
      // Pose of link frame 3 (the wrist joints do not move it).
      Eigen::VectorXd q123 = Eigen::VectorXd::Zero(6);
      q123 << q1, q2, q3, 0, 0, 0;
      const Mat4 link3 = robot_.chain(q123).link[2];
      // Wrist: M = Rot(a, q4) B Rot(b, q5) C Rot(c, q6).
      const Vec3 wa = jt[3].axis.normalized(), wb = jt[4].axis.normalized(),
                 wc = jt[5].axis.normalized();
      const Mat3 ma = R(jt[3].pre), mb = R(jt[3].post) * R(jt[4].pre),
                 mc = R(jt[4].post) * R(jt[5].pre), md = R(jt[5].post);
      const Mat3 mm = ma.transpose() * R(link3).transpose() * R(pose) * md.transpose();
      const Vec3 cp = mc * wc;
      const Vec3 y = mm * wc;
      rot_coeffs(mb.transpose() * wa, wb, cp, &ca, &cb, &kk);
      const Trig t5 = solve_trig(ca, cb, wa.dot(y) - kk);
      if (t5.degenerate || t5.count == 0) continue;
      for (int i5 = 0; i5 < 2; ++i5) {
        const double q5 = t5.q[i5];
        const Vec3 x = mb * (rot(wb, q5) * cp);
        double q4 = 0;
        bool wsing = sing;
        if (!planar_angle(wa, x, y, &q4)) wsing = true;
        const Mat3 nn = mc.transpose() * rot(wb, q5).transpose() * mb.transpose() *
                        rot(wa, q4).transpose() * mm;
        Vec3 e = wc.unitOrthogonal();
        double q6 = 0;
        planar_angle(wc, e, nn * e, &q6);
        IkSolution s;
        s.q.resize(6);
        s.q << q1, q2, q3, q4, q5, q6;
        s.branch = static_cast<int>(i1) | (i3 << 1) | (i5 << 2);
        s.singular = wsing;
        out.push_back(s);
      }
    }
  }
  return out;
}

void InverseKinematics::finish(IkSolution* s, const Mat4& pose) const {
  Eigen::Matrix<double, 6, 1> e = pose_error(pose, robot_.tool_pose(s->q));
  // Polish by Newton steps (rounding near tangencies costs digits).
  for (int it = 0; it < 4 && e.norm() > 1e-14; ++it) {
    const Eigen::MatrixXd jac = robot_.jacobian(s->q);
    const Eigen::VectorXd dq = jac.completeOrthogonalDecomposition().solve(e);
    const Eigen::VectorXd qn = s->q + dq;
    const Eigen::Matrix<double, 6, 1> en = pose_error(pose, robot_.tool_pose(qn));
    if (!(en.norm() < e.norm())) break;
    s->q = qn;
    e = en;
  }
  s->error = e.head<3>().norm() + e.tail<3>().norm();
  if (sigma_min(s->q) < options_.singular_sigma) s->singular = true;
}

std::vector<IkSolution> InverseKinematics::solve_all(const Mat4& pose,
                                                     const Eigen::VectorXd* seed) const {
  if (!pose.allFinite()) throw InvalidArgument("inverse kinematics: the pose is not finite");
  const int n = robot_.dof();
  const Eigen::VectorXd s0 = seed ? *seed : Eigen::VectorXd::Zero(n);
  if (s0.size() != n) check_joint_vector(robot_, s0, "inverse kinematics seed");
  std::vector<IkSolution> out;
  if (analytic()) {
    for (IkSolution& s : analytic_all(pose)) {
      finish(&s, pose);
      if (s.error > 1e3 * options_.tolerance + 1e-9) continue;  // lost to rounding
      if (!fit_limits(&s.q, s0)) continue;
      out.push_back(s);
    }
  } else {
    std::mt19937_64 rng(options_.seed);
    for (int r = 0; r <= options_.restarts; ++r) {
      Eigen::VectorXd start(n);
      for (int j = 0; j < n; ++j) {
        const double lo = std::max(robot_.joints[j].lower, -kPi);
        const double hi = std::min(robot_.joints[j].upper, kPi);
        start(j) = r == 0 ? s0(j) : lo + (hi - lo) * std::uniform_real_distribution<>(0, 1)(rng);
      }
      IkSolution s;
      if (!solve_numerical(pose, start, &s.q)) continue;
      if (!fit_limits(&s.q, s0)) continue;
      bool dup = false;
      for (const auto& o : out)
        if ((o.q - s.q).cwiseAbs().maxCoeff() < 1e-6) dup = true;
      if (dup) continue;
      finish(&s, pose);
      out.push_back(s);
    }
  }
  return out;
}

bool InverseKinematics::solve_nearest(const Mat4& pose,
                                      const Eigen::VectorXd& seed,
                                      IkSolution* out) const {
  check_joint_vector(robot_, seed, "inverse kinematics seed");
  if (!pose.allFinite()) throw InvalidArgument("inverse kinematics: the pose is not finite");
  if (!analytic()) {
    // Continuation from the seed first; random restarts only if that fails.
    IkSolution s;
    if (solve_numerical(pose, seed, &s.q) && fit_limits(&s.q, seed) &&
        (s.q - seed).cwiseAbs().maxCoeff() < 1.0) {
      finish(&s, pose);
      *out = s;
      return true;
    }
  }
  if (analytic()) {
    // Rank the raw branches by distance and polish only the one kept (the polish, the
    // singularity check and the FK of every branch would cost 8 times as much).
    std::vector<IkSolution> raw = analytic_all(pose);
    std::vector<std::pair<double, size_t>> order;
    for (size_t i = 0; i < raw.size(); ++i)
      if (fit_limits(&raw[i].q, seed)) order.push_back({(raw[i].q - seed).squaredNorm(), i});
    std::sort(order.begin(), order.end());
    for (const auto& o : order) {
      IkSolution s = raw[o.second];
      finish(&s, pose);
      if (s.error > 1e3 * options_.tolerance + 1e-9) continue;
      if (!fit_limits(&s.q, seed)) continue;  // the polish may cross a limit by rounding
      *out = s;
      return true;
    }
    return false;
  }
  const std::vector<IkSolution> all = solve_all(pose, &seed);
  if (all.empty()) return false;
  size_t best = 0;
  for (size_t i = 1; i < all.size(); ++i)
    if ((all[i].q - seed).norm() < (all[best].q - seed).norm()) best = i;
  *out = all[best];
  return true;
}

IkPath solve_path(const InverseKinematics& ik,
                  const std::vector<Mat4>& poses,
                  const Eigen::VectorXd& q_start,
                  double jump_threshold_rad) {
  const RobotModel& r = ik.robot();
  const int n = r.dof();
  Eigen::VectorXd prev(n);
  if (q_start.size() == 0) {
    for (int j = 0; j < n; ++j) {
      const double lo = r.joints[j].lower, hi = r.joints[j].upper;
      prev(j) = (lo <= 0 && hi >= 0) ? 0.0 : 0.5 * (lo + hi);
    }
  } else {
    check_joint_vector(r, q_start, "q_start");
    prev = q_start;
  }
  IkPath path;
  path.q.resize(static_cast<Eigen::Index>(poses.size()), n);
  path.status.assign(poses.size(), kPointOk);
  path.branch.assign(poses.size(), -1);
  int prev_branch = -1;
  bool have_prev = q_start.size() != 0;
  for (size_t i = 0; i < poses.size(); ++i) {
    IkSolution s;
    int st = kPointOk;
    if (!ik.solve_nearest(poses[i], prev, &s)) {
      st |= kPointUnreachable;
      path.q.row(static_cast<Eigen::Index>(i)) = prev.transpose();
      path.status[i] = st;
      continue;
    }
    if (s.singular) st |= kPointSingular;
    if (have_prev) {
      if (prev_branch >= 0 && s.branch >= 0 && s.branch != prev_branch) st |= kPointBranchChange;
      if ((s.q - prev).cwiseAbs().maxCoeff() > jump_threshold_rad) st |= kPointJump;
    }
    path.q.row(static_cast<Eigen::Index>(i)) = s.q.transpose();
    path.status[i] = st;
    path.branch[i] = s.branch;
    prev = s.q;
    prev_branch = s.branch;
    have_prev = true;
  }
  return path;
}

std::string describe_point_status(int status) {
  if (status == kPointOk) return "ok";
  std::string s;
  auto add = [&](const char* t) { s += (s.empty() ? "" : ", ") + std::string(t); };
  if (status & kPointSingular) add("singular");
  if (status & kPointUnreachable) add("unreachable");
  if (status & kPointBranchChange) add("branch change (wrist flip)");
  if (status & kPointJump) add("joint jump");
  if (status & kPointNotConverged) add("compensation not converged");
  return s;
}

}  // namespace stiff
