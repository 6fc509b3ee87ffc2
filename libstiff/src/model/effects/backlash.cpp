// backlash: lost motion of the reducers with a gravity preload (docs/effects.md).
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <limits>

#include "stiff/kinematics/joint_torque.hpp"
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// A dead zone of width b_j: the gravity preload holds the gear against one flank; the load
/// traverses the gap only when it reverses the joint torque:
///   dtheta_j += b_j/2 [sgn((1 + s_j) tau_g + tau_F) - sgn(tau_g)].
/// The preload tau_g comes from the robot file's masses and centres of mass, which users know
/// to about 30 %; s_j is the relative error of joint j's preload. The data tell s_j only
/// through which rows jumped, a sharp threshold that a derivative cannot find: the effect
/// estimates it from the data it is built on by threshold regression (Hansen 2000), the
/// least-squares threshold of the joint-compliance + backlash model within the band the mass
/// uncertainty allows, and holds it there (its start and null value: b_j = 0 switches the
/// effect off whatever s_j is; a fit keeps it).
/// The sign is smoothed, sgn(x) ~ tanh(x / eps) with eps = 0.05 N*m (well below the load
/// torques of a test), so that the model has a derivative with respect to everything that
/// changes the torques (force frame, offsets). A joint without preload (tau_g = 0, e.g. a
/// vertical joint 1) jumps by b/2 sgn(tau_F): the mean over its unknown start in the gap.
class Backlash : public EffectT<Backlash> {
 public:
  explicit Backlash(const EffectSetup& s) {
    const int n = s.robot->dof();
    const Preload s0 = preload_correction(s);
    for (int j = 0; j < n; ++j)
      params_.push_back(effects::parameter(
          "b" + std::to_string(j + 1), "rad",
          "backlash (lost motion) of joint " + std::to_string(j + 1) + ", full gap width", 0.0,
          0.05, 1.5e-4, 0.0, 0.0));
    for (int j = 0; j < n; ++j) {
      params_.push_back(effects::parameter(
          "s" + std::to_string(j + 1), "1",
          "relative error of the gravity preload of joint " + std::to_string(j + 1) +
              " (where its backlash jumps), from the data",
          kScaleLow, kScaleHigh, kMassUncertainty, s0.s(j), s0.s(j)));
      params_.back().from_data = true;
      params_.back().confidence_lower = s0.lower(j);
      params_.back().confidence_upper = s0.upper(j);
    }
    for (int j = 0; j < n; ++j) {
      params_.push_back(effects::parameter(
          "g" + std::to_string(j + 1), "1",
          "turn of the lumped centre of mass that loads joint " + std::to_string(j + 1) +
              " about its axis (tangent), held at 0; its range is what the data do not exclude",
          -kMassUncertainty, kMassUncertainty, kMassUncertainty, 0.0, 0.0));
      params_.back().from_data = true;
      params_.back().confidence_lower = s0.turn_lower(j);
      params_.back().confidence_upper = s0.turn_upper(j);
    }
  }
  const std::string& name() const override { return name_; }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    const double arcmin = M_PI / (180.0 * 60.0);
    set_parameter(p, "b1", 0.3 * arcmin);
    for (int j = 1; j < 5; ++j) set_parameter(p, "b" + std::to_string(j + 1), 0.5 * arcmin);
    return true;
  }
  std::vector<std::string> experiment_hints() const override {
    return {effects::kHintLoadReversal, effects::kHintLoadLevel, effects::kHintGravityVariety};
  }
  std::string description() const override {
    return "backlash with gravity preload: dtheta_j += b_j/2 [sgn((1+s_j) tau_g+tau_F) - "
           "sgn(tau_g)], s_j the preload error found from the data (smooth sign, eps 0.05 N*m); "
           "independent of the load level";
  }
  std::string reference() const override {
    return "Harmonic Drive / Nabtesco RV catalogues (lost motion <= 1 arcmin); FIGAROH "
           "(Thanh et al. 2023) backlash over position, gravity torque and direction; Hansen, "
           "Econometrica 68 (2000) (threshold regression)";
  }
  unsigned requirements() const override { return kNeedsMasses; }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }

  static constexpr double kEps = 0.05;  ///< N*m
  /// Relative uncertainty of the link masses and of the centres of mass. The preload is
  /// their product: off by a factor in [(1-u)^2, (1+u)^2].
  static constexpr double kMassUncertainty = 0.3;
  static constexpr double kScaleLow = (1 - kMassUncertainty) * (1 - kMassUncertainty) - 1;
  static constexpr double kScaleHigh = (1 + kMassUncertainty) * (1 + kMassUncertainty) - 1;

  template <typename T>
  void joint_t(const T* p, EvalState<T>& s) const {
    using std::tanh;
    const auto& tg = s.context->tau_gravity;
    const int n = static_cast<int>(s.dtheta.size());
    // The turns g_j are 0 but where the diagnosis tries the ends of their confidence sets.
    Eigen::VectorXd tq;
    for (int j = 0; j < n && tq.size() == 0; ++j)
      if (scalar(p[2 * n + j]) != 0.0) gravity_torques(*s.robot, s.context->chain, &tq);
    for (int j = 0; j < n; ++j) {
      // s_j, g_j by their value only: the threshold regression decides them, not a derivative.
      double pre = tg(j);
      if (scalar(p[2 * n + j]) != 0.0) pre += scalar(p[2 * n + j]) * tq(j);
      const T loaded = tanh((T((1 + scalar(p[n + j])) * pre) + s.tau(j)) / T(kEps));
      const T preload = T(std::tanh(pre / kEps));
      s.dtheta(j) += T(0.5) * p[j] * (loaded - preload);
    }
  }

 private:
  /// Upper quantile of chi2 with one degree of freedom at tail probability p: z^2 with
  /// erfc(z / sqrt 2) = p (bisection).
  static double chi2_1_quantile(double p) {
    double lo = 0, hi = 40;
    for (int i = 0; i < 100; ++i) {
      const double mid = 0.5 * (lo + hi);
      (std::erfc(mid / std::sqrt(2.0)) > p ? lo : hi) = mid;
    }
    return lo * lo;
  }
  /// Critical value of the likelihood-ratio confidence set of a threshold at level 1 - alpha,
  /// c = -2 ln(1 - sqrt(1 - alpha)) (Hansen 2000, eq. 17: the LR statistic's limit law
  /// P(xi <= x) = (1 - exp(-x/2))^2 under a small threshold effect; conservative for a large
  /// one). 7.35 at alpha = 5 %.
  static double threshold_lr_critical(double alpha) {
    return -2.0 * std::log(1.0 - std::sqrt(1.0 - alpha));
  }
  /// tanh(x / eps), exactly +-1 in double precision beyond 20 eps (tanh 20 = 1 - 8.5e-18)
  /// without evaluating it: the searches below take it for every row and threshold.
  static double smooth_sign(double x) {
    return std::abs(x) > 20 * kEps ? std::copysign(1.0, x) : std::tanh(x / kEps);
  }
  static double scalar(double x) { return x; }
  static double scalar(const Jet& x) { return x.a; }

  /// The preload errors s_j that the data support: coordinate-wise threshold regression of
  /// d = sum_j c_j J_j(P) tau_F,j + b_j/2 [sgn((1+s_j) tau_g + tau_F) - sgn(tau_g)] J_j(P)
  /// (weighted least squares in c, b) over s_j in the band of the mass uncertainty. Between two
  /// rows' thresholds the decisions, hence the fit, do not change: the candidates are the
  /// midpoints. Zero where the data (displacement rows) cannot tell, and without data.
  /// The estimate s and the confidence interval [lower, upper] of each joint's preload error
  /// (NaN without data).
  struct Preload {
    Eigen::VectorXd s, lower, upper, turn_lower, turn_upper;
  };
  static Preload preload_correction(const EffectSetup& setup) {
    const RobotModel& robot = *setup.robot;
    const int n = robot.dof();
    Preload out;
    out.s = Eigen::VectorXd::Zero(n);
    out.lower = out.upper = out.turn_lower = out.turn_upper =
        Eigen::VectorXd::Constant(n, std::numeric_limits<double>::quiet_NaN());
    Eigen::VectorXd& s = out.s;
    if (!setup.data || !robot.has_masses()) return out;
    struct Row {
      Eigen::Matrix3Xd jp;  // J_j(P), translational columns
      Eigen::VectorXd tau, tg, tq;
    };
    std::vector<Row> rows;
    std::vector<Eigen::Vector3d> obs;
    std::vector<double> wt;
    std::vector<int> at;  // the row's index in the data
    bool sigma = true;
    for (const auto& m : setup.data->rows) sigma = sigma && (m.absolute || m.sigma_d > 0);
    for (size_t k = 0; k < setup.data->rows.size(); ++k) {
      const Measurement& m = setup.data->rows[k];
      if (m.absolute || m.q.size() != n || !m.q.allFinite()) continue;
      const ChainState c = robot.chain(m.q);
      const Eigen::Vector3d p = robot.point_position(c, robot.measured_point);
      const Eigen::Vector3d l = robot.point_position(c, robot.load_point);
      Row r;
      r.jp.resize(3, n);
      r.tau.resize(n);
      for (int j = 0; j < n; ++j) {
        const Eigen::Vector3d z = c.axis.col(j), o = c.origin.col(j);
        Eigen::Vector3d wp, wl;
        lever_arm(z, o, p, wp);
        lever_arm(z, o, l, wl);
        r.jp.col(j) = wp;
        r.tau(j) = joint_torque(wl, z, m.force, m.moment);
      }
      r.tg = gravity_torques(robot, c, &r.tq);
      rows.push_back(std::move(r));
      obs.push_back(m.displacement);
      wt.push_back(sigma ? 1.0 / m.sigma_d : 1.0);
      at.push_back(static_cast<int>(k));
    }
    const int N = static_cast<int>(rows.size());
    if (N < 2 * n) return out;
    // Weighted design: what the model's other effects do (EffectSetup::companion_columns: a
    // point offset, a force frame, the joint compliance, ...), so that the thresholds are decided
    // on what they leave; alone in its model, the joint compliance it acts with. Then one
    // backlash column per joint.
    const Eigen::MatrixXd& cols = setup.companion_columns;
    const bool companions = cols.rows() == 3 * static_cast<int>(setup.data->rows.size());
    Eigen::MatrixXd lin(3 * N, companions ? cols.cols() : n), x(3 * N, n);
    Eigen::VectorXd y(3 * N);
    for (int i = 0; i < N; ++i) {
      y.segment<3>(3 * i) = wt[i] * obs[i];
      if (companions)
        lin.middleRows<3>(3 * i) = wt[i] * cols.middleRows<3>(3 * at[i]);
      else
        for (int j = 0; j < n; ++j)
          lin.block<3, 1>(3 * i, j) = wt[i] * rows[i].tau(j) * rows[i].jp.col(j);
    }
    auto column = [&](int j, double sj, Eigen::Ref<Eigen::VectorXd> dst, double gj = 0.0) {
      for (int i = 0; i < N; ++i) {
        const Row& r = rows[i];
        const double pre = r.tg(j) + gj * r.tq(j);
        const double jump = 0.5 * (smooth_sign((1 + sj) * pre + r.tau(j)) - smooth_sign(pre));
        dst.segment<3>(3 * i) = wt[i] * jump * r.jp.col(j);
      }
    };
    for (int j = 0; j < n; ++j) column(j, 0.0, x.col(j));
    // Two coordinate sweeps decide s; a third, with every s decided, gives the confidence sets.
    for (int sweep = 0; sweep < 3; ++sweep) {
      const bool last = sweep == 2;
      for (int j = 0; j < n; ++j) {
        // Orthonormal basis of every other column (rank-revealing: joint 6 and its gap have no
        // lever arm with P and L on the flange axis); RSS(x) = |r0|^2 - (x~.r0)^2 / |x~|^2.
        Eigen::MatrixXd other(3 * N, lin.cols() + n - 1);
        other << lin, x.leftCols(j), x.rightCols(n - j - 1);
        // Unit columns: the span is the same, and the rank threshold compares like with like.
        for (int c = 0; c < other.cols(); ++c) {
          const double norm = other.col(c).norm();
          if (norm > 0) other.col(c) /= norm;
        }
        Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(other);
        qr.setThreshold(1e-10);
        const int rank = static_cast<int>(qr.rank());
        const Eigen::MatrixXd q = qr.householderQ() * Eigen::MatrixXd::Identity(3 * N, rank);
        const Eigen::VectorXd r0 = y - q * (q.transpose() * y);
        const int dof = 3 * N - rank - 1;
        // Per row, the column's block u_i = w_i J_j(P_i) times the row's jump: u_i.r0,
        // |u_i|^2 and Q_i^T u_i, so that a candidate costs O(N rank) (the confidence set tries
        // many).
        Eigen::VectorXd along(N), sq(N);
        Eigen::MatrixXd proj(rank, N);
        for (int i = 0; i < N; ++i) {
          const Eigen::Vector3d u = wt[i] * rows[i].jp.col(j);
          along(i) = u.dot(r0.segment<3>(3 * i));
          sq(i) = u.squaredNorm();
          proj.col(i) = q.middleRows(3 * i, 3).transpose() * u;
        }
        Eigen::VectorXd jump(N);
        const double tiny = 1e-20 * y.squaredNorm();
        auto gain = [&](double sj, double gj) {
          for (int i = 0; i < N; ++i) {
            const Row& r = rows[i];
            const double pre = r.tg(j) + gj * r.tq(j);
            jump(i) = 0.5 * (smooth_sign((1 + sj) * pre + r.tau(j)) - smooth_sign(pre));
          }
          // |(I - Q Q^T) c|^2 = |c|^2 - |Q^T c|^2, and (I - Q Q^T) c . r0 = c . r0.
          const double cc = jump.cwiseAbs2().dot(sq);
          const double nn = cc - (proj * jump).squaredNorm();
          // A column (nearly) inside the others' span: no gain (and no cancellation noise).
          if (!(nn > tiny) || !(nn > 1e-9 * cc)) return 0.0;
          const double u = jump.dot(along);
          return u * u / nn;
        };
        // Edges of the intervals of s between the rows' thresholds, with the preload's lumped
        // centre of mass turned by gj: (1 + s)(tau_g + gj tau_q) + tau_F = 0 there.
        auto edges = [&](double gj) {
          std::vector<double> e = {kScaleLow};
          for (const auto& r : rows) {
            const double pre = r.tg(j) + gj * r.tq(j);
            if (std::abs(pre) > kEps) {
              const double v = -r.tau(j) / pre - 1;
              if (v > kScaleLow && v < kScaleHigh) e.push_back(v);
            }
          }
          std::sort(e.begin() + 1, e.end());
          e.push_back(kScaleHigh);
          return e;
        };
        if (last) {
          // What the data do not exclude: the likelihood-ratio confidence set of the threshold
          // (Hansen 2000) over the preload's scale s and the turn g of its lumped centre of
          // mass (a centre of mass off the file's line, which no scale reproduces), both in
          // the band of the mass uncertainty: every (s, g) whose residual sum of squares exceeds
          // the best by less than c times the residual variance, with the decided value; as
          // the box spanning them. g only widens what is uncertain: the model holds it at 0
          // (estimating it over-fits: docs/effects.md).
          constexpr int kTurns = 12;  // g on a grid of steps 2u/12 = 0.05
          struct Cell {
            double s_lo, s_hi, g, gain;
          };
          std::vector<Cell> cells;
          double top = gain(s(j), 0.0);
          for (int t = 0; t <= kTurns; ++t) {
            const double gj = -kMassUncertainty + 2.0 * kMassUncertainty * t / kTurns;
            const std::vector<double> e = edges(gj);
            for (size_t k = 0; k + 1 < e.size(); ++k) {
              const double g = gain(0.5 * (e[k] + e[k + 1]), gj);
              cells.push_back({e[k], e[k + 1], gj, g});
              top = std::max(top, g);
            }
          }
          const double var = (r0.squaredNorm() - top) / std::max(dof, 1);
          const double c = threshold_lr_critical(0.05) * var;
          double lo = s(j), hi = s(j), glo = 0.0, ghi = 0.0;
          for (const Cell& cl : cells) {
            const bool decided = cl.g == 0.0 && cl.s_lo <= s(j) && s(j) <= cl.s_hi;
            if (decided || top - cl.gain <= c) {
              lo = std::min(lo, cl.s_lo);
              hi = std::max(hi, cl.s_hi);
              glo = std::min(glo, cl.g);
              ghi = std::max(ghi, cl.g);
            }
          }
          out.lower(j) = lo;
          out.upper(j) = hi;
          out.turn_lower(j) = glo;
          out.turn_upper(j) = ghi;
          continue;
        }
        const std::vector<double> edge = edges(0.0);
        if (edge.size() == 2) continue;  // no calibration row tells where joint j reverses
        // A candidate per interval (its midpoint) and the file's preload, s = 0.
        std::vector<double> cand = {0.0};
        for (size_t k = 0; k + 1 < edge.size(); ++k) cand.push_back(0.5 * (edge[k] + edge[k + 1]));
        const double at_file = gain(0.0, 0.0);
        double best = at_file, best_s = 0.0;
        for (const double sj : cand) {
          const double g = gain(sj, 0.0);
          // A larger gain wins; on a tie (the same decisions) the smaller correction.
          if (g > best * (1 + 1e-12) ||
              (g >= best * (1 - 1e-12) && std::abs(sj) < std::abs(best_s))) {
            best = g;
            best_s = sj;
          }
        }
        // The robot file's preload stands unless the data reject it: the drop of the residual
        // sum of squares from s = 0 to the best threshold, in units of the residual variance,
        // against the chi2(1) quantile at alpha / (number of thresholds tried) (Bonferroni:
        // the search picks the best of them; alpha = 5 %).
        const double var = (r0.squaredNorm() - best) / std::max(dof, 1);
        s(j) = dof > 0 && best - at_file > chi2_1_quantile(0.05 / cand.size()) * var ? best_s : 0.0;
        column(j, s(j), x.col(j));
      }
    }
    return out;
  }

  std::string name_ = "backlash";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_backlash_effect(const EffectSetup& s) {
  return std::make_unique<Backlash>(s);
}

}  // namespace stiff
