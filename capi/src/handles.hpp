// Definitions of the opaque C handles: real structs around core objects (no casts).
#pragma once

#include <memory>
#include <string>

#include "stiff/error.hpp"
#include "stiff/identify/fit.hpp"
#include "stiff/io/dataset.hpp"
#include "stiff/io/robot_io.hpp"
#include "stiff/kinematics/robot_model.hpp"
#include "stiff/model/model.hpp"

struct stiff_robot {
  stiff::RobotModel model;
  stiff::RobotFileReport report;  ///< what the reader decided (URDF chain, locked joints)
};

struct stiff_dataset {
  stiff::Dataset data;
};

struct stiff_result {
  stiff::FitResult fit;
};

/// A robot with an identified model, ready for prediction and compensation.
struct stiff_model {
  stiff::RobotModel robot;
  stiff::FitResult fit;
  std::unique_ptr<stiff::DeflectionModel> model;
  Eigen::VectorXd theta;
};

namespace stiff::capi {

/// Rows of joint values must be as wide as the robot has joints: a caller's array of the wrong
/// shape is refused, not read misaligned.
inline void require_joint_width(size_t n, const stiff_robot* robot) {
  const size_t dof = static_cast<size_t>(robot->model.dof());
  if (n != dof)
    throw InvalidArgument("q has " + std::to_string(n) + " values per row, the robot has " +
                          std::to_string(dof) + " joints");
}

}  // namespace stiff::capi
