// Where the model fails: per-pose residuals and trend tests of the residual against the
// covariates (docs/diagnosis.md, section 4).
#include <algorithm>
#include <cmath>

#include "diagnose/analysis.hpp"
#include "diagnose/text.hpp"

namespace stiff::diagnose_detail {

namespace {
// The trend groups of mechanisms outside the library.
constexpr const char* kBaseTilt = "base_tilt";
constexpr const char* kBaseShift = "base_shift";
constexpr const char* kSensorCrosstalk = "sensor_crosstalk";
constexpr const char* kLoadResponseDrift = "load_response_drift";
const std::string kPoseCompliance = "pose_compliance_";  // + the joint's number
}  // namespace

bool is_outside_library(const std::string& covariate) {
  return covariate == kBaseTilt || covariate == kBaseShift || covariate == kSensorCrosstalk ||
         covariate == kLoadResponseDrift || covariate.rfind(kPoseCompliance, 0) == 0;
}

/// Residual structure against covariates ("where it fails").
void where(const Context& cx, const Level& L, Diagnosis& d) {
  const Analysis& a = L.a;
  const Dataset& calib = *cx.calib;
  const Noise& noise = *cx.noise;
  const RobotModel& robot = *cx.robot;
  const int rows = static_cast<int>(calib.rows.size());
  // Per-pose residuals.
  for (int r = 0; r < rows; ++r) {
    PoseResidual p;
    p.row = r;
    p.id = calib.rows[r].id;
    const Eigen::Vector3d e = calib.rows[r].observed() - a.pred_all.row(r).transpose();
    for (int k = 0; k < 3; ++k) {
      p.residual_m[k] = e(k);
      p.predicted_m[k] = a.pred_all(r, k);
    }
    p.norm_m = e.norm();
    p.norm_sigma = noise.known ? e.norm() / noise.sigma(r) : NAN;
    p.outlier = a.outlier[r];
    d.residuals.push_back(p);
  }
  std::vector<PoseResidual> sorted = d.residuals;
  std::stable_sort(sorted.begin(), sorted.end(), [&](const PoseResidual& x, const PoseResidual& y) {
    const double sx = noise.known ? x.norm_m / noise.sigma(x.row) : x.norm_m;
    const double sy = noise.known ? y.norm_m / noise.sigma(y.row) : y.norm_m;
    return sx > sy;
  });
  for (int i = 0; i < std::min<int>(cx.opt->worst_poses, rows); ++i) d.worst.push_back(sorted[i]);
  // Per-axis RMS and chi2 (used rows).
  const int nu = static_cast<int>(a.used_rows.size());
  for (int k = 0; k < 3; ++k) {
    double ss_w = 0, ss_m = 0;
    for (int i = 0; i < nu; ++i) {
      ss_w += a.r(3 * i + k) * a.r(3 * i + k);
      ss_m += std::pow(a.r(3 * i + k) / a.w(i), 2);
    }
    d.axis_rms_m[k] = std::sqrt(ss_m / nu);
    const double dof = nu * static_cast<double>(a.n - a.p) / a.n;
    d.axis_chi2_p[k] = noise.known && dof > 0 ? stats::chi2_sf(ss_w, dof) : 1.0;
  }
  // Covariates per used row.
  const int dof = robot.dof();
  std::vector<std::pair<std::string, std::string>> names;
  std::vector<std::vector<double>> values;
  auto add = [&](const std::string& n, const std::string& desc, std::vector<double> v) {
    names.emplace_back(n, desc);
    values.push_back(std::move(v));
  };
  std::vector<std::vector<double>> q(dof), tl(dof), tg(dof);
  std::vector<double> fx, fy, fz, level, pred, time, ones;
  bool any_gravity = false;
  for (int i = 0; i < nu; ++i) {
    const auto& m = a.used.rows[i];
    const auto& c = a.ctx[i];
    const Matrix6X<double> jl =
        robot.jacobian_at(c.chain, robot.point_position(c.chain, robot.load_point));
    Eigen::Matrix<double, 6, 1> wr;
    wr << m.force, m.moment;
    const VectorXd tau = jl.transpose() * wr;
    for (int j = 0; j < dof; ++j) {
      q[j].push_back(m.q(j));
      tl[j].push_back(tau(j));
      const double g = c.tau_gravity.size() > j ? c.tau_gravity(j) : 0.0;
      tg[j].push_back(g);
      if (std::abs(g) > 1e-9) any_gravity = true;
    }
    const double f = m.force.norm();
    fx.push_back(f > 0 ? m.force.x() / f : 0.0);
    fy.push_back(f > 0 ? m.force.y() / f : 0.0);
    fz.push_back(f > 0 ? m.force.z() / f : 0.0);
    level.push_back(f);
    pred.push_back(a.pred_all.row(a.used_rows[i]).norm());
    time.push_back(c.time);
    ones.push_back(1.0);
  }
  add("offset", "constant (mean residual different from zero)", ones);
  for (int j = 0; j < dof; ++j)
    add("q" + std::to_string(j + 1), "joint angle " + std::to_string(j + 1), q[j]);
  for (int j = 0; j < dof; ++j)
    add("tau_load_" + std::to_string(j + 1),
        "load torque of joint " + std::to_string(j + 1) + " (J^T W)", tl[j]);
  if (any_gravity)
    for (int j = 0; j < dof; ++j)
      add("tau_gravity_" + std::to_string(j + 1),
          "gravity torque of joint " + std::to_string(j + 1), tg[j]);
  add("load_dir_x", "load direction, base x (F_x/|F|)", fx);
  add("load_dir_y", "load direction, base y (F_y/|F|)", fy);
  add("load_dir_z", "load direction, base z (F_z/|F|)", fz);
  add("load_level", "load level |F|", level);
  add("predicted", "predicted deflection |d|", pred);
  add("time", cx.had_time ? "measurement time" : "measurement order", time);
  std::vector<CovariateTest> tests;
  std::vector<double> lps;
  // A test of the residual against a group, kept when the group survives projection.
  auto record_score = [&](const std::string& name, const std::string& desc,
                          const GroupScore& g) -> CovariateTest* {
    if (g.df == 0) return nullptr;
    CovariateTest ct;
    ct.covariate = name;
    ct.description = desc;
    ct.df = g.df;
    ct.statistic = g.f;
    ct.p_value = std::exp(g.log_p);
    tests.push_back(ct);
    lps.push_back(g.log_p);
    return &tests.back();
  };
  auto group_score = [&](const MatrixXd& z) {
    return score_group(a, z, VectorXd::Ones(z.cols()), 1e-6);
  };
  auto record = [&](const std::string& name, const std::string& desc, const MatrixXd& z) {
    return record_score(name, desc, group_score(z));
  };
  // The group's test with each candidate's directions taken out as well, the least significant
  // (none when a candidate spans the group): a trend one candidate explains is that
  // candidate's evidence, which the candidates' own tests weigh.
  auto beyond_candidates = [&](const MatrixXd& z) {
    GroupScore weakest = group_score(z);
    for (const MatrixXd& b : L.bases) {
      if (weakest.df == 0) break;
      if (b.cols() == 0) continue;
      GroupScore g = group_score(z - b * (b.transpose() * z));
      if (g.df == 0 || g.log_p > weakest.log_p) weakest = std::move(g);
    }
    return weakest;
  };
  for (size_t t = 0; t < names.size(); ++t) {
    const auto& v = values[t];
    double mean = 0;
    for (double x : v) mean += x;
    mean /= nu;
    const bool constant = names[t].first == "offset";
    MatrixXd z = MatrixXd::Zero(a.n, 3);
    double var = 0;
    for (int i = 0; i < nu; ++i) {
      const double c = constant ? 1.0 : v[i] - mean;
      var += c * c;
      for (int k = 0; k < 3; ++k) z(3 * i + k, k) = c * a.w(i);
    }
    if (!(var > 1e-24)) continue;
    CovariateTest* ct = record(names[t].first, names[t].second, z);
    if (!ct) continue;
    for (int k = 0; k < 3; ++k) {
      if (constant) {
        double s = 0, ss = 0;
        for (int i = 0; i < nu; ++i) {
          s += a.r(3 * i + k);
          ss += a.r(3 * i + k) * a.r(3 * i + k);
        }
        ct->correlation[k] = ss > 0 ? s / std::sqrt(nu * ss) : 0.0;
        continue;
      }
      double sxy = 0, syy = 0, sxx = 0, ym = 0;
      for (int i = 0; i < nu; ++i) ym += a.r(3 * i + k) / a.w(i);
      ym /= nu;
      for (int i = 0; i < nu; ++i) {
        const double y = a.r(3 * i + k) / a.w(i) - ym;
        const double x = v[i] - mean;
        sxy += x * y;
        sxx += x * x;
        syy += y * y;
      }
      ct->correlation[k] = sxx > 0 && syy > 0 ? sxy / std::sqrt(sxx * syy) : 0.0;
    }
  }
  // The arm turning as a whole about the axes of its mounting plane (base x and y) under the
  // load's moment there (a compliant pedestal, floor, wall or mounting plate): theta = (c_x M_x,
  // c_y M_y, 0), the base moment M = L x F + m, and the displacement theta x (P + h e_z) about a
  // pivot h below the base frame (four columns: c_x, c_y and their products with h). No effect of
  // the library has this form; the joints, the links and a force-frame error take part of it up,
  // and what they leave shows here.
  {
    MatrixXd z = MatrixXd::Zero(a.n, 4);
    for (int i = 0; i < nu; ++i) {
      const auto& m = a.used.rows[i];
      const auto& c = a.ctx[i];
      const Eigen::Vector3d p = robot.point_position(c.chain, robot.measured_point);
      const Eigen::Vector3d l = robot.point_position(c.chain, robot.load_point);
      const Eigen::Vector3d mb = l.cross(m.force) + m.moment;
      const Eigen::Vector3d ex = Eigen::Vector3d::UnitX(), ey = Eigen::Vector3d::UnitY();
      const Eigen::Vector3d ez = Eigen::Vector3d::UnitZ();
      const Eigen::Vector3d cols[4] = {mb.x() * ex.cross(p), mb.y() * ey.cross(p),
                                       mb.x() * ex.cross(ez), mb.y() * ey.cross(ez)};
      for (int k = 0; k < 4; ++k) z.block<3, 1>(3 * i, k) = a.w(i) * cols[k];
    }
    record(kBaseTilt,
           "the arm turning as a whole about the base x and y axes (its mounting plane) under "
           "the load's moment there (pedestal or floor compliance, not in the library)",
           z);
  }
  // A joint whose compliance varies with the arm's angles (a reducer's stiffness over its
  // output turn, a shoulder stiffer as the forearm folds): per joint j its deflection under the
  // load, J_j(P) tau_j, times the first harmonics cos q_k, sin q_k of each angle that moves the
  // arm (the mean compliance is the joint model's). Ten columns take up much of what the
  // library's pose-dependent laws (nonlinear joint, compensator, backlash) leave, so the group
  // counts only beyond each candidate; and not with a law decided from the data (backlash):
  // its preload follows the gravity torque, a function of the same angles, so a preload shape
  // off the truth leaves exactly this pattern at its joints.
  if (!has_confidence_sets(*a.model)) {
    const int angles = std::max(1, dof - 1);
    for (int j = 0; j < dof; ++j) {
      MatrixXd z = MatrixXd::Zero(a.n, 2 * angles);
      for (int i = 0; i < nu; ++i) {
        const auto& m = a.used.rows[i];
        const auto& c = a.ctx[i];
        const Matrix6X<double> jm =
            robot.jacobian_at(c.chain, robot.point_position(c.chain, robot.measured_point));
        const Eigen::Vector3d defl = jm.block<3, 1>(0, j) * tl[j][i];
        for (int k = 0; k < angles; ++k) {
          z.block<3, 1>(3 * i, 2 * k) = a.w(i) * std::cos(m.q(k)) * defl;
          z.block<3, 1>(3 * i, 2 * k + 1) = a.w(i) * std::sin(m.q(k)) * defl;
        }
      }
      record_score(kPoseCompliance + std::to_string(j + 1),
                   "the compliance of joint " + std::to_string(j + 1) +
                       " varying with the arm's angles (not in the library)",
                   beyond_candidates(z));
    }
  }
  // The arm shifting as a whole under the load's force (a compliant base plate or floor):
  // d = C_b F with C_b symmetric in the base frame (six columns). A series compliance at the
  // tool turns with the flange; this does not.
  {
    MatrixXd z = MatrixXd::Zero(a.n, 6);
    for (int i = 0; i < nu; ++i) {
      const Eigen::Vector3d& f = a.used.rows[i].force;
      const int pairs[6][2] = {{0, 0}, {1, 1}, {2, 2}, {0, 1}, {0, 2}, {1, 2}};
      for (int k = 0; k < 6; ++k) {
        z(3 * i + pairs[k][0], k) += a.w(i) * f(pairs[k][1]);
        if (pairs[k][0] != pairs[k][1]) z(3 * i + pairs[k][1], k) += a.w(i) * f(pairs[k][0]);
      }
    }
    record(kBaseShift,
           "the arm shifting as a whole under the load's force, fixed in the base frame (base "
           "plate or floor compliance, not in the library)",
           z);
  }
  // The response to the load changing in scale over a session (the joints softening as their
  // reducers warm up, a force sensor's gain drifting): one column, the model's deflection under
  // the row's load (its prediction less that without load, so that drift terms cancel) times
  // the reading's time from the session's mean time.
  {
    std::vector<double> sum(1, 0.0), count(1, 0.0);
    for (int i = 0; i < nu; ++i) {
      const size_t s = static_cast<size_t>(a.ctx[i].session);
      if (s >= sum.size()) sum.resize(s + 1, 0.0), count.resize(s + 1, 0.0);
      sum[s] += a.ctx[i].time;
      count[s] += 1;
    }
    MatrixXd z = MatrixXd::Zero(a.n, 1);
    for (int i = 0; i < nu; ++i) {
      const auto& m = a.used.rows[i];
      if (m.force.squaredNorm() == 0.0 && m.moment.squaredNorm() == 0.0) continue;
      const auto& c = a.ctx[i];
      const size_t s = static_cast<size_t>(c.session);
      Measurement unloaded = m;
      unloaded.force.setZero();
      unloaded.moment.setZero();
      const Eigen::Vector3d deflection = a.model->predict(a.theta, m, c).head<3>() -
                                         a.model->predict(a.theta, unloaded, c).head<3>();
      z.block<3, 1>(3 * i, 0) = a.w(i) * (c.time - sum[s] / count[s]) * deflection;
    }
    record(kLoadResponseDrift,
           "the response to the load changing in scale over the session (joints warming up, "
           "a force sensor's gain drifting; not in the library)",
           z);
  }
  // Cross-talk of a force sensor on the flange: its reading off by a symmetric matrix with a
  // zero diagonal in the sensor frame (the off-diagonal part of its calibration matrix; the
  // diagonal gains and the rotation are force_frame's). The displacement it leaves is the
  // model's own response to the force error, G(q) R E_k R^T F, with G the model's
  // displacement per unit force at the row: the response is taken from the fitted model by a
  // small step of the force, so the columns are those of whatever the arm's compliance is.
  {
    constexpr double step = 1e-4;  // relative: a backlash decision flips only at its threshold
    MatrixXd z = MatrixXd::Zero(a.n, 3);
    for (int i = 0; i < nu; ++i) {
      const auto& m = a.used.rows[i];
      if (m.force.squaredNorm() == 0.0) continue;  // an unloaded (absolute) row: no cross-talk
      const auto& c = a.ctx[i];
      const Eigen::Matrix3d rot = c.chain.flange.topLeftCorner<3, 3>();
      const Eigen::Vector3d fs = rot.transpose() * m.force;
      const Eigen::Vector3d d0 = a.model->predict(a.theta, m, c).head<3>();
      const int pairs[3][2] = {{0, 1}, {0, 2}, {1, 2}};
      for (int k = 0; k < 3; ++k) {
        Eigen::Vector3d df = Eigen::Vector3d::Zero();
        df(pairs[k][0]) = fs(pairs[k][1]);
        df(pairs[k][1]) = fs(pairs[k][0]);
        Measurement mk = m;
        mk.force += step * (rot * df);
        z.block<3, 1>(3 * i, k) = a.w(i) / step * (a.model->predict(a.theta, mk, c).head<3>() - d0);
      }
    }
    record(kSensorCrosstalk,
           "the model's response to a force error symmetric between the sensor's axes (force "
           "sensor cross-talk, not in the library)",
           z);
  }
  const auto adj = stats::holm_adjust(lps);
  for (size_t t = 0; t < tests.size(); ++t) {
    tests[t].p_adjusted = adj[t];
    tests[t].significant = adj[t] < cx.opt->alpha;
  }
  std::stable_sort(tests.begin(), tests.end(), [](const CovariateTest& x, const CovariateTest& y) {
    return x.p_value < y.p_value;
  });
  d.covariates = tests;
}

std::optional<CovariateTest> strong_trend(const Context& cx, const Level& L, bool outside_only) {
  Diagnosis d;
  where(cx, L, d);
  for (const auto& c : d.covariates)  // sorted by p
    if (c.significant && c.p_adjusted < cx.opt->alpha / 10 &&
        (!outside_only || is_outside_library(c.covariate)))
      return c;
  return std::nullopt;
}

std::string signature_of(const Diagnosis& d) {
  std::vector<std::string> parts;
  for (const auto& c : d.covariates)
    if (c.significant && parts.size() < 4)
      parts.push_back(c.covariate + " (F = " + num(c.statistic, 3) +
                      ", p_adj = " + num(c.p_adjusted, 2) + ")");
  const char* ax = "xyz";
  for (int k = 0; k < 3; ++k)
    if (d.axis_chi2_p[k] < d.alpha)
      parts.push_back(std::string("axis ") + ax[k] + " (RMS " + um(d.axis_rms_m[k]) + ")");
  if (parts.empty()) return "no significant trend against the covariates tested";
  return "the residual correlates with " + join(parts, ", ");
}

}  // namespace stiff::diagnose_detail
