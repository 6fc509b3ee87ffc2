/// \file path_io.hpp
/// Machining paths (docs/compensation.md): a CSV of tool poses or a G-code subset, read into
/// tool poses in the robot base frame (SI). Bad input throws ParseError "path:line:column:
/// reason"; nothing is read half.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

namespace stiff {

/// One point of a path.
struct PathPoint {
  Eigen::Matrix4d pose = Eigen::Matrix4d::Identity();  ///< tool pose, base frame [m]
  Eigen::Matrix<double, 6, 1> wrench =
      Eigen::Matrix<double, 6, 1>::Zero();  ///< (F [N], M [N*m]) at the load point, base frame
  int line = 0;                             ///< line of the input file it came from (1-based)
  double feed_m_s = 0.0;                    ///< programmed feed [m/s]; 0 when not given
  bool rapid = false;                       ///< G0 move
};

struct ToolPath {
  std::vector<PathPoint> points;
  bool has_wrench = false;  ///< the file had per-point wrench columns
  std::string source;

  size_t size() const { return points.size(); }
  std::vector<Eigen::Matrix4d> poses() const;
  Eigen::MatrixXd wrenches() const;  ///< rows x 6
};

struct PathOptions {
  /// Workpiece frame in the base frame: the file's poses are given in it.
  Eigen::Matrix4d frame = Eigen::Matrix4d::Identity();
  /// Tool orientation in the workpiece frame, for G-code and for CSV files without
  /// orientation columns. Default: tool z axis pointing down (-z), RotX(pi).
  Eigen::Matrix3d tool_orientation = (Eigen::Matrix3d() << 1, 0, 0, 0, -1, 0, 0, 0, -1).finished();
  /// G-code: split G1 moves into segments no longer than this [m]; 0 keeps the end points.
  double segment_m = 0.0;
};

/// Pose from a position [m] and fixed-axis XYZ (roll-pitch-yaw) angles [rad]:
/// R = Rz(rz) Ry(ry) Rx(rx).
Eigen::Matrix4d pose_from_xyz_rpy(const Eigen::Matrix<double, 6, 1>& xyz_rpy);
/// Inverse of pose_from_xyz_rpy (angles in (-pi, pi], ry in [-pi/2, pi/2]).
Eigen::Matrix<double, 6, 1> xyz_rpy_from_pose(const Eigen::Matrix4d& pose);

/// CSV path: header with x, y, z (_m, _mm, _um); orientation rx, ry, rz (_rad, _deg; fixed-axis
/// XYZ) or qw, qx, qy, qz (unitless), or none (options.tool_orientation); optional wrench
/// fx, fy, fz (_N) and mx, my, mz (_Nm, _Nmm) in the path's frame; optional id and feed
/// (_mm_min, _m_s); other columns are ignored. `#` lines are comments.
ToolPath parse_path_csv(const std::string& text,
                        const std::string& name_for_errors,
                        const PathOptions& options = {});
/// G-code subset: G0/G1 with X Y Z and F, G90/G91, G20/G21, comments ( ) and ;, N numbers,
/// M/S/T words ignored; G2/G3 (arcs) and rotary axes are rejected naming the line.
ToolPath parse_gcode(const std::string& text,
                     const std::string& name_for_errors,
                     const PathOptions& options = {});
/// Read a path file: .csv as CSV, anything else (.nc, .ngc, .gcode, .tap, ...) as G-code.
ToolPath read_path(const std::string& path, const PathOptions& options = {});

}  // namespace stiff
