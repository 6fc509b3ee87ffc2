/// \file robot_io.hpp
/// Robot description files: the project's YAML format (docs/formats.md) and URDF serial chains.
#pragma once

#include <string>

#include "stiff/kinematics/robot_model.hpp"

namespace stiff {

/// Read a robot description. Files ending in .urdf are read as URDF, others as YAML.
/// Throws ParseError ("path:line:col: reason") or IoError.
RobotModel load_robot(const std::string& path);

/// Parse the YAML robot format from text; `name_for_errors` labels messages.
RobotModel parse_robot_yaml(const std::string& text, const std::string& name_for_errors);

/// Parse a URDF serial chain from text: the chain from the root link to `tip_link` (empty:
/// the unique leaf; an error if the tree branches). Revolute and continuous joints become
/// joints; fixed joints fold into the neighbouring transforms.
RobotModel parse_robot_urdf(const std::string& text,
                            const std::string& name_for_errors,
                            const std::string& tip_link = "");

/// Write the robot in the YAML format (SI units), e.g. into an FMU's resources.
std::string robot_to_yaml(const RobotModel& robot);

}  // namespace stiff
