/// \file dataset.hpp
/// Measurement files (docs/formats.md): one experiment, a set of loaded measurements of one
/// robot. Readers convert every column to SI; writers write SI. Bad input throws ParseError
/// with "path:line:column: reason" and nothing is read half.
#pragma once

#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

namespace stiff {

/// One loaded measurement, SI units, base frame.
struct Measurement {
  std::string id;
  Eigen::VectorXd q;                                       ///< joint positions [rad]
  Eigen::Vector3d force = Eigen::Vector3d::Zero();         ///< force at the load point [N]
  Eigen::Vector3d moment = Eigen::Vector3d::Zero();        ///< moment about the load point [N*m]
  Eigen::Vector3d displacement = Eigen::Vector3d::Zero();  ///< loaded - unloaded [m]
  Eigen::Vector3d rotation = Eigen::Vector3d::Zero();      ///< small rotation [rad]
  double sigma_d = 0.0;  ///< std. deviation of each displacement component [m]; 0: unknown
  double time = 0.0;     ///< time of the loaded reading [s]; NaN-free, 0 when absent
  std::string session;   ///< measurement session label; empty when absent
  std::vector<std::string> extra;  ///< values of the dataset's extra columns, in order

  // Absolute rows (docs/formats.md, absolute measurements): the pose of the target in the
  // instrument's frame instead of a loaded-minus-unloaded difference.
  bool absolute = false;  ///< an absolute row (px, py, pz given); else a displacement row
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  ///< target in the instrument frame [m]
  bool has_orientation = false;  ///< a, b, c given: `orientation` holds the probe's rotation
  Eigen::Matrix3d orientation = Eigen::Matrix3d::Identity();  ///< probe frame in the instrument
  double temperature = 0.0;  ///< [deg C] when Dataset::has_temperature
  double sigma_p = 0.0;      ///< std. deviation of each position component [m]; 0: unknown
  double sigma_o = 0.0;      ///< std. deviation of each orientation component [rad]; 0: unknown

  /// What the model predicts for this row: the absolute position or the displacement [m].
  const Eigen::Vector3d& observed() const { return absolute ? position : displacement; }
  /// Standard deviation of observed() [m]; 0: unknown.
  double sigma() const { return absolute ? sigma_p : sigma_d; }
};

/// Euler-angle conventions of the a, b, c columns (`# euler:` metadata).
enum class EulerConvention {
  xyz,  ///< R = Rx(a) Ry(b) Rz(c) (intrinsic X-Y-Z)
  zyx,  ///< R = Rz(a) Ry(b) Rx(c) (intrinsic Z-Y-X, the KUKA A, B, C order)
};
/// Rotation matrix of Euler angles [rad] in a convention.
Eigen::Matrix3d euler_to_matrix(EulerConvention c, double a, double b, double cc);
/// Euler angles [rad] of a rotation matrix in a convention (the inverse of euler_to_matrix
/// with b in [-pi/2, pi/2]).
Eigen::Vector3d matrix_to_euler(EulerConvention c, const Eigen::Matrix3d& r);

/// One experiment: rows, which optional columns exist, metadata and unknown columns kept.
struct Dataset {
  std::vector<Measurement> rows;
  int dof = 0;  ///< joint count (columns q1..qn)
  bool has_id = false;
  bool has_moment = false;
  bool has_displacement = false;
  bool has_rotation = false;
  bool has_sigma = false;
  bool has_time = false;
  bool has_session = false;
  bool has_force = false;                        ///< fx, fy, fz columns (absent: no external load)
  bool has_position = false;                     ///< px, py, pz columns (absolute rows)
  bool has_orientation = false;                  ///< a, b, c columns (6-D absolute rows)
  EulerConvention euler = EulerConvention::xyz;  ///< convention of a, b, c (`# euler:`)
  bool has_temperature = false;                  ///< temp column
  bool has_sigma_p = false;                      ///< sigma_p column
  bool has_sigma_o = false;                      ///< sigma_o column
  /// `# key: value` comment lines, in file order.
  std::vector<std::pair<std::string, std::string>> metadata;
  /// Names of columns the format does not know; kept and written back.
  std::vector<std::string> extra_columns;

  size_t size() const { return rows.size(); }
  /// Number of absolute rows.
  int absolute_rows() const;
  /// Metadata value for key, or `fallback`.
  std::string meta(const std::string& key, const std::string& fallback = "") const;
  void set_meta(const std::string& key, const std::string& value);
  /// Index of an extra column, -1 if absent.
  int extra_index(const std::string& name) const;
};

/// Fewest absolute rows a session needs for its registration (three points fix a frame).
constexpr int kMinRowsPerSession = 3;

/// Read a measurement file. `dof` is the robot's joint count (q1..q<dof> required; a q column
/// beyond it is an error); 0 infers it from the columns. Displacement columns are optional
/// (a plan file has none): `has_displacement` tells.
Dataset read_measurements_csv(const std::string& path, int dof = 0);
/// Parse from text; `name` labels error messages.
Dataset parse_measurements_csv(const std::string& text, const std::string& name, int dof = 0);

/// Write in SI units (q in rad). Optional columns are written when the dataset has them.
std::string format_measurements_csv(const Dataset& data);
/// Write atomically (temporary file, then rename).
void write_measurements_csv(const std::string& path, const Dataset& data);

/// Check a dataset for use with a `dof`-joint robot: sizes, finite values, unique ids, and
/// (when `need_displacement`) measured displacements or absolute positions on every row.
/// Throws InvalidArgument naming the row.
void validate_dataset(const Dataset& data, int dof, bool need_displacement);

}  // namespace stiff
