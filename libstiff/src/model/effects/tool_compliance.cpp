// tool_compliance: series compliance of the force sensor and tooling between flange and SMR
// (docs/effects.md).
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// A constant symmetric translational compliance S of the tooling, in the flange frame:
/// d += R_06 S R_06^T F. S positive semi-definite (diagonal >= 0 enforced, off-diagonal free).
/// An optical sensor such as the OnRobot HEX-E deflects ~8 um/N; it matters when the SMR is on
/// the tool side of the sensor.
class ToolCompliance : public EffectT<ToolCompliance> {
 public:
  explicit ToolCompliance(const EffectSetup&) {
    const char* names[6] = {"s_xx", "s_yy", "s_zz", "s_xy", "s_xz", "s_yz"};
    for (int k = 0; k < 6; ++k)
      params_.push_back(effects::parameter(names[k], "m/N",
                                           std::string("tool-frame compliance entry ") +
                                               (names[k] + 2) +
                                               " of the sensor/tooling (flange frame)",
                                           k < 3 ? 0.0 : -1e-3, 1e-3, 1e-6, 0.0, 0.0));
  }
  const std::string& name() const override { return name_; }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    set_parameter(p, "s_xx", 2e-6);
    set_parameter(p, "s_yy", 1.5e-6);
    set_parameter(p, "s_zz", 0.5e-6);
    set_parameter(p, "s_xy", 0.3e-6);
    set_parameter(p, "s_xz", -0.2e-6);
    set_parameter(p, "s_yz", 0.1e-6);
    return true;
  }
  std::vector<std::string> experiment_hints() const override { return {effects::kHintLoadLevel}; }
  std::string description() const override {
    return "series compliance of sensor and tooling: d += R_06 S R_06^T F, S symmetric 3x3 in "
           "the flange frame";
  }
  std::string reference() const override {
    return "OnRobot HEX-E datasheet (deflection at nominal load); docs/effects.md";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  bool linear() const override { return true; }

  template <typename T>
  void cartesian_t(const T* p, EvalState<T>& s) const {
    Matrix3<T> m;
    m << p[0], p[3], p[4], p[3], p[1], p[5], p[4], p[5], p[2];
    const Matrix3<T> rf = effects::flange_rotation(s);
    s.d += rf * (m * (rf.transpose() * s.force));
  }

 private:
  std::string name_ = "tool_compliance";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_tool_compliance_effect(const EffectSetup& s) {
  return std::make_unique<ToolCompliance>(s);
}

}  // namespace stiff
