// thermal: uniform thermal expansion of the arm from the temperature column (absolute rows).
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// Every link length (and the target's offset) grows by alpha (T - T_ref): a uniform scaling
/// of all translations of the chain, which scales the position of P about the base origin,
/// p -> (1 + alpha (T - T_ref)) p, rotations unchanged. T_ref = 20 deg C, the reference
/// temperature of dimensional metrology (ISO 1). Added in the cartesian stage as
/// alpha (T - T_ref) p (first order: alpha dT ~ 1e-4). Needs the `temp` column.
class Thermal : public EffectT<Thermal> {
 public:
  explicit Thermal(const EffectSetup& s) {
    if (s.data && s.data->absolute_rows() > 0 && !s.data->has_temperature)
      throw InvalidArgument("effect 'thermal' needs a 'temp' column (deg C) in the data");
    params_.push_back(effects::parameter(
        "alpha", "1/K", "linear thermal expansion coefficient of the arm (aluminium 2.3e-5)", -1e-3,
        1e-3, 1e-5, 0.0, 0.0));
  }
  const std::string& name() const override { return name_; }
  std::string description() const override {
    return "uniform thermal expansion of the arm: p -> (1 + alpha (T - 20 C)) p (absolute "
           "data with a temp column)";
  }
  std::string reference() const override {
    return "ISO 1:2016 (reference temperature 20 C); Mooring, Roth & Driels (1991)";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  unsigned requirements() const override { return kNeedsAbsolute | kNeedsTemperature; }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    p[0] = 2.3e-5;  // aluminium links
    return true;
  }
  std::vector<std::string> experiment_hints() const override {
    return {
        "the same poses measured cold and after a warm-up run (a scale change with "
        "temperature, not a fixed geometric error)"};
  }

  template <typename T>
  void cartesian_t(const T* p, EvalState<T>& s) const {
    if (!s.measurement->absolute) return;
    const T e = p[0] * T(s.measurement->temperature - kReference);
    s.d += e * s.p_meas;
  }

 private:
  static constexpr double kReference = 20.0;  // [deg C]
  std::string name_ = "thermal";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_thermal_effect(const EffectSetup& s) {
  return std::make_unique<Thermal>(s);
}

}  // namespace stiff
