// drift: thermal drift / offset of robot and tracker between the unloaded and the loaded
// reading (docs/effects.md).
#include <map>

#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// Warm-up of robot and tracker adds to every loaded-minus-unloaded reading a term that does
/// not scale with the load: per session an offset b and a rate v,
///   d_meas = d + b + v (t - t0),
/// t the reading's time [s] (the row index when the data has no `t` column), t0 the session's
/// mean time in the data the model was built with (0 without data).
class Drift : public EffectT<Drift> {
 public:
  explicit Drift(const EffectSetup& s) {
    const int sessions = std::max(1, s.sessions);
    t0_.assign(sessions, 0.0);
    std::vector<std::string> labels(sessions);
    if (s.data) {
      std::map<std::string, int> index;
      std::vector<double> sum(sessions, 0.0);
      std::vector<int> count(sessions, 0);
      for (size_t r = 0; r < s.data->rows.size(); ++r) {
        const auto& m = s.data->rows[r];
        auto it = index.find(m.session);
        if (it == index.end()) {
          const int k = static_cast<int>(index.size());
          it = index.emplace(m.session, k).first;
          if (k < sessions) labels[k] = m.session;
        }
        const int k = it->second;
        if (k >= sessions) continue;
        const double t = s.data->has_time ? m.time : static_cast<double>(r);
        sum[k] += t;
        ++count[k];
      }
      for (int k = 0; k < sessions; ++k)
        if (count[k] > 0) t0_[k] = sum[k] / count[k];
    }
    const char* axis[3] = {"x", "y", "z"};
    for (int k = 0; k < sessions; ++k) {
      const std::string suffix = sessions > 1 ? "_s" + std::to_string(k + 1) : "";
      const std::string where =
          sessions > 1 ? " in session " + std::to_string(k + 1) + " ('" + labels[k] + "')" : "";
      for (int a = 0; a < 3; ++a)
        params_.push_back(effects::parameter(
            std::string("offset_") + axis[a] + suffix, "m",
            std::string("constant offset of the measured displacement, base ") + axis[a] + where,
            -0.01, 0.01, 5e-6, 0.0, 0.0));
      for (int a = 0; a < 3; ++a)
        params_.push_back(effects::parameter(
            std::string("rate_") + axis[a] + suffix, "m/s",
            std::string("drift rate of the measured displacement, base ") + axis[a] + where, -1e-3,
            1e-3, 1e-7, 0.0, 0.0));
    }
  }
  const std::string& name() const override { return name_; }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    set_parameter(p, "offset_x", 5e-6);
    set_parameter(p, "offset_y", -8e-6);
    set_parameter(p, "offset_z", 3e-6);
    set_parameter(p, "rate_x", 1e-7);
    set_parameter(p, "rate_z", -5e-8);
    return true;
  }
  std::vector<std::string> experiment_hints() const override {
    return {effects::kHintLoadReversal};
  }
  std::string description() const override {
    return "thermal drift: per session an offset and a linear rate in time, d += b + v (t - "
           "t0); does not scale with the load";
  }
  std::string reference() const override {
    return "Pollack Periodica (AT960-MR warm-up test); ISO 9283 (drift of pose "
           "characteristics); docs/effects.md";
  }
  unsigned requirements() const override { return kNeedsTime; }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  bool linear() const override { return true; }

  template <typename T>
  void measurement_t(const T* p, EvalState<T>& s) const {
    int k = s.context->session;
    if (k < 0 || k >= static_cast<int>(t0_.size())) k = 0;
    const T dt = T(s.context->time - t0_[k]);
    for (int a = 0; a < 3; ++a) s.d(a) += p[6 * k + a] + p[6 * k + 3 + a] * dt;
  }

 private:
  std::vector<double> t0_;
  std::string name_ = "drift";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_drift_effect(const EffectSetup& s) {
  return std::make_unique<Drift>(s);
}

}  // namespace stiff
