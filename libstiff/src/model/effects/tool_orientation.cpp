// tool_orientation: rotation of a 6-D probe's frame on the flange (absolute rows with orientation).
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// A 6-D probe (T-Mac, 6-DoF target) reports its own frame, mounted on the flange with an
/// unknown rotation: R_probe = R_06 R(w) (rotation vector w, exact), the orientation the
/// instrument measures before its registration. With `tool` (the probe's origin) it is the
/// full tool frame. Only rows with a measured orientation see it: on position-only data the
/// identification holds it and names it (docs/identifiability.md). Started from the first
/// alignment (the mean rotation of the measured probe frames against the nominal flange's), so
/// that a probe mounted at any angle starts close.
class ToolOrientation : public EffectT<ToolOrientation> {
 public:
  explicit ToolOrientation(const EffectSetup& s) {
    Eigen::Vector3d start = Eigen::Vector3d::Zero();
    if (s.data && s.data->has_orientation) start = effects::alignment(*s.robot, *s.data).probe;
    const char* axis[3] = {"x", "y", "z"};
    for (int a = 0; a < 3; ++a)
      params_.push_back(effects::parameter(
          std::string("w_") + axis[a], "rad",
          std::string("rotation vector of the probe frame in the flange frame, ") + axis[a], -4.0,
          4.0, 1e-3, 0.0, start(a)));
  }
  const std::string& name() const override { return name_; }
  std::string description() const override {
    return "tool orientation: rotation of a 6-D probe's frame on the flange (absolute data with "
           "orientation)";
  }
  std::string reference() const override {
    return "Mooring, Roth & Driels, Fundamentals of Manipulator Calibration (1991), tool frame; "
           "Nubiola & Bonev, Robotics Comput.-Integr. Manuf. 29(1), 2013 (6-D measurements)";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  unsigned requirements() const override { return kNeedsAbsolute | kNeedsOrientation; }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    // A probe mounted with its axes a few degrees off the flange's.
    set_parameter(p, "w_x", 0.03);
    set_parameter(p, "w_y", -0.05);
    set_parameter(p, "w_z", 0.08);
    return true;
  }
  std::vector<std::string> experiment_hints() const override {
    return {
        "a 6-D probe (measured orientation): positions alone do not see how the probe's "
        "frame sits on the flange"};
  }

  bool has_absolute_columns() const override { return true; }
  void absolute_columns(const double* p,
                        const EvalState<double>& /*s*/,
                        const AbsoluteTangents& t,
                        double* out) const override {
    // R(w + dw) = R(w) Exp(J_r dw) turns the predicted orientation R as Exp(R J_r dw) R (the
    // probe's rotation is the last factor); positions do not see it.
    if (t.rows() < 6) return;
    const Eigen::Map<const Eigen::Vector3d> w(p);
    Eigen::Map<Eigen::Matrix<double, 6, 3>> c(out);
    c.bottomRows<3>() = t.turn * t.orientation * effects::right_jacobian(w);
  }

  template <typename T>
  void geometry_t(const T* p, EvalState<T>& s) const {
    if (s.oriented) s.probe = (s.probe * effects::rotation_matrix(p)).eval();
  }

 private:
  std::string name_ = "tool_orientation";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_tool_orientation_effect(const EffectSetup& s) {
  return std::make_unique<ToolOrientation>(s);
}

}  // namespace stiff
