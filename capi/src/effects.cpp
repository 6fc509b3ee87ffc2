// The effect registry through the C ABI.
#include <nlohmann/json.hpp>

#include "boundary.hpp"
#include "handles.hpp"

using namespace stiff;
using namespace stiff::capi;

namespace {
// A generic 6R arm with masses, used to describe effects when no robot is given.
RobotModel generic_arm() {
  RobotModel r;
  r.name = "generic 6R";
  const double a[6][3] = {{0, 0, 0.4},      {-M_PI / 2, 0.05, 0},
                          {0, 0.4, 0},      {-M_PI / 2, 0.03, 0.4},
                          {M_PI / 2, 0, 0}, {-M_PI / 2, 0, 0.1}};
  for (const auto& row : a) {
    Joint j = modified_dh_joint(row[0], row[1], row[2], 0.0);
    j.mass = 2.0;
    r.joints.push_back(j);
  }
  r.tool_mass = 1.0;
  return r;
}
}  // namespace

extern "C" {

size_t stiff_effect_count(void) { return effect_registry().size(); }

stiff_status stiff_effect_name(char* name, size_t capacity, size_t* needed, size_t index) {
  return guarded(__func__, [&] {
    const auto& reg = effect_registry();
    if (index >= reg.size())
      throw InvalidArgument("effect index " + std::to_string(index) + " out of range (" +
                            std::to_string(reg.size()) + " effects)");
    return copy_string(reg[index].name, name, capacity, needed);
  });
}

stiff_status stiff_effect_describe(
    char* json, size_t capacity, size_t* needed, const stiff_robot* robot, const char* name) {
  return guarded(__func__, [&] {
    require_string(name, "name");
    const RobotModel r = robot ? robot->model : generic_arm();
    EffectSetup setup;
    setup.robot = &r;
    auto e = make_effect(name, setup);
    nlohmann::json j;
    j["name"] = e->name();
    j["description"] = e->description();
    j["reference"] = e->reference();
    std::vector<std::string> needs;
    if (e->requirements() & kNeedsMasses) needs.push_back("masses");
    if (e->requirements() & kNeedsTime) needs.push_back("time");
    if (e->requirements() & kNeedsSessions) needs.push_back("sessions");
    if (e->requirements() & kNeedsAbsolute) needs.push_back("absolute");
    if (e->requirements() & kNeedsTemperature) needs.push_back("temperature");
    if (e->requirements() & kNeedsOrientation) needs.push_back("orientation");
    j["needs"] = needs;
    j["parameters"] = nlohmann::json::array();
    for (const auto& p : e->parameters())
      j["parameters"].push_back({{"name", p.name},
                                 {"unit", p.unit},
                                 {"meaning", p.meaning},
                                 {"lower", p.lower},
                                 {"upper", p.upper},
                                 {"typical", p.typical},
                                 {"null_value", p.null_value}});
    return copy_string(j.dump(), json, capacity, needed);
  });
}

}  // extern "C"
