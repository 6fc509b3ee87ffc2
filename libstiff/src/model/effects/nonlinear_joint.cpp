// nonlinear_joint: a joint whose torque-torsion curve is not a straight line (strain-wave and
// cycloidal reducers, docs/effects.md), in a form general enough for the reducers users have:
// hardening or softening, symmetric or not, about the gravity preload or about the unloaded
// state. Linear in its parameters, so the score test uses it as it stands; every term is
// optional (ParameterSpec::optional_term): a fit keeps the sub-form the data support.
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// Per joint, with tau_F the load torque and tau_g the gravity preload:
///   dtheta_j += e_j [phi(tau_g + tau_F) - phi(tau_g)]   soft zone about zero torque, the
///               catalogue three-segment curve (phi = T1 tanh(./T1), knee T1 fixed: 10 N*m arm,
///               2 N*m wrist), a secant about the preload; e > 0 hardening, e < 0 softening;
///             + w_j [psi(tau_g + tau_F) - psi(tau_g)]    (arm joints) the same with a knee
///               three times as wide (psi = 3 T1 tanh(./(3 T1))): a catalogue's knee grows with
///               the reducer's size, and two knees a factor 3 apart (and their sum) span the
///               sizes of an arm; an alternative to e, outside the common sub-forms, so that a
///               fit pays the extended criterion's price to keep it;
///             + s_j tau_F |tau_F| / T0                   symmetric change of stiffness with
///               the load torque (s < 0 hardening, s > 0 softening), about the unloaded state;
///             + a_j tau_F^2 / T0                         asymmetric curve (stiffer in one
///               direction of the load than in the other);
///             + h_j [(tau_g + tau_F)^3 - tau_g^3] / T0^2  hardening (h < 0) or softening
///               with the cube of the total torque, the smooth symmetric law about zero torque
///               (a Duffing spring), about the gravity preload;
///             + r_j [|tau_g + tau_F| - |tau_g|]          bilinear curve with its kink at the
///               torque reversal: compliance c_j + r_j for positive total torque, c_j - r_j for
///               negative (a reducer stiffer in one direction), about the gravity preload;
///             + g_j tau_F^3 / T0^2                       symmetric hardening (g < 0) or
///               softening with the cube of the load torque, about the unloaded state;
///             + k_j |tau_F|                              a kink at the unloaded state: the
///               reducer's loading branch steeper one way than the other (its hysteresis: a
///               load taken from rest always climbs the loading branch, whichever its sign).
/// T0 = 100 N*m makes s, a and g the change of compliance at 100 N*m [rad/(N*m)]. a and s are
/// the second-order terms of a curve about the unloaded state (even, and odd with a kink), g
/// its smooth odd third-order term (a Duffing spring about the unloaded state: s alone leaves
/// a cubic's misfit at the largest loads, above the noise of a 10 um tracker), e the
/// saturating soft zone that a series of low order cannot follow. h and r are laws
/// of the total torque, so the preload moves the compliance the load sees: h by 3 h tau_g^2,
/// r by its sign; the load-centred terms cannot follow that across poses. s and a belong
/// to the arm joints (all but the last three of a 6-axis arm): a load at the flange moves the
/// wrist torques by a few N*m only, where a second-order term is noise, and the wrist's soft
/// zone (2 N*m knee) already covers its reducers. The terms overlap (each other and the linear
/// compliance): a term the data do not support only adds prediction variance, so all of them
/// are optional and identification keeps those that pay for themselves (docs/identifiability.md).
class NonlinearJoint : public EffectT<NonlinearJoint> {
 public:
  static constexpr double kT0 = 100.0;  ///< N*m
  static constexpr double kWide = 3.0;  ///< the wide soft zone's knee, in the narrow one's

  explicit NonlinearJoint(const EffectSetup& s) {
    const int n = s.robot->dof();
    auto optional = [](ParameterSpec p) {
      p.optional_term = true;
      return p;
    };
    for (int j = 0; j < n; ++j) {
      knee_.push_back(j < n - 3 || n <= 3 ? 10.0 : 2.0);
      const std::string jn = std::to_string(j + 1);
      params_.push_back(optional(effects::parameter(
          "e" + jn, "rad/(N*m)",
          "extra compliance of joint " + jn + " in the soft zone about zero torque (knee " +
              std::to_string(static_cast<int>(knee_.back())) + " N*m; < 0: softening)",
          -1e-2, 1e-2, 1e-5, 0.0, 0.0)));
    }
    arm_ = n > 3 ? n - 3 : n;
    std::vector<ParameterSpec> wide;  // after the other terms: their indices stay as they were
    for (int j = 0; j < arm_; ++j) {
      const std::string jn = std::to_string(j + 1);
      wide.push_back(optional(effects::parameter(
          "w" + jn, "rad/(N*m)",
          "extra compliance of joint " + jn + " in a wide soft zone about zero torque (knee " +
              std::to_string(static_cast<int>(kWide * knee_[j])) + " N*m; < 0: softening)",
          -1e-2, 1e-2, 1e-5, 0.0, 0.0)));
    }
    // Only the arm joints carry the second-order terms and the laws of the total torque (see
    // above): a parameter without a regressor would count as a degree of freedom in the F tests
    // and cost them power. Each term: its letter and what it is, after "joint j".
    const std::pair<const char*, const char*> arm_terms[] = {
        {"s", "'s compliance change at 100 N*m of load torque, symmetric (< 0 hardening)"},
        {"a", "'s compliance asymmetry at 100 N*m (positive load torque softer when > 0)"},
        {"h", "'s cubic compliance change with the total torque at 100 N*m (< 0 hardening)"},
        {"r", ": half the difference of its compliances for positive and negative total torque"},
        {"g", "'s cubic compliance change with the load torque at 100 N*m (< 0 hardening)"},
        {"k", ": half the difference of its compliances for positive and negative load torque"}};
    for (const auto& [letter, what] : arm_terms)
      for (int j = 0; j < arm_; ++j) {
        const std::string jn = std::to_string(j + 1);
        params_.push_back(optional(effects::parameter(
            letter + jn, "rad/(N*m)", "joint " + jn + what, -1e-2, 1e-2, 1e-6, 0.0, 0.0)));
      }
    params_.insert(params_.end(), wide.begin(), wide.end());
  }
  const std::string& name() const override { return name_; }
  /// The families a reducer's law comes in, each scored on its own by the diagnosis: the
  /// smooth second-order function of the load torque about the unloaded state (s, a), its cube
  /// and its kink there (g, k), the catalogue soft zone (e), and every function of the total
  /// torque, preload included (e, h, r). The wide soft zone (w) is in none of them: a rare
  /// alternative to e (docs/effects.md). (The second-order family is the common one: scored
  /// with the cube and the kink in its columns it lost power at N = 30.)
  std::vector<std::vector<int>> sub_forms() const override {
    const int n = static_cast<int>(knee_.size());
    std::vector<int> load, higher, total;
    for (int j = 0; j < n; ++j) total.push_back(j);
    for (int j = 0; j < arm_; ++j) {
      load.push_back(n + j);
      load.push_back(n + arm_ + j);
      higher.push_back(n + 4 * arm_ + j);
      higher.push_back(n + 5 * arm_ + j);
      total.push_back(n + 2 * arm_ + j);
      total.push_back(n + 3 * arm_ + j);
    }
    std::vector<int> zone(total.begin(), total.begin() + n);
    return {load, higher, zone, total};
  }
  bool example_parameters(const Eigen::VectorXd& c, double* p) const override {
    for (int j = 0; j < 5 && j < c.size(); ++j)
      set_parameter(p, "e" + std::to_string(j + 1), 0.5 * c(j));
    return true;
  }
  std::vector<std::string> experiment_hints() const override {
    return {effects::kHintLoadReversal, effects::kHintLoadLevel, effects::kHintGravityVariety};
  }
  std::string description() const override {
    return "nonlinear reducer: dtheta_j += e_j [phi(tau_g+tau_F) - phi(tau_g)] + w_j "
           "[psi(tau_g+tau_F) - psi(tau_g)] + s_j tau_F|tau_F|/T0 + a_j tau_F^2/T0 + h_j "
           "[(tau_g+tau_F)^3 - tau_g^3]/T0^2 + r_j [|tau_g+tau_F| - |tau_g|] + g_j tau_F^3/T0^2 "
           "+ k_j |tau_F| (arm joints), phi = T1 tanh(tau/T1), psi = 3 T1 tanh(tau/(3 T1)), T0 "
           "= 100 N*m: soft zones about zero torque (two knees), symmetric and asymmetric "
           "hardening or softening about the unloaded state and about the preload, a kinked "
           "curve; a fit keeps the terms the data support";
  }
  std::string reference() const override {
    return "Harmonic Drive AG, engineering data CSF/CSG (three-segment torque-torsion curve); "
           "Ruderman & Bertram, IFAC 2012 (nonlinear HD compliance); Nabtesco RV hysteresis "
           "curves";
  }
  unsigned requirements() const override { return kNeedsMasses; }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  bool linear() const override { return true; }

  template <typename T>
  void joint_t(const T* p, EvalState<T>& s) const {
    using std::abs;
    using std::tanh;
    const auto& tg = s.context->tau_gravity;
    const int n = static_cast<int>(s.dtheta.size());
    for (int j = 0; j < n; ++j) {
      const T t = s.tau(j);
      // The soft zone of knee T1 about zero torque, loaded minus unloaded (at the preload).
      auto zone = [&](double t1) {
        return T(t1) * tanh((T(tg(j)) + t) / T(t1)) - T(t1 * std::tanh(tg(j) / t1));
      };
      s.dtheta(j) += p[j] * zone(knee_[j]);
      if (j >= arm_) continue;
      s.dtheta(j) += p[n + 6 * arm_ + j] * zone(kWide * knee_[j]);
      s.dtheta(j) += (p[n + j] * abs(t) + p[n + arm_ + j] * t) * t / T(kT0);
      const T total = T(tg(j)) + t;
      const double g = tg(j);  // cubed by hand: std::pow would need a newer libm in the FMU
      s.dtheta(j) += p[n + 2 * arm_ + j] * (total * total * total - T(g * g * g)) / T(kT0 * kT0);
      s.dtheta(j) += p[n + 3 * arm_ + j] * (abs(total) - T(std::abs(g)));
      s.dtheta(j) += p[n + 4 * arm_ + j] * t * t * t / T(kT0 * kT0);
      s.dtheta(j) += p[n + 5 * arm_ + j] * abs(t);
    }
  }

 private:
  std::vector<double> knee_;
  int arm_ = 0;  ///< joints with second-order terms
  std::string name_ = "nonlinear_joint";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_nonlinear_joint_effect(const EffectSetup& s) {
  return std::make_unique<NonlinearJoint>(s);
}

}  // namespace stiff
