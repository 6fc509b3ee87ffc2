// The effect registry: one line per effect. A new effect is one file in model/effects/ that
// defines make_<name>_effect, plus its name in STIFF_EFFECT_LIST here (docs/architecture.md).
#include <sstream>

#include "stiff/model/effects/common.hpp"

// clang-format off
#define STIFF_EFFECT_LIST(X) \
  X(joint) X(complementary) X(link) X(gravity_compensator) X(nonlinear_joint) X(backlash) \
  X(coupling) X(tracker_frame) X(force_frame) X(point_offset) X(tool_compliance) X(drift) \
  X(joint_offset) X(kinematic) X(registration) X(tool) X(gravity_lumped) X(harmonic) \
  X(thermal) X(tool_orientation)
// clang-format on

namespace stiff {

#define STIFF_DECLARE(name) std::unique_ptr<Effect> make_##name##_effect(const EffectSetup&);
STIFF_EFFECT_LIST(STIFF_DECLARE)
#undef STIFF_DECLARE

const std::vector<EffectEntry>& effect_registry() {
#define STIFF_ENTRY(name) EffectEntry{#name, &make_##name##_effect},
  static const std::vector<EffectEntry> registry = {STIFF_EFFECT_LIST(STIFF_ENTRY)};
#undef STIFF_ENTRY
  return registry;
}

std::vector<bool> Effect::common_terms() const {
  const std::vector<std::vector<int>> forms = sub_forms();
  std::vector<bool> common(static_cast<size_t>(size()), forms.empty());
  for (const auto& form : forms)
    for (int k : form) common[static_cast<size_t>(k)] = true;
  return common;
}

void Effect::set_parameter(double* p, const std::string& parameter, double value) const {
  for (int k = 0; k < size(); ++k)
    if (parameters()[static_cast<size_t>(k)].name == parameter) {
      p[k] = value;
      return;
    }
  throw InvalidArgument("effect '" + name() + "' has no parameter '" + parameter + "'");
}

std::vector<std::string> effect_names() {
  std::vector<std::string> n;
  for (const auto& e : effect_registry()) n.push_back(e.name);
  return n;
}

std::unique_ptr<Effect> make_effect(const std::string& name, const EffectSetup& setup) {
  for (const auto& e : effect_registry()) {
    if (name != e.name) continue;
    auto effect = e.factory(setup);
    const unsigned req = effect->requirements();
    if ((req & kNeedsMasses) && !setup.robot->has_masses())
      throw InvalidArgument(
          "effect '" + name + "' needs link masses (gravity torques), but robot '" +
          setup.robot->name + "' has none: add 'mass' and 'com' to its joints or a 'tool' mass");
    if ((req & kNeedsSessions) && setup.data && !setup.data->has_session)
      throw InvalidArgument("effect '" + name + "' needs a 'session' column in the data");
    return effect;
  }
  std::ostringstream known;
  for (const auto& e : effect_registry()) known << " " << e.name;
  throw InvalidArgument("unknown effect '" + name + "'; known effects:" + known.str());
}

}  // namespace stiff
