#include "stiff/kinematics/sampling.hpp"

#include <cmath>

namespace stiff {

Eigen::VectorXd random_joint_pose(const RobotModel& robot,
                                  double range_fraction,
                                  const std::vector<double>& q_fixed,
                                  Rng& rng) {
  const int n = robot.dof();
  Eigen::VectorXd q(n);
  for (int j = 0; j < n; ++j) {
    const Joint& jt = robot.joints[j];
    const double mid = 0.5 * (jt.lower + jt.upper);
    const double half = 0.5 * (jt.upper - jt.lower) * range_fraction;
    const double fixed = q_fixed.empty() ? NAN : q_fixed[j];
    q(j) = std::isnan(fixed) ? rng.uniform(mid - half, mid + half) : fixed;
  }
  return q;
}

std::vector<double> signed_load_grid(double min_N, double max_N, double step_N) {
  std::vector<double> negative, positive;
  // The 1e-9 keeps a bound that is a multiple of the step (35 N on a 5 N grid) in the grid.
  const long first = static_cast<long>(std::ceil(min_N / step_N - 1e-9));
  const long last = static_cast<long>(std::floor(max_N / step_N + 1e-9));
  for (long k = first; k <= last; ++k) {
    const double v = static_cast<double>(k) * step_N;
    positive.push_back(v);
    if (v != 0) negative.insert(negative.begin(), -v);
  }
  negative.insert(negative.end(), positive.begin(), positive.end());
  return negative;
}

double random_load_component(double min_N,
                             double max_N,
                             const std::vector<double>& grid,
                             Rng& rng) {
  if (!grid.empty()) return grid[rng.index(grid.size())];
  return rng.uniform(min_N, max_N) * (rng.uniform() < 0.5 ? -1.0 : 1.0);
}

}  // namespace stiff
