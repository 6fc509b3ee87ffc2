/// \file simulate.hpp
/// The virtual robot: simulates loaded-minus-unloaded measurements from a true model (joint
/// stiffness plus any physical effects) with a realistic, seeded noise model.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "stiff/io/dataset.hpp"
#include "stiff/model/model.hpp"

namespace stiff {

/// The truth hidden in simulated data: effects and their parameters (SI).
struct Truth {
  std::vector<std::string> effects;  ///< e.g. {"joint", "backlash"}
  Eigen::VectorXd theta;             ///< parameters in model order
};

/// Truth with only the joint effect: compliances 1/k [rad/(N*m)].
Truth joint_truth(const Eigen::VectorXd& stiffness_Nm_per_rad);

/// Parse a truth file (docs/formats.md): `stiffness_Nm_per_rad: [...]` and `effects:` with
/// parameters by name (missing parameters take their null value). Throws ParseError.
Truth parse_truth_yaml(const std::string& text,
                       const std::string& name_for_errors,
                       const RobotModel& robot);
Truth read_truth(const std::string& path, const RobotModel& robot);

/// Measurement errors of the simulated experiment.
struct NoiseModel {
  double tracker_sigma_m = 10e-6;  ///< constant part of the tracker's per-axis sigma [m]
  double tracker_ppm = 0.0;        ///< distance-proportional part [1e-6 of the distance]
  Eigen::Vector3d tracker_position_m{2.0, 0.0, 0.5};  ///< tracker station, base frame [m]
  double force_relative = 0.0;                        ///< relative force error (1 sigma) per axis
  double force_absolute_N = 0.0;  ///< absolute force error (1 sigma) per axis [N]
  /// How the two force errors combine per component: a linear sum rel |F_k| + abs (true, the
  /// convention of "a + b x" instrument specifications) or a quadrature sum.
  bool force_error_linear = true;
  double joint_sigma_rad = 0.0;  ///< joint reading error (1 sigma) [rad]
  double outlier_rate = 0.0;     ///< fraction of rows with a gross tracker error
  double outlier_size_m = 0.0;   ///< size of a gross error (norm) [m]
  uint64_t seed = 1;
  /// Per-axis tracker sigma for a point at `p` (base frame) [m].
  double tracker_sigma_at(const Eigen::Vector3d& p) const;
};

/// The largest fraction of rows with a gross error the virtual robot simulates: beyond half the
/// rows no robust estimator can tell outliers from data.
inline constexpr double kMaxOutlierRate = 0.5;

/// Throws InvalidArgument naming the field for a noise model simulate() cannot use: an error
/// size that is negative or not finite, an outlier rate above kMaxOutlierRate, a tracker
/// position that is not finite. simulate() runs it; every surface shows its message.
void check_noise_model(const NoiseModel& noise);

NoiseModel parse_noise_yaml(const std::string& text, const std::string& name_for_errors);
NoiseModel read_noise(const std::string& path);

/// Design of an experiment: poses and loads (a plan file without displacements).
/// Random valid poses uniform in `range_fraction` of each joint's range (the sampler of
/// kinematics/sampling.hpp, shared with the planner's candidate pool), loads with per-axis
/// magnitude uniform in [load_min_N, load_max_N] (or on a grid of load_step_N) and random sign;
/// q_fixed (NaN: free) holds joints at a value (the paper holds q6 = 0).
struct RandomDesignOptions {
  int count = 20;
  double range_fraction = 0.95;
  double load_min_N = 15.0;
  double load_max_N = 35.0;
  double load_step_N = 0.0;     ///< per-axis grid step [N]; 0 = continuous magnitudes
  std::vector<double> q_fixed;  ///< per joint, NaN = free; empty = all free
  double min_sigma = 0.05;      ///< reject poses with translational sigma_min(J) below [m]
  /// Keep only poses whose measured point lies in the box (base frame) [m].
  bool use_workspace_box = false;
  Eigen::Vector3d box_min_m = Eigen::Vector3d::Constant(-1e9);
  Eigen::Vector3d box_max_m = Eigen::Vector3d::Constant(1e9);
  uint64_t seed = 1;
};
Dataset random_design(const RobotModel& robot, const RandomDesignOptions& options);

/// Simulate the displacements of every row of `design` (poses, loads) under `truth`; writes
/// dx, dy, dz (and sigma_d) and, when the noise has force or joint errors, the recorded (noisy)
/// forces and joint readings. Metadata records the source and the noise. Rows keep their ids.
/// `outlier_rows` (may be null) receives the indices of rows given a gross error.
Dataset simulate(const RobotModel& robot,
                 const Truth& truth,
                 const Dataset& design,
                 const NoiseModel& noise,
                 std::vector<int>* outlier_rows = nullptr);

}  // namespace stiff
