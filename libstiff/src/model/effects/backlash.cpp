// backlash: lost motion of the reducers with a gravity preload (docs/effects.md).
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// A dead zone of width b_j: the gravity preload holds the gear against one flank; the load
/// traverses the gap only when it reverses the joint torque:
///   dtheta_j += b_j/2 [sgn(tau_g + tau_F) - sgn(tau_g)].
/// The sign is smoothed, sgn(x) ~ tanh(x / eps) with eps = 0.05 N*m (well below the load
/// torques of a test), so that the model has a derivative with respect to everything that
/// changes the torques (force frame, offsets). A joint without preload (tau_g = 0, e.g. a
/// vertical joint 1) jumps by b/2 sgn(tau_F): the mean over its unknown start in the gap.
class Backlash : public EffectT<Backlash> {
 public:
  explicit Backlash(const EffectSetup& s) {
    for (int j = 0; j < s.robot->dof(); ++j)
      params_.push_back(effects::parameter(
          "b" + std::to_string(j + 1), "rad",
          "backlash (lost motion) of joint " + std::to_string(j + 1) + ", full gap width", 0.0,
          0.05, 1.5e-4, 0.0, 0.0));
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
    return "backlash with gravity preload: dtheta_j += b_j/2 [sgn(tau_g+tau_F) - sgn(tau_g)] "
           "(smooth sign, eps 0.05 N*m); independent of the load level";
  }
  std::string reference() const override {
    return "Harmonic Drive / Nabtesco RV catalogues (lost motion <= 1 arcmin); FIGAROH "
           "(Thanh et al. 2023) backlash over position, gravity torque and direction";
  }
  unsigned requirements() const override { return kNeedsMasses; }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  bool linear() const override { return true; }

  static constexpr double kEps = 0.05;  ///< N*m

  template <typename T>
  void joint_t(const T* p, EvalState<T>& s) const {
    using std::tanh;
    const auto& tg = s.context->tau_gravity;
    for (int j = 0; j < s.dtheta.size(); ++j) {
      const T loaded = tanh((T(tg(j)) + s.tau(j)) / T(kEps));
      const T preload = T(std::tanh(tg(j) / kEps));
      s.dtheta(j) += T(0.5) * p[j] * (loaded - preload);
    }
  }

 private:
  std::string name_ = "backlash";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_backlash_effect(const EffectSetup& s) {
  return std::make_unique<Backlash>(s);
}

}  // namespace stiff
