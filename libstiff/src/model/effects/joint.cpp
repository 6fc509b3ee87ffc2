// joint: diagonal joint compliance, the paper's model (Jiang & Fang 2023).
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

class JointCompliance : public EffectT<JointCompliance> {
 public:
  explicit JointCompliance(const EffectSetup& s) {
    for (int j = 0; j < s.robot->dof(); ++j) {
      ParameterSpec p;
      p.name = "c" + std::to_string(j + 1);
      p.unit = "rad/(N*m)";
      p.meaning = "compliance 1/k of joint " + std::to_string(j + 1) +
                  " (reducer and drive torsion under the external joint torque)";
      p.lower = 0.0;
      p.upper = 1e-2;
      p.typical = 1e-5;
      p.null_value = 0.0;
      p.start = 1e-5;
      params_.push_back(p);
    }
  }
  const std::string& name() const override { return name_; }
  bool example_parameters(const Eigen::VectorXd& c, double* p) const override {
    for (int j = 0; j < static_cast<int>(c.size()) && j < size(); ++j) p[j] = c(j);
    return true;
  }
  std::string description() const override {
    return "diagonal joint compliance: dtheta_j = c_j tau_j (the paper's model)";
  }
  std::string reference() const override {
    return "Salisbury (1980); Jiang & Fang, Trans. CSAM 54(1), 2023, eqs. 1-5";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  bool linear() const override { return true; }
  bool has_displacement_derivatives() const override { return true; }
  void displacement_derivatives(const EvalState<double>& s, double* out) const override {
    // dtheta_j = c_j tau_j moves P along column j of J_p(P).
    for (int j = 0; j < static_cast<int>(s.tau.size()); ++j)
      for (int k = 0; k < 3; ++k) out[3 * j + k] = s.jac_meas(k, j) * s.tau(j);
  }

  template <typename T>
  void joint_t(const T* c, EvalState<T>& s) const {
    const int n = static_cast<int>(s.dtheta.size());
    s.compliance.resize(n);
    for (int j = 0; j < n; ++j) {
      s.dtheta(j) += c[j] * s.tau(j);
      s.compliance(j) = c[j];
    }
  }

 private:
  std::string name_ = "joint";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_joint_effect(const EffectSetup& s) {
  return std::make_unique<JointCompliance>(s);
}

}  // namespace stiff
