// harmonic: transmission errors periodic in the joint angle (absolute rows).
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// A reducer and its encoder mounting add an angle error periodic in the joint angle; its
/// first and second harmonics (eccentricity, ellipticity) are
///   theta_j = q_j + s1_j sin q_j + c1_j cos q_j + s2_j sin 2q_j + c2_j cos 2q_j.
/// The constant term is the joint offset (joint_offset). Acts on absolute rows.
class Harmonic : public EffectT<Harmonic> {
 public:
  explicit Harmonic(const EffectSetup& s) {
    const char* what[4] = {"s1_", "c1_", "s2_", "c2_"};
    const char* text[4] = {"sin q", "cos q", "sin 2q", "cos 2q"};
    for (int j = 0; j < s.robot->dof(); ++j)
      for (int k = 0; k < 4; ++k)
        params_.push_back(effects::parameter(
            what[k] + std::to_string(j + 1), "rad",
            "transmission error of joint " + std::to_string(j + 1) + ", " + text[k] + " term",
            -0.05, 0.05, 1e-4, 0.0, 0.0));
  }
  const std::string& name() const override { return name_; }
  std::string description() const override {
    return "transmission errors periodic in the joint angle, first and second harmonics "
           "(absolute data)";
  }
  std::string reference() const override {
    return "Whitney, Lozinski & Rourke, J. Dyn. Sys. Meas. Control 108(1), 1986 (gear "
           "transmission errors in calibration)";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  unsigned requirements() const override { return kNeedsAbsolute; }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    // Eccentricity of 0.1-0.2 mrad, ellipticity about half of it.
    static const double a[4] = {1.5e-4, -1e-4, 6e-5, -4e-5};
    for (int k = 0; k < size(); ++k) p[k] = a[k % 4] * (1.0 - 0.1 * (k / 4));
    return true;
  }
  std::vector<std::string> experiment_hints() const override {
    return {
        "each joint stepped over a full turn (or its range) with the others fixed: a "
        "periodic error repeats with the angle, a geometric one does not"};
  }

  bool has_absolute_columns() const override { return true; }
  void absolute_columns(const double* /*p*/,
                        const EvalState<double>& s,
                        const AbsoluteTangents& t,
                        double* out) const override {
    const Eigen::VectorXd& q = s.measurement->q;
    const int rows = t.rows();
    for (int j = 0; j < t.dq.cols(); ++j) {
      const double a = q(j);
      const double basis[4] = {std::sin(a), std::cos(a), std::sin(2 * a), std::cos(2 * a)};
      for (int k = 0; k < 4; ++k)
        Eigen::Map<Eigen::VectorXd>(out + rows * (4 * j + k), rows) = t.dq.col(j) * basis[k];
    }
  }

  template <typename T>
  void geometry_t(const T* p, EvalState<T>& s) const {
    const Eigen::VectorXd& q = s.measurement->q;
    for (int j = 0; j < s.dq.size(); ++j) {
      const double a = q(j);
      const T* c = p + 4 * j;
      s.dq(j) +=
          c[0] * std::sin(a) + c[1] * std::cos(a) + c[2] * std::sin(2 * a) + c[3] * std::cos(2 * a);
    }
  }

 private:
  std::string name_ = "harmonic";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_harmonic_effect(const EffectSetup& s) {
  return std::make_unique<Harmonic>(s);
}

}  // namespace stiff
