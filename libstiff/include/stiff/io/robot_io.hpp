/// \file robot_io.hpp
/// Robot description files: the project's YAML format (docs/formats.md) and URDF serial chains.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "stiff/kinematics/robot_model.hpp"

namespace stiff {

/// Which part of a robot file stiff uses and what is mounted on its flange. Unset fields keep
/// the file's values (a URDF has none: points at the tip frame's origin, no tool mass).
struct RobotLoadOptions {
  std::string base_link;  ///< URDF: first link of the chain; empty: `base_link`, else the root
  std::string tip_link;   ///< URDF: last link; empty: `tool0`, `flange`, else the only candidate
  std::optional<Eigen::Vector3d> measured_point;  ///< SMR / tool point, tip (flange) frame [m]
  std::optional<Eigen::Vector3d> load_point;      ///< where the force acts, tip frame [m]
  std::optional<double> tool_mass;                ///< [kg]
  std::optional<Eigen::Vector3d> tool_com;        ///< tool centre of mass, tip frame [m]
};

/// What the reader decided, for `stiff robot show`: the chain's end links and one line per
/// decision a user should know (locked joints, continuous ranges, links left out).
struct RobotFileReport {
  std::string base_link, tip_link;  ///< empty for YAML robots
  std::vector<std::string> notes;
};

/// Read a robot description. Files ending in .urdf are read as URDF, others as YAML.
/// Throws ParseError ("path:line:col: reason"), IoError, or InvalidArgument for options that
/// do not fit the file.
RobotModel load_robot(const std::string& path,
                      const RobotLoadOptions& options = {},
                      RobotFileReport* report = nullptr);

/// Parse the YAML robot format from text; `name_for_errors` labels messages.
RobotModel parse_robot_yaml(const std::string& text, const std::string& name_for_errors);

/// Parse a URDF serial chain from text: the chain from `base_link` to `tip_link` (defaults in
/// RobotLoadOptions; an error listing the candidate tips when the choice is ambiguous). The
/// base link may also be a frame fixed beside the chain (ROS-Industrial `base`). Revolute joints
/// become joints, a revolute joint with lower = upper is locked there (a fixed transform),
/// continuous joints get one turn either way [-2 pi, 2 pi]; fixed joints fold into the
/// neighbouring transforms. Prismatic, planar and floating joints are refused on the chain.
RobotModel parse_robot_urdf(const std::string& text,
                            const std::string& name_for_errors,
                            const std::string& tip_link = "",
                            const std::string& base_link = "",
                            RobotFileReport* report = nullptr);

/// Write the robot in the YAML format (SI units), e.g. into an FMU's resources.
std::string robot_to_yaml(const RobotModel& robot);

/// What robot_to_urdf writes besides the chain.
struct UrdfWriteOptions {
  /// Pose of the base in a `world` link joined to `base_link` by a fixed joint (a
  /// calibration's registration: the base in the instrument frame); unset: no world link.
  std::optional<Eigen::Matrix4d> world_from_base;
  /// Lines of the header comment (what the robot is, what the description leaves out).
  std::vector<std::string> comments;
};

/// Write the robot as a URDF serial chain with the same kinematics (docs/formats.md, "URDF
/// export"): links base_link, link_1..link_n, tool0 (the flange: the last link frame) and tcp
/// (the measured point, flange orientation); joint j's origin is post_{j-1} pre_j as xyz and
/// fixed-axis roll-pitch-yaw, its axis and limits as in the robot, the flange transform
/// post_n a fixed joint to tool0. Masses become point-mass inertials (stiff holds no inertia
/// tensors), the tool's on tool0. Names are XML-escaped; a generated joint name that a joint
/// of the robot already uses gets a suffix. Throws InvalidArgument for non-finite or
/// non-rigid transforms.
std::string robot_to_urdf(const RobotModel& robot, const UrdfWriteOptions& options = {});

}  // namespace stiff
