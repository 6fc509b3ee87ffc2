// force_frame: orientation and scale errors of the force sensor (docs/effects.md).
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// Two physically common variants, both in the model so that the data chooses:
/// a sensor on the flange reports the load in its own frame, with a clocking error omega
/// (rotation about the flange axes) and per-axis gain errors s; a load applied through a
/// fixture (weights and pulleys, a cable to a load cell on the floor) has its direction and
/// gain errors fixed in the base frame (omega_b, s_b):
///   F_true = R(omega_b) diag(1 + s_b) R_06 R(omega) diag(1 + s) R_06^T F_meas  (and moment).
/// A common scale (s_x = s_y = s_z) is exactly collinear with the joint compliances,
/// A(sF) c = A(F) (s c): no displacement data can see it, only an independent force
/// reference (dead weights). identify() therefore holds one scale of each frame at 0 (the gains
/// are gauge parameters, ParameterSpec::gauge) and names the combination.
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
    for (int k = 0; k < 3; ++k) {
      params_.push_back(effects::parameter(
          std::string("scale_") + axis[k], "1",
          std::string("relative gain error of the force sensor's ") + axis[k] + " axis", -0.5, 0.5,
          0.02, 0.0, 0.0));
      params_.back().gauge = 1;  // the sensor's frame
    }
    for (int k = 0; k < 3; ++k)
      params_.push_back(
          effects::parameter(std::string("omega_base_") + axis[k], "rad",
                             std::string("rotation of the applied load about the base ") + axis[k] +
                                 " axis (fixture or load-cell alignment fixed in the base frame)",
                             -0.5, 0.5, 0.02, 0.0, 0.0));
    for (int k = 0; k < 3; ++k) {
      params_.push_back(effects::parameter(
          std::string("scale_base_") + axis[k], "1",
          std::string("relative gain error of the load along the base ") + axis[k] + " axis", -0.5,
          0.5, 0.02, 0.0, 0.0));
      params_.back().gauge = 2;  // the base frame
    }
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
    return "force frame: clocking omega and per-axis gain s of a flange sensor, direction "
           "omega_b and gain s_b of a load fixed in the base frame, F = R(omega_b) diag(1+s_b) "
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
    const Matrix3<T> rb = effects::rotation_matrix(p + 6);
    Vector3<T> gain_b;
    for (int k = 0; k < 3; ++k) gain_b(k) = T(1) + p[9 + k];
    const Matrix3<T> map = rb * gain_b.asDiagonal() * rf * r * gain.asDiagonal() * rf.transpose();
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
