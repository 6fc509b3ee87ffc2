// nonlinear_joint: hardening torque-torsion curve of strain-wave / cycloidal reducers, measured
// as a secant about the gravity preload (docs/effects.md).
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// theta_j(tau) = c_j tau + e_j T1_j tanh(tau / T1_j): below the knee torque T1 the reducer is
/// softer by e_j (catalogue K1 < K3). The loaded-minus-unloaded reading is a secant about the
/// gravity preload tau_g, so dtheta_j += e_j [phi(tau_g + tau_F) - phi(tau_g)],
/// phi = T1 tanh(./T1). T1 is the catalogue knee torque, fixed: 10 N*m for the arm joints and
/// 2 N*m for the last three (wrist) joints, which is harmonic-drive size 25 / 14 class.
class NonlinearJoint : public EffectT<NonlinearJoint> {
 public:
  explicit NonlinearJoint(const EffectSetup& s) {
    const int n = s.robot->dof();
    for (int j = 0; j < n; ++j) {
      knee_.push_back(j < n - 3 || n <= 3 ? 10.0 : 2.0);
      params_.push_back(effects::parameter("e" + std::to_string(j + 1), "rad/(N*m)",
                                           "extra compliance of joint " + std::to_string(j + 1) +
                                               " at small torque (soft zone of the reducer, knee " +
                                               std::to_string(static_cast<int>(knee_.back())) +
                                               " N*m)",
                                           0.0, 1e-2, 1e-5, 0.0, 0.0));
    }
  }
  const std::string& name() const override { return name_; }
  bool example_parameters(const Eigen::VectorXd& c, double* p) const override {
    for (int j = 0; j < 5 && j < c.size(); ++j)
      set_parameter(p, "e" + std::to_string(j + 1), 0.5 * c(j));
    return true;
  }
  std::vector<std::string> experiment_hints() const override {
    return {effects::kHintLoadReversal, effects::kHintLoadLevel, effects::kHintGravityVariety};
  }
  std::string description() const override {
    return "hardening reducer: dtheta_j += e_j [phi(tau_g+tau_F) - phi(tau_g)], phi = T1 "
           "tanh(tau/T1); soft near zero torque, stiff when preloaded by gravity";
  }
  std::string reference() const override {
    return "Harmonic Drive AG, engineering data CSF/CSG (three-segment torque-torsion curve); "
           "Ruderman & Bertram, IFAC 2012 (nonlinear HD compliance)";
  }
  unsigned requirements() const override { return kNeedsMasses; }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  bool linear() const override { return true; }

  template <typename T>
  void joint_t(const T* p, EvalState<T>& s) const {
    using std::tanh;
    const auto& tg = s.context->tau_gravity;
    for (int j = 0; j < s.dtheta.size(); ++j) {
      const double t1 = knee_[j];
      const T loaded = T(t1) * tanh((T(tg(j)) + s.tau(j)) / T(t1));
      const T preload = T(t1 * std::tanh(tg(j) / t1));
      s.dtheta(j) += p[j] * (loaded - preload);
    }
  }

 private:
  std::vector<double> knee_;
  std::string name_ = "nonlinear_joint";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_nonlinear_joint_effect(const EffectSetup& s) {
  return std::make_unique<NonlinearJoint>(s);
}

}  // namespace stiff
