/// \file sampling.hpp
/// Random joint poses and loads: the one sampler behind the random design of the virtual
/// robot, the planner's candidate pool and the studies built on them.
#pragma once

#include <vector>

#include "stiff/kinematics/robot_model.hpp"
#include "stiff/random.hpp"

namespace stiff {

/// A pose uniform in the centred `range_fraction` of each joint's range; `q_fixed` (empty, or
/// one value per joint, NaN = free) holds joints at a value. Draws one number per free joint.
Eigen::VectorXd random_joint_pose(const RobotModel& robot,
                                  double range_fraction,
                                  const std::vector<double>& q_fixed,
                                  Rng& rng);

/// The signed per-axis load values of a grid: every multiple of step_N in [min_N, max_N] with
/// both signs (0 once), ascending. Empty when no multiple lies in the range.
std::vector<double> signed_load_grid(double min_N, double max_N, double step_N);

/// A load component [N]: from `grid` when it is not empty (uniform over its values), else a
/// magnitude uniform in [min_N, max_N] with a random sign.
double random_load_component(double min_N, double max_N, const std::vector<double>& grid, Rng& rng);

}  // namespace stiff
