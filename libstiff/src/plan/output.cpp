// Plan file (measurement file without displacements) and JSON summary of a plan.
#include <cmath>
#include <nlohmann/json.hpp>
#include <sstream>

#include "io/number_text.hpp"
#include "stiff/plan/plan.hpp"

namespace stiff {
namespace {

using nlohmann::json;

/// Plan files: ten significant digits.
std::string num(double v) { return detail::num(v, 10); }

json number(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

json vec(const Eigen::VectorXd& v) {
  json a = json::array();
  for (int i = 0; i < v.size(); ++i) a.push_back(number(v(i)));
  return a;
}

}  // namespace

Dataset plan_to_dataset(const PlanResult& r) {
  Dataset d;
  d.has_id = true;
  d.extra_columns = {"fx_flange_N", "fy_flange_N", "fz_flange_N", "contribution"};
  for (const auto& m : r.measurements) {
    Measurement x;
    x.id = m.id;
    x.q = m.q_rad;
    x.force = m.force_base_N;
    x.extra = {num(m.force_flange_N(0)), num(m.force_flange_N(1)), num(m.force_flange_N(2)),
               num(m.contribution)};
    d.rows.push_back(x);
  }
  d.dof = r.measurements.empty() ? 0 : static_cast<int>(r.measurements.front().q_rad.size());
  d.set_meta("robot", r.robot);
  d.set_meta("source", "stiff plan");
  d.set_meta("criterion", r.criterion);
  d.set_meta("found_by", r.found_by);
  for (const auto& [k, v] : r.criteria) d.set_meta("criterion_" + k, num(v));
  d.set_meta("seed", std::to_string(r.seed));
  d.set_meta("pool", std::to_string(r.pool_poses) + " poses x " + std::to_string(r.pool_loads) +
                         " loads = " + std::to_string(r.pool_size) + " elements");
  d.set_meta("min_sigma_m", num(r.min_sigma_m));
  return d;
}

std::string plan_summary_json(const PlanResult& r) {
  json j;
  j["robot"] = r.robot;
  j["criterion"] = r.criterion;
  j["larger_is_better"] = r.larger_is_better;
  j["value"] = number(r.value);
  j["found_by"] = r.found_by;
  j["seed"] = r.seed;
  json c = json::object();
  for (const auto& [k, v] : r.criteria) c[k] = number(v);
  j["criteria"] = c;
  j["identified_joints"] = r.identified_joints;
  j["pool"] = {{"elements", r.pool_size},
               {"poses", r.pool_poses},
               {"loads", r.pool_loads},
               {"min_sigma_m", number(r.min_sigma_m)}};
  json tr = json::array();
  for (const auto& t : r.trace)
    tr.push_back({{"optimizer", t.optimizer},
                  {"start_score", number(t.start_score)},
                  {"best_score", number(t.best_score)},
                  {"best_value", number(t.best_value)},
                  {"iterations", t.iterations},
                  {"evaluations", t.evaluations},
                  {"accepted", t.accepted},
                  {"seconds", number(t.seconds)},
                  {"initial_temperature", number(t.initial_temperature)},
                  {"initial_swap_count", t.initial_swap_count},
                  {"message", t.message}});
  j["trace"] = tr;
  json ms = json::array();
  for (const auto& m : r.measurements)
    ms.push_back({{"id", m.id},
                  {"pool_element", m.pool_element},
                  {"q_rad", vec(m.q_rad)},
                  {"force_base_N", vec(m.force_base_N)},
                  {"force_flange_N", vec(m.force_flange_N)},
                  {"tool_position_m", vec(m.tool_position_m)},
                  {"contribution", number(m.contribution)},
                  {"criterion_drop", number(m.criterion_drop)}});
  j["measurements"] = ms;
  return j.dump(2);
}

}  // namespace stiff
