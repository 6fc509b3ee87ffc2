#include "model.h"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "stiff/compensate/compensate.hpp"

namespace stiff::fmu {

namespace {

// Reader of resources/model.txt (format in stiff/export/fmu_export.hpp). Strict: any surprise is an
// error naming file:line, since a silently misread model would give wrong physics.
class LineReader {
 public:
  LineReader(const std::string& path) : path_(path), in_(path) {
    if (!in_) throw std::runtime_error("cannot open '" + path + "': " + std::strerror(errno));
  }
  // Next non-comment line split into tokens; false at end of file.
  bool next(std::vector<std::string>* tokens, std::string* rest_after_first = nullptr) {
    std::string line;
    while (std::getline(in_, line)) {
      ++line_;
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (line.empty() || line[0] == '#') continue;
      tokens->clear();
      std::istringstream s(line);
      std::string t;
      while (s >> t) tokens->push_back(t);
      if (tokens->empty()) continue;
      if (rest_after_first) {
        const size_t p =
            line.find_first_not_of(" \t", line.find(tokens->front()) + tokens->front().size());
        *rest_after_first = p == std::string::npos ? std::string() : line.substr(p);
      }
      return true;
    }
    return false;
  }
  [[noreturn]] void fail(const std::string& what) const {
    throw std::runtime_error(path_ + ":" + std::to_string(line_) + ": " + what);
  }
  std::vector<std::string> expect(const char* key, size_t count, std::string* rest = nullptr) {
    std::vector<std::string> t;
    if (!next(&t, rest)) fail(std::string("unexpected end of file, expected '") + key + "'");
    return check(t, key, count);
  }
  /// The tokens of a line already read, checked as expect() does.
  std::vector<std::string> check(const std::vector<std::string>& t,
                                 const char* key,
                                 size_t count) const {
    if (t[0] != key) fail(std::string("expected '") + key + "', found '" + t[0] + "'");
    if (count != 0 && t.size() != count + 1)
      fail(std::string("'") + key + "' needs " + std::to_string(count) + " values, found " +
           std::to_string(t.size() - 1));
    return t;
  }
  double number(const std::string& s) const {
    char* end = nullptr;
    const double v = std::strtod(s.c_str(), &end);
    if (end == s.c_str() || *end != '\0') fail("'" + s + "' is not a number");
    return v;
  }
  int integer(const std::string& s) const {
    const double v = number(s);
    if (!(v == std::floor(v)) || std::fabs(v) > 1e9) fail("'" + s + "' is not an integer");
    return static_cast<int>(v);
  }

 private:
  std::string path_;
  std::ifstream in_;
  int line_ = 0;
};

Eigen::Matrix4d matrix4(const LineReader& r, const std::vector<std::string>& t, size_t first) {
  Eigen::Matrix4d m;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) m(i, j) = r.number(t[first + 4 * i + j]);
  return m;
}

Eigen::Vector3d vector3(const LineReader& r, const std::vector<std::string>& t, size_t first) {
  return Eigen::Vector3d(r.number(t[first]), r.number(t[first + 1]), r.number(t[first + 2]));
}

}  // namespace

size_t Variable::size(int dof) const {
  if (role == Role::q_array) return static_cast<size_t>(dof);
  if (role == Role::wrench_array) return 6;
  return 1;
}

std::shared_ptr<const Layout> read_layout(const std::string& resources_dir) {
  std::string dir = resources_dir;
  if (!dir.empty() && dir.back() != '/') dir += '/';
  LineReader r(dir + "model.txt");
  auto layout = std::make_shared<Layout>();
  auto t = r.expect("stiff-fmu-model", 1);
  if (r.integer(t[1]) != fmu_format::kVersion)
    r.fail("model file version " + t[1] + ", this FMU binary reads version " +
           std::to_string(fmu_format::kVersion));
  layout->guid = r.expect("guid", 1)[1];
  layout->fmi = r.integer(r.expect("fmi", 1)[1]);
  std::string rest;
  r.expect("robot", 0, &rest);
  layout->robot.name = rest;
  const int n = r.integer(r.expect("dof", 1)[1]);
  if (n < 1 || n > kMaxJoints) r.fail("dof must be 1.." + std::to_string(kMaxJoints));
  for (int j = 0; j < n; ++j) {
    t = r.expect("joint", 16 + 3 + 16 + 2 + 1 + 3);
    Joint joint;
    joint.name = "joint" + std::to_string(j + 1);
    joint.pre = matrix4(r, t, 1);
    joint.axis = vector3(r, t, 17);
    joint.post = matrix4(r, t, 20);
    joint.lower = r.number(t[36]);
    joint.upper = r.number(t[37]);
    joint.mass = r.number(t[38]);
    joint.com = vector3(r, t, 39);
    layout->robot.joints.push_back(joint);
  }
  layout->robot.measured_point = vector3(r, r.expect("measured_point", 3), 1);
  layout->robot.load_point = vector3(r, r.expect("load_point", 3), 1);
  t = r.expect("tool", 4);
  layout->robot.tool_mass = r.number(t[1]);
  layout->robot.tool_com = vector3(r, t, 2);
  layout->robot.gravity = vector3(r, r.expect("gravity", 3), 1);
  t = r.expect("effects", 0);
  if (t.size() < 2 || static_cast<size_t>(r.integer(t[1])) != t.size() - 2)
    r.fail("'effects' needs a count and that many names");
  layout->effects.assign(t.begin() + 2, t.end());
  // Optional: the fit's session count (per-session parameters, e.g. the registration). Only
  // the count matters here: the outputs are in the base frame, not an instrument's.
  std::vector<std::string> sessions;
  if (!r.next(&t)) r.fail("unexpected end of file, expected 'variables'");
  if (t[0] == "sessions") {
    const int s = r.integer(r.check(t, "sessions", 1)[1]);
    if (s < 1 || s > 100000) r.fail("bad session count");
    for (int k = 0; k < s; ++k) sessions.push_back(std::to_string(k + 1));
    if (!r.next(&t)) r.fail("unexpected end of file, expected 'variables'");
  }
  try {
    layout->model =
        std::make_unique<DeflectionModel>(layout->robot, layout->effects, nullptr, sessions);
  } catch (const std::exception& e) {
    r.fail(std::string("this FMU binary cannot build the model: ") + e.what());
  }
  const int count = r.integer(r.check(t, "variables", 1)[1]);
  if (count < 1 || count > 100000) r.fail("bad variable count");
  // References: the fixed ones below kParameters, then one per model parameter.
  const int max_vr = static_cast<int>(fmu_format::vr::kParameters) + 100000;
  for (int k = 0; k < count; ++k) {
    t = r.expect("var", 0);
    if (t.size() < 5) r.fail("'var' needs <vr> <name> <role> <index> <start>... <min> <max>");
    Variable v;
    const int ref = r.integer(t[1]);
    if (ref < 0 || ref > max_vr) r.fail("value reference " + t[1] + " out of range");
    v.vr = static_cast<uint32_t>(ref);
    v.name = t[2];
    int role = -1;
    for (int i = 0; i < fmu_format::kRoleCount; ++i)
      if (t[3] == fmu_format::kRoleNames[i]) role = i;
    if (role < 0) r.fail("unknown role '" + t[3] + "'");
    v.role = static_cast<Role>(role);
    v.index = r.integer(t[4]);
    const size_t size = v.size(n);
    if (t.size() != 5 + size + 2)
      r.fail("'var " + v.name + "' needs " + std::to_string(size) + " start value(s), min, max");
    for (size_t e = 0; e < size; ++e) v.starts.push_back(r.number(t[5 + e]));
    v.start = v.starts.front();
    v.min = r.number(t[5 + size]);
    v.max = r.number(t[6 + size]);
    if (static_cast<size_t>(ref) >= layout->by_vr.size())
      layout->by_vr.resize(static_cast<size_t>(ref) + 1, -1);
    if (layout->by_vr[static_cast<size_t>(ref)] >= 0)
      r.fail("value reference " + t[1] + " given twice");
    layout->by_vr[static_cast<size_t>(ref)] = static_cast<int>(layout->variables.size());
    int limit = 1;
    switch (v.role) {
      case Role::q:
      case Role::q_cmd:
        limit = n;
        break;
      case Role::wrench:
      case Role::deflection:
        limit = 6;
        break;
      case Role::tool_position:
        limit = 3;
        break;
      case Role::parameter:
        limit = layout->model->parameter_count();
        break;
      default:
        break;
    }
    if (v.index < 0 || v.index >= limit) r.fail("index out of range for " + v.name);
    layout->variables.push_back(v);
  }
  // Every parameter of the model must have a variable, or theta would be incomplete.
  std::vector<bool> seen(static_cast<size_t>(layout->model->parameter_count()), false);
  for (const auto& v : layout->variables)
    if (v.role == Role::parameter) seen[static_cast<size_t>(v.index)] = true;
  for (size_t k = 0; k < seen.size(); ++k)
    if (!seen[k]) r.fail("no variable for model parameter " + std::to_string(k));
  r.expect("end", 0);
  return layout;
}

Model::Model(std::shared_ptr<const Layout> layout) : layout_(std::move(layout)) { reset(); }

void Model::reset() {
  const int n = dof();
  values_ = Values{};
  values_.q.assign(static_cast<size_t>(n), 0.0);
  values_.theta.assign(static_cast<size_t>(layout_->model->parameter_count()), 0.0);
  for (const auto& v : layout_->variables) {
    const auto i = static_cast<size_t>(v.index);
    switch (v.role) {
      case Role::q:
        values_.q[i] = v.start;
        break;
      case Role::wrench:
        values_.wrench[i] = v.start;
        break;
      case Role::q_array:
        for (size_t k = 0; k < values_.q.size(); ++k) values_.q[k] = v.starts[k];
        break;
      case Role::wrench_array:
        for (size_t k = 0; k < 6; ++k) values_.wrench[k] = v.starts[k];
        break;
      case Role::wrench_frame:
        values_.wrench_frame = static_cast<int>(v.start);
        break;
      case Role::parameter:
        values_.theta[i] = v.start;
        break;
      default:
        break;
    }
  }
  measurement_.q.resize(n);
  theta_.resize(static_cast<Eigen::Index>(values_.theta.size()));
  qcmd_.assign(static_cast<size_t>(n), 0.0);
  invalidate();
}

const Variable* Model::variable(uint32_t vr) const {
  if (vr >= layout_->by_vr.size()) return nullptr;
  const int i = layout_->by_vr[vr];
  return i < 0 ? nullptr : &layout_->variables[static_cast<size_t>(i)];
}

Status Model::set_real(const Variable& var, const double* v, std::string* msg) {
  const size_t count = var.size(dof());
  for (size_t i = 0; i < count; ++i)
    if (!std::isfinite(v[i])) {
      *msg = "variable '" + var.name + "': value is not finite";
      return Status::error;
    }
  switch (var.role) {
    case Role::q:
      values_.q[static_cast<size_t>(var.index)] = v[0];
      break;
    case Role::wrench:
      values_.wrench[var.index] = v[0];
      break;
    case Role::q_array:
      for (size_t i = 0; i < count; ++i) values_.q[i] = v[i];
      break;
    case Role::wrench_array:
      for (size_t i = 0; i < 6; ++i) values_.wrench[i] = v[i];
      break;
    case Role::parameter:
      if (v[0] < var.min || v[0] > var.max) {
        char b[200];
        std::snprintf(b, sizeof b, "parameter '%s' = %.17g is outside its bounds [%.17g, %.17g]",
                      var.name.c_str(), v[0], var.min, var.max);
        *msg = b;
        return Status::error;
      }
      values_.theta[static_cast<size_t>(var.index)] = v[0];
      break;
    default:
      *msg = "variable '" + var.name + "' cannot be set";
      return Status::error;
  }
  invalidate();
  return Status::ok;
}

Status Model::set_integer(const Variable& var, long long v, std::string* msg) {
  if (var.role != Role::wrench_frame) {
    *msg = "variable '" + var.name + "' is not an integer variable";
    return Status::error;
  }
  if (v != 0 && v != 1) {
    *msg = "wrench_frame must be 0 (base frame) or 1 (tool frame), got " + std::to_string(v);
    return Status::error;
  }
  values_.wrench_frame = static_cast<int>(v);
  invalidate();
  return Status::ok;
}

long long Model::get_integer(const Variable&) const { return values_.wrench_frame; }

Status Model::validate(std::string* msg) const {
  for (const auto& v : layout_->variables) {
    if (v.role != Role::parameter) continue;
    const double x = values_.theta[static_cast<size_t>(v.index)];
    if (!std::isfinite(x) || x < v.min || x > v.max) {
      char b[200];
      std::snprintf(b, sizeof b, "parameter '%s' = %.17g is not finite or outside [%.17g, %.17g]",
                    v.name.c_str(), x, v.min, v.max);
      *msg = b;
      return Status::error;
    }
  }
  for (double x : values_.q)
    if (!std::isfinite(x)) {
      *msg = "a joint position is not finite";
      return Status::error;
    }
  return Status::ok;
}

Eigen::Matrix<double, 6, 1> Model::base_wrench(const Eigen::Matrix3d& r_tool) const {
  Eigen::Matrix<double, 6, 1> w;
  const Eigen::Vector3d f(values_.wrench[0], values_.wrench[1], values_.wrench[2]);
  const Eigen::Vector3d m(values_.wrench[3], values_.wrench[4], values_.wrench[5]);
  if (values_.wrench_frame == 1)
    w << r_tool * f, r_tool * m;
  else
    w << f, m;
  return w;
}

Eigen::Matrix<double, 6, 1> Model::predict_at(const Eigen::VectorXd& q,
                                              Eigen::Vector3d* p,
                                              MeasurementContext* context) {
  const DeflectionModel& model = *layout_->model;
  measurement_.q = q;
  MeasurementContext& c = *context;
  c = model.context(measurement_, 0);
  if (p) *p = layout_->robot.point_position(c.chain, layout_->robot.measured_point);
  c.time = values_.time;
  const Eigen::Matrix<double, 6, 1> w = base_wrench(c.chain.flange.block<3, 3>(0, 0));
  measurement_.force = w.head<3>();
  measurement_.moment = w.tail<3>();
  return model.predict(theta_, measurement_, c);
}

Eigen::Matrix4d Model::loaded_at(const Eigen::VectorXd& q) {
  MeasurementContext c;
  Eigen::Vector3d p;
  const Eigen::Matrix<double, 6, 1> d = predict_at(q, &p, &c);
  if (layout_->model->absolute_accuracy()) {
    Vector6d w;
    w << measurement_.force, measurement_.moment;  // the base wrench at q (predict_at)
    return predicted_tool_pose(*layout_->model, theta_, q, w, values_.time);
  }
  Eigen::Matrix4d rigid = Eigen::Matrix4d::Identity();
  rigid.block<3, 3>(0, 0) = c.chain.flange.block<3, 3>(0, 0);
  rigid.block<3, 1>(0, 3) = p;
  return loaded_pose(rigid, d);
}

Status Model::deflection(const double** d6, std::string* msg) {
  if (!deflection_valid_) {
    if (validate(msg) != Status::ok) return Status::error;
    for (size_t k = 0; k < values_.theta.size(); ++k)
      theta_(static_cast<Eigen::Index>(k)) = values_.theta[k];
    const Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(values_.q.data(), dof());
    Eigen::Vector3d p;
    MeasurementContext c;
    const Eigen::Matrix<double, 6, 1> d = predict_at(q, &p, &c);
    flange_rotation_ = c.chain.flange.block<3, 3>(0, 0);
    p_unloaded_ = p;
    for (int i = 0; i < 6; ++i) out_[i] = d(i);
    for (int i = 0; i < 3; ++i) out_[6 + i] = p(i) + d(i);
    // A calibrated model: the tool is where the corrected chain, deflected under the wrench
    // and the robot's weight, puts it.
    if (layout_->model->absolute_accuracy()) {
      const Eigen::Matrix4d t = loaded_at(q);
      for (int i = 0; i < 3; ++i) out_[6 + i] = t(i, 3);
    }
    for (double x : out_)
      if (!std::isfinite(x)) {
        *msg = "the deflection overflows (not finite): parameters, pose or wrench out of range";
        return Status::error;
      }
    // A deflection of a kilometre is no arm's: the linear model was fed an absurd wrench (1e308 N
    // gave 1e303 m), and what follows from it (q_cmd) is overflow, not a singular pose.
    const double moved = d.head<3>().norm();
    if (moved > 1e3 || d.tail<3>().norm() > 1e3) {
      char b[200];
      std::snprintf(b, sizeof b,
                    "the deflection overflows: %.3g m (%.3g rad) under this wrench is beyond any "
                    "arm; check the wrench and parameter units",
                    moved, d.tail<3>().norm());
      *msg = b;
      return Status::error;
    }
    deflection_valid_ = true;
  }
  *d6 = out_;
  return Status::ok;
}

// Compensated joint targets: the core's solver (stiff::solve_compensation) drives the loaded
// pose of the measured point, p(qc) + d(qc, W) with rotation exp(rot(qc, W)) R(qc), to the
// rigid pose at q (position only for n < 6). The wrench may be given in the tool frame, so it
// is re-evaluated at every qc.
Status Model::compensation(const double** qcmd, std::string* msg) {
  const double* d6 = nullptr;
  if (!compensation_valid_) {
    const Status s = deflection(&d6, msg);
    if (s != Status::ok) return s;
    const RobotModel& robot = layout_->robot;
    const int n = dof();
    const Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(values_.q.data(), n);
    Eigen::Matrix4d target = Eigen::Matrix4d::Identity();
    target.block<3, 3>(0, 0) = flange_rotation_;
    target.block<3, 1>(0, 3) = p_unloaded_;
    const auto loaded = [&](const Eigen::VectorXd& qc) { return loaded_at(qc); };
    const PoseCompensation solved = solve_compensation(robot, loaded, target, q);
    Eigen::VectorXd qc = solved.q_cmd;
    const double err = solved.residual;
    compensation_status_ = Status::ok;
    compensation_message_.clear();
    if (!qc.allFinite()) {
      compensation_status_ = Status::error;
      compensation_message_ = "compensation failed: non-finite joint target (singular pose?)";
      qc = q;
    } else if (!solved.converged) {
      compensation_status_ = Status::warning;
      char b[200];
      std::snprintf(b, sizeof b,
                    "compensation did not converge (residual %.3g m/rad): singular pose or "
                    "joint limit; q_cmd is the damped least-squares estimate",
                    err);
      compensation_message_ = b;
    }
    for (int i = 0; i < n; ++i) qcmd_[static_cast<size_t>(i)] = qc(i);
    compensation_valid_ = true;
    compensation_reported_ = false;
  }
  *qcmd = qcmd_.data();
  // A warning is told once per evaluation, not once per q_cmd output read (the status stays).
  if (compensation_status_ == Status::error ||
      (compensation_status_ == Status::warning && !compensation_reported_))
    *msg = compensation_message_;
  compensation_reported_ = true;
  return compensation_status_;
}

Status Model::get_real(const Variable& var, double* v, std::string* msg) {
  const auto i = static_cast<size_t>(var.index);
  switch (var.role) {
    case Role::time:
      v[0] = values_.time;
      return Status::ok;
    case Role::q:
      v[0] = values_.q[i];
      return Status::ok;
    case Role::wrench:
      v[0] = values_.wrench[i];
      return Status::ok;
    case Role::q_array:
      for (size_t k = 0; k < values_.q.size(); ++k) v[k] = values_.q[k];
      return Status::ok;
    case Role::wrench_array:
      for (size_t k = 0; k < 6; ++k) v[k] = values_.wrench[k];
      return Status::ok;
    case Role::parameter:
      v[0] = values_.theta[i];
      return Status::ok;
    case Role::deflection:
    case Role::tool_position: {
      const double* d = nullptr;
      const Status s = deflection(&d, msg);
      if (s == Status::error) return s;
      v[0] = d[(var.role == Role::deflection ? 0 : 6) + var.index];
      return s;
    }
    case Role::q_cmd: {
      const double* qc = nullptr;
      const Status s = compensation(&qc, msg);
      if (s == Status::error) return s;
      v[0] = qc[i];
      return s;
    }
    default:
      *msg = "variable '" + var.name + "' is not a Real variable";
      return Status::error;
  }
}

void Model::restore(const Values& v) {
  values_ = v;
  invalidate();
}

// Blob: magic "STFS", u32 version, u32 total size, u64 hash of the GUID, u32 n, u32 P, then
// time, wrench_frame (as double), q[n], wrench[6], theta[P]; all little-endian host doubles.
namespace {
constexpr uint32_t kBlobVersion = 1;
uint64_t fnv1a(const std::string& s) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : s) h = (h ^ c) * 1099511628211ull;
  return h;
}
template <typename T>
void put(std::vector<uint8_t>* b, T v) {
  const size_t at = b->size();
  b->resize(at + sizeof(T));
  std::memcpy(b->data() + at, &v, sizeof(T));
}
template <typename T>
T take(const uint8_t* d, size_t* at) {
  T v;
  std::memcpy(&v, d + *at, sizeof(T));
  *at += sizeof(T);
  return v;
}
}  // namespace

std::vector<uint8_t> Model::serialize() const {
  std::vector<uint8_t> b(4);
  std::memcpy(b.data(), "STFS", 4);
  put<uint32_t>(&b, kBlobVersion);
  put<uint32_t>(&b, 0);  // size, patched below
  put<uint64_t>(&b, fnv1a(layout_->guid));
  put<uint32_t>(&b, static_cast<uint32_t>(values_.q.size()));
  put<uint32_t>(&b, static_cast<uint32_t>(values_.theta.size()));
  put<double>(&b, values_.time);
  put<double>(&b, values_.wrench_frame);
  for (double x : values_.q) put<double>(&b, x);
  for (double x : values_.wrench) put<double>(&b, x);
  for (double x : values_.theta) put<double>(&b, x);
  const auto size = static_cast<uint32_t>(b.size());
  std::memcpy(b.data() + 8, &size, sizeof size);
  return b;
}

bool Model::deserialize(const uint8_t* d, size_t size, std::string* msg, size_t trailer) {
  const size_t header = 4 + 4 + 4 + 8 + 4 + 4;
  if (!d || size < header || std::memcmp(d, "STFS", 4) != 0) {
    *msg = "not a stiff FMU state (bad magic or too short)";
    return false;
  }
  size_t at = 4;
  const auto version = take<uint32_t>(d, &at);
  const auto total = take<uint32_t>(d, &at);
  const auto hash = take<uint64_t>(d, &at);
  const auto n = take<uint32_t>(d, &at);
  const auto p = take<uint32_t>(d, &at);
  if (version != kBlobVersion) {
    *msg = "FMU state version " + std::to_string(version) + " is not supported";
    return false;
  }
  if (hash != fnv1a(layout_->guid) || n != values_.q.size() || p != values_.theta.size()) {
    *msg = "FMU state belongs to another model (GUID or sizes differ)";
    return false;
  }
  const size_t expected = header + 8 * (2 + size_t{n} + 6 + size_t{p});
  if (total != size || size != expected) {
    *msg = "FMU state has " + std::to_string(size + trailer) + " bytes, expected " +
           std::to_string(expected + trailer) +
           (size < expected ? " (truncated?)" : " (extra bytes at the end)");
    return false;
  }
  Values v;
  v.time = take<double>(d, &at);
  const double frame = take<double>(d, &at);
  v.q.resize(n);
  for (auto& x : v.q) x = take<double>(d, &at);
  for (auto& x : v.wrench) x = take<double>(d, &at);
  v.theta.resize(p);
  for (auto& x : v.theta) x = take<double>(d, &at);
  if (frame != 0.0 && frame != 1.0) {
    *msg = "FMU state holds an invalid wrench_frame";
    return false;
  }
  v.wrench_frame = static_cast<int>(frame);
  restore(v);
  return true;
}

}  // namespace stiff::fmu
