// Definitions of the opaque C handles: real structs around core objects (no casts).
#pragma once

#include <memory>

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
