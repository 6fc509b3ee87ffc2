// joint_offset: zero offsets of the joint encoders (absolute rows).
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// The joint angle the kinematics see is the commanded one plus a constant offset per joint:
/// theta_j = q_j + dq_j (encoder zero, mastering error). Acts on absolute rows only: a
/// loaded-minus-unloaded difference does not see it to first order.
class JointOffset : public EffectT<JointOffset> {
 public:
  explicit JointOffset(const EffectSetup& s) {
    for (int j = 0; j < s.robot->dof(); ++j)
      params_.push_back(effects::parameter(
          "dq" + std::to_string(j + 1), "rad",
          "zero offset of joint " + std::to_string(j + 1) + " (encoder mastering)", -0.5, 0.5, 1e-3,
          0.0, 0.0));
  }
  const std::string& name() const override { return name_; }
  std::string description() const override {
    return "joint zero offsets: the kinematics use q_j + dq_j (absolute data)";
  }
  std::string reference() const override {
    return "Mooring, Roth & Driels, Fundamentals of Manipulator Calibration (1991), ch. 3";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  unsigned requirements() const override { return kNeedsAbsolute; }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    // Mastering errors of an industrial arm: a few tenths of a milliradian.
    static const double dq[6] = {4e-4, -6e-4, 3e-4, -5e-4, 7e-4, -2e-4};
    for (int j = 0; j < size(); ++j) p[j] = dq[j % 6];
    return true;
  }
  std::vector<std::string> experiment_hints() const override {
    return {
        "poses spread over each joint's whole range (a constant offset separates from the "
        "periodic transmission errors of `harmonic` only then)"};
  }

  bool has_absolute_columns() const override { return true; }
  void absolute_columns(const double* /*p*/,
                        const EvalState<double>& /*s*/,
                        const AbsoluteTangents& t,
                        double* out) const override {
    Eigen::Map<Eigen::MatrixXd>(out, t.rows(), t.dq.cols()) = t.dq;
  }

  template <typename T>
  void geometry_t(const T* p, EvalState<T>& s) const {
    for (int j = 0; j < s.dq.size(); ++j) s.dq(j) += p[j];
  }

 private:
  std::string name_ = "joint_offset";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_joint_offset_effect(const EffectSetup& s) {
  return std::make_unique<JointOffset>(s);
}

}  // namespace stiff
