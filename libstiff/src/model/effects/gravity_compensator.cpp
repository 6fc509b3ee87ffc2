// gravity_compensator: configuration-dependent compliance of the joint carrying a gravity
// compensator spring (docs/effects.md).
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// A compensator spring between link 1 and link 2 adds a tangent stiffness k_gc(q2) to joint 2
/// that depends on q2 through the spring's geometry. Without that geometry the library uses
/// its Fourier series to second order:
///   c2(q2) = c2 + alpha cos q2 + beta sin q2 + alpha2 cos 2q2 + beta2 sin 2q2,
/// i.e. dtheta_2 += (...) tau_2. The spring's tangent stiffness has a sin^2(phi) term and the
/// 1/l^3 of its length (second and higher harmonics), and the joint's compliance is
/// 1/(k2 + k_gc), whose expansion adds k_gc^2 (second harmonics again); the second-harmonic
/// terms are optional (ParameterSpec::optional_term): a fit keeps them only when the data
/// support them. Joint 2 (the shoulder) by default.
class GravityCompensator : public EffectT<GravityCompensator> {
 public:
  explicit GravityCompensator(const EffectSetup& s) : joint_(s.robot->dof() >= 2 ? 1 : 0) {
    const std::string j = std::to_string(joint_ + 1);
    params_.push_back(effects::parameter("alpha", "rad/(N*m)",
                                         "cos(q" + j + ") part of the compliance of joint " + j,
                                         -1e-2, 1e-2, 3e-6, 0.0, 0.0));
    params_.push_back(effects::parameter("beta", "rad/(N*m)",
                                         "sin(q" + j + ") part of the compliance of joint " + j,
                                         -1e-2, 1e-2, 3e-6, 0.0, 0.0));
    for (const char* f : {"cos", "sin"}) {
      ParameterSpec p =
          effects::parameter(std::string(f[0] == 'c' ? "alpha2" : "beta2"), "rad/(N*m)",
                             std::string(f) + "(2 q" + j + ") part of the compliance of joint " + j,
                             -1e-2, 1e-2, 3e-6, 0.0, 0.0);
      p.optional_term = true;
      params_.push_back(p);
    }
  }
  const std::string& name() const override { return name_; }
  bool example_parameters(const Eigen::VectorXd& c, double* p) const override {
    set_parameter(p, "alpha", 0.08 * c(1));
    set_parameter(p, "beta", 0.05 * c(1));
    return true;
  }
  std::vector<std::string> experiment_hints() const override {
    return {effects::kHintGravityVariety};
  }
  std::string description() const override {
    return "gravity compensator spring: joint-2 compliance varies with q2, c2(q2) = c2 + alpha "
           "cos q2 + beta sin q2 (+ alpha2 cos 2q2 + beta2 sin 2q2 when the data support them)";
  }
  std::string reference() const override {
    return "Klimchik et al., arXiv:1311.6810 and 1311.6674 (2013), stiffness of manipulators "
           "with gravity compensators";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  bool linear() const override { return true; }

  template <typename T>
  void joint_t(const T* p, EvalState<T>& s) const {
    using std::cos;
    using std::sin;
    const double q = s.measurement->q(joint_);
    s.dtheta(joint_) +=
        (p[0] * T(cos(q)) + p[1] * T(sin(q)) + p[2] * T(cos(2 * q)) + p[3] * T(sin(2 * q))) *
        s.tau(joint_);
  }

 private:
  int joint_;
  std::string name_ = "gravity_compensator";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_gravity_compensator_effect(const EffectSetup& s) {
  return std::make_unique<GravityCompensator>(s);
}

}  // namespace stiff
