/// \file fmu_export.hpp
/// Export of an identified deflection model as a Functional Mock-up Unit (FMI 2.0 or 3.0,
/// Model Exchange and Co-Simulation in one binary) for co-simulation (docs/fmu.md).
///
/// The FMU binary (fmu/) is generic: it evaluates any stiff::DeflectionModel. Everything that
/// depends on the robot and the fit is generated here, at export time, from one source of truth
/// (the model's parameter list):
///   - modelDescription.xml (variables, units, start values, model structure),
///   - the GUID / instantiationToken, a hash of the XML and of the model file,
///   - resources/model.txt: the value-reference table, start values, bounds, robot kinematics
///     and the fit, in the small line-based numeric format below, which the binary reads at
///     instantiation (and checks against the GUID it is given),
///   - resources/robot.yaml: the robot in the project's YAML format, for humans.
///
/// resources/model.txt, format "stiff-fmu-model" version 2 (ASCII, one record per line, tokens
/// separated by blanks, numbers with 17 significant digits so that they round-trip exactly;
/// lines starting with '#' are comments):
///   stiff-fmu-model 1
///   guid <guid>
///   fmi <2|3>
///   robot <name (rest of line)>
///   dof <n>
///   joint <pre: 16 row-major> <axis: 3> <post: 16 row-major> <lower> <upper> <mass> <com: 3>
///   measured_point <x> <y> <z>
///   load_point <x> <y> <z>
///   tool <mass> <com x> <com y> <com z>
///   gravity <gx> <gy> <gz>
///   effects <count> <name>...
///   sessions <count>            (only for a fit with sessions: per-session parameter blocks)
///   variables <count>
///   var <vr> <name> <role> <index> <start>... <min> <max>
///       (vr: the fixed references of fmu_format::vr, unique; one start per element: n for
///       q_array, 6 for wrench_array, else 1)
///   end
#pragma once

#include <cstdint>
#include <string>

#include "stiff/identify/fit.hpp"
#include "stiff/kinematics/robot_model.hpp"

namespace stiff {

/// Options of export_fmu.
struct FmuExportOptions {
  /// FMI version of the FMU: 2 (FMI 2.0, binaries/linux64) or 3 (FMI 3.0, binaries/x86_64-linux).
  int fmi_version = 2;
  /// modelIdentifier: name of the shared library inside the FMU; [A-Za-z_][A-Za-z0-9_]*.
  std::string model_identifier = "stiff_arm";
  /// Folder holding linux64/ and x86_64-linux/ with the generic FMU libraries (stiff_arm.so).
  /// Empty: environment variable STIFF_FMU_BINARIES, else the build tree's fmu/binaries. (The C
  /// ABI adds an installed package's folder: `fmu` next to the loaded libstiff_c.so.)
  std::string binaries_dir;
  /// FMI 3 only: the inputs are the arrays q[n] and wrench[6] instead of the scalars q1..qn,
  /// fx..mz. One set of inputs per FMU: an importer that writes every input then writes each
  /// value once, and none is left unset.
  bool array_inputs = false;
};

/// Write `path` (.fmu, a zip file) with the model `fit` of `robot` baked in: parameters are the
/// fit's values as start values, tunable, named `<effect>_<parameter>` (e.g. joint_c1).
/// The file is written atomically (temporary file in the same folder, then renamed).
/// Throws InvalidArgument (bad options, a fit that does not match the robot or the effects),
/// IoError (binaries missing, output not writable).
void export_fmu(const RobotModel& robot,
                const FitResult& fit,
                const std::string& path,
                const FmuExportOptions& options = {});

/// The folder export_fmu would take the FMU binaries from with `options` (see binaries_dir).
std::string fmu_binaries_dir(const FmuExportOptions& options = {});

namespace fmu_format {

/// Version of resources/model.txt written by export_fmu and read by the FMU binary.
/// 2: fixed value references, one start value per array element.
constexpr int kVersion = 2;

/// Value references (docs/fmu.md): fixed, the same in every FMU whatever its robot and model,
/// so that a master that stores connections by reference survives a re-export. Joint j
/// (1-based) adds j; the model's parameters follow after the reserved range, in model order.
namespace vr {
constexpr uint32_t kTime = 0;            ///< FMI 3 independent variable
constexpr uint32_t kQ = 0;               ///< q<j>: kQ + j = 1 .. n
constexpr uint32_t kWrench = 100;        ///< fx fy fz mx my mz: 100 .. 105
constexpr uint32_t kQArray = 110;        ///< FMI 3 array input q[n]
constexpr uint32_t kWrenchArray = 111;   ///< FMI 3 array input wrench[6]
constexpr uint32_t kWrenchFrame = 120;   ///< Integer parameter wrench_frame
constexpr uint32_t kDeflection = 200;    ///< dx dy dz rx ry rz: 200 .. 205
constexpr uint32_t kToolPosition = 210;  ///< x_tool y_tool z_tool: 210 .. 212
constexpr uint32_t kQCmd = 300;          ///< q_cmd<j>: kQCmd + j = 301 .. 300 + n
constexpr uint32_t kParameters = 1000;   ///< parameter k (0-based, model order): 1000 + k
static_assert(kQ + kMaxJoints < kWrench && kQCmd + kMaxJoints < kParameters,
              "the joint ranges must fit below the next block");
}  // namespace vr

/// What a variable of the FMU is; the FMU binary dispatches on it.
enum class Role : int {
  time = 0,           ///< FMI 3 independent variable [s]
  q = 1,              ///< input: joint position q<index+1> [rad]
  wrench = 2,         ///< input: wrench component (fx fy fz mx my mz)[index] [N, N*m]
  q_array = 3,        ///< FMI 3 input array q[n] (instead of the scalars q<i>)
  wrench_array = 4,   ///< FMI 3 input array wrench[6] (instead of fx..mz)
  wrench_frame = 5,   ///< Integer parameter: 0 = base frame, 1 = tool frame
  parameter = 6,      ///< Real parameter theta[index] of the deflection model
  deflection = 7,     ///< output (dx dy dz rx ry rz)[index] [m, rad], base frame
  tool_position = 8,  ///< output: loaded tool point (x y z)[index], base frame [m]
  q_cmd = 9,          ///< output: compensated joint target q_cmd<index+1> [rad]
};

constexpr const char* kRoleNames[] = {
    "time",         "q",         "wrench",     "q_array",       "wrench_array",
    "wrench_frame", "parameter", "deflection", "tool_position", "q_cmd"};
constexpr int kRoleCount = 10;

}  // namespace fmu_format

}  // namespace stiff
