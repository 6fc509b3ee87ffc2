// complementary: load-dependent geometric stiffness (conservative congruence transformation,
// docs/effects.md) plus the forward-kinematics curvature of the same order.
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// Equilibrium under load is K dtheta = J(q + dtheta)^T W, i.e. (K - K_g) dtheta = J^T W with
/// K_g = d(J(q)^T W)/dq. To second order in the deflection the displacement gains
///   d2 = J_p C K_g dtheta + 1/2 sum_ij dtheta_i dtheta_j d^2 p/(dq_i dq_j),
/// both scaled by gamma (1 = physics, 0 = effect off). K_g and the FK Hessian are analytic:
/// for revolute joints dJ_j/dq_i = z_i x J_j (i <= j) and z_j x J_i (i > j).
class Complementary : public EffectT<Complementary> {
 public:
  explicit Complementary(const EffectSetup&) {
    params_.push_back(effects::parameter(
        "gamma", "1",
        "scale of the second-order (geometric) stiffness terms J C K_g dtheta + 1/2 dtheta^T H "
        "dtheta; 1 = the physical value",
        -1e3, 1e3, 1.0, 0.0, 1.0));
  }
  const std::string& name() const override { return name_; }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    set_parameter(p, "gamma", 1.0);
    return true;
  }
  std::vector<std::string> experiment_hints() const override {
    return {effects::kHintLoadReversal, effects::kHintLoadLevel};
  }
  std::string description() const override {
    return "complementary (geometric) stiffness K_g = d(J^T F)/dq under load: d += gamma (J C "
           "K_g dtheta + 1/2 dtheta^T H_p dtheta); grows with the load squared";
  }
  std::string reference() const override {
    return "Chen & Kao, Int. J. Robotics Research 19(9), 2000 (conservative congruence "
           "transformation); Alici & Shirinzadeh, IEEE T-RO 21(4), 2005";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  bool reads_jacobians() const override { return true; }

  template <typename T>
  void cartesian_t(const T* p, EvalState<T>& s) const {
    const int n = static_cast<int>(s.dtheta.size());
    if (s.compliance.size() != n) return;  // needs the joint effect's compliances
    const auto& chain = s.context->chain;
    // Extra joint torque K_g dtheta from the change of geometry under the deflection.
    VectorX<T> dtau = VectorX<T>::Zero(n);
    for (int j = 0; j < n; ++j) {
      const Vector3<T> zj = chain.axis.col(j).template cast<T>();
      const Vector3<T> jl_j = s.jac_load.template block<3, 1>(0, j);
      for (int i = 0; i < n; ++i) {
        const Vector3<T> zi = chain.axis.col(i).template cast<T>();
        T kg;
        if (i <= j) {
          kg = zi.cross(jl_j).dot(s.force) + zi.cross(zj).dot(s.moment);
        } else {
          const Vector3<T> jl_i = s.jac_load.template block<3, 1>(0, i);
          kg = zj.cross(jl_i).dot(s.force);
        }
        dtau(j) += kg * s.dtheta(i);
      }
    }
    VectorX<T> dth2(n);
    for (int j = 0; j < n; ++j) dth2(j) = p[0] * s.compliance(j) * dtau(j);
    // Curvature of the forward kinematics: 1/2 sum_ij dtheta_i dtheta_j dJ_j(P)/dq_i.
    Vector3<T> h = Vector3<T>::Zero();
    for (int i = 0; i < n; ++i) {
      const Vector3<T> zi = chain.axis.col(i).template cast<T>();
      Vector3<T> inner = T(0.5) * s.dtheta(i) * s.jac_meas.template block<3, 1>(0, i);
      for (int j = i + 1; j < n; ++j) inner += s.dtheta(j) * s.jac_meas.template block<3, 1>(0, j);
      h += s.dtheta(i) * zi.cross(inner);
    }
    s.d += s.jac_meas.template topRows<3>() * dth2 + p[0] * h;
    s.rot += s.jac_meas.template bottomRows<3>() * dth2;
  }

 private:
  std::string name_ = "complementary";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_complementary_effect(const EffectSetup& s) {
  return std::make_unique<Complementary>(s);
}

}  // namespace stiff
