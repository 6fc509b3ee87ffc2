// drift: thermal drift / offset of robot and tracker between the unloaded and the loaded
// reading (docs/effects.md).
#include <map>

#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// Warm-up of robot and tracker adds to every loaded-minus-unloaded reading a term that does
/// not scale with the load: per session an offset b and a rate v,
///   d_meas = d + b + v t,
/// t the reading's time since the session's first reading in the data (the row order when the
/// data has no `t` column; DeflectionModel::contexts): b is the offset at the start of the
/// session, and a new session (a validation file) restarts the warm-up.
class Drift : public EffectT<Drift> {
 public:
  explicit Drift(const EffectSetup& s) {
    const int sessions = std::max(1, s.sessions);
    sessions_ = sessions;
    std::vector<std::string> labels(sessions);
    if (s.data) {
      std::map<std::string, int> index;
      for (const auto& m : s.data->rows) {
        if (index.count(m.session)) continue;
        const int k = static_cast<int>(index.size());
        index.emplace(m.session, k);
        if (k < sessions) labels[k] = m.session;
      }
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
    // Offset and rate belong to the session's warm-up, not to the robot: a session the fit has
    // not seen has its own (ParameterSpec::per_session).
    for (auto& p : params_) p.per_session = true;
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
    return "thermal drift: per session an offset and a linear rate in time, d += b + v t (t "
           "since the session's first reading); does not scale with the load";
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
    if (k < 0 || k >= sessions_) k = 0;
    const T dt = T(s.context->time);
    for (int a = 0; a < 3; ++a) s.d(a) += p[6 * k + a] + p[6 * k + 3 + a] * dt;
  }

 private:
  int sessions_ = 1;
  std::string name_ = "drift";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_drift_effect(const EffectSetup& s) {
  return std::make_unique<Drift>(s);
}

}  // namespace stiff
