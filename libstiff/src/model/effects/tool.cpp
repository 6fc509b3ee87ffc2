// tool: position of the measured target on the flange.
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// The target (SMR, probe) sits at r_P + dr in the flange frame, dr unknown: it moves every
/// absolute position by R_06 dr and every lever arm of a displacement row. Started, on
/// absolute data, from the first alignment of the nominal robot.
class Tool : public EffectT<Tool> {
 public:
  explicit Tool(const EffectSetup& s) {
    Eigen::Vector3d start = Eigen::Vector3d::Zero();
    if (s.data && s.data->absolute_rows() > 0)
      start = effects::alignment(*s.robot, *s.data).point_offset;
    const char* axis[3] = {"x", "y", "z"};
    for (int a = 0; a < 3; ++a)
      params_.push_back(effects::parameter(
          std::string("r_") + axis[a], "m",
          std::string("offset of the measured target from the robot file's point, flange ") +
              axis[a],
          -2.0, 2.0, 1e-3, start(a), start(a)));
  }
  const std::string& name() const override { return name_; }
  std::string description() const override {
    return "tool: offset of the measured target from its nominal position on the flange";
  }
  std::string reference() const override {
    return "Mooring, Roth & Driels, Fundamentals of Manipulator Calibration (1991), tool frame";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  // On loaded-minus-unloaded rows alone its offset is point_offset's measured point.
  unsigned requirements() const override { return kNeedsAbsolute; }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    // A target nest mounted a few centimetres off the nominal point.
    set_parameter(p, "r_x", 0.02);
    set_parameter(p, "r_y", -0.015);
    set_parameter(p, "r_z", 0.03);
    return true;
  }
  std::vector<std::string> experiment_hints() const override {
    return {
        "the same target position reached with different flange orientations (the offset "
        "turns with the flange, axis errors of the arm do not)"};
  }

  template <typename T>
  void wrench_t(const T* p, EvalState<T>& s) const {
    for (int a = 0; a < 3; ++a) s.r_meas(a) += p[a];
  }

 private:
  std::string name_ = "tool";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_tool_effect(const EffectSetup& s) { return std::make_unique<Tool>(s); }

}  // namespace stiff
