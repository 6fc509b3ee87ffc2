// force_frame: orientation and scale errors of the force sensor (docs/effects.md).
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// The sensor reports the load in its own frame, mounted on the flange with a clocking error
/// omega (rotation about the flange axes) and per-axis gain errors s:
///   F_true = R_06 R(omega) diag(1 + s) R_06^T F_meas   (same for the moment).
/// A common scale (s_x = s_y = s_z) is exactly collinear with the joint compliances,
/// A(sF) c = A(F) (s c): no displacement data can see it, only an independent force
/// reference (dead weights). identify() then holds one scale at 0 and names the combination.
class ForceFrame : public EffectT<ForceFrame> {
 public:
  explicit ForceFrame(const EffectSetup&) {
    const char* axis[3] = {"x", "y", "z"};
    for (int k = 0; k < 3; ++k)
      params_.push_back(
          effects::parameter(std::string("omega_") + axis[k], "rad",
                             std::string("rotation of the force-sensor frame about the flange ") +
                                 axis[k] + " axis (clocking)",
                             -0.5, 0.5, 0.02, 0.0, 0.0));
    for (int k = 0; k < 3; ++k)
      params_.push_back(effects::parameter(
          std::string("scale_") + axis[k], "1",
          std::string("relative gain error of the force sensor's ") + axis[k] + " axis", -0.5, 0.5,
          0.02, 0.0, 0.0));
  }
  const std::string& name() const override { return name_; }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    set_parameter(p, "omega_x", 0.01);
    set_parameter(p, "omega_y", -0.01);
    set_parameter(p, "omega_z", 0.087);  // 5 deg clocking of the sensor
    set_parameter(p, "scale_x", 0.02);
    set_parameter(p, "scale_y", -0.01);
    return true;
  }
  std::string description() const override {
    return "force-sensor frame: clocking omega about the flange axes and per-axis gain s, F = "
           "R_06 R(omega) diag(1+s) R_06^T F_meas (a common gain is not identifiable)";
  }
  std::string reference() const override {
    return "OnRobot HEX-E/H datasheet (crosstalk < 5 %); docs/effects.md";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }

  template <typename T>
  void wrench_t(const T* p, EvalState<T>& s) const {
    const Matrix3<T> rf = effects::flange_rotation(s);
    const Matrix3<T> r = effects::rotation_matrix(p);
    Vector3<T> gain;
    for (int k = 0; k < 3; ++k) gain(k) = T(1) + p[3 + k];
    const Matrix3<T> map = rf * r * gain.asDiagonal() * rf.transpose();
    s.force = map * s.force;
    s.moment = map * s.moment;
  }

 private:
  std::string name_ = "force_frame";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_force_frame_effect(const EffectSetup& s) {
  return std::make_unique<ForceFrame>(s);
}

}  // namespace stiff
