#include "stiff/identify/fit.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "stiff/error.hpp"
#include "stiff/io/text_io.hpp"

namespace stiff {

using nlohmann::json;

namespace {
json number_or_null(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }
double number_from(const json& j) {
  return j.is_number() ? j.get<double>() : std::numeric_limits<double>::quiet_NaN();
}
}  // namespace

Eigen::VectorXd FitResult::theta() const {
  Eigen::VectorXd t(parameters.size());
  for (size_t k = 0; k < parameters.size(); ++k) t(k) = parameters[k].value;
  return t;
}

std::map<std::string, double> FitResult::values() const {
  std::map<std::string, double> v;
  for (const auto& p : parameters) v[p.effect + "." + p.name] = p.value;
  return v;
}

Eigen::VectorXd FitResult::joint_stiffness() const {
  std::vector<double> k;
  for (const auto& p : parameters)
    if (p.effect == "joint") k.push_back(p.value > 0 ? 1.0 / p.value : INFINITY);
  return Eigen::Map<Eigen::VectorXd>(k.data(), k.size());
}

Eigen::VectorXd FitResult::joint_stiffness_se() const {
  std::vector<double> k;
  for (const auto& p : parameters)
    if (p.effect == "joint")
      k.push_back(p.identified && p.value != 0 ? p.standard_error / (p.value * p.value) : NAN);
  return Eigen::Map<Eigen::VectorXd>(k.data(), k.size());
}

std::vector<bool> FitResult::joint_identified() const {
  std::vector<bool> out;
  for (const auto& p : parameters)
    if (p.effect == "joint") out.push_back(p.identified);
  return out;
}

std::string fit_to_json(const FitResult& f) {
  json j;
  j["format"] = "stiff-fit";
  j["version"] = 1;
  j["robot"] = {{"name", f.robot_name}, {"file", f.robot_path}};
  if (!f.robot_digest.empty()) j["robot"]["kinematics_digest"] = f.robot_digest;
  j["model"] = f.model;
  if (!f.sessions.empty()) j["sessions"] = f.sessions;
  j["method"] = f.method;
  j["loss"] = {{"name", f.loss}, {"scale_m", f.loss_scale_m}};
  json params = json::array();
  for (const auto& p : f.parameters)
    params.push_back({{"effect", p.effect},
                      {"name", p.name},
                      {"unit", p.unit},
                      {"meaning", p.meaning},
                      {"value", number_or_null(p.value)},
                      {"standard_error", number_or_null(p.standard_error)},
                      {"identified", p.identified}});
  for (size_t i = 0; i < f.parameters.size(); ++i)
    if (!f.parameters[i].identified && !f.parameters[i].held.empty())
      params[i]["held"] = f.parameters[i].held;
  j["parameters"] = params;
  const Eigen::VectorXd k = f.joint_stiffness(), kse = f.joint_stiffness_se();
  const auto ident = f.joint_identified();
  json joints = json::array();
  for (int i = 0; i < k.size(); ++i)
    joints.push_back({{"joint", i + 1},
                      {"stiffness_Nm_per_rad", number_or_null(ident[i] ? k(i) : NAN)},
                      {"stiffness_se_Nm_per_rad", number_or_null(kse(i))},
                      {"identified", static_cast<bool>(ident[i])}});
  j["joints"] = joints;
  j["fit"] = {{"measurements", f.measurements},
              {"rank", f.rank},
              {"dof", f.dof},
              {"condition_number", number_or_null(f.condition_number)},
              {"rms_m", f.rms_m},
              {"sigma_hat_m", number_or_null(f.sigma_hat_m)},
              {"noise_floor_m", f.noise_floor_m},
              {"chi2", f.chi2}};
  if (f.oriented_rows > 0) {
    j["fit"]["oriented_rows"] = f.oriented_rows;
    j["fit"]["orientation_rms_rad"] = f.orientation_rms_rad;
    j["fit"]["orientation_mean_rad"] = f.orientation_mean_rad;
    j["fit"]["orientation_max_rad"] = f.orientation_max_rad;
    j["fit"]["orientation_length_m"] = f.orientation_length_m;
  }
  if (f.model_error_m > 0) j["fit"]["model_error_m"] = f.model_error_m;
  if (f.model_error_rad > 0) j["fit"]["model_error_rad"] = f.model_error_rad;
  json cov = json::array();
  for (int r = 0; r < f.covariance.rows(); ++r) {
    json row = json::array();
    for (int c = 0; c < f.covariance.cols(); ++c) row.push_back(number_or_null(f.covariance(r, c)));
    cov.push_back(row);
  }
  j["covariance"] = cov;
  json outl = json::array();
  for (const auto& o : f.outliers)
    outl.push_back({{"row", o.row},
                    {"id", o.id},
                    {"residual_m", o.residual_m},
                    {"weight", o.weight},
                    {"reason", o.reason}});
  j["outliers"] = outl;
  j["warnings"] = f.warnings;
  return j.dump(2) + "\n";
}

FitResult fit_from_json(const std::string& text, const std::string& file) {
  json j;
  try {
    j = json::parse(text);
  } catch (const json::exception& e) {  // parse_error, and out_of_range for number overflow
    throw ParseError(file, 0, 0, std::string("not valid JSON: ") + e.what());
  }
  auto need = [&](const json& obj, const char* key) -> const json& {
    if (!obj.is_object() || !obj.contains(key))
      throw ParseError(file, 0, 0, std::string("fit file lacks '") + key + "'");
    return obj.at(key);
  };
  try {
    if (need(j, "format") != "stiff-fit")
      throw ParseError(file, 0, 0, "not a stiff fit file (format is not 'stiff-fit')");
    if (need(j, "version").get<int>() != 1)
      throw ParseError(file, 0, 0, "unsupported fit file version");
    FitResult f;
    f.robot_name = need(j, "robot").value("name", "");
    f.robot_path = need(j, "robot").value("file", "");
    f.robot_digest = need(j, "robot").value("kinematics_digest", "");
    f.model = need(j, "model").get<std::vector<std::string>>();
    if (j.contains("sessions")) f.sessions = j["sessions"].get<std::vector<std::string>>();
    if (f.model.empty()) throw ParseError(file, 0, 0, "fit file has an empty model");
    f.method = j.value("method", "");
    if (j.contains("loss")) {
      f.loss = j["loss"].value("name", "none");
      f.loss_scale_m = j["loss"].value("scale_m", 0.0);
    }
    for (const auto& p : need(j, "parameters")) {
      FitParameter q;
      q.effect = need(p, "effect").get<std::string>();
      q.name = need(p, "name").get<std::string>();
      q.unit = p.value("unit", "");
      q.meaning = p.value("meaning", "");
      q.value = number_from(need(p, "value"));
      if (!std::isfinite(q.value))
        throw ParseError(file, 0, 0,
                         "parameter " + q.effect + "." + q.name + " is not a finite number");
      q.standard_error = p.contains("standard_error") ? number_from(p["standard_error"]) : NAN;
      q.identified = p.value("identified", true);
      if (!q.identified && p.contains("held")) {
        const auto& h = p["held"];
        if (!h.is_string() ||
            (h != "undetermined" && h != "bound" && h != "decided" && h != "left_out"))
          throw ParseError(file, 0, 0,
                           "parameter " + q.effect + "." + q.name +
                               ": \"held\" is none of undetermined, bound, decided, left_out");
        q.held = h.get<std::string>();
      }
      f.parameters.push_back(q);
    }
    if (j.contains("fit")) {
      const auto& s = j["fit"];
      f.measurements = s.value("measurements", 0);
      f.rank = s.value("rank", 0);
      f.dof = s.value("dof", 0);
      f.condition_number =
          s.contains("condition_number") ? number_from(s["condition_number"]) : NAN;
      f.rms_m = s.value("rms_m", 0.0);
      f.sigma_hat_m = s.contains("sigma_hat_m") ? number_from(s["sigma_hat_m"]) : NAN;
      f.noise_floor_m = s.value("noise_floor_m", 0.0);
      f.chi2 = s.value("chi2", 0.0);
      f.oriented_rows = s.value("oriented_rows", 0);
      f.orientation_rms_rad = s.value("orientation_rms_rad", 0.0);
      f.orientation_mean_rad = s.value("orientation_mean_rad", 0.0);
      f.orientation_max_rad = s.value("orientation_max_rad", 0.0);
      f.orientation_length_m = s.value("orientation_length_m", 0.0);
      f.model_error_m = s.value("model_error_m", 0.0);
      f.model_error_rad = s.value("model_error_rad", 0.0);
    }
    const int p = static_cast<int>(f.parameters.size());
    f.covariance = Eigen::MatrixXd::Constant(p, p, NAN);
    if (j.contains("covariance")) {
      // p x p, symmetric, a variance >= 0 on the diagonal; null for unidentified parameters.
      const json& cj = j["covariance"];
      auto bad = [&](const std::string& why) {
        throw ParseError(file, 0, 0, "malformed covariance: " + why);
      };
      if (!cj.is_array() || cj.size() != static_cast<size_t>(p))
        bad("it must be " + std::to_string(p) + " rows for the " + std::to_string(p) +
            " parameters");
      for (int r = 0; r < p; ++r) {
        if (!cj[r].is_array() || cj[r].size() != static_cast<size_t>(p))
          bad("row " + std::to_string(r + 1) + " must hold " + std::to_string(p) + " values");
        for (int c = 0; c < p; ++c) {
          if (!cj[r][c].is_number() && !cj[r][c].is_null())
            bad("entry (" + std::to_string(r + 1) + ", " + std::to_string(c + 1) +
                ") is not a number");
          f.covariance(r, c) = number_from(cj[r][c]);
        }
      }
      for (int r = 0; r < p; ++r) {
        if (f.covariance(r, r) < 0) bad("variance " + std::to_string(r + 1) + " is negative");
        for (int c = 0; c < r; ++c) {
          const double a = f.covariance(r, c), b = f.covariance(c, r);
          if ((std::isnan(a) != std::isnan(b)) ||
              (!std::isnan(a) && std::abs(a - b) > 1e-9 * std::max(std::abs(a), std::abs(b))))
            bad("it is not symmetric at (" + std::to_string(r + 1) + ", " + std::to_string(c + 1) +
                ")");
        }
      }
    }
    if (j.contains("warnings")) f.warnings = j["warnings"].get<std::vector<std::string>>();
    return f;
  } catch (const json::exception& e) {
    throw ParseError(file, 0, 0, std::string("malformed fit file: ") + e.what());
  }
}

std::string kinematics_digest(const RobotModel& robot) {
  // FNV-1a over the rounded numbers: the same arm read from YAML, URDF or the robot.yaml inside
  // an FMU gives the same digest; another arm (or another measured point) does not.
  uint64_t h = 1469598103934665603ULL;
  auto mix = [&](double v) {
    const long long q = std::isfinite(v) ? std::llround(v * 1e9) : 0;
    for (int b = 0; b < 8; ++b) {
      h ^= static_cast<uint64_t>(q >> (8 * b)) & 0xff;
      h *= 1099511628211ULL;
    }
  };
  mix(robot.dof());
  for (const auto& jt : robot.joints) {
    for (int k = 0; k < 16; ++k) mix(jt.pre(k / 4, k % 4));
    for (int k = 0; k < 3; ++k) mix(jt.axis(k));
    for (int k = 0; k < 16; ++k) mix(jt.post(k / 4, k % 4));
  }
  for (int k = 0; k < 3; ++k) mix(robot.measured_point(k));
  for (int k = 0; k < 3; ++k) mix(robot.load_point(k));
  char buf[32];
  std::snprintf(buf, sizeof buf, "fnv1a64:%016llx", static_cast<unsigned long long>(h));
  return buf;
}

FitResult read_fit(const std::string& path) { return fit_from_json(read_text_file(path), path); }

void write_fit(const std::string& path, const FitResult& fit) {
  write_text_file_atomic(path, fit_to_json(fit));
}

double stated_noise_m(const Dataset& data) {
  if (data.has_sigma || data.has_sigma_p) {
    std::vector<double> s;
    for (const auto& m : data.rows) s.push_back(m.sigma());
    std::nth_element(s.begin(), s.begin() + s.size() / 2, s.end());
    return s[s.size() / 2];
  }
  const std::string meta = data.meta("tracker_sigma_m");
  if (!meta.empty()) {
    char* end = nullptr;
    const double v = std::strtod(meta.c_str(), &end);
    if (end != meta.c_str() && std::isfinite(v) && v > 0) return v;
  }
  return 0.0;
}

namespace {
/// Throws InvalidArgument (prefixed by `what`) unless the fit applies to this robot and model
/// as it stands (fit_for_model).
void check_fit_applies(const FitResult& fit,
                       const RobotModel& robot,
                       const DeflectionModel& model,
                       const std::string& what) {
  const std::string w = what.empty() ? std::string() : what + ": ";
  if (!fit.robot_digest.empty()) {
    const std::string mine = kinematics_digest(robot);
    if (fit.robot_digest != mine)
      throw InvalidArgument(w + "the fit was identified on robot '" + fit.robot_name +
                            "' (kinematics " + fit.robot_digest + "), robot '" + robot.name +
                            "' has other kinematics (" + mine + "); identify it on this robot");
  } else if (!fit.robot_name.empty() && fit.robot_name != robot.name) {
    throw InvalidArgument(w + "the fit was identified on robot '" + fit.robot_name + "', not '" +
                          robot.name + "'");
  }
  if (model.parameter_count() != static_cast<int>(fit.parameters.size()))
    throw InvalidArgument(w + "the fit has " + std::to_string(fit.parameters.size()) +
                          " parameters, model '" + model.model_string() + "' of robot '" +
                          robot.name + "' has " + std::to_string(model.parameter_count()));
  for (int k = 0; k < model.parameter_count(); ++k) {
    const FitParameter& p = fit.parameters[static_cast<size_t>(k)];
    const ParameterSpec& sp = model.spec(k);
    const std::string expected = model.owner(k).name() + "." + sp.name;
    if (p.effect != model.owner(k).name() || p.name != sp.name)
      throw InvalidArgument(w + "fit parameter " + std::to_string(k + 1) + " is " + p.effect + "." +
                            p.name + ", the model expects " + expected +
                            " (parameters are matched by name and order)");
    if (!std::isfinite(p.value) || p.value < sp.lower || p.value > sp.upper) {
      char range[96];
      std::snprintf(range, sizeof range, "[%.6g, %.6g]", sp.lower, sp.upper);
      char val[32];
      std::snprintf(val, sizeof val, "%.6g", p.value);
      throw InvalidArgument(w + "fit parameter " + expected + " = " + val + " " + sp.unit +
                            " is outside its physical range " + range);
    }
  }
}
}  // namespace

FitResult fit_for_model(const FitResult& fit,
                        const RobotModel& robot,
                        const DeflectionModel& model,
                        const std::string& what) {
  const int p = model.parameter_count();
  if (static_cast<int>(fit.parameters.size()) < p) {
    std::vector<FitParameter> params;
    std::vector<int> from;  // the fit's index of each parameter, -1 for an inserted one
    size_t j = 0;
    for (int k = 0; k < p; ++k) {
      const ParameterSpec& sp = model.spec(k);
      const std::string& effect = model.owner(k).name();
      if (j < fit.parameters.size() && fit.parameters[j].effect == effect &&
          fit.parameters[j].name == sp.name) {
        params.push_back(fit.parameters[j]);
        from.push_back(static_cast<int>(j++));
      } else if (sp.optional_term || sp.spread) {  // a fit from before it: its null value
        FitParameter q;
        q.effect = effect;
        q.name = sp.name;
        q.unit = sp.unit;
        q.meaning = sp.meaning;
        q.value = sp.null_value;
        q.standard_error = NAN;
        q.identified = false;
        q.held = sp.spread ? "decided" : "left_out";
        params.push_back(q);
        from.push_back(-1);
      } else {
        break;  // not a missing optional term: check_fit_applies names the mismatch
      }
    }
    if (static_cast<int>(params.size()) == p && j == fit.parameters.size()) {
      FitResult out = fit;
      out.parameters = std::move(params);
      if (fit.covariance.size() > 0) {
        out.covariance = Eigen::MatrixXd::Constant(p, p, NAN);
        for (int a = 0; a < p; ++a)
          for (int b = 0; b < p; ++b)
            if (from[a] >= 0 && from[b] >= 0)
              out.covariance(a, b) = fit.covariance(from[a], from[b]);
      }
      check_fit_applies(out, robot, model, what);
      return out;
    }
  }
  check_fit_applies(fit, robot, model, what);
  return fit;
}

Eigen::MatrixXd predict_dataset(const RobotModel& robot,
                                const FitResult& fit,
                                const Dataset& data) {
  validate_dataset(data, robot.dof(), false);
  // Built as the C API's model is, from the fit alone: an effect built on these rows would
  // take them for rows it has decided something on (backlash's jumps).
  const DeflectionModel model(robot, fit.model, nullptr, fit.sessions);
  const Eigen::VectorXd theta = fit_for_model(fit, robot, model, "predict").theta();
  Eigen::MatrixXd out(data.rows.size(), 6);
  const auto ctx = model.contexts(data);  // the one time axis (model.cpp)
  for (size_t r = 0; r < data.rows.size(); ++r)
    out.row(r) = model.predict(theta, data.rows[r], ctx[r]).transpose();
  return out;
}

}  // namespace stiff
