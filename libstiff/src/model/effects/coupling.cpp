// coupling: symmetric off-diagonal joint compliance of adjacent joints
// (docs/effects.md).
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// C is symmetric with entries c_{j,j+1} for adjacent joints (wrist gear trains, parallelogram
/// drives, bearing tilt): dtheta_j += c_{j,j+1} tau_{j+1}, dtheta_{j+1} += c_{j,j+1} tau_j.
/// A physical C is positive definite, |c_{j,j+1}| < sqrt(c_j c_{j+1}); the fit does not
/// enforce it (check rho = c_{j,j+1} / sqrt(c_j c_{j+1}) in the result).
class Coupling : public EffectT<Coupling> {
 public:
  explicit Coupling(const EffectSetup& s) {
    for (int j = 0; j + 1 < s.robot->dof(); ++j) {
      const std::string a = std::to_string(j + 1), b = std::to_string(j + 2);
      params_.push_back(effects::parameter(
          "c" + a + b, "rad/(N*m)",
          "coupling compliance of joints " + a + " and " + b + " (torque on one turns the other)",
          -1e-2, 1e-2, 3e-6, 0.0, 0.0));
    }
  }
  const std::string& name() const override { return name_; }
  bool example_parameters(const Eigen::VectorXd& c, double* p) const override {
    set_parameter(p, "c23", 0.2 * std::sqrt(c(1) * c(2)));
    set_parameter(p, "c34", 0.1 * std::sqrt(c(2) * c(3)));
    set_parameter(p, "c45", 0.3 * std::sqrt(c(3) * c(4)));
    return true;
  }
  std::string description() const override {
    return "joint coupling: symmetric off-diagonal compliance c_{j,j+1} of adjacent joints "
           "(torque on joint j deflects joint j+1)";
  }
  std::string reference() const override {
    return "Oliveira & Trabasso (symmetric positive-definite joint stiffness identification); "
           "Abele et al., CIRP Annals 56(1), 2007";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  bool linear() const override { return true; }

  template <typename T>
  void joint_t(const T* p, EvalState<T>& s) const {
    const VectorX<T> tau = s.tau;
    for (int j = 0; j + 1 < s.dtheta.size(); ++j) {
      s.dtheta(j) += p[j] * tau(j + 1);
      s.dtheta(j + 1) += p[j] * tau(j);
    }
  }

 private:
  std::string name_ = "coupling";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_coupling_effect(const EffectSetup& s) {
  return std::make_unique<Coupling>(s);
}

}  // namespace stiff
