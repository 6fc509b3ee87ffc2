// tracker_frame: misregistration of the laser tracker's frame (docs/effects.md).
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// The tracker reports displacements in its registered frame, which is off the robot base by a
/// small rotation omega: d_meas = R(omega) d (exact rotation, Rodrigues). A translation of the
/// frame cancels in the loaded-minus-unloaded difference.
class TrackerFrame : public EffectT<TrackerFrame> {
 public:
  explicit TrackerFrame(const EffectSetup&) {
    const char* axis[3] = {"x", "y", "z"};
    for (int k = 0; k < 3; ++k)
      params_.push_back(effects::parameter(
          std::string("omega_") + axis[k], "rad",
          std::string("rotation of the tracker frame about the base ") + axis[k] + " axis", -0.5,
          0.5, 0.01, 0.0, 0.0));
  }
  const std::string& name() const override { return name_; }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    set_parameter(p, "omega_x", 0.01);
    set_parameter(p, "omega_y", -0.005);
    set_parameter(p, "omega_z", 0.015);
    return true;
  }
  std::string description() const override {
    return "tracker frame misregistration: the measured displacement is rotated, d_meas = "
           "R(omega) d (1 deg gives 1.7 % of d)";
  }
  std::string reference() const override {
    return "Leica AT960 / AT500 user manuals (frame registration); Nubiola & Bonev, Robotics "
           "Comput.-Integr. Manuf. 29(1), 2013 (base-frame registration)";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }

  template <typename T>
  void measurement_t(const T* p, EvalState<T>& s) const {
    const Matrix3<T> r = effects::rotation_matrix(p);
    s.d = r * s.d;
    s.rot = r * s.rot;
    if (s.oriented) s.orientation = (r * s.orientation).eval();
  }

 private:
  std::string name_ = "tracker_frame";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_tracker_frame_effect(const EffectSetup& s) {
  return std::make_unique<TrackerFrame>(s);
}

}  // namespace stiff
