// Identification, fit results, prediction.
#include "stiff/identify/identify.hpp"

#include <algorithm>
#include <limits>

#include "boundary.hpp"
#include "handles.hpp"
#include "stiff/io/robot_io.hpp"

using namespace stiff;
using namespace stiff::capi;

namespace {

const FitResult& fit_of(const stiff_result* r) {
  require(r, "result");
  return r->fit;
}

/// What predict_rows returns per row.
enum class RowPrediction { position, orientation, cross_fitted };

/// stiff_predict_dataset (positions or displacements), stiff_predict_dataset_orientation (the
/// probe's orientation of absolute rows, NaN on the others) and
/// stiff_predict_dataset_cross_fitted (DeflectionModel::predict_cross_fitted): the checks,
/// then the prediction of every row, 3 values each.
stiff_status predict_rows(double* out,
                          size_t capacity,
                          size_t* needed,
                          const stiff_model* model,
                          const stiff_dataset* dataset,
                          RowPrediction what) {
  require(model, "model");
  require(dataset, "dataset");
  const Dataset& data = dataset->data;
  require_capacity(3 * data.rows.size(), out, capacity, needed);
  const DeflectionModel& dm = *model->model;
  // Cross-fitting estimates the session's own parameters from its measured rows.
  validate_dataset(data, model->robot.dof(), what == RowPrediction::cross_fitted);
  for (const auto& m : data.rows)
    if (m.absolute && dm.find("registration") >= 0 && !dm.has_session(m.session))
      throw InvalidArgument("measurement '" + m.id + "': session '" + m.session +
                            "' was not registered by this fit; identify with its rows, or "
                            "refit the registration of this set-up");
  const std::vector<MeasurementContext> ctx = dm.contexts(data);
  if (what == RowPrediction::cross_fitted) {
    const std::vector<Eigen::Vector3d> p = dm.predict_cross_fitted(model->theta, data, ctx);
    for (size_t r = 0; r < p.size(); ++r) {
      if (!p[r].allFinite())
        throw NumericalError("row " + std::to_string(r) + ": the prediction is not finite");
      for (int k = 0; k < 3; ++k) out[3 * r + k] = p[r](k);
    }
    return STIFF_OK;
  }
  for (size_t r = 0; r < data.rows.size(); ++r) {
    const Eigen::Matrix<double, 6, 1> d = dm.predict(model->theta, data.rows[r], ctx[r]);
    if (!d.allFinite())
      throw NumericalError("row " + std::to_string(r) + ": the prediction is not finite");
    for (int k = 0; k < 3; ++k)
      out[3 * r + k] = what == RowPrediction::position
                           ? d(k)
                           : (data.rows[r].absolute ? d(3 + k) : std::nan(""));
  }
  return STIFF_OK;
}

}  // namespace

extern "C" {

stiff_status stiff_identify_options_init(stiff_identify_options* options, size_t struct_size) {
  return guarded(__func__, [&] {
    // The core's IdentifyOptions{}: nothing is restated here.
    const IdentifyOptions io;
    stiff_identify_options o{};
    o.model = kDefaultModel;
    o.loss = static_string([] { return IdentifyOptions{}.loss; });
    o.loss_scale_m = io.loss_scale_m;
    o.max_iterations = static_cast<uint32_t>(io.max_iterations);
    o.method = STIFF_METHOD_AUTO;
    o.max_relative_se = io.max_relative_se;
    o.orientation_length_m = io.orientation_length_m;
    o.select_terms = io.select_terms ? 1 : -1;
    return init_options(options, struct_size, offsetof(stiff_identify_options, max_relative_se),
                        "stiff_identify_options", o);
  });
}

stiff_status stiff_identify(stiff_result** out,
                            const stiff_robot* robot,
                            const stiff_dataset* data,
                            const stiff_identify_options* options) {
  if (out) *out = nullptr;
  return guarded(__func__, [&] {
    require(out, "out");
    require(robot, "robot");
    require(data, "data");
    const stiff_identify_options o = read_options(options);
    const std::vector<std::string> effects = parse_model_string(o.model ? o.model : kDefaultModel);
    if (o.method > STIFF_METHOD_CERES)
      throw InvalidArgument("unknown method " + std::to_string(o.method));
    // The C fields' 0 means the default, a negative max_relative_se "off" (the core's 0); every
    // value is then checked once, by the core, whichever method solves.
    IdentifyOptions io;
    if (o.loss) io.loss = o.loss;
    io.loss_scale_m = o.loss_scale_m;
    if (o.max_relative_se != 0.0)
      io.max_relative_se = o.max_relative_se < 0.0 ? 0.0 : o.max_relative_se;
    if (o.orientation_length_m < 0.0) io.use_orientation = false;
    if (o.orientation_length_m > 0.0) io.orientation_length_m = o.orientation_length_m;
    if (o.max_iterations)
      io.max_iterations =
          static_cast<int>(std::min<uint32_t>(o.max_iterations, std::numeric_limits<int>::max()));
    if (o.select_terms != 0) io.select_terms = o.select_terms > 0;
    check_identify_options(io);
    const bool linear_ok = effects.size() == 1 && effects[0] == kDefaultModel &&
                           io.loss == IdentifyOptions{}.loss && !o.start;
    auto r = std::make_unique<stiff_result>();
    // Absolute rows need the nonlinear path (the linear one reads displacement rows only).
    const bool displacement_only = data->data.absolute_rows() == 0;
    if (o.method == STIFF_METHOD_LINEAR ||
        (o.method == STIFF_METHOD_AUTO && linear_ok && displacement_only)) {
      if (!linear_ok)
        throw InvalidArgument("the linear method fits the model 'joint' without robust loss only");
      LinearOptions lo;
      lo.max_relative_se = io.max_relative_se;
      r->fit = identify_joint_linear(robot->model, data->data, lo);
    } else {
      if (o.start) io.start = &o.start->fit;
      if (o.refit && *o.refit) io.refit = parse_model_string(o.refit);
      if (o.progress) {
        const auto fn = o.progress;
        void* ud = o.progress_user_data;
        io.progress = [fn, ud](int iteration, double cost) {
          int stop = 1;
          try {
            stop = fn(static_cast<uint32_t>(iteration), cost, ud);
          } catch (...) {
            stop = 1;  // an exception in user code stops the call cleanly
          }
          return stop == 0;
        };
      }
      r->fit = identify(robot->model, data->data, effects, io);
    }
    // Finite but absurd inputs (e.g. a displacement of 1e308 m) can overflow the solution:
    // never hand back a "successful" fit with inf/NaN parameters (docs/reliability.md).
    for (const FitParameter& p : r->fit.parameters)
      if (!std::isfinite(p.value))
        throw NumericalError("identify: parameter " + p.effect + "." + p.name +
                             " is not finite: the data's magnitudes overflow the solution "
                             "(check the units: displacements in m, forces in N)");
    *out = r.release();
    return STIFF_OK;
  });
}

stiff_status stiff_robot_calibrated(stiff_robot** out,
                                    const stiff_robot* robot,
                                    const stiff_result* fit) {
  if (out) *out = nullptr;
  return guarded(__func__, [&] {
    require(out, "out");
    require(robot, "robot");
    std::vector<std::string> left_out;
    auto r = std::make_unique<stiff_robot>();
    r->model = calibrated_robot(robot->model, fit_of(fit), &left_out);
    r->report = robot->report;
    r->report.notes.push_back(
        "calibrated: the joint offsets, kinematic errors and tool of the "
        "fit built into the chain");
    for (const auto& l : left_out) r->report.notes.push_back("not built in: " + l);
    *out = r.release();
    return STIFF_OK;
  });
}

stiff_status stiff_result_registration(double pose[16],
                                       const stiff_result* fit,
                                       const char* session) {
  return guarded(__func__, [&] {
    require(pose, "pose");
    const Eigen::Matrix4d t = registration_pose(fit_of(fit), session ? session : "");
    for (int k = 0; k < 16; ++k) pose[k] = t(k / 4, k % 4);
    return STIFF_OK;
  });
}

stiff_status stiff_robot_to_urdf(char* text,
                                 size_t capacity,
                                 size_t* needed,
                                 const stiff_robot* robot,
                                 const double world_pose[16]) {
  return guarded(__func__, [&] {
    require(robot, "robot");
    UrdfWriteOptions o;
    if (world_pose) {
      Eigen::Matrix4d t;
      for (int k = 0; k < 16; ++k) t(k / 4, k % 4) = world_pose[k];
      o.world_from_base = t;
    }
    o.comments.push_back("written by stiff " + std::string(stiff_version_string()) +
                         ": the kinematic chain stiff uses (docs/formats.md, URDF export)");
    for (const auto& n : robot->report.notes) o.comments.push_back(n);
    return copy_string(robot_to_urdf(robot->model, o), text, capacity, needed);
  });
}

void stiff_result_destroy(stiff_result* result) { delete result; }

stiff_status stiff_result_read_json(stiff_result** out, const char* path) {
  if (out) *out = nullptr;
  return guarded(__func__, [&] {
    require(out, "out");
    require_string(path, "path");
    auto r = std::make_unique<stiff_result>();
    r->fit = read_fit(path);
    *out = r.release();
    return STIFF_OK;
  });
}

stiff_status stiff_result_write_json(const stiff_result* result, const char* path) {
  return guarded(__func__, [&] {
    require_string(path, "path");
    write_fit(path, fit_of(result));
    return STIFF_OK;
  });
}

stiff_status stiff_result_json(char* json,
                               size_t capacity,
                               size_t* needed,
                               const stiff_result* result) {
  return guarded(__func__,
                 [&] { return copy_string(fit_to_json(fit_of(result)), json, capacity, needed); });
}

stiff_status stiff_result_joint_stiffness(double* values,
                                          size_t capacity,
                                          size_t* needed,
                                          const stiff_result* result) {
  return guarded(__func__, [&] {
    const FitResult& f = fit_of(result);
    Eigen::VectorXd k = f.joint_stiffness();
    const auto ident = f.joint_identified();
    for (int j = 0; j < k.size(); ++j)
      if (!ident[j]) k(j) = NAN;
    return copy_out(k.data(), static_cast<size_t>(k.size()), values, capacity, needed);
  });
}

stiff_status stiff_result_joint_stiffness_se(double* values,
                                             size_t capacity,
                                             size_t* needed,
                                             const stiff_result* result) {
  return guarded(__func__, [&] {
    const Eigen::VectorXd k = fit_of(result).joint_stiffness_se();
    return copy_out(k.data(), static_cast<size_t>(k.size()), values, capacity, needed);
  });
}

stiff_status stiff_result_parameters(double* values,
                                     double* standard_errors,
                                     size_t capacity,
                                     size_t* needed,
                                     const stiff_result* result) {
  return guarded(__func__, [&] {
    const FitResult& f = fit_of(result);
    const size_t p = f.parameters.size();
    require_capacity(p, values, capacity, needed);
    for (size_t k = 0; k < p; ++k) {
      values[k] = f.parameters[k].value;
      if (standard_errors) standard_errors[k] = f.parameters[k].standard_error;
    }
    return STIFF_OK;
  });
}

stiff_status stiff_result_covariance(double* covariance,
                                     size_t capacity,
                                     size_t* needed,
                                     const stiff_result* result) {
  return guarded(__func__, [&] {
    const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> c =
        fit_of(result).covariance;
    return copy_out(c.data(), static_cast<size_t>(c.size()), covariance, capacity, needed);
  });
}

stiff_status stiff_result_residuals(double* residuals,
                                    size_t capacity,
                                    size_t* needed,
                                    const stiff_result* result) {
  return guarded(__func__, [&] {
    const Eigen::VectorXd& r = fit_of(result).residuals;
    return copy_out(r.data(), static_cast<size_t>(r.size()), residuals, capacity, needed);
  });
}

stiff_status stiff_result_orientation_residuals(double* residuals,
                                                size_t capacity,
                                                size_t* needed,
                                                const stiff_result* result) {
  return guarded(__func__, [&] {
    const Eigen::VectorXd& r = fit_of(result).orientation_residuals;
    return copy_out(r.data(), static_cast<size_t>(r.size()), residuals, capacity, needed);
  });
}

stiff_status stiff_result_statistics(stiff_fit_statistics* statistics, const stiff_result* result) {
  return guarded(__func__, [&] {
    require(statistics, "statistics");
    const FitResult& f = fit_of(result);
    stiff_fit_statistics s = read_options(statistics, true);
    s.measurements = static_cast<uint32_t>(f.measurements);
    s.rank = static_cast<uint32_t>(f.rank);
    s.dof = static_cast<uint32_t>(f.dof);
    s.rms_m = f.rms_m;
    s.sigma_hat_m = f.sigma_hat_m;
    s.noise_floor_m = f.noise_floor_m;
    s.chi2 = f.chi2;
    s.condition_number = f.condition_number;
    s.outliers = static_cast<uint32_t>(f.outliers.size());
    s.warnings = static_cast<uint32_t>(f.warnings.size());
    s.oriented_rows = static_cast<uint32_t>(f.oriented_rows);
    s.orientation_rms_rad = f.orientation_rms_rad;
    s.orientation_mean_rad = f.orientation_mean_rad;
    s.orientation_max_rad = f.orientation_max_rad;
    s.orientation_length_m = f.orientation_length_m;
    s.model_error_m = f.model_error_m;
    s.model_error_rad = f.model_error_rad;
    // Write back only the caller's part of the struct.
    const size_t n = std::min<size_t>(statistics->struct_size, sizeof s);
    s.struct_size = statistics->struct_size;
    std::memcpy(statistics, &s, n);
    return STIFF_OK;
  });
}

stiff_status stiff_result_warning(
    char* text, size_t capacity, size_t* needed, const stiff_result* result, size_t index) {
  return guarded(__func__, [&] {
    const FitResult& f = fit_of(result);
    if (index >= f.warnings.size())
      throw InvalidArgument("warning " + std::to_string(index) + " out of range (" +
                            std::to_string(f.warnings.size()) + " warnings)");
    return copy_string(f.warnings[index], text, capacity, needed);
  });
}

stiff_status stiff_model_create(stiff_model** out,
                                const stiff_robot* robot,
                                const stiff_result* fit) {
  if (out) *out = nullptr;
  return guarded(__func__, [&] {
    require(out, "out");
    require(robot, "robot");
    const FitResult& f = fit_of(fit);
    auto m = std::make_unique<stiff_model>();
    m->robot = robot->model;
    m->model = std::make_unique<DeflectionModel>(m->robot, f.model, nullptr, f.sessions);
    m->fit = fit_for_model(f, m->robot, *m->model, "");
    m->theta = m->fit.theta();
    *out = m.release();
    return STIFF_OK;
  });
}

void stiff_model_destroy(stiff_model* model) { delete model; }

namespace {
/// `row`: the reading's place in a batch, its time for effects that drift with time (the row
/// order is the time axis of data without a `t` column, as in identify and diagnose).
void predict_one(const stiff_model* model,
                 const double* q,
                 size_t n,
                 const double* wrench,
                 double* out,
                 size_t row = 0) {
  const RobotModel& r = model->robot;
  if (n != static_cast<size_t>(r.dof()))
    throw InvalidArgument("q has " + std::to_string(n) + " values, the robot has " +
                          std::to_string(r.dof()) + " joints");
  require_finite(q, n, "q");
  require_finite(wrench, 6, "wrench");
  Measurement m;
  m.q = Eigen::Map<const Eigen::VectorXd>(q, static_cast<Eigen::Index>(n));
  m.force = Eigen::Map<const Eigen::Vector3d>(wrench);
  m.moment = Eigen::Map<const Eigen::Vector3d>(wrench + 3);
  const MeasurementContext c = model->model->context(m, static_cast<int>(row));
  const Eigen::Matrix<double, 6, 1> d = model->model->predict(model->theta, m, c);
  if (!d.allFinite()) throw NumericalError("the predicted deflection is not finite");
  for (int k = 0; k < 6; ++k) out[k] = d(k);
}
}  // namespace

stiff_status stiff_predict(double deflection[6],
                           const stiff_model* model,
                           const double* q,
                           size_t n,
                           const double wrench[6]) {
  return guarded(__func__, [&] {
    require(deflection, "deflection");
    require(model, "model");
    require(q, "q");
    require(wrench, "wrench");
    predict_one(model, q, n, wrench, deflection);
    return STIFF_OK;
  });
}

stiff_status stiff_predict_dataset(double* predicted,
                                   size_t capacity,
                                   size_t* needed,
                                   const stiff_model* model,
                                   const stiff_dataset* dataset) {
  return guarded(__func__, [&] {
    return predict_rows(predicted, capacity, needed, model, dataset, RowPrediction::position);
  });
}

stiff_status stiff_predict_dataset_cross_fitted(double* predicted,
                                                size_t capacity,
                                                size_t* needed,
                                                const stiff_model* model,
                                                const stiff_dataset* dataset) {
  return guarded(__func__, [&] {
    return predict_rows(predicted, capacity, needed, model, dataset, RowPrediction::cross_fitted);
  });
}

stiff_status stiff_predict_dataset_orientation(double* rotation_vectors,
                                               size_t capacity,
                                               size_t* needed,
                                               const stiff_model* model,
                                               const stiff_dataset* dataset) {
  return guarded(__func__, [&] {
    return predict_rows(rotation_vectors, capacity, needed, model, dataset,
                        RowPrediction::orientation);
  });
}

stiff_status stiff_predict_batch(double* deflection,
                                 size_t capacity,
                                 size_t* needed,
                                 const stiff_model* model,
                                 const double* q,
                                 const double* wrench,
                                 size_t rows,
                                 size_t n) {
  return guarded(__func__, [&] {
    require(model, "model");
    require(q, "q");
    require(wrench, "wrench");
    require_capacity(values_of(rows, 6, "deflection"), deflection, capacity, needed);
    for (size_t r = 0; r < rows; ++r) {
      try {
        predict_one(model, q + r * n, n, wrench + 6 * r, deflection + 6 * r, r);
      } catch (const stiff::Error& e) {
        throw stiff::Error(e.status(), "row " + std::to_string(r) + ": " + e.what());
      }
    }
    return STIFF_OK;
  });
}

}  // extern "C"
