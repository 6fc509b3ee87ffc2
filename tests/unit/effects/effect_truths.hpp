// Realistic true values of every effect on the paper's arm (effects-and-diagnosis.md, table of
// section 1 and section 3.1), shared by the effect and identification tests.
#pragma once

#include <cmath>
#include <string>

#include "stiff/model.hpp"
#include "stiff/simulate.hpp"
#include "test_support.hpp"

namespace stiff::test {

/// Truth "joint + effect" with the paper's joint stiffness and a representative effect size.
/// Parameters the data cannot see in a flange-centred set-up (joint 6 terms, the common force
/// scale) are left at their null value so that the identifiable ones are defined uniquely.
inline Truth effect_truth(const std::string& effect, const RobotModel& robot) {
  DeflectionModel m(robot, {"joint", effect == "joint" ? "complementary" : effect});
  Truth t;
  t.effects = {"joint", effect};
  t.theta = m.null_parameters();
  const Eigen::VectorXd c = paper_stiffness().cwiseInverse();
  t.theta.head(6) = c;
  const int o = m.offset(1);
  auto set = [&](const std::string& name, double v) {
    for (int k = 0; k < m.effects()[1]->size(); ++k)
      if (m.effects()[1]->parameters()[k].name == name) {
        t.theta(o + k) = v;
        return;
      }
    throw std::runtime_error("no parameter " + name);
  };
  if (effect == "joint") {
    t.effects = {"joint"};
    t.theta = t.theta.head(6).eval();
  } else if (effect == "complementary") {
    set("gamma", 1.0);
  } else if (effect == "link") {
    for (const auto& p : m.effects()[1]->parameters()) set(p.name, 1.0 / 3e5);  // k = 3e5 N*m/rad
  } else if (effect == "gravity_compensator") {
    set("alpha", 0.08 * c(1));
    set("beta", 0.05 * c(1));
  } else if (effect == "nonlinear_joint") {
    for (int j = 0; j < 5; ++j) set("e" + std::to_string(j + 1), 0.5 * c(j));
  } else if (effect == "backlash") {
    const double arcmin = M_PI / (180.0 * 60.0);
    set("b1", 0.3 * arcmin);
    for (int j = 1; j < 5; ++j) set("b" + std::to_string(j + 1), 0.5 * arcmin);
  } else if (effect == "coupling") {
    set("c23", 0.2 * std::sqrt(c(1) * c(2)));
    set("c34", 0.1 * std::sqrt(c(2) * c(3)));
    set("c45", 0.3 * std::sqrt(c(3) * c(4)));
  } else if (effect == "tracker_frame") {
    set("omega_x", 0.01);
    set("omega_y", -0.005);
    set("omega_z", 0.015);
  } else if (effect == "force_frame") {
    set("omega_x", 0.01);
    set("omega_y", -0.01);
    set("omega_z", 0.087);  // 5 deg clocking
    set("scale_x", 0.02);
    set("scale_y", -0.01);
  } else if (effect == "point_offset") {
    set("meas_x", 0.03);
    set("meas_y", -0.02);
    set("meas_z", 0.05);
    set("load_x", 0.04);
    set("load_y", 0.01);
    set("load_z", 0.06);
  } else if (effect == "tool_compliance") {
    set("s_xx", 2e-6);
    set("s_yy", 1.5e-6);
    set("s_zz", 0.5e-6);
    set("s_xy", 0.3e-6);
    set("s_xz", -0.2e-6);
    set("s_yz", 0.1e-6);
  } else if (effect == "drift") {
    set("offset_x", 5e-6);
    set("offset_y", -8e-6);
    set("offset_z", 3e-6);
    set("rate_x", 1e-7);
    set("rate_z", -5e-8);
  }
  return t;
}

/// The paper's 60-pose random design (loads 15-35 N per axis).
inline Dataset design60(uint64_t seed, int count = 60) {
  RandomDesignOptions o;
  o.count = count;
  o.seed = seed;
  return random_design(rokae(), o);
}

}  // namespace stiff::test
