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
};

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
  /// `# key: value` comment lines, in file order.
  std::vector<std::pair<std::string, std::string>> metadata;
  /// Names of columns the format does not know; kept and written back.
  std::vector<std::string> extra_columns;

  size_t size() const { return rows.size(); }
  /// Metadata value for key, or `fallback`.
  std::string meta(const std::string& key, const std::string& fallback = "") const;
  void set_meta(const std::string& key, const std::string& value);
  /// Index of an extra column, -1 if absent.
  int extra_index(const std::string& name) const;
};

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
/// (when `need_displacement`) measured displacements. Throws InvalidArgument naming the row.
void validate_dataset(const Dataset& data, int dof, bool need_displacement);

}  // namespace stiff
