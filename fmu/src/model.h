// The compliant-arm model behind the FMI glue (Reference-FMUs' model interface, implemented
// once for FMI 2 and FMI 3): variable table, values, validation, evaluation, state blobs.
// The physics is stiff::DeflectionModel; nothing here re-implements it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "stiff/export/fmu_export.hpp"
#include "stiff/model/model.hpp"

namespace stiff::fmu {

using fmu_format::Role;

/// Outcome of a model call, mapped by the glue onto fmi2Status / fmi3Status.
enum class Status { ok, warning, discard, error };

struct Variable {
  uint32_t vr = 0;
  std::string name;
  Role role = Role::time;
  int index = 0;               ///< joint, wrench component, parameter or output index
  double start = 0.0;          ///< scalars
  std::vector<double> starts;  ///< arrays: one per element
  double min = -1e300;
  double max = 1e300;
  bool is_integer() const { return role == Role::wrench_frame; }
  /// Number of scalar values (arrays: n or 6).
  size_t size(int dof) const;
};

/// What resources/model.txt describes; shared read-only by the instances of one FMU.
struct Layout {
  std::string guid;
  int fmi = 2;
  RobotModel robot;
  std::vector<std::string> effects;
  std::vector<Variable> variables;  ///< in the model file's order
  std::vector<int> by_vr;           ///< index into `variables` of each value reference, or -1
  std::unique_ptr<DeflectionModel> model;
};

/// Read resources/model.txt from `resources_dir` (a native folder path). Throws std::exception
/// with a message naming the file and line.
std::shared_ptr<const Layout> read_layout(const std::string& resources_dir);

/// Values of one instance. Plain data, so that an FMU state is a copy of it.
struct Values {
  double time = 0.0;
  std::vector<double> q;                  ///< [rad]
  double wrench[6] = {0, 0, 0, 0, 0, 0};  ///< as given, in the frame wrench_frame
  int wrench_frame = 0;
  std::vector<double> theta;  ///< model parameters
};

class Model {
 public:
  explicit Model(std::shared_ptr<const Layout> layout);

  const Layout& layout() const { return *layout_; }
  int dof() const { return layout_->robot.dof(); }
  /// Back to the start values of the model file.
  void reset();

  /// Look up a variable; nullptr for an unknown value reference.
  const Variable* variable(uint32_t vr) const;

  /// Set/get the scalars of one variable (arrays: all their elements). `n` is the number of
  /// values at `v`; the caller has checked it against Variable::size. Messages go to `msg`.
  Status set_real(const Variable& var, const double* v, std::string* msg);
  Status get_real(const Variable& var, double* v, std::string* msg);
  Status set_integer(const Variable& var, long long v, std::string* msg);
  long long get_integer(const Variable& var) const;

  /// Check every parameter (finite, within its bounds) and the inputs (finite).
  Status validate(std::string* msg) const;

  /// d (deflection + rotation) of the tool point at the current inputs [m, rad], base frame.
  Status deflection(const double** d6, std::string* msg);
  /// Compensated joint targets (damped least-squares Newton, see docs/fmu.md).
  Status compensation(const double** qcmd, std::string* msg);

  const Values& values() const { return values_; }
  void set_time(double t) { values_.time = t; }

  /// Pointer-free, versioned, size-checked blob of the values (FMU state).
  std::vector<uint8_t> serialize() const;
  /// Restore from serialize(); false (and a message) for a truncated or foreign blob.
  /// `trailer`: bytes of the caller's blob after the model's part (sizes in messages are the
  /// blob's).
  bool deserialize(const uint8_t* data, size_t size, std::string* msg, size_t trailer = 0);
  /// Copy of the values / restore from a copy (fmi*GetFMUstate / SetFMUstate).
  Values save() const { return values_; }
  void restore(const Values& v);

 private:
  void invalidate() { deflection_valid_ = compensation_valid_ = false; }
  /// Wrench (F, M) in the base frame for tool rotation `r_tool`.
  Eigen::Matrix<double, 6, 1> base_wrench(const Eigen::Matrix3d& r_tool) const;
  /// Deflection at joint vector q (base-frame wrench computed at q); `p` (optional) receives
  /// the unloaded tool point position [m].
  Eigen::Matrix<double, 6, 1> predict_at(const Eigen::VectorXd& q,
                                         Eigen::Vector3d* p,
                                         MeasurementContext* context);

  /// Tool pose (base frame) with the joints commanded to q under the current wrench: the
  /// calibrated model's for a model of absolute accuracy (stiff::predicted_tool_pose), else
  /// FK(q) displaced by the deflection.
  Eigen::Matrix4d loaded_at(const Eigen::VectorXd& q);

  std::shared_ptr<const Layout> layout_;
  Values values_;
  Eigen::VectorXd theta_;
  Measurement measurement_;
  bool deflection_valid_ = false;
  bool compensation_valid_ = false;
  Status compensation_status_ = Status::ok;
  std::string compensation_message_;
  bool compensation_reported_ = false;           ///< the warning of this evaluation was logged
  double out_[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};  ///< d (6) and loaded tool position (3)
  Eigen::Matrix3d flange_rotation_ = Eigen::Matrix3d::Identity();  ///< unloaded, at q
  Eigen::Vector3d p_unloaded_ = Eigen::Vector3d::Zero();           ///< tool point at q
  std::vector<double> qcmd_;
};

}  // namespace stiff::fmu
