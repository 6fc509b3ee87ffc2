// backlash: lost motion of the reducers with a gravity preload (docs/effects.md).
#include <Eigen/SVD>
#include <algorithm>

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
    const Eigen::VectorXd s0 = preload_correction(s);
    for (int j = 0; j < n; ++j)
      params_.push_back(effects::parameter(
          "b" + std::to_string(j + 1), "rad",
          "backlash (lost motion) of joint " + std::to_string(j + 1) + ", full gap width", 0.0,
          0.05, 1.5e-4, 0.0, 0.0));
    for (int j = 0; j < n; ++j) {
      params_.push_back(effects::parameter("s" + std::to_string(j + 1), "1",
                                           "relative error of the gravity preload of joint " +
                                               std::to_string(j + 1) +
                                               " (where its backlash jumps), from the data",
                                           kScaleLow, kScaleHigh, kMassUncertainty, s0(j), s0(j)));
      params_.back().from_data = true;
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
    for (int j = 0; j < n; ++j) {
      // s_j by its value only: the threshold regression decides it, not a derivative.
      const T loaded = tanh((T((1 + scalar(p[n + j])) * tg(j)) + s.tau(j)) / T(kEps));
      const T preload = T(std::tanh(tg(j) / kEps));
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
  static double scalar(double x) { return x; }
  static double scalar(const Jet& x) { return x.a; }

  /// The preload errors s_j that the data support: coordinate-wise threshold regression of
  /// d = sum_j c_j J_j(P) tau_F,j + b_j/2 [sgn((1+s_j) tau_g + tau_F) - sgn(tau_g)] J_j(P)
  /// (weighted least squares in c, b) over s_j in the band of the mass uncertainty. Between two
  /// rows' thresholds the decisions, hence the fit, do not change: the candidates are the
  /// midpoints. Zero where the data (displacement rows) cannot tell, and without data.
  static Eigen::VectorXd preload_correction(const EffectSetup& setup) {
    const RobotModel& robot = *setup.robot;
    const int n = robot.dof();
    Eigen::VectorXd s = Eigen::VectorXd::Zero(n);
    if (!setup.data || !robot.has_masses()) return s;
    struct Row {
      Eigen::Matrix3Xd jp;  // J_j(P), translational columns
      Eigen::VectorXd tau, tg;
    };
    std::vector<Row> rows;
    std::vector<Eigen::Vector3d> obs;
    std::vector<double> wt;
    bool sigma = true;
    for (const auto& m : setup.data->rows) sigma = sigma && (m.absolute || m.sigma_d > 0);
    for (const auto& m : setup.data->rows) {
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
      r.tg = gravity_torques(robot, c);
      rows.push_back(std::move(r));
      obs.push_back(m.displacement);
      wt.push_back(sigma ? 1.0 / m.sigma_d : 1.0);
    }
    const int N = static_cast<int>(rows.size());
    if (N < 2 * n) return s;
    // Weighted design: joint compliance columns, then one backlash column per joint.
    Eigen::MatrixXd x(3 * N, 2 * n);
    Eigen::VectorXd y(3 * N);
    for (int i = 0; i < N; ++i) {
      y.segment<3>(3 * i) = wt[i] * obs[i];
      for (int j = 0; j < n; ++j)
        x.block<3, 1>(3 * i, j) = wt[i] * rows[i].tau(j) * rows[i].jp.col(j);
    }
    auto column = [&](int j, double sj, Eigen::Ref<Eigen::VectorXd> out) {
      for (int i = 0; i < N; ++i) {
        const Row& r = rows[i];
        const double jump =
            0.5 * (std::tanh(((1 + sj) * r.tg(j) + r.tau(j)) / kEps) - std::tanh(r.tg(j) / kEps));
        out.segment<3>(3 * i) = wt[i] * jump * r.jp.col(j);
      }
    };
    for (int j = 0; j < n; ++j) column(j, 0.0, x.col(n + j));
    Eigen::VectorXd cand_col(3 * N);
    for (int sweep = 0; sweep < 2; ++sweep) {
      for (int j = 0; j < n; ++j) {
        // Rows whose decision changes within the band: (1 + s) tau_g + tau_F = 0 there.
        std::vector<double> cut;
        for (const auto& r : rows)
          if (std::abs(r.tg(j)) > kEps) {
            const double v = -r.tau(j) / r.tg(j) - 1;
            if (v > kScaleLow && v < kScaleHigh) cut.push_back(v);
          }
        if (cut.empty()) continue;
        std::sort(cut.begin(), cut.end());
        // Orthonormal basis of every other column (rank-revealing: joint 6 and its gap have no
        // lever arm with P and L on the flange axis); RSS(x) = |r0|^2 - (x~.r0)^2 / |x~|^2.
        Eigen::MatrixXd other(3 * N, 2 * n - 1);
        other << x.leftCols(n + j), x.rightCols(n - j - 1);
        const Eigen::JacobiSVD<Eigen::MatrixXd> svd(other, Eigen::ComputeThinU);
        const auto& sv = svd.singularValues();
        int rank = 0;
        while (rank < sv.size() && sv(rank) > 1e-10 * sv(0)) ++rank;
        const Eigen::MatrixXd q = svd.matrixU().leftCols(rank);
        const Eigen::VectorXd r0 = y - q * (q.transpose() * y);
        auto gain = [&](double sj) {
          column(j, sj, cand_col);
          cand_col -= q * (q.transpose() * cand_col);
          const double nn = cand_col.squaredNorm();
          if (!(nn > 1e-20 * y.squaredNorm())) return 0.0;
          const double u = cand_col.dot(r0);
          return u * u / nn;
        };
        std::vector<double> cand = {0.0, 0.5 * (kScaleLow + cut.front())};
        for (size_t k = 0; k + 1 < cut.size(); ++k) cand.push_back(0.5 * (cut[k] + cut[k + 1]));
        cand.push_back(0.5 * (cut.back() + kScaleHigh));
        const double at_file = gain(0.0);
        double best = at_file, best_s = 0.0;
        for (const double sj : cand) {
          const double g = gain(sj);
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
        const int dof = 3 * N - rank - 1;
        const double var = (r0.squaredNorm() - best) / std::max(dof, 1);
        s(j) = dof > 0 && best - at_file > chi2_1_quantile(0.05 / cand.size()) * var ? best_s : 0.0;
        column(j, best_s, x.col(n + j));
      }
    }
    return s;
  }

  std::string name_ = "backlash";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_backlash_effect(const EffectSetup& s) {
  return std::make_unique<Backlash>(s);
}

}  // namespace stiff
