// Export of the identified model as an FMU (docs/fmu.md). The variable table is built once here
// and written twice, as modelDescription.xml and as resources/model.txt for the generic binary.
#include "stiff/export/fmu_export.hpp"

#include <sys/stat.h>

#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <set>
#include <sstream>

#include "io/number_text.hpp"
#include "io/xml.hpp"
#include "io/zip.hpp"
#include "stiff/error.hpp"
#include "stiff/io/robot_io.hpp"
#include "stiff/io/text_io.hpp"
#include "stiff/model/model.hpp"

#ifndef STIFF_FMU_DEFAULT_BINARIES
#define STIFF_FMU_DEFAULT_BINARIES ""
#endif

namespace stiff {
namespace {

using fmu_format::Role;

struct Var {
  uint32_t vr = 0;  // value reference (fmu_format::vr)
  std::string name;
  Role role = Role::time;
  int index = 0;
  double start = 0.0;
  double min = -1e300;
  double max = 1e300;
  std::string unit;
  std::string description;
  int size = 1;                // arrays: element count
  std::vector<double> starts;  // arrays: start of each element (empty: `start` for all)
};

bool is_identifier(const std::string& s) {
  if (s.empty() || !(std::isalpha(static_cast<unsigned char>(s[0])) || s[0] == '_')) return false;
  for (char c : s)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_')) return false;
  return true;
}

using detail::exact;

std::string xml(const std::string& s) { return detail::xml_attribute(s); }

// Unit strings of the core ("rad/(N*m)") -> FMI unit names and SI base-unit exponents.
struct UnitInfo {
  const char* name;
  const char* base;  // attributes of <BaseUnit>, "" for dimensionless/unknown
};
const UnitInfo kUnits[] = {
    {"s", "s=\"1\""},
    {"m", "m=\"1\""},
    {"rad", "rad=\"1\""},
    {"N", "kg=\"1\" m=\"1\" s=\"-2\""},
    {"N.m", "kg=\"1\" m=\"2\" s=\"-2\""},
    {"rad/(N.m)", "kg=\"-1\" m=\"-2\" s=\"2\" rad=\"1\""},
    {"N.m/rad", "kg=\"1\" m=\"2\" s=\"-2\" rad=\"-1\""},
    {"m/N", "kg=\"-1\" s=\"2\""},
    {"rad/N", "kg=\"-1\" m=\"-1\" s=\"2\" rad=\"1\""},
    {"m/(N.m)", "kg=\"-1\" m=\"-1\" s=\"2\""},
    {"kg", "kg=\"1\""},
};
std::string fmi_unit(std::string u) {
  for (char& c : u)
    if (c == '*') c = '.';
  if (u == "1" || u == "-") return "";
  return u;
}

std::vector<Var> build_variables(const DeflectionModel& model, int fmi, bool arrays) {
  namespace vr = fmu_format::vr;
  const int n = model.robot().dof();
  static const char* kWrench[6] = {"fx", "fy", "fz", "mx", "my", "mz"};
  static const char* kDefl[6] = {"dx", "dy", "dz", "rx", "ry", "rz"};
  static const char* kTool[3] = {"x_tool", "y_tool", "z_tool"};
  std::vector<Var> v;
  const auto add = [&](uint32_t ref, std::string name, Role role, int index, std::string unit,
                       std::string description, int size = 1, double min = -1e300,
                       double max = 1e300) {
    Var x;
    x.vr = ref;
    x.name = std::move(name);
    x.role = role;
    x.index = index;
    x.min = min;
    x.max = max;
    x.unit = std::move(unit);
    x.description = std::move(description);
    x.size = size;
    v.push_back(std::move(x));
  };
  if (fmi == 3) add(vr::kTime, "time", Role::time, 0, "s", "simulation time");
  // One set of inputs: scalars (FMI 2, FMI 3 by default) or arrays (FMI 3 on request).
  for (int j = 0; j < n && !arrays; ++j)
    add(vr::kQ + static_cast<uint32_t>(j + 1), "q" + std::to_string(j + 1), Role::q, j, "rad",
        "commanded (unloaded) position of joint " + std::to_string(j + 1));
  for (int k = 0; k < 6 && !arrays; ++k)
    add(vr::kWrench + static_cast<uint32_t>(k), kWrench[k], Role::wrench, k, k < 3 ? "N" : "N.m",
        std::string(k < 3 ? "force" : "moment") +
            " on the tool at the load point, frame selected by wrench_frame");
  if (arrays) {
    add(vr::kQArray, "q", Role::q_array, 0, "rad",
        "commanded (unloaded) joint positions q1..qn as an array", n);
    add(vr::kWrenchArray, "wrench", Role::wrench_array, 0, "",
        "(fx fy fz [N], mx my mz [N.m]) on the tool at the load point, frame selected by "
        "wrench_frame",
        6);
  }
  add(vr::kWrenchFrame, "wrench_frame", Role::wrench_frame, 0, "",
      "frame of the wrench inputs: 0 = robot base, 1 = tool (flange orientation)", 1, 0, 1);
  for (int k = 0; k < 6; ++k)
    add(vr::kDeflection + static_cast<uint32_t>(k), kDefl[k], Role::deflection, k,
        k < 3 ? "m" : "rad",
        std::string(k < 3 ? "displacement" : "small rotation") +
            " of the tool point under the wrench, base frame");
  for (int k = 0; k < 3; ++k)
    add(vr::kToolPosition + static_cast<uint32_t>(k), kTool[k], Role::tool_position, k, "m",
        "position of the loaded (deflected) tool point, base frame");
  for (int j = 0; j < n; ++j)
    add(vr::kQCmd + static_cast<uint32_t>(j + 1), "q_cmd" + std::to_string(j + 1), Role::q_cmd, j,
        "rad",
        "compensated target of joint " + std::to_string(j + 1) +
            ": puts the loaded tool where q puts the unloaded one");
  // The model's own parameters come after the fixed variables, in the model's order.
  for (int k = 0; k < model.parameter_count(); ++k) {
    const ParameterSpec& s = model.spec(k);
    add(vr::kParameters + static_cast<uint32_t>(k), model.owner(k).name() + "_" + s.name,
        Role::parameter, k, fmi_unit(s.unit), s.meaning, 1, s.lower, s.upper);
  }
  std::set<std::string> names;
  std::set<uint32_t> refs;
  for (const auto& x : v) {
    if (!names.insert(x.name).second)
      throw InvalidArgument("fmu export: two FMU variables would be named '" + x.name + "'");
    if (!refs.insert(x.vr).second)
      throw InvalidArgument("fmu export: two FMU variables would have value reference " +
                            std::to_string(x.vr));
  }
  return v;
}

bool has_bound(double x) { return std::isfinite(x) && std::fabs(x) < 1e299; }

std::string model_file(const RobotModel& robot,
                       const DeflectionModel& model,
                       const std::vector<Var>& vars,
                       int fmi,
                       const std::string& guid) {
  std::ostringstream o;
  o << "# stiff FMU model (format in stiff/export/fmu_export.hpp), written by stiff fmu export and "
       "read\n"
       "# by the FMU binary at instantiation. SI units: m, rad, kg, N, N*m. Do not edit: the\n"
       "# GUID in modelDescription.xml is a hash of this file.\n";
  o << "stiff-fmu-model " << fmu_format::kVersion << "\n";
  o << "guid " << guid << "\n";
  o << "fmi " << fmi << "\n";
  std::string name = robot.name;
  for (char& c : name)
    if (c == '\n' || c == '\r') c = ' ';
  o << "robot " << (name.empty() ? "robot" : name) << "\n";
  o << "dof " << robot.dof() << "\n";
  for (const auto& j : robot.joints) {
    o << "joint";
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) o << ' ' << exact(j.pre(r, c));
    for (int r = 0; r < 3; ++r) o << ' ' << exact(j.axis(r));
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) o << ' ' << exact(j.post(r, c));
    o << ' ' << exact(j.lower) << ' ' << exact(j.upper) << ' ' << exact(j.mass);
    for (int r = 0; r < 3; ++r) o << ' ' << exact(j.com(r));
    o << "\n";
  }
  auto v3 = [&](const char* key, const Eigen::Vector3d& v) {
    o << key << ' ' << exact(v(0)) << ' ' << exact(v(1)) << ' ' << exact(v(2)) << "\n";
  };
  v3("measured_point", robot.measured_point);
  v3("load_point", robot.load_point);
  o << "tool " << exact(robot.tool_mass) << ' ' << exact(robot.tool_com(0)) << ' '
    << exact(robot.tool_com(1)) << ' ' << exact(robot.tool_com(2)) << "\n";
  v3("gravity", robot.gravity);
  o << "effects " << model.effects().size();
  for (const auto& e : model.effects()) o << ' ' << e->name();
  // Per-session parameters (registration) come in blocks, one per session of the fit.
  if (!model.session_labels().empty()) o << "\nsessions " << model.session_labels().size();
  o << "\nvariables " << vars.size() << "\n";
  for (const Var& v : vars) {
    o << "var " << v.vr << ' ' << v.name << ' ' << fmu_format::kRoleNames[static_cast<int>(v.role)]
      << ' ' << v.index;
    for (int e = 0; e < v.size; ++e)
      o << ' ' << exact(v.starts.empty() ? v.start : v.starts[static_cast<size_t>(e)]);
    o << ' ' << exact(v.min) << ' ' << exact(v.max) << "\n";
  }
  o << "end\n";
  return o.str();
}

std::string model_description(const std::vector<Var>& vars,
                              int fmi,
                              const std::string& id,
                              const std::string& robot_name,
                              const std::string& model_string,
                              const std::string& guid) {
  const bool v3 = fmi == 3;
  std::ostringstream o;
  o << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n";
  o << "<fmiModelDescription fmiVersion=\"" << (v3 ? "3.0" : "2.0") << "\" modelName=\"" << xml(id)
    << "\" " << (v3 ? "instantiationToken" : "guid") << "=\"" << guid << "\"\n"
    << "  description=\"Deflection of the tool of robot '" << xml(robot_name)
    << "' under a wrench, identified model " << xml(model_string) << " (stiff)\"\n"
    << "  generationTool=\"stiff fmu export\" variableNamingConvention=\"" << (v3 ? "flat" : "flat")
    << "\"" << (v3 ? "" : " numberOfEventIndicators=\"0\"") << ">\n";
  const char* state = v3 ? "FMUState" : "FMUstate";
  o << "  <ModelExchange modelIdentifier=\"" << id << "\" canGetAndSet" << state
    << "=\"true\" canSerialize" << state
    << "=\"true\" canBeInstantiatedOnlyOncePerProcess=\"false\""
    << (v3 ? " needsCompletedIntegratorStep=\"false\""
           : " completedIntegratorStepNotNeeded=\"true\" "
             "canNotUseMemoryManagementFunctions=\"true\"")
    << "/>\n";
  o << "  <CoSimulation modelIdentifier=\"" << id
    << "\" canHandleVariableCommunicationStepSize=\"true\" canGetAndSet" << state
    << "=\"true\" canSerialize" << state
    << "=\"true\" canBeInstantiatedOnlyOncePerProcess=\"false\""
    << (v3 ? " hasEventMode=\"false\"" : " canNotUseMemoryManagementFunctions=\"true\"") << "/>\n";
  std::set<std::string> used;
  for (const auto& v : vars)
    if (!v.unit.empty()) used.insert(v.unit);
  o << "  <UnitDefinitions>\n";
  for (const auto& u : used) {
    const char* base = "";
    for (const auto& k : kUnits)
      if (u == k.name) base = k.base;
    o << "    <Unit name=\"" << xml(u) << "\">";
    if (*base) o << "<BaseUnit " << base << "/>";
    o << "</Unit>\n";
  }
  o << "  </UnitDefinitions>\n";
  o << "  <LogCategories>\n"
       "    <Category name=\"logStatusError\" description=\"errors: bad arguments, invalid "
       "parameters, illegal call sequence\"/>\n"
       "    <Category name=\"logStatusWarning\" description=\"warnings: compensation not "
       "converged (singular pose)\"/>\n"
       "    <Category name=\"logCalls\" description=\"every FMI function call\"/>\n"
       "  </LogCategories>\n";
  o << "  <DefaultExperiment startTime=\"0\" stopTime=\"1\" stepSize=\"0.01\"/>\n";
  o << "  <ModelVariables>\n";
  std::vector<size_t> inputs, outputs;
  for (size_t k = 0; k < vars.size(); ++k) {
    const Var& v = vars[k];
    std::string causality, variability, initial, type = v3 ? "Float64" : "Real";
    bool with_start = true;
    switch (v.role) {
      case Role::time:
        causality = "independent";
        variability = "continuous";
        with_start = false;
        break;
      case Role::q:
      case Role::wrench:
      case Role::q_array:
      case Role::wrench_array:
        causality = "input";
        variability = "continuous";
        inputs.push_back(k);
        break;
      case Role::wrench_frame:
        causality = "parameter";
        variability = "tunable";
        initial = v3 ? "" : "exact";
        type = v3 ? "Int32" : "Integer";
        break;
      case Role::parameter:
        causality = "parameter";
        variability = "tunable";
        initial = v3 ? "" : "exact";
        break;
      default:
        causality = "output";
        variability = "continuous";
        with_start = false;
        outputs.push_back(k);
    }
    std::string attrs;
    if (!v.unit.empty() && type != "Integer" && type != "Int32")
      attrs += " unit=\"" + xml(v.unit) + "\"";
    if (has_bound(v.min) && v.role != Role::time) attrs += " min=\"" + exact(v.min) + "\"";
    if (has_bound(v.max) && v.role != Role::time) attrs += " max=\"" + exact(v.max) + "\"";
    std::string start;
    if (with_start) {
      for (int e = 0; e < v.size; ++e)
        start +=
            (e ? " " : "") + exact(v.starts.empty() ? v.start : v.starts[static_cast<size_t>(e)]);
      if (type == "Integer" || type == "Int32") start = std::to_string(static_cast<int>(v.start));
      attrs += " start=\"" + start + "\"";
    }
    if (v3) {
      o << "    <" << type << " name=\"" << xml(v.name) << "\" valueReference=\"" << v.vr
        << "\" causality=\"" << causality << "\" variability=\"" << variability << "\"";
      if (!initial.empty()) o << " initial=\"" << initial << "\"";
      o << " description=\"" << xml(v.description) << "\"" << attrs;
      if (v.role == Role::q_array || v.role == Role::wrench_array)
        o << ">\n      <Dimension start=\"" << v.size << "\"/>\n    </" << type << ">\n";
      else
        o << "/>\n";
    } else {
      o << "    <ScalarVariable name=\"" << xml(v.name) << "\" valueReference=\"" << v.vr
        << "\" causality=\"" << causality << "\" variability=\"" << variability << "\"";
      if (!initial.empty()) o << " initial=\"" << initial << "\"";
      o << " description=\"" << xml(v.description) << "\">\n      <" << type << attrs
        << "/>\n    </ScalarVariable>\n";
    }
  }
  o << "  </ModelVariables>\n  <ModelStructure>\n";
  // FMI 2: 1-based indices of ScalarVariables; FMI 3: value references.
  auto ref = [&](size_t k) { return std::to_string(v3 ? vars[k].vr : k + 1); };
  std::string deps;
  for (size_t i : inputs) deps += (deps.empty() ? "" : " ") + ref(i);
  if (v3) {
    for (size_t k : outputs)
      o << "    <Output valueReference=\"" << ref(k) << "\" dependencies=\"" << deps << "\"/>\n";
    for (size_t k : outputs) o << "    <InitialUnknown valueReference=\"" << ref(k) << "\"/>\n";
  } else {
    o << "    <Outputs>\n";
    for (size_t k : outputs)
      o << "      <Unknown index=\"" << ref(k) << "\" dependencies=\"" << deps << "\"/>\n";
    o << "    </Outputs>\n    <InitialUnknowns>\n";
    for (size_t k : outputs) o << "      <Unknown index=\"" << ref(k) << "\"/>\n";
    o << "    </InitialUnknowns>\n";
  }
  o << "  </ModelStructure>\n</fmiModelDescription>\n";
  return o.str();
}

// GUID: two FNV-1a 64-bit hashes of the XML and the model file (both written with the GUID
// field empty), formatted as a UUID.
std::string make_guid(const std::string& content) {
  uint64_t h1 = 1469598103934665603ull, h2 = 0x84222325cbf29ce4ull;
  for (unsigned char c : content) {
    h1 = (h1 ^ c) * 1099511628211ull;
    h2 = (h2 ^ c) * 0x100000001b3ull;
    h2 ^= h2 >> 29;
  }
  char b[64];
  std::snprintf(b, sizeof b, "{%08x-%04x-%04x-%04x-%012llx}", static_cast<unsigned>(h1 >> 32),
                static_cast<unsigned>((h1 >> 16) & 0xffff), static_cast<unsigned>(h1 & 0xffff),
                static_cast<unsigned>(h2 >> 48),
                static_cast<unsigned long long>(h2 & 0xffffffffffffull));
  return b;
}

void replace_all(std::string* s, const std::string& from, const std::string& to) {
  for (size_t p = s->find(from); p != std::string::npos; p = s->find(from, p + to.size()))
    s->replace(p, from.size(), to);
}

std::string read_binary(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError("fmu export: cannot read '" + path + "'");
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string documentation(const std::vector<Var>& vars,
                          const std::string& robot,
                          const std::string& model,
                          int fmi) {
  std::ostringstream o;
  o << "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>stiff_arm</title></head>"
       "<body>\n<h1>Compliant-arm deflection model (stiff)</h1>\n<p>Robot <b>"
    << xml(robot) << "</b>, identified model <b>" << xml(model) << "</b>, FMI " << fmi
    << ".0, Model Exchange and Co-Simulation. The FMU is algebraic (no states): the outputs "
       "follow the inputs instantly. The deflection is the compliance model of the stiff "
       "library (d = J C J<sup>T</sup> W for the joint model); q_cmd are the joint targets "
       "that put the loaded tool where q puts the unloaded one (damped least-squares Newton "
       "iteration, residual below 1e-12 m). The binary needs glibc 2.17 or newer "
       "on x86-64 Linux.</p>\n<table border=\"1\">\n"
       "<tr><th>vr</th><th>name</th><th>unit</th><th>description</th></tr>\n";
  for (size_t k = 0; k < vars.size(); ++k)
    o << "<tr><td>" << vars[k].vr << "</td><td>" << xml(vars[k].name) << "</td><td>"
      << xml(vars[k].unit) << "</td><td>" << xml(vars[k].description) << "</td></tr>\n";
  o << "</table>\n<p>Licences: see licenses/ (FMI headers BSD-2-Clause, Eigen MPL-2.0).</p>\n"
       "</body></html>\n";
  return o.str();
}

const char* kFmiLicense =
    "FMI 2.0 and FMI 3.0 C headers (fmi2Functions.h, fmi2FunctionTypes.h, fmi2TypesPlatform.h,\n"
    "fmi3Functions.h, fmi3FunctionTypes.h, fmi3PlatformTypes.h), used unmodified to build the\n"
    "binary of this FMU.\n\n"
    "Copyright (C) 2008-2011 MODELISAR consortium,\n"
    "              2012-2024 Modelica Association Project \"FMI\".\n"
    "All rights reserved.\n\n"
    "This file is licensed by the copyright holders under the 2-Clause BSD License\n"
    "(https://opensource.org/licenses/BSD-2-Clause):\n\n"
    "Redistribution and use in source and binary forms, with or without modification, are\n"
    "permitted provided that the following conditions are met:\n\n"
    "- Redistributions of source code must retain the above copyright notice, this list of\n"
    "  conditions and the following disclaimer.\n"
    "- Redistributions in binary form must reproduce the above copyright notice, this list of\n"
    "  conditions and the following disclaimer in the documentation and/or other materials\n"
    "  provided with the distribution.\n\n"
    "THIS SOFTWARE IS PROVIDED BY THE COPYRIGHT HOLDERS AND CONTRIBUTORS \"AS IS\" AND ANY\n"
    "EXPRESS OR IMPLIED WARRANTIES, INCLUDING, BUT NOT LIMITED TO, THE IMPLIED WARRANTIES OF\n"
    "MERCHANTABILITY AND FITNESS FOR A PARTICULAR PURPOSE ARE DISCLAIMED. IN NO EVENT SHALL THE\n"
    "COPYRIGHT HOLDER OR CONTRIBUTORS BE LIABLE FOR ANY DIRECT, INDIRECT, INCIDENTAL, SPECIAL,\n"
    "EXEMPLARY, OR CONSEQUENTIAL DAMAGES (INCLUDING, BUT NOT LIMITED TO, PROCUREMENT OF\n"
    "SUBSTITUTE GOODS OR SERVICES; LOSS OF USE, DATA, OR PROFITS; OR BUSINESS INTERRUPTION)\n"
    "HOWEVER CAUSED AND ON ANY THEORY OF LIABILITY, WHETHER IN CONTRACT, STRICT LIABILITY, OR\n"
    "TORT (INCLUDING NEGLIGENCE OR OTHERWISE) ARISING IN ANY WAY OUT OF THE USE OF THIS\n"
    "SOFTWARE, EVEN IF ADVISED OF THE POSSIBILITY OF SUCH DAMAGE.\n";

const char* kEigenLicense =
    "Eigen (https://eigen.tuxfamily.org), a C++ template library for linear algebra, is compiled\n"
    "into the binary of this FMU. Eigen is Free Software licensed under the Mozilla Public\n"
    "License, version 2.0 (MPL-2.0). The source code of Eigen, and the full text of the licence,\n"
    "are available at https://gitlab.com/libeigen/eigen and https://mozilla.org/MPL/2.0/.\n"
    "Eigen was used unmodified.\n\n"
    "The header ceres/jet.h of Ceres Solver (BSD-3-Clause, Copyright Google Inc.) is compiled\n"
    "in for the automatic-differentiation scalar type; no Ceres library is linked.\n";

}  // namespace

std::string fmu_binaries_dir(const FmuExportOptions& options) {
  if (!options.binaries_dir.empty()) return options.binaries_dir;
  if (const char* env = std::getenv("STIFF_FMU_BINARIES"); env && *env) return env;
  return STIFF_FMU_DEFAULT_BINARIES;
}

void export_fmu(const RobotModel& robot,
                const FitResult& fit,
                const std::string& path,
                const FmuExportOptions& options) {
  if (options.fmi_version != 2 && options.fmi_version != 3)
    throw InvalidArgument("fmu export: fmi_version must be 2 or 3, not " +
                          std::to_string(options.fmi_version));
  // It names binaries/<platform>/<id>.so inside the zip: a file name (at most 255 bytes on the
  // importers' file systems; 200 leaves room for the extension and the platform's prefix).
  if (options.model_identifier.size() > 200)
    throw InvalidArgument("fmu export: model identifier is " +
                          std::to_string(options.model_identifier.size()) +
                          " characters long; at most 200 (it names the FMU's binary file)");
  if (!is_identifier(options.model_identifier))
    throw InvalidArgument("fmu export: model identifier '" + options.model_identifier +
                          "' is not a C identifier");
  if (path.empty()) throw InvalidArgument("fmu export: output path is empty");
  const DeflectionModel model(robot, fit.model, nullptr, fit.sessions);
  const FitResult conformed = fit_for_model(fit, robot, model, "fmu export");
  if (options.array_inputs && options.fmi_version != 3)
    throw InvalidArgument(
        "fmu export: array inputs need FMI 3 (fmi_version = 3); FMI 2 has "
        "scalar variables only");
  std::vector<Var> vars = build_variables(model, options.fmi_version, options.array_inputs);
  // Joint inputs start at a home pose away from singularities: at the all-zero pose of most
  // arms (a wrist singularity) any load leaves the compensation unconverged from the first read.
  const Eigen::VectorXd home = home_pose(robot);
  for (auto& v : vars) {
    if (v.role == Role::parameter)
      v.start = conformed.parameters[static_cast<size_t>(v.index)].value;
    if (v.role == Role::q) v.start = home(v.index);
    if (v.role == Role::q_array) v.starts.assign(home.data(), home.data() + home.size());
  }

  const std::string platform = options.fmi_version == 2 ? "linux64" : "x86_64-linux";
  const std::string bin_dir = fmu_binaries_dir(options);
  const std::string bin = bin_dir + "/" + platform + "/stiff_arm.so";
  struct stat st;
  if (bin_dir.empty() || ::stat(bin.c_str(), &st) != 0)
    throw IoError("fmu export: FMU binary '" + bin +
                  "' not found; build the target stiff_fmu (cmake -DSTIFF_BUILD_FMU=ON), set "
                  "STIFF_FMU_BINARIES to the folder holding linux64/ and x86_64-linux/, or pass "
                  "binaries_dir");

  // One source of truth: the GUID hashes both generated files, written with it left empty.
  const std::string placeholder = "@STIFF_GUID@";
  std::string description = model_description(vars, options.fmi_version, options.model_identifier,
                                              robot.name, model.model_string(), placeholder);
  std::string model_txt = model_file(robot, model, vars, options.fmi_version, placeholder);
  const std::string guid = make_guid(description + '\0' + model_txt);
  replace_all(&description, placeholder, guid);
  replace_all(&model_txt, placeholder, guid);

  std::vector<detail::ZipEntry> entries;
  entries.push_back({"modelDescription.xml", description, false});
  entries.push_back(
      {"binaries/" + platform + "/" + options.model_identifier + ".so", read_binary(bin), true});
  entries.push_back({"resources/model.txt", model_txt, false});
  entries.push_back({"resources/robot.yaml", robot_to_yaml(robot), false});
  entries.push_back({"documentation/index.html",
                     documentation(vars, robot.name, model.model_string(), options.fmi_version),
                     false});
  entries.push_back({"documentation/licenses/FMI-headers-BSD-2-Clause.txt", kFmiLicense, false});
  entries.push_back({"documentation/licenses/Eigen-MPL-2.0.txt", kEigenLicense, false});
  write_text_file_atomic(path, detail::zip_stored(entries));
}

}  // namespace stiff
