// Truths for the registry-driven tests: the paper's arm with each effect's own example values,
// shared by the effect and identification tests.
#pragma once

#include <Eigen/Geometry>
#include <cmath>
#include <random>
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

/// What the effect requires of the data (Effect::requirements).
inline unsigned requirements_of(const std::string& effect, const RobotModel& robot) {
  EffectSetup setup;
  setup.robot = &robot;
  return make_effect(effect, setup)->requirements();
}

/// The rows the effects act on: a design of loaded-minus-unloaded rows as it is, or, when an
/// effect acts on absolute rows only (kNeedsAbsolute), every row turned into an absolute row of
/// one tracker placement whose frame is the robot base (position: the nominal forward
/// kinematics of the measured point, the row's load kept), with a workshop's spread of
/// temperatures (14-26 deg C) when an effect needs them, and the nominal flange orientation as a
/// 6-D probe's when an effect needs orientations. A session column when one is needed.
inline Dataset data_for(const std::vector<std::string>& effects,
                        const RobotModel& robot,
                        Dataset data) {
  unsigned req = 0;
  for (const auto& e : effects) req |= requirements_of(e, robot);
  if (req & (kNeedsSessions | kNeedsAbsolute)) {
    data.has_session = true;
    for (auto& m : data.rows) m.session = "s1";
  }
  if (!(req & kNeedsAbsolute)) return data;
  data.has_position = true;
  data.has_temperature = true;
  for (size_t r = 0; r < data.rows.size(); ++r) {
    Measurement& m = data.rows[r];
    m.absolute = true;
    m.position = robot.point_position(robot.chain(m.q), robot.measured_point);
    m.temperature = 20.0 + 6.0 * std::sin(0.7 * static_cast<double>(r));
    if (req & kNeedsOrientation) {
      m.has_orientation = true;
      m.orientation = robot.chain(m.q).flange.topLeftCorner<3, 3>();
    }
  }
  data.has_orientation = (req & kNeedsOrientation) != 0;
  return data;
}
inline Dataset data_for(const std::string& effect, const RobotModel& robot, Dataset data) {
  return data_for(std::vector<std::string>{"joint", effect}, robot, std::move(data));
}

/// The virtual robot's measurements of a design: simulate() for loaded-minus-unloaded rows;
/// for effects that act on absolute rows only, the rows of data_for() with the truth's
/// predicted positions plus Gaussian tracker noise (per axis, noise.tracker_sigma_m) and, with
/// orientations, the predicted probe orientation turned by a noise of tracker_sigma_m per metre
/// [rad] per axis.
inline Dataset measure(const RobotModel& robot,
                       const Truth& truth,
                       const Dataset& design,
                       const NoiseModel& noise) {
  unsigned req = 0;
  for (const auto& e : truth.effects) req |= requirements_of(e, robot);
  if (!(req & kNeedsAbsolute)) return simulate(robot, truth, design, noise);
  Dataset data = data_for(truth.effects, robot, design);
  const DeflectionModel m(robot, truth.effects, &data);
  const auto ctx = m.contexts(data);
  std::mt19937_64 rng(noise.seed);
  std::normal_distribution<double> z(0.0, noise.tracker_sigma_m);
  for (size_t r = 0; r < data.rows.size(); ++r) {
    auto& row = data.rows[r];
    const Eigen::Matrix<double, 6, 1> p = m.predict(truth.theta, row, ctx[r]);
    row.position = p.head<3>();
    for (int a = 0; a < 3; ++a) row.position(a) += z(rng);
    if (row.has_orientation) {
      const Eigen::Vector3d w = p.tail<3>() + Eigen::Vector3d(z(rng), z(rng), z(rng));
      row.orientation = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
    }
  }
  return data;
}

/// The paper's 60-pose random design (loads 15-35 N per axis).
inline Dataset design60(uint64_t seed, int count = 60) {
  RandomDesignOptions o;
  o.count = count;
  o.seed = seed;
  return random_design(rokae(), o);
}

}  // namespace stiff::test
