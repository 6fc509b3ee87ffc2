// point_offset: measured point (SMR) and load point away from the flange centre
// (docs/effects.md).
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// The measured point P and the load point L sit at r_m and r_l (flange frame) from where the
/// robot file puts them: P = p6 + R_06 (r_P + r_m), L = p6 + R_06 (r_L + r_l). The lever arms
/// change every Jacobian column; joint 6 becomes visible through the joint effect, its term
/// c6 (z6 x R_06 r_m)(z6 . (R_06 r_l x F)) being second order in the offsets (identify() frees
/// c6 once the offsets are known).
class PointOffset : public EffectT<PointOffset> {
 public:
  explicit PointOffset(const EffectSetup&) {
    const char* axis[3] = {"x", "y", "z"};
    for (int k = 0; k < 3; ++k)
      params_.push_back(effects::parameter(
          std::string("meas_") + axis[k], "m",
          std::string("offset of the measured point (SMR) from its nominal position, flange ") +
              axis[k],
          -0.5, 0.5, 0.03, 0.0, 0.0));
    for (int k = 0; k < 3; ++k)
      params_.push_back(effects::parameter(
          std::string("load_") + axis[k], "m",
          std::string("offset of the load point from its nominal position, flange ") + axis[k],
          -0.5, 0.5, 0.03, 0.0, 0.0));
  }
  const std::string& name() const override { return name_; }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    set_parameter(p, "meas_x", 0.03);
    set_parameter(p, "meas_y", -0.02);
    set_parameter(p, "meas_z", 0.05);
    set_parameter(p, "load_x", 0.04);
    set_parameter(p, "load_y", 0.01);
    set_parameter(p, "load_z", 0.06);
    return true;
  }
  std::string description() const override {
    return "offset of the measured point and of the load point from the flange axis (flange "
           "frame): changes every lever arm and makes joint 6 visible";
  }
  std::string reference() const override {
    return "docs/effects.md; Jiang & Fang 2023 (SMR on the flange "
           "axis leaves joint 6 unidentified)";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }

  template <typename T>
  void wrench_t(const T* p, EvalState<T>& s) const {
    for (int k = 0; k < 3; ++k) {
      s.r_meas(k) += p[k];
      s.r_load(k) += p[3 + k];
    }
  }

 private:
  std::string name_ = "point_offset";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_point_offset_effect(const EffectSetup& s) {
  return std::make_unique<PointOffset>(s);
}

}  // namespace stiff
