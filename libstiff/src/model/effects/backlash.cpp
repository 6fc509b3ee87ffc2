// backlash: lost motion of the reducers with a gravity preload (docs/effects.md).
#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <deque>
#include <limits>
#include <mutex>
#include <string>
#include <unordered_map>

#include "stiff/kinematics/joint_torque.hpp"
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// A dead zone of width b_j: the gravity preload holds the gear against one flank; the load
/// traverses the gap only when it reverses the joint torque:
///   dtheta_j += b_j/2 [sgn(tau_p,j + tau_F) - sgn(tau_p,j)],  tau_p,j = sum_k (1 + m_k) tau_g,jk,
/// tau_g,jk the torque of link k's weight on joint j from the robot file (the tool with the last
/// link). The masses are what users do not know: m_k is the relative error of link k's mass,
/// one value that moves the preload of every joint carrying link k. The data tell the m_k only
/// through which rows jumped, sharp thresholds that a derivative cannot find: the effect
/// estimates them from the data it is built on by threshold regression (Hansen 2000) over every
/// link's mass at once, from none to twice the file's, and holds them there (their start and
/// null value: b_j = 0 switches the effect off whatever m_k is; a fit keeps them).
/// What the data leave open of the masses (their posterior second moments V about m, held as
/// v_kl) makes a new pose's jump a matter of chance near its reversal: there the model predicts
/// the expected jump, sgn(x) ~ erf(x / w sqrt 2) with w^2 = t^T V t (t_k = tau_g,jk), and on the
/// poses the masses were decided on the decided one. w is at least eps = 0.05 N*m (well below
/// the load torques of a test), so that the model has a derivative with respect to everything
/// that changes the torques (force frame, offsets). A joint without preload (tau_g = 0, e.g. a
/// vertical joint 1) jumps by b/2 sgn(tau_F): the mean over its unknown start in the gap.
class Backlash : public EffectT<Backlash> {
 public:
  explicit Backlash(const EffectSetup& s) {
    const int n = s.robot->dof();
    const Preload s0 = preload_correction(s);
    if (s.data)
      for (const Measurement& m : s.data->rows) decided_.push_back(pose_key(m));
    std::sort(decided_.begin(), decided_.end());
    for (int j = 0; j < n; ++j)
      params_.push_back(effects::parameter(
          "b" + std::to_string(j + 1), "rad",
          "backlash (lost motion) of joint " + std::to_string(j + 1) + ", full gap width", 0.0,
          0.05, 1.5e-4, 0.0, 0.0));
    for (int k = 0; k < n; ++k) {
      params_.push_back(
          effects::parameter("m" + std::to_string(k + 1), "1",
                             "relative error of the mass of link " + std::to_string(k + 1) +
                                 (k + 1 == n ? " and the tool" : "") +
                                 " in the robot file (where the backlash jumps), from the data",
                             kMassLow, kMassHigh, kMassUncertainty, s0.m(k), s0.m(k)));
      params_.back().from_data = true;
      params_.back().confidence_lower = s0.lower(k);
      params_.back().confidence_upper = s0.upper(k);
    }
    for (int k = 0; k < n; ++k)
      for (int l = k; l < n; ++l) {
        params_.push_back(effects::parameter(
            "v" + std::to_string(k + 1) + std::to_string(l + 1), "1",
            "covariance of m" + std::to_string(k + 1) + " and m" + std::to_string(l + 1) +
                " left by the data (new poses near a reversal get the expected jump)",
            -4.0, 4.0, kMassUncertainty * kMassUncertainty, s0.cov(k, l), s0.cov(k, l)));
        params_.back().from_data = true;
        params_.back().spread = true;
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
    return "backlash with gravity preload: dtheta_j += b_j/2 [sgn(tau_p,j + tau_F) - "
           "sgn(tau_p,j)], tau_p,j = sum_k (1+m_k) tau_g,jk, the link masses' errors m_k found "
           "from the data; a new pose near its reversal gets the expected jump over what the data "
           "leave open of them (erf, covariance v_kl); independent of the load level";
  }
  std::string reference() const override {
    return "Harmonic Drive / Nabtesco RV catalogues (lost motion <= 1 arcmin); FIGAROH "
           "(Thanh et al. 2023) backlash over position, gravity torque and direction; Hansen, "
           "Econometrica 68 (2000) (threshold regression)";
  }
  unsigned requirements() const override { return kNeedsMasses; }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }

  static constexpr double kEps = 0.05;  ///< N*m
  /// A link's mass is searched from none to twice the robot file's; the turn of a centre of
  /// mass (what the data leave open) over 30 % of its distance.
  static constexpr double kMassLow = -1.0;
  static constexpr double kMassHigh = 1.0;
  static constexpr double kMassUncertainty = 0.3;
  /// What a robot file tells of a link's mass: within half of it (one standard deviation).
  static constexpr double kMassPrior = 0.5;

  template <typename T>
  void joint_t(const T* p, EvalState<T>& s) const {
    const Eigen::MatrixXd& tl = s.context->tau_gravity_links;
    const int n = static_cast<int>(s.dtheta.size());
    assert(tl.rows() == n && tl.cols() == n);  // every context comes from DeflectionModel
    // The turns g_j are 0 but where the diagnosis tries the ends of their confidence sets.
    const T* mass = p + n;
    const T* cov = p + 2 * n;  // upper triangle, row by row
    const T* turn = cov + n * (n + 1) / 2;
    // A pose and load the masses were decided on had its jumps observed: the data, not the
    // posterior's spread, decide it (the spread is what a new pose does not know).
    const bool on_decided_pose =
        !decided_.empty() &&
        std::binary_search(decided_.begin(), decided_.end(), pose_key(*s.measurement));
    Eigen::VectorXd tq;
    for (int j = 0; j < n && tq.size() == 0; ++j)
      if (scalar(turn[j]) != 0.0) gravity_torques(*s.robot, s.context->chain, &tq);
    for (int j = 0; j < n; ++j) {
      // m_k, v_kl, g_j by their value only: the threshold regression decides them, not a
      // derivative. The expected sign over a Gaussian preload of variance w^2 is
      // erf(x / w sqrt 2); w^2 = t^T V t for the torques t_k = tau_g,jk and the masses' posterior
      // covariance V, and at least eps^2 (the smoothing).
      double pre = 0, var = 0;
      for (int k = 0, at = 0; k < n; ++k) {
        pre += tl(j, k) * (1 + scalar(mass[k]));
        for (int l = k; l < n && !on_decided_pose; ++l, ++at)
          var += (l == k ? 1.0 : 2.0) * tl(j, k) * tl(j, l) * scalar(cov[at]);
      }
      if (scalar(turn[j]) != 0.0) pre += scalar(turn[j]) * tq(j);
      const double scale = 1.0 / std::sqrt(2.0 * std::max(var, kEps * kEps));
      using std::erf;
      const T loaded = erf((T(pre) + s.tau(j)) * T(scale));
      const T preload = T(std::erf(pre * scale));
      s.dtheta(j) += T(0.5) * p[j] * (loaded - preload);
    }
  }
  /// A joint that gravity does not preload at this pose (every link's torque on it below eps:
  /// a vertical joint 1) rests anywhere in its gap between readings, uniformly: its deflection
  /// from the unloaded reading scatters about the model's mean b/2 sgn(tau_F) with the variance
  /// of that rest, b^2/12.
  bool scatters() const override { return true; }
  void joint_scatter(const double* p,
                     const EvalState<double>& s,
                     Eigen::VectorXd& var) const override {
    const Eigen::MatrixXd& tl = s.context->tau_gravity_links;
    if (tl.rows() != var.size()) return;
    for (Eigen::Index j = 0; j < var.size(); ++j)
      if (tl.row(j).cwiseAbs().maxCoeff() < kEps) var(j) += p[j] * p[j] / 12.0;
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
  /// The search decides jumps by the exact sign (0 at 0, a joint without preload): the
  /// model's smooth sign would let it place a threshold within eps of a row and fit that row's
  /// residual by a fraction of the jump.
  static double sign(double x) { return x > 0 ? 1.0 : x < 0 ? -1.0 : 0.0; }
  static double scalar(double x) { return x; }
  static double scalar(const Jet& x) { return x.a; }
  /// Radical inverse of i in base b (Halton 1960): low-discrepancy points in [0, 1).
  static double radical_inverse(int i, int b) {
    double f = 1.0, r = 0.0;
    for (; i > 0; i /= b) {
      f /= b;
      r += f * (i % b);
    }
    return r;
  }

  /// The link masses' errors m that the data support, by threshold regression of
  /// d = (the model's other effects) + sum_j b_j/2 [sgn(tau_p,j + tau_F) - sgn(tau_p,j)] J_j(P)
  /// (weighted least squares in their coefficients and b) over m in the box [-1, 1]^L of the L
  /// links with mass: the decisions, hence the fit, change only where a row's threshold is
  /// crossed, so no derivative finds them. A low-discrepancy design of the box, then coordinate
  /// sweeps from its best points, maximising the posterior with the file's masses as the
  /// prior. The file's masses (m = 0) stand unless the data reject them. The estimate m and its
  /// confidence box [lower, upper], the range of each joint's turn (NaN without data), and the
  /// posterior's second moments of m about the estimate (0 without data).
  struct Preload {
    Eigen::VectorXd m, lower, upper, turn_lower, turn_upper;
    Eigen::MatrixXd cov;
  };
  /// preload_correction() of the same inputs again (a diagnosis builds one model several
  /// times: to score it, to fit it, to cross-fit a session) is looked up, not searched again:
  /// the last few results, keyed by every input the search reads, compared exactly.
  static Preload preload_correction(const EffectSetup& setup) {
    if (!setup.data || !setup.robot->has_masses()) return search_preload(setup);
    std::vector<double> key;
    const RobotModel& robot = *setup.robot;
    for (const auto& j : robot.joints) {
      key.push_back(j.mass);
      key.insert(key.end(), j.com.data(), j.com.data() + 3);
      key.insert(key.end(), j.pre.data(), j.pre.data() + 16);
      key.insert(key.end(), j.post.data(), j.post.data() + 16);
      key.insert(key.end(), j.axis.data(), j.axis.data() + 3);
    }
    key.push_back(robot.tool_mass);
    key.insert(key.end(), robot.tool_com.data(), robot.tool_com.data() + 3);
    key.insert(key.end(), robot.gravity.data(), robot.gravity.data() + 3);
    key.insert(key.end(), robot.measured_point.data(), robot.measured_point.data() + 3);
    key.insert(key.end(), robot.load_point.data(), robot.load_point.data() + 3);
    for (const Measurement& m : setup.data->rows) {
      key.push_back(m.absolute ? 1.0 : 0.0);
      key.push_back(m.sigma_d);
      key.insert(key.end(), m.q.data(), m.q.data() + m.q.size());
      key.insert(key.end(), m.force.data(), m.force.data() + 3);
      key.insert(key.end(), m.moment.data(), m.moment.data() + 3);
      key.insert(key.end(), m.displacement.data(), m.displacement.data() + 3);
    }
    const Eigen::MatrixXd& cols = setup.companion_columns;
    key.push_back(static_cast<double>(cols.rows()));
    key.insert(key.end(), cols.data(), cols.data() + cols.size());
    key.push_back(static_cast<double>(setup.companion_rows.size()));
    for (const auto& w : setup.companion_rows)
      for (const Eigen::Vector3d* v : {&w.r_meas, &w.r_load, &w.force, &w.moment})
        key.insert(key.end(), v->data(), v->data() + 3);
    struct Entry {
      std::vector<double> key;
      Preload value;
    };
    static std::mutex mutex;
    static std::deque<Entry> cache;
    constexpr size_t kEntries = 16;
    auto same = [&](const Entry& e) {
      return e.key.size() == key.size() &&
             std::memcmp(e.key.data(), key.data(), key.size() * sizeof(double)) == 0;
    };
    {
      const std::lock_guard<std::mutex> lock(mutex);
      for (const Entry& e : cache)
        if (same(e)) return e.value;
    }
    Preload found = search_preload(setup);
    const std::lock_guard<std::mutex> lock(mutex);
    cache.push_front({std::move(key), found});
    if (cache.size() > kEntries) cache.pop_back();
    return found;
  }
  static Preload search_preload(const EffectSetup& setup) {
    const RobotModel& robot = *setup.robot;
    const int n = robot.dof();
    Preload out;
    out.m = Eigen::VectorXd::Zero(n);
    out.lower = out.upper = out.turn_lower = out.turn_upper =
        Eigen::VectorXd::Constant(n, std::numeric_limits<double>::quiet_NaN());
    out.cov = Eigen::MatrixXd::Zero(n, n);
    if (!setup.data || !robot.has_masses()) return out;
    struct Row {
      Eigen::Matrix3Xd jp;  // J_j(P), translational columns
      Eigen::VectorXd tau, tq;
    };
    std::vector<Row> rows;
    std::vector<Eigen::Vector3d> obs;
    std::vector<double> wt;
    std::vector<int> at;  // the row's index in the data
    // Every row's by-link torques tau_g,jk stacked (row n i + j: joint j of row i), so that the
    // preloads of a candidate are one product.
    Eigen::MatrixXd tl_all(n * setup.data->rows.size(), n);
    bool sigma = true;
    for (const auto& m : setup.data->rows) sigma = sigma && (m.absolute || m.sigma_d > 0);
    for (size_t k = 0; k < setup.data->rows.size(); ++k) {
      const Measurement& m = setup.data->rows[k];
      if (m.absolute || m.q.size() != n || !m.q.allFinite()) continue;
      const ChainState c = robot.chain(m.q);
      // Where the model's other effects put the points and the wrench (a fitted point offset
      // moves the wrist's lever arms and load torques), else where the robot file has them.
      const bool moved = setup.companion_rows.size() == setup.data->rows.size();
      const EffectSetup::CompanionRow w =
          moved ? setup.companion_rows[k]
                : EffectSetup::CompanionRow{robot.measured_point, robot.load_point, m.force,
                                            m.moment};
      const Eigen::Vector3d p = robot.point_position(c, w.r_meas);
      const Eigen::Vector3d l = robot.point_position(c, w.r_load);
      Row r;
      r.jp.resize(3, n);
      r.tau.resize(n);
      for (int j = 0; j < n; ++j) {
        const Eigen::Vector3d z = c.axis.col(j), o = c.origin.col(j);
        Eigen::Vector3d wp, wl;
        lever_arm(z, o, p, wp);
        lever_arm(z, o, l, wl);
        r.jp.col(j) = wp;
        r.tau(j) = joint_torque(wl, z, w.force, w.moment);
      }
      Eigen::MatrixXd tq;
      tl_all.middleRows(n * rows.size(), n) = gravity_torques_by_link(robot, c, &tq);
      r.tq = tq.rowwise().sum();
      rows.push_back(std::move(r));
      obs.push_back(m.displacement);
      wt.push_back(sigma ? 1.0 / m.sigma_d : 1.0);
      at.push_back(static_cast<int>(k));
    }
    const int N = static_cast<int>(rows.size());
    if (N < 2 * n) return out;
    tl_all.conservativeResize(N * n, n);
    // The links whose mass loads a joint on these rows.
    std::vector<int> links;
    for (int k = 0; k < n; ++k) {
      if (tl_all.col(k).cwiseAbs().maxCoeff() > kEps) links.push_back(k);
    }
    if (links.empty()) return out;
    // Weighted design: what the model's other effects do (EffectSetup::companion_columns: a
    // point offset, a force frame, the joint compliance, ...), so that the thresholds are decided
    // on what they leave; alone in its model, the joint compliance it acts with.
    const Eigen::MatrixXd& cols = setup.companion_columns;
    const bool companions = cols.rows() == 3 * static_cast<int>(setup.data->rows.size());
    Eigen::MatrixXd lin(3 * N, companions ? cols.cols() : n);
    Eigen::VectorXd y(3 * N);
    for (int i = 0; i < N; ++i) {
      y.segment<3>(3 * i) = wt[i] * obs[i];
      if (companions)
        lin.middleRows<3>(3 * i) = wt[i] * cols.middleRows<3>(3 * at[i]);
      else
        for (int j = 0; j < n; ++j)
          lin.block<3, 1>(3 * i, j) = wt[i] * rows[i].tau(j) * rows[i].jp.col(j);
    }
    // Orthonormal basis Q of the other effects' columns (unit columns: the rank threshold
    // compares like with like); r0 what they leave.
    for (int c = 0; c < lin.cols(); ++c) {
      const double norm = lin.col(c).norm();
      if (norm > 0) lin.col(c) /= norm;
    }
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(lin);
    qr.setThreshold(1e-10);
    const int rank = static_cast<int>(qr.rank());
    const Eigen::MatrixXd q = qr.householderQ() * Eigen::MatrixXd::Identity(3 * N, rank);
    const Eigen::VectorXd r0 = y - q * (q.transpose() * y);
    const int dof = 3 * N - rank - n;
    // Per row and joint, the gap's block u_ij = w_i J_j(P_i): u.r0, the Gram entries u_ij.u_il
    // (column j n + l) and Q_i^T u, so that a candidate costs O(N n (rank + n)) without
    // allocating.
    Eigen::MatrixXd along(N, n), gram(N, n * n);
    std::vector<Eigen::MatrixXd> proj(n, Eigen::MatrixXd(rank, N));
    for (int i = 0; i < N; ++i) {
      const Eigen::Matrix3Xd u = wt[i] * rows[i].jp;
      along.row(i) = (u.transpose() * r0.segment<3>(3 * i)).transpose();
      const Eigen::MatrixXd uu = u.transpose() * u;
      for (int j = 0; j < n; ++j)
        for (int l = 0; l < n; ++l) gram(i, j * n + l) = uu(j, l);
      const Eigen::MatrixXd qu = q.middleRows(3 * i, 3).transpose() * u;
      for (int j = 0; j < n; ++j) proj[j].col(i) = qu.col(j);
    }
    // Joints whose gap has a lever arm with the measured point on some row.
    std::vector<int> levered;
    for (int j = 0; j < n; ++j)
      if (gram.col(j * n + j).maxCoeff() > 0) levered.push_back(j);
    const int nl = static_cast<int>(levered.size());
    if (nl == 0) return out;
    Eigen::MatrixXd jump(N, n);
    Eigen::VectorXd mass(n), pre_all(N * n);
    auto decide = [&](const Eigen::VectorXd& m, const Eigen::VectorXd& g) {
      mass = m.array() + 1.0;
      pre_all.noalias() = tl_all * mass;
      for (int i = 0; i < N; ++i)
        for (const int j : levered) {
          const double pre = pre_all(n * i + j) + g(j) * rows[i].tq(j);
          jump(i, j) = 0.5 * (sign(pre + rows[i].tau(j)) - sign(pre));
        }
    };
    // The drop of the residual sum of squares when the gaps' columns join the others':
    // b^T A^+ b, A the Gram matrix of the columns with Q's span removed.
    const double tiny = 1e-20 * y.squaredNorm();
    Eigen::VectorXd b(nl), t(nl);
    Eigen::MatrixXd a(nl, nl), pj(rank, nl);
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(nl);
    // The drop depends on the jump decisions alone, which change in steps: the sweeps and the
    // bisections below meet the same decisions again and again, so each is computed once.
    std::unordered_map<std::string, double> known;
    std::string decisions(static_cast<size_t>(N) * nl, '\0');
    auto gain = [&]() {
      for (int x = 0; x < nl; ++x)
        for (int i = 0; i < N; ++i)  // 2 jump is an integer in [-2, 2]
          decisions[static_cast<size_t>(x) * N + i] = static_cast<char>(2 * jump(i, levered[x]));
      const auto [hit, fresh] = known.try_emplace(decisions, 0.0);
      if (!fresh) return hit->second;
      for (int x = 0; x < nl; ++x) {
        const int j = levered[x];
        b(x) = jump.col(j).dot(along.col(j));
        pj.col(x).noalias() = proj[j] * jump.col(j);
      }
      a.noalias() = -pj.transpose() * pj;
      for (int x = 0; x < nl; ++x)
        for (int z = x; z < nl; ++z) {
          const int j = levered[x], l = levered[z];
          a(x, z) += jump.col(j).cwiseProduct(jump.col(l)).dot(gram.col(j * n + l));
          a(z, x) = a(x, z);
        }
      es.compute(a);
      const Eigen::VectorXd& ev = es.eigenvalues();
      // A column (nearly) inside the others' span adds nothing (and no cancellation noise).
      const double floor = std::max(tiny, 1e-9 * a.diagonal().maxCoeff());
      t.noalias() = es.eigenvectors().transpose() * b;
      double out_gain = 0;
      for (int k = 0; k < nl; ++k)
        if (ev(k) > floor) out_gain += t(k) * t(k) / ev(k);
      hit->second = out_gain;
      return out_gain;
    };
    const Eigen::VectorXd none = Eigen::VectorXd::Zero(n);
    struct Tried {
      Eigen::VectorXd m;
      double gain;
    };
    std::vector<Tried> tried;
    auto evaluate = [&](const Eigen::VectorXd& m) {
      decide(m, none);
      tried.push_back({m, gain()});
      return tried.back().gain;
    };
    const double at_file = evaluate(none);
    const double rss0 = r0.squaredNorm();
    constexpr int kGrid = 41;  // a link's mass in steps of 5 % of the file's
    // A Halton design of the box, then coordinate sweeps over a grid of each link's mass from
    // the design's best points (the decisions change in steps: a local search stalls, a design
    // alone is coarse).
    constexpr int kDesign = 512, kStarts = 6, kSweeps = 3;
    constexpr int kPrimes[] = {2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53};
    const int dims = std::min(static_cast<int>(links.size()), 16);
    for (int i = 1; i <= kDesign; ++i) {
      Eigen::VectorXd m = none;
      for (int d = 0; d < dims; ++d)
        m(links[d]) = kMassLow + (kMassHigh - kMassLow) * radical_inverse(i, kPrimes[d]);
      evaluate(m);
    }
    // Many cells fit the rows about alike, and the one with the smallest residual is often far
    // from the file's masses and decides new poses worse: the search maximises the posterior
    // instead, the file's masses as a Gaussian prior of each m_k with standard deviation
    // kMassPrior, the fit's likelihood with the residual variance of the design's best point.
    double best_design = at_file;
    for (const Tried& point : tried) best_design = std::max(best_design, point.gain);
    const double prior_weight = (rss0 - best_design) / std::max(dof, 1) / (kMassPrior * kMassPrior);
    auto score = [&](const Eigen::VectorXd& m, double g) {
      return g - prior_weight * m.squaredNorm();
    };
    std::vector<int> order(kDesign);  // the design's points, after the file's (tried[0])
    for (int i = 0; i < kDesign; ++i) order[i] = i + 1;
    std::partial_sort(order.begin(), order.begin() + kStarts, order.end(), [&](int u, int v) {
      return score(tried[u].m, tried[u].gain) > score(tried[v].m, tried[v].gain);
    });
    std::vector<std::pair<Eigen::VectorXd, double>> starts;
    for (int st = 0; st < kStarts; ++st)
      starts.emplace_back(tried[order[st]].m, score(tried[order[st]].m, tried[order[st]].gain));
    Eigen::VectorXd best_m = none;
    double best_score = at_file;
    for (auto& [m, here] : starts) {
      for (int sweep = 0; sweep < kSweeps; ++sweep)
        for (int d = 0; d < dims; ++d) {
          const int k = links[d];
          double keep = m(k);
          for (int step = 0; step < kGrid; ++step) {
            m(k) = kMassLow + (kMassHigh - kMassLow) * step / (kGrid - 1);
            const double g = score(m, evaluate(m));
            if (g > here + 1e-12 * std::abs(here)) {
              here = g;
              keep = m(k);
            }
          }
          m(k) = keep;
        }
      if (here > best_score + 1e-12 * std::abs(best_score)) {
        best_score = here;
        best_m = m;
      }
    }
    decide(best_m, none);
    const double best = gain();
    // The file's masses stand unless the data reject them: the drop of the residual sum of
    // squares, in units of the residual variance, against the chi2(1) quantile at alpha /
    // (number of points tried) (Bonferroni: the search picks the best of them; alpha = 5 %).
    const double var = (rss0 - best) / std::max(dof, 1);
    const bool rejected = dof > 0 && best - at_file > chi2_1_quantile(0.05 / tried.size()) * var;
    // Every mass vector that decides the calibration rows' jumps alike fits them alike: the
    // best is a cell, convex (each decision is a half-space in the masses), and the sweeps end
    // on its wall, next to some row's reversal, where a new pose's jump is most often decided
    // wrongly. Its middle instead (when it replaces the file's masses), axis by axis (bisection
    // to the walls, rounds until it stays).
    auto in_best_cell = [&](const Eigen::VectorXd& m) {
      decide(m, none);
      return std::abs(gain() - best) <= 1e-9 * std::abs(best);
    };
    double moved = 1;
    for (int round = 0; rejected && round < 8 && moved > 2e-3; ++round) {
      moved = 0;
      for (int d = 0; d < dims; ++d) {
        const int k = links[d];
        double wall[2];
        for (int side = 0; side < 2; ++side) {
          Eigen::VectorXd m = best_m;
          double in = best_m(k), beyond = side ? kMassHigh : kMassLow;
          m(k) = beyond;
          if (in_best_cell(m)) {
            wall[side] = beyond;
            continue;
          }
          for (int it = 0; it < 12; ++it) {
            m(k) = 0.5 * (in + beyond);
            (in_best_cell(m) ? in : beyond) = m(k);
          }
          wall[side] = in;
        }
        moved = std::max(moved, std::abs(0.5 * (wall[0] + wall[1]) - best_m(k)));
        best_m(k) = 0.5 * (wall[0] + wall[1]);
      }
    }
    out.m = rejected ? best_m : none;
    // What the data do not exclude: the likelihood-ratio confidence set of the thresholds
    // (Hansen 2000), every point tried whose residual sum of squares exceeds the best by less
    // than c times the residual variance, with the decided value; as the box spanning them.
    const double c = threshold_lr_critical(0.05) * var;
    for (const int k : links) out.lower(k) = out.upper(k) = out.m(k);
    for (const Tried& point : tried)
      if (best - point.gain <= c)
        for (const int k : links) {
          out.lower(k) = std::min(out.lower(k), point.m(k));
          out.upper(k) = std::max(out.upper(k), point.m(k));
        }
    // How far the masses may sit from the estimate: the posterior's second moments about it,
    // by importance sampling (Halton points of the confidence box, each weighted by its
    // posterior, exp(score / 2 s^2)). A pose whose preload is that close to its reversal is
    // decided by chance, and the model predicts the expected jump there (joint_t). The moments
    // are joint ones: the masses the rows decide only in combination (the wrist's and the
    // tool's) are correlated, and their independent spreads would blur decided rows.
    if (var > 0) {
      constexpr int kPosterior = 256;
      double top = -std::numeric_limits<double>::infinity();
      std::vector<std::pair<Eigen::VectorXd, double>> drawn;
      for (int i = 1; i <= kPosterior; ++i) {
        Eigen::VectorXd m = out.m;
        for (int d = 0; d < dims; ++d) {
          const int k = links[d];
          m(k) = out.lower(k) + (out.upper(k) - out.lower(k)) * radical_inverse(i, kPrimes[d]);
        }
        decide(m, none);
        drawn.emplace_back(m, score(m, gain()));
        top = std::max(top, drawn.back().second);
      }
      double total = 0;
      Eigen::MatrixXd sq = Eigen::MatrixXd::Zero(n, n);
      for (const auto& [m, sc] : drawn) {
        const double w = std::exp((sc - top) / (2 * var));
        total += w;
        sq += w * (m - out.m) * (m - out.m).transpose();
      }
      if (total > 0) out.cov = sq / total;
    }
    // The turn of each joint's lumped centre of mass (a centre of mass off the file's line,
    // which no mass reproduces): the range over which the decided masses' fit stays in the set.
    // It only widens what is uncertain: the model holds it at 0 (estimating it over-fits:
    // docs/effects.md).
    constexpr int kTurns = 12;  // g on a grid of steps 2u/12 = 0.05
    for (int j = 0; j < n; ++j) {
      double glo = 0.0, ghi = 0.0;
      for (int step = 0; step <= kTurns; ++step) {
        Eigen::VectorXd g = none;
        g(j) = -kMassUncertainty + 2.0 * kMassUncertainty * step / kTurns;
        decide(out.m, g);
        if (best - gain() <= c) {
          glo = std::min(glo, g(j));
          ghi = std::max(ghi, g(j));
        }
      }
      out.turn_lower(j) = glo;
      out.turn_upper(j) = ghi;
    }
    return out;
  }

  /// Hash of a row's joint angles and load, what decides its jumps (their bit patterns, word by
  /// word, FNV-1a's multiplier with a final avalanche; read on every evaluation).
  static uint64_t pose_key(const Measurement& m) {
    uint64_t h = 1469598103934665603ull;
    auto mix = [&h](const double* x, Eigen::Index count) {
      for (Eigen::Index i = 0; i < count; ++i) {
        uint64_t w;
        std::memcpy(&w, x + i, sizeof w);
        h = (h ^ w) * 1099511628211ull;
      }
    };
    mix(m.q.data(), m.q.size());
    mix(m.force.data(), 3);
    mix(m.moment.data(), 3);
    return h ^ (h >> 29);
  }

  std::string name_ = "backlash";
  std::vector<uint64_t> decided_;  ///< pose_key of the rows the masses were decided on
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_backlash_effect(const EffectSetup& s) {
  return std::make_unique<Backlash>(s);
}

}  // namespace stiff
