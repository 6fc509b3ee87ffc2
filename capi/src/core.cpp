// Version, errors, robots, datasets.
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <thread>

#include "boundary.hpp"
#include "handles.hpp"
#include "stiff/io/robot_io.hpp"
#include "stiff/io/text_io.hpp"
#include "stiff/sim/simulate.hpp"

namespace stiff::capi {
namespace {
thread_local std::string last_error;
}

stiff_status fail(const char* function, stiff_status status, const std::string& what) noexcept {
  try {
    last_error = std::string(function) + ": " + what;
  } catch (...) {
    // Out of memory while formatting: keep the previous message.
  }
  return status;
}

}  // namespace stiff::capi

using namespace stiff;
using namespace stiff::capi;

extern "C" {

uint32_t stiff_version(void) { return STIFF_VERSION_NUMBER; }

const char* stiff_version_string(void) {
#define STIFF_STR2(x) #x
#define STIFF_STR(x) STIFF_STR2(x)
  return STIFF_STR(STIFF_VERSION_MAJOR) "." STIFF_STR(STIFF_VERSION_MINOR) "." STIFF_STR(
      STIFF_VERSION_PATCH);
}

const char* stiff_status_name(stiff_status status) {
  switch (enum_value(status)) {
    case STIFF_OK:
      return "STIFF_OK";
    case STIFF_E_INVALID_ARGUMENT:
      return "STIFF_E_INVALID_ARGUMENT";
    case STIFF_E_INVALID_STATE:
      return "STIFF_E_INVALID_STATE";
    case STIFF_E_PARSE:
      return "STIFF_E_PARSE";
    case STIFF_E_IO:
      return "STIFF_E_IO";
    case STIFF_E_BUFFER_TOO_SMALL:
      return "STIFF_E_BUFFER_TOO_SMALL";
    case STIFF_E_NUMERICAL:
      return "STIFF_E_NUMERICAL";
    case STIFF_E_CANCELLED:
      return "STIFF_E_CANCELLED";
    case STIFF_E_NO_MEMORY:
      return "STIFF_E_NO_MEMORY";
    case STIFF_E_INTERNAL:
      return "STIFF_E_INTERNAL";
  }
  return "STIFF_E_UNKNOWN";
}

const char* stiff_last_error(void) { return stiff::capi::last_error.c_str(); }

stiff_status stiff_robot_load(stiff_robot** out, const char* path) {
  if (out) *out = nullptr;
  return guarded(__func__, [&] {
    require(out, "out");
    require_string(path, "path");
    auto r = std::make_unique<stiff_robot>();
    r->model = load_robot(path, {}, &r->report);
    *out = r.release();
    return STIFF_OK;
  });
}

void stiff_robot_destroy(stiff_robot* robot) { delete robot; }

stiff_status stiff_robot_options_init(stiff_robot_options* options, size_t struct_size) {
  return guarded(__func__, [&] {
    // RobotLoadOptions{}: the reader chooses the chain ends and keeps the file's points.
    stiff_robot_options o{};
    o.base_link = static_string([] { return RobotLoadOptions{}.base_link; });
    o.tip_link = static_string([] { return RobotLoadOptions{}.tip_link; });
    const RobotLoadOptions lo;
    o.set = (lo.measured_point ? STIFF_ROBOT_SET_MEASURED_POINT : 0u) |
            (lo.load_point ? STIFF_ROBOT_SET_LOAD_POINT : 0u) |
            (lo.tool_mass ? STIFF_ROBOT_SET_TOOL_MASS : 0u) |
            (lo.tool_com ? STIFF_ROBOT_SET_TOOL_COM : 0u);
    return init_options(options, struct_size, sizeof(stiff_robot_options), "stiff_robot_options",
                        o);
  });
}

stiff_status stiff_robot_load_with(stiff_robot** out,
                                   const char* path,
                                   const stiff_robot_options* options) {
  if (out) *out = nullptr;
  return guarded(__func__, [&] {
    require(out, "out");
    require_string(path, "path");
    const stiff_robot_options o = read_options(options);
    RobotLoadOptions lo;
    if (o.base_link) lo.base_link = o.base_link;
    if (o.tip_link) lo.tip_link = o.tip_link;
    if (o.set & ~(STIFF_ROBOT_SET_MEASURED_POINT | STIFF_ROBOT_SET_LOAD_POINT |
                  STIFF_ROBOT_SET_TOOL_MASS | STIFF_ROBOT_SET_TOOL_COM))
      throw InvalidArgument("options.set has unknown bits");
    auto vec = [](const double* v, const char* what) {
      require_finite(v, 3, what);
      return Eigen::Vector3d(v[0], v[1], v[2]);
    };
    if (o.set & STIFF_ROBOT_SET_MEASURED_POINT)
      lo.measured_point = vec(o.measured_point_m, "measured_point_m");
    if (o.set & STIFF_ROBOT_SET_LOAD_POINT) lo.load_point = vec(o.load_point_m, "load_point_m");
    if (o.set & STIFF_ROBOT_SET_TOOL_MASS) lo.tool_mass = o.tool_mass_kg;
    if (o.set & STIFF_ROBOT_SET_TOOL_COM) lo.tool_com = vec(o.tool_com_m, "tool_com_m");
    auto r = std::make_unique<stiff_robot>();
    r->model = load_robot(path, lo, &r->report);
    *out = r.release();
    return STIFF_OK;
  });
}

stiff_status stiff_robot_joint_name(
    char* name, size_t capacity, size_t* needed, const stiff_robot* robot, size_t index) {
  return guarded(__func__, [&] {
    require(robot, "robot");
    if (index >= static_cast<size_t>(robot->model.dof()))
      throw InvalidArgument("joint index " + std::to_string(index) + " is not below the dof " +
                            std::to_string(robot->model.dof()));
    return copy_string(robot->model.joints[index].name, name, capacity, needed);
  });
}

stiff_status stiff_robot_points(double measured_point[3],
                                double load_point[3],
                                double* tool_mass,
                                double tool_com[3],
                                const stiff_robot* robot) {
  return guarded(__func__, [&] {
    require(robot, "robot");
    const RobotModel& m = robot->model;
    for (int k = 0; k < 3; ++k) {
      if (measured_point) measured_point[k] = m.measured_point(k);
      if (load_point) load_point[k] = m.load_point(k);
      if (tool_com) tool_com[k] = m.tool_com(k);
    }
    if (tool_mass) *tool_mass = m.tool_mass;
    return STIFF_OK;
  });
}

stiff_status stiff_robot_notes(char* text,
                               size_t capacity,
                               size_t* needed,
                               const stiff_robot* robot) {
  return guarded(__func__, [&] {
    require(robot, "robot");
    std::string s;
    for (const auto& n : robot->report.notes) s += n + "\n";
    return copy_string(s, text, capacity, needed);
  });
}

stiff_status stiff_robot_to_yaml(char* text,
                                 size_t capacity,
                                 size_t* needed,
                                 const stiff_robot* robot) {
  return guarded(__func__, [&] {
    require(robot, "robot");
    std::string s;
    for (const auto& n : robot->report.notes) s += "# " + n + "\n";
    s += robot_to_yaml(robot->model);
    return copy_string(s, text, capacity, needed);
  });
}

stiff_status stiff_robot_dof(size_t* dof, const stiff_robot* robot) {
  return guarded(__func__, [&] {
    require(dof, "dof");
    require(robot, "robot");
    *dof = static_cast<size_t>(robot->model.dof());
    return STIFF_OK;
  });
}

stiff_status stiff_robot_name(char* name,
                              size_t capacity,
                              size_t* needed,
                              const stiff_robot* robot) {
  return guarded(__func__, [&] {
    require(robot, "robot");
    return copy_string(robot->model.name, name, capacity, needed);
  });
}

stiff_status stiff_robot_limits(
    double* lower, double* upper, size_t capacity, size_t* needed, const stiff_robot* robot) {
  return guarded(__func__, [&] {
    require(robot, "robot");
    const size_t n = robot->model.dof();
    if (needed) *needed = n;
    if (capacity < n) too_small(capacity, n, "values");
    // A NULL buffer counts as capacity 0 (stiff.h); say which one it was.
    for (const auto& [buffer, name] : {std::pair{lower, "lower"}, std::pair{upper, "upper"}})
      if (n > 0 && !buffer)
        throw Error(Status::buffer_too_small, std::string(name) + " is NULL (capacity 0), " +
                                                  std::to_string(n) + " values needed");
    for (size_t j = 0; j < n; ++j) {
      lower[j] = robot->model.joints[j].lower;
      upper[j] = robot->model.joints[j].upper;
    }
    return STIFF_OK;
  });
}

namespace {
Eigen::VectorXd joint_vector(const stiff_robot* robot, const double* q, size_t n) {
  require(robot, "robot");
  require(q, "q");
  if (n != static_cast<size_t>(robot->model.dof()))
    throw InvalidArgument("q has " + std::to_string(n) + " values, the robot has " +
                          std::to_string(robot->model.dof()) + " joints");
  require_finite(q, n, "q");
  return Eigen::Map<const Eigen::VectorXd>(q, static_cast<Eigen::Index>(n));
}
}  // namespace

stiff_status stiff_robot_tool_pose(double pose[16],
                                   const stiff_robot* robot,
                                   const double* q,
                                   size_t n) {
  return guarded(__func__, [&] {
    require(pose, "pose");
    const Eigen::VectorXd qv = joint_vector(robot, q, n);
    const Eigen::Matrix4d t = robot->model.tool_pose(qv);
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) pose[4 * r + c] = t(r, c);
    return STIFF_OK;
  });
}

stiff_status stiff_robot_jacobian(double* jacobian,
                                  size_t capacity,
                                  size_t* needed,
                                  const stiff_robot* robot,
                                  const double* q,
                                  size_t n) {
  return guarded(__func__, [&] {
    const Eigen::VectorXd qv = joint_vector(robot, q, n);
    const Eigen::Matrix<double, 6, Eigen::Dynamic, Eigen::RowMajor> j = robot->model.jacobian(qv);
    return copy_out(j.data(), static_cast<size_t>(j.size()), jacobian, capacity, needed);
  });
}

stiff_status stiff_robot_jacobians(double* jacobians,
                                   size_t capacity,
                                   size_t* needed,
                                   const stiff_robot* robot,
                                   const double* q,
                                   size_t rows,
                                   size_t n) {
  return guarded(__func__, [&] {
    require(robot, "robot");
    const RobotModel& r = robot->model;
    stiff::capi::require_joint_width(n, robot);
    require_capacity(values_of(rows, 6 * n, "jacobians"), jacobians, capacity, needed);
    require(q, "q");
    require_finite(q, values_of(rows, n, "q"), "q");
    for (size_t i = 0; i < rows; ++i) {
      const Eigen::Matrix<double, 6, Eigen::Dynamic, Eigen::RowMajor> j =
          r.jacobian(Eigen::Map<const Eigen::VectorXd>(q + i * n, static_cast<Eigen::Index>(n)));
      std::copy(j.data(), j.data() + j.size(), jacobians + i * 6 * n);
    }
    return STIFF_OK;
  });
}

stiff_status stiff_dataset_read_csv(stiff_dataset** out,
                                    const stiff_robot* robot,
                                    const char* path) {
  if (out) *out = nullptr;
  return guarded(__func__, [&] {
    require(out, "out");
    require_string(path, "path");
    auto d = std::make_unique<stiff_dataset>();
    d->data = read_measurements_csv(path, robot ? robot->model.dof() : 0);
    *out = d.release();
    return STIFF_OK;
  });
}

stiff_status stiff_dataset_write_csv(const stiff_dataset* dataset, const char* path) {
  return guarded(__func__, [&] {
    require(dataset, "dataset");
    require_string(path, "path");
    write_measurements_csv(path, dataset->data);
    return STIFF_OK;
  });
}

stiff_status stiff_file_write(const char* path, const void* data, size_t size) {
  return guarded(__func__, [&] {
    require_string(path, "path");
    if (!data && size > 0) throw InvalidArgument("data is NULL");
    write_file_atomic(path, static_cast<const char*>(data), size);
    return STIFF_OK;
  });
}

stiff_status stiff_dataset_create(stiff_dataset** out,
                                  size_t rows,
                                  size_t dof,
                                  const double* q,
                                  const double* force,
                                  const double* moment,
                                  const double* displacement,
                                  const double* sigma_d) {
  if (out) *out = nullptr;
  return guarded(__func__, [&] {
    require(out, "out");
    require(q, "q");
    require(force, "force");
    if (rows == 0) throw InvalidArgument("rows must be > 0");
    if (dof == 0 || dof > static_cast<size_t>(kMaxJoints))
      throw InvalidArgument("dof must be in 1.." + std::to_string(kMaxJoints) +
                            " (the most joints a robot may have)");
    require_finite(q, values_of(rows, dof, "q"), "q");
    require_finite(force, values_of(rows, 3, "force"), "force");
    if (moment) require_finite(moment, rows * 3, "moment");
    if (displacement) require_finite(displacement, rows * 3, "displacement");
    if (sigma_d) {
      require_finite(sigma_d, rows, "sigma_d");
      for (size_t r = 0; r < rows; ++r)
        if (!(sigma_d[r] > 0))
          throw InvalidArgument("sigma_d[" + std::to_string(r) + "] must be > 0");
    }
    auto d = std::make_unique<stiff_dataset>();
    Dataset& ds = d->data;
    ds.dof = static_cast<int>(dof);
    ds.has_id = true;
    ds.has_moment = moment != nullptr;
    ds.has_displacement = displacement != nullptr;
    ds.has_sigma = sigma_d != nullptr;
    for (size_t r = 0; r < rows; ++r) {
      Measurement m;
      m.id = std::to_string(r + 1);
      m.q = Eigen::Map<const Eigen::VectorXd>(q + r * dof, static_cast<Eigen::Index>(dof));
      m.force = Eigen::Map<const Eigen::Vector3d>(force + 3 * r);
      if (moment) m.moment = Eigen::Map<const Eigen::Vector3d>(moment + 3 * r);
      if (displacement) m.displacement = Eigen::Map<const Eigen::Vector3d>(displacement + 3 * r);
      if (sigma_d) m.sigma_d = sigma_d[r];
      ds.rows.push_back(std::move(m));
    }
    *out = d.release();
    return STIFF_OK;
  });
}

void stiff_dataset_destroy(stiff_dataset* dataset) { delete dataset; }

stiff_status stiff_dataset_size(size_t* rows, size_t* dof, const stiff_dataset* dataset) {
  return guarded(__func__, [&] {
    require(dataset, "dataset");
    if (rows) *rows = dataset->data.rows.size();
    if (dof) *dof = static_cast<size_t>(dataset->data.dof);
    return STIFF_OK;
  });
}

namespace {
bool column_present(const Dataset& d, int column) {
  switch (column) {
    case STIFF_COLUMN_Q:
    case STIFF_COLUMN_FORCE:
      return true;
    case STIFF_COLUMN_MOMENT:
      return d.has_moment;
    case STIFF_COLUMN_DISPLACEMENT:
      return d.has_displacement;
    case STIFF_COLUMN_ROTATION:
      return d.has_rotation;
    case STIFF_COLUMN_SIGMA:
      return d.has_sigma;
    case STIFF_COLUMN_TIME:
      return d.has_time;
    case STIFF_COLUMN_ABSOLUTE:
      return true;
    case STIFF_COLUMN_POSITION:
      return d.has_position;
    case STIFF_COLUMN_SIGMA_P:
      return d.has_sigma_p;
    case STIFF_COLUMN_TEMPERATURE:
      return d.has_temperature;
    case STIFF_COLUMN_ORIENTATION:
      return d.has_orientation;
  }
  throw InvalidArgument("unknown column " + std::to_string(static_cast<int>(column)));
}
}  // namespace

stiff_status stiff_dataset_has(int* present, const stiff_dataset* dataset, stiff_column column) {
  return guarded(__func__, [&] {
    require(present, "present");
    require(dataset, "dataset");
    *present = column_present(dataset->data, enum_value(column)) ? 1 : 0;
    return STIFF_OK;
  });
}

stiff_status stiff_dataset_get(double* values,
                               size_t capacity,
                               size_t* needed,
                               const stiff_dataset* dataset,
                               stiff_column column) {
  return guarded(__func__, [&] {
    require(dataset, "dataset");
    const Dataset& d = dataset->data;
    const int c = enum_value(column);
    if (!column_present(d, c)) throw InvalidArgument("the dataset has no such column");
    std::vector<double> v;
    for (const auto& m : d.rows) {
      switch (column) {
        case STIFF_COLUMN_Q:
          for (int j = 0; j < d.dof; ++j) v.push_back(m.q(j));
          break;
        case STIFF_COLUMN_FORCE:
          v.insert(v.end(), m.force.data(), m.force.data() + 3);
          break;
        case STIFF_COLUMN_MOMENT:
          v.insert(v.end(), m.moment.data(), m.moment.data() + 3);
          break;
        case STIFF_COLUMN_DISPLACEMENT:
          v.insert(v.end(), m.displacement.data(), m.displacement.data() + 3);
          break;
        case STIFF_COLUMN_ROTATION:
          v.insert(v.end(), m.rotation.data(), m.rotation.data() + 3);
          break;
        case STIFF_COLUMN_SIGMA:
          v.push_back(m.sigma_d);
          break;
        case STIFF_COLUMN_TIME:
          v.push_back(m.time);
          break;
        case STIFF_COLUMN_ABSOLUTE:
          v.push_back(m.absolute ? 1.0 : 0.0);
          break;
        case STIFF_COLUMN_POSITION:
          for (int k = 0; k < 3; ++k) v.push_back(m.absolute ? m.position(k) : NAN);
          break;
        case STIFF_COLUMN_SIGMA_P:
          v.push_back(m.sigma_p);
          break;
        case STIFF_COLUMN_TEMPERATURE:
          v.push_back(m.temperature);
          break;
        case STIFF_COLUMN_ORIENTATION: {
          const Eigen::AngleAxisd aa(m.orientation);
          const Eigen::Vector3d w = aa.angle() * aa.axis();
          for (int k = 0; k < 3; ++k) v.push_back(m.has_orientation ? w(k) : NAN);
          break;
        }
      }
    }
    return copy_out(v.data(), v.size(), values, capacity, needed);
  });
}

stiff_status stiff_dataset_set_displacement(stiff_dataset* dataset,
                                            const double* displacement,
                                            size_t rows) {
  return guarded(__func__, [&] {
    require(dataset, "dataset");
    require(displacement, "displacement");
    if (rows != dataset->data.rows.size())
      throw InvalidArgument("displacement has " + std::to_string(rows) + " rows, the dataset " +
                            std::to_string(dataset->data.rows.size()));
    require_finite(displacement, values_of(rows, 3, "displacement"), "displacement");
    for (size_t r = 0; r < rows; ++r)
      dataset->data.rows[r].displacement = Eigen::Map<const Eigen::Vector3d>(displacement + 3 * r);
    dataset->data.has_displacement = true;
    return STIFF_OK;
  });
}

stiff_status stiff_dataset_id(
    char* id, size_t capacity, size_t* needed, const stiff_dataset* dataset, size_t row) {
  return guarded(__func__, [&] {
    require(dataset, "dataset");
    if (row >= dataset->data.rows.size())
      throw InvalidArgument("row " + std::to_string(row) + " out of range (dataset has " +
                            std::to_string(dataset->data.rows.size()) + ")");
    return copy_string(dataset->data.rows[row].id, id, capacity, needed);
  });
}

namespace {
/// The noise model's fields into the C struct (all but struct_size).
void put_noise(const NoiseModel& n, stiff_noise_options& o) {
  o.tracker_sigma_m = n.tracker_sigma_m;
  o.tracker_ppm = n.tracker_ppm;
  for (int k = 0; k < 3; ++k) o.tracker_position_m[k] = n.tracker_position_m(k);
  o.force_relative = n.force_relative;
  o.force_absolute_N = n.force_absolute_N;
  o.joint_sigma_rad = n.joint_sigma_rad;
  o.outlier_rate = n.outlier_rate;
  o.outlier_size_m = n.outlier_size_m;
  o.seed = n.seed;
}
}  // namespace

stiff_status stiff_noise_options_init(stiff_noise_options* options, size_t struct_size) {
  return guarded(__func__, [&] {
    // The virtual robot's default noise (NoiseModel{}), the one stiff_simulate uses for NULL.
    const NoiseModel n;
    stiff_noise_options o{};
    put_noise(n, o);
    return init_options(options, struct_size, sizeof(stiff_noise_options), "stiff_noise_options",
                        o);
  });
}

stiff_status stiff_noise_read(stiff_noise_options* noise, const char* path) {
  return guarded(__func__, [&] {
    require(noise, "noise");
    require_string(path, "path");
    stiff_noise_options o = read_options(noise, true);
    const NoiseModel n = read_noise(path);
    put_noise(n, o);
    const size_t size = std::min<size_t>(noise->struct_size, sizeof o);
    o.struct_size = noise->struct_size;
    std::memcpy(noise, &o, size);
    return STIFF_OK;
  });
}

stiff_status stiff_design_random(stiff_dataset** out,
                                 const stiff_robot* robot,
                                 size_t count,
                                 uint64_t seed) {
  if (out) *out = nullptr;
  return guarded(__func__, [&] {
    require(out, "out");
    require(robot, "robot");
    if (count == 0 || count > 1000000) throw InvalidArgument("count must be in 1..1e6");
    RandomDesignOptions o;
    o.count = static_cast<int>(count);
    o.seed = seed;
    auto d = std::make_unique<stiff_dataset>();
    d->data = random_design(robot->model, o);
    *out = d.release();
    return STIFF_OK;
  });
}

stiff_status stiff_design_random_options_init(stiff_design_random_options* options,
                                              size_t struct_size) {
  return guarded(__func__, [&] {
    const RandomDesignOptions d;  // the defaults are the core's, nothing restated here
    stiff_design_random_options o{};
    o.count = static_cast<uint32_t>(d.count);
    o.seed = d.seed;
    o.range_fraction = d.range_fraction;
    o.load_min_N = d.load_min_N;
    o.load_max_N = d.load_max_N;
    o.load_step_N = d.load_step_N;
    o.min_sigma_m = d.min_sigma;
    for (int k = 0; k < 3; ++k) {
      o.box_min_m[k] = d.box_min_m(k);
      o.box_max_m[k] = d.box_max_m(k);
    }
    return init_options(options, struct_size, sizeof(stiff_design_random_options),
                        "stiff_design_random_options", o);
  });
}

stiff_status stiff_design_random_with_options(stiff_dataset** out,
                                              const stiff_robot* robot,
                                              const stiff_design_random_options* options) {
  if (out) *out = nullptr;
  return guarded(__func__, [&] {
    require(out, "out");
    require(robot, "robot");
    const stiff_design_random_options o = read_options(options);
    const double nums[] = {o.range_fraction, o.load_min_N, o.load_max_N, o.load_step_N,
                           o.min_sigma_m};
    require_finite(nums, sizeof nums / sizeof nums[0], "options");
    RandomDesignOptions d;
    if (o.count > 1000000) throw InvalidArgument("count must be in 1..1e6");
    if (o.count) d.count = static_cast<int>(o.count);
    if (o.seed) d.seed = o.seed;
    if (o.range_fraction != 0) d.range_fraction = o.range_fraction;
    if (o.load_min_N != 0) d.load_min_N = o.load_min_N;
    if (o.load_max_N != 0) d.load_max_N = o.load_max_N;
    if (o.load_step_N != 0) d.load_step_N = o.load_step_N;
    if (o.min_sigma_m != 0) d.min_sigma = o.min_sigma_m;
    if (o.q_fixed) {
      if (o.q_fixed_count != static_cast<size_t>(robot->model.dof()))
        throw InvalidArgument("q_fixed has " + std::to_string(o.q_fixed_count) +
                              " values, the robot has " + std::to_string(robot->model.dof()) +
                              " joints");
      d.q_fixed.assign(o.q_fixed, o.q_fixed + o.q_fixed_count);
    }
    if (o.use_workspace_box) {
      require_finite(o.box_min_m, 3, "box_min_m");
      require_finite(o.box_max_m, 3, "box_max_m");
      d.use_workspace_box = true;
      d.box_min_m = Eigen::Vector3d(o.box_min_m);
      d.box_max_m = Eigen::Vector3d(o.box_max_m);
    }
    auto h = std::make_unique<stiff_dataset>();
    h->data = random_design(robot->model, d);  // validated once, in the core
    *out = h.release();
    return STIFF_OK;
  });
}

stiff_status stiff_simulate(stiff_dataset** out,
                            const stiff_robot* robot,
                            const stiff_dataset* design,
                            const char* truth_path,
                            const double* stiffness,
                            size_t n,
                            const stiff_noise_options* noise) {
  if (out) *out = nullptr;
  return guarded(__func__, [&] {
    require(out, "out");
    require(robot, "robot");
    const RobotModel& rm = robot->model;
    Truth truth;
    if (truth_path) {
      require_string(truth_path, "truth_path");
      truth = read_truth(truth_path, rm);
    } else {
      require(stiffness, "stiffness (or truth_path)");
      if (n != static_cast<size_t>(rm.dof()))
        throw InvalidArgument("stiffness has " + std::to_string(n) + " values, the robot has " +
                              std::to_string(rm.dof()) + " joints");
      require_finite(stiffness, n, "stiffness");
      for (size_t j = 0; j < n; ++j)
        if (!(stiffness[j] > 0))
          throw InvalidArgument("stiffness[" + std::to_string(j) + "] must be > 0");
      truth =
          joint_truth(Eigen::Map<const Eigen::VectorXd>(stiffness, static_cast<Eigen::Index>(n)));
    }
    const stiff_noise_options o = read_options(noise);
    NoiseModel nm;
    if (noise) {
      // Checked once, in the core (check_noise_model), with the message every surface shows.
      nm.tracker_sigma_m = o.tracker_sigma_m;
      nm.tracker_ppm = o.tracker_ppm;
      if (o.tracker_position_m[0] != 0 || o.tracker_position_m[1] != 0 ||
          o.tracker_position_m[2] != 0)
        nm.tracker_position_m = Eigen::Vector3d(o.tracker_position_m);
      nm.force_relative = o.force_relative;
      nm.force_absolute_N = o.force_absolute_N;
      nm.joint_sigma_rad = o.joint_sigma_rad;
      nm.outlier_rate = o.outlier_rate;
      nm.outlier_size_m = o.outlier_size_m;
      if (o.seed) nm.seed = o.seed;
    }
    Dataset plan;
    if (design) {
      plan = design->data;
    } else {
      RandomDesignOptions ro;
      ro.seed = nm.seed;
      plan = random_design(rm, ro);
    }
    auto d = std::make_unique<stiff_dataset>();
    d->data = simulate(rm, truth, plan, nm);
    *out = d.release();
    return STIFF_OK;
  });
}

}  // extern "C"
