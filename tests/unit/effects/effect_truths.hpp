// Truths for the registry-driven tests: the paper's arm with each effect's own example values,
// shared by the effect and identification tests.
#pragma once

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "stiff/model/model.hpp"
#include "stiff/sim/simulate.hpp"
#include "test_support.hpp"

namespace stiff::test {

/// Truth "joint + effect" with the paper's joint stiffness and the effect's own example
/// (Effect::example_parameters). An effect without an example is an error naming it: every
/// registered effect must give one, so that the registry-driven tests cover it.
inline Truth effect_truth(const std::string& effect, const RobotModel& robot) {
  const Eigen::VectorXd c = paper_stiffness().cwiseInverse();
  Truth t;
  if (effect == "joint") {
    t.effects = {"joint"};
    t.theta = c;
    return t;
  }
  DeflectionModel m(robot, {"joint", effect});
  t.effects = {"joint", effect};
  t.theta = m.null_parameters();
  t.theta.head(6) = c;
  if (!m.effects()[1]->example_parameters(c, t.theta.data() + m.offset(1)))
    throw std::runtime_error("effect '" + effect +
                             "' gives no example_parameters(): add one in its source file");
  return t;
}

/// Every registered effect but the joint compliance itself (which every model starts from).
inline std::vector<std::string> registered_effects() {
  std::vector<std::string> out;
  for (const auto& name : effect_names())
    if (name != "joint") out.push_back(name);
  return out;
}

/// The paper's 60-pose random design (loads 15-35 N per axis).
inline Dataset design60(uint64_t seed, int count = 60) {
  RandomDesignOptions o;
  o.count = count;
  o.seed = seed;
  return random_design(rokae(), o);
}

}  // namespace stiff::test
