#include "stiff/sim/simulate.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <map>
#include <set>
#include <sstream>

#include "../io/yaml_load.hpp"
#include "io/number_text.hpp"
#include "stiff/error.hpp"
#include "stiff/io/text_io.hpp"
#include "stiff/kinematics/sampling.hpp"
#include "stiff/random.hpp"

namespace stiff {
namespace {

[[noreturn]] void fail_at(const std::string& file, const YAML::Node& n, const std::string& why) {
  const auto m = n.Mark();
  throw ParseError(file, m.is_null() ? 0 : m.line + 1, m.is_null() ? 0 : m.column + 1, why);
}

double yaml_number(const std::string& file, const YAML::Node& n, const std::string& what) {
  double v = 0;
  try {
    v = n.as<double>();
  } catch (const YAML::Exception&) {
    fail_at(file, n, what + " must be a number");
  }
  if (!std::isfinite(v)) fail_at(file, n, what + " is not finite");
  return v;
}

YAML::Node load_yaml(const std::string& text, const std::string& file) {
  YAML::Node root = detail::load_yaml_document(text, file);
  if (!root.IsMap()) throw ParseError(file, 1, 1, "expected a YAML mapping");
  return root;
}

std::string fmt(double v) { return detail::num(v, 6); }

}  // namespace

double NoiseModel::tracker_sigma_at(const Eigen::Vector3d& p) const {
  return tracker_sigma_m + tracker_ppm * 1e-6 * (p - tracker_position_m).norm();
}

Truth joint_truth(const Eigen::VectorXd& k) {
  Truth t;
  t.effects = {"joint"};
  t.theta = k.cwiseInverse();
  return t;
}

static Truth parse_truth_yaml_unguarded(const std::string& text,
                                        const std::string& file,
                                        const RobotModel& robot) {
  const YAML::Node root = load_yaml(text, file);
  for (const auto& kv : root) {
    const auto key = kv.first.as<std::string>();
    if (key != "stiffness_Nm_per_rad" && key != "effects")
      fail_at(file, kv.first, "unknown key '" + key + "' (use stiffness_Nm_per_rad, effects)");
  }
  const auto ks = root["stiffness_Nm_per_rad"];
  if (!ks || !ks.IsSequence())
    throw ParseError(file, 1, 1, "missing 'stiffness_Nm_per_rad: [k1, ..., kn]'");
  if (static_cast<int>(ks.size()) != robot.dof())
    fail_at(file, ks,
            "stiffness_Nm_per_rad has " + std::to_string(ks.size()) + " values for a " +
                std::to_string(robot.dof()) + "-joint robot");
  std::vector<std::string> names{"joint"};
  std::map<std::string, std::map<std::string, std::pair<double, YAML::Node>>> values;
  if (const auto eff = root["effects"]) {
    if (!eff.IsMap()) fail_at(file, eff, "'effects' must map effect names to parameters");
    for (const auto& kv : eff) {
      const auto ename = kv.first.as<std::string>();
      if (ename == "joint") fail_at(file, kv.first, "give joint stiffness in stiffness_Nm_per_rad");
      names.push_back(ename);
      if (kv.second.IsNull()) continue;
      if (!kv.second.IsMap())
        fail_at(file, kv.second, "parameters of '" + ename + "' must be a mapping");
      for (const auto& pv : kv.second)
        values[ename][pv.first.as<std::string>()] = {
            yaml_number(file, pv.second, ename + "." + pv.first.as<std::string>()), pv.first};
    }
  }
  DeflectionModel model(robot, names);
  Truth t;
  t.effects = names;
  t.theta = model.null_parameters();
  for (int j = 0; j < robot.dof(); ++j) {
    const double k = yaml_number(file, ks[j], "stiffness of joint " + std::to_string(j + 1));
    if (!(k > 0))
      fail_at(file, ks[j], "stiffness of joint " + std::to_string(j + 1) + " must be > 0");
    t.theta(j) = 1.0 / k;
  }
  for (size_t e = 1; e < names.size(); ++e) {
    const auto& effect = *model.effects()[e];
    auto& given = values[names[e]];
    for (int k = 0; k < effect.size(); ++k) {
      const auto& spec = effect.parameters()[k];
      const auto it = given.find(spec.name);
      if (it == given.end()) continue;
      if (it->second.first < spec.lower || it->second.first > spec.upper)
        fail_at(file, it->second.second,
                names[e] + "." + spec.name + " = " + fmt(it->second.first) +
                    " is outside its physical range [" + fmt(spec.lower) + ", " + fmt(spec.upper) +
                    "] " + spec.unit);
      t.theta(model.offset(static_cast<int>(e)) + k) = it->second.first;
      given.erase(it);
    }
    if (!given.empty())
      fail_at(file, given.begin()->second.second,
              "effect '" + names[e] + "' has no parameter '" + given.begin()->first + "'");
  }
  return t;
}

// yaml-cpp throws on conversions the readers do not check themselves (e.g. a key that is a
// list); it must never escape as anything but a ParseError with its location.
static ParseError yaml_parse_error(const std::string& file, const YAML::Exception& e) {
  return ParseError(file, e.mark.is_null() ? 0 : e.mark.line + 1,
                    e.mark.is_null() ? 0 : e.mark.column + 1, e.msg);
}

Truth parse_truth_yaml(const std::string& text, const std::string& file, const RobotModel& robot) {
  try {
    return parse_truth_yaml_unguarded(text, file, robot);
  } catch (const YAML::Exception& e) {
    throw yaml_parse_error(file, e);
  }
}

Truth read_truth(const std::string& path, const RobotModel& robot) {
  return parse_truth_yaml(read_text_file(path), path, robot);
}

static NoiseModel parse_noise_yaml_unguarded(const std::string& text, const std::string& file) {
  const YAML::Node root = load_yaml(text, file);
  NoiseModel n;
  // One quantity, two units: which one is meant is a guess; refuse it.
  std::map<std::string, std::string> quantity_key;
  for (const auto& kv : root) {
    const auto key = kv.first.as<std::string>();
    const auto& v = kv.second;
    for (const char* q : {"tracker_sigma", "joint_sigma"})
      if (key.rfind(q, 0) == 0) {
        const auto [it, fresh] = quantity_key.emplace(q, key);
        if (!fresh)
          fail_at(file, kv.first,
                  "'" + key + "' and '" + it->second + "' give the same quantity twice; keep one");
      }
    auto nonneg = [&](double x) {
      if (x < 0) fail_at(file, v, key + " must be >= 0");
      return x;
    };
    if (key == "tracker_sigma_m")
      n.tracker_sigma_m = nonneg(yaml_number(file, v, key));
    else if (key == "tracker_sigma_um")
      n.tracker_sigma_m = nonneg(yaml_number(file, v, key)) * 1e-6;
    else if (key == "tracker_ppm")
      n.tracker_ppm = nonneg(yaml_number(file, v, key));
    else if (key == "tracker_position_m") {
      if (!v.IsSequence() || v.size() != 3) fail_at(file, v, key + " must be [x, y, z]");
      for (int i = 0; i < 3; ++i) n.tracker_position_m(i) = yaml_number(file, v[i], key);
    } else if (key == "force_relative")
      n.force_relative = nonneg(yaml_number(file, v, key));
    else if (key == "force_absolute_N")
      n.force_absolute_N = nonneg(yaml_number(file, v, key));
    else if (key == "force_error_sum") {
      const std::string how = v.IsScalar() ? v.as<std::string>() : "";
      if (how != "linear" && how != "quadrature")
        fail_at(file, v, "force_error_sum must be 'linear' or 'quadrature'");
      n.force_error_linear = how == "linear";
    } else if (key == "joint_sigma_rad")
      n.joint_sigma_rad = nonneg(yaml_number(file, v, key));
    else if (key == "joint_sigma_deg")
      n.joint_sigma_rad = nonneg(yaml_number(file, v, key)) * M_PI / 180.0;
    else if (key == "outlier_rate") {
      n.outlier_rate = nonneg(yaml_number(file, v, key));
      if (n.outlier_rate > kMaxOutlierRate)
        fail_at(file, v, "outlier_rate must be <= " + fmt(kMaxOutlierRate));
    } else if (key == "outlier_size_m")
      n.outlier_size_m = nonneg(yaml_number(file, v, key));
    else if (key == "seed")
      n.seed = static_cast<uint64_t>(nonneg(yaml_number(file, v, key)));
    else
      fail_at(file, kv.first,
              "unknown key '" + key +
                  "' (known: tracker_sigma_m, tracker_sigma_um, tracker_ppm, tracker_position_m, "
                  "force_relative, force_absolute_N, force_error_sum, joint_sigma_rad, "
                  "joint_sigma_deg, "
                  "outlier_rate, outlier_size_m, seed)");
  }
  return n;
}

NoiseModel parse_noise_yaml(const std::string& text, const std::string& file) {
  try {
    return parse_noise_yaml_unguarded(text, file);
  } catch (const YAML::Exception& e) {
    throw yaml_parse_error(file, e);
  }
}

NoiseModel read_noise(const std::string& path) {
  return parse_noise_yaml(read_text_file(path), path);
}

Dataset random_design(const RobotModel& robot, const RandomDesignOptions& o) {
  const int n = robot.dof();
  if (o.count <= 0) throw InvalidArgument("random design: count must be > 0");
  if (!(o.range_fraction > 0 && o.range_fraction <= 1))
    throw InvalidArgument("random design: range fraction must be in (0, 1]");
  if (!(o.load_min_N >= 0 && o.load_max_N >= o.load_min_N && o.load_max_N > 0) ||
      !std::isfinite(o.load_max_N))
    throw InvalidArgument("random design: empty load range");
  if (!(o.load_step_N >= 0) || !std::isfinite(o.load_step_N))
    throw InvalidArgument("random design: load step must be a finite value >= 0 N");
  if (!o.q_fixed.empty() && static_cast<int>(o.q_fixed.size()) != n)
    throw InvalidArgument("random design: q_fixed needs one value per joint");
  for (size_t j = 0; j < o.q_fixed.size(); ++j)
    if (std::isinf(o.q_fixed[j]))
      throw InvalidArgument("random design: q_fixed[" + std::to_string(j) + "] is infinite");
  if (!(o.min_sigma >= 0)) throw InvalidArgument("random design: min_sigma must be >= 0 m");
  if (o.use_workspace_box && !(o.box_min_m.allFinite() && o.box_max_m.allFinite() &&
                               (o.box_min_m.array() < o.box_max_m.array()).all()))
    throw InvalidArgument("random design: the workspace box needs finite min < max on every axis");
  const std::vector<double> grid = o.load_step_N > 0
                                       ? signed_load_grid(o.load_min_N, o.load_max_N, o.load_step_N)
                                       : std::vector<double>{};
  if (o.load_step_N > 0 && grid.empty())
    throw InvalidArgument("random design: no multiple of the load step in the load range");
  Rng rng(o.seed);
  Dataset d;
  d.dof = n;
  d.has_id = true;
  long tries = 0;
  while (static_cast<int>(d.rows.size()) < o.count) {
    if (++tries > 1000L * o.count)
      throw NumericalError(
          "random design: almost every pose is near-singular or outside the workspace box");
    Measurement m;
    m.q = random_joint_pose(robot, o.range_fraction, o.q_fixed, rng);
    for (int k = 0; k < 3; ++k)
      m.force(k) = random_load_component(o.load_min_N, o.load_max_N, grid, rng);
    if (o.use_workspace_box) {
      const Eigen::Vector3d p = robot.point_position(robot.chain(m.q), robot.measured_point);
      if ((p.array() < o.box_min_m.array()).any() || (p.array() > o.box_max_m.array()).any())
        continue;
    }
    if (translational_conditioning(robot, m.q).sigma_min < o.min_sigma) continue;
    char id[32];
    std::snprintf(id, sizeof id, "r%03d", static_cast<int>(d.rows.size()) + 1);
    m.id = id;
    d.rows.push_back(m);
  }
  d.set_meta("robot", robot.name);
  d.set_meta("source", "stiff random design, seed " + std::to_string(o.seed));
  return d;
}

void check_noise_model(const NoiseModel& noise) {
  const std::pair<const char*, double> sizes[] = {
      {"tracker_sigma_m", noise.tracker_sigma_m}, {"tracker_ppm", noise.tracker_ppm},
      {"force_relative", noise.force_relative},   {"force_absolute_N", noise.force_absolute_N},
      {"joint_sigma_rad", noise.joint_sigma_rad}, {"outlier_rate", noise.outlier_rate},
      {"outlier_size_m", noise.outlier_size_m}};
  for (const auto& [name, value] : sizes)
    if (!(std::isfinite(value) && value >= 0))
      throw InvalidArgument(std::string("simulate: noise ") + name +
                            " must be finite and >= 0 (got " + fmt(value) + ")");
  if (noise.outlier_rate > kMaxOutlierRate)
    throw InvalidArgument("simulate: noise outlier_rate must be <= " + fmt(kMaxOutlierRate) +
                          " (got " + fmt(noise.outlier_rate) + ")");
  if (!noise.tracker_position_m.allFinite())
    throw InvalidArgument("simulate: noise tracker_position_m must be finite");
}

Dataset simulate(const RobotModel& robot,
                 const Truth& truth,
                 const Dataset& design,
                 const NoiseModel& noise,
                 std::vector<int>* outlier_rows) {
  check_noise_model(noise);
  validate_dataset(design, robot.dof(), false);
  DeflectionModel model(robot, truth.effects, &design);
  if (truth.theta.size() != model.parameter_count())
    throw InvalidArgument("simulate: truth has " + std::to_string(truth.theta.size()) +
                          " parameters, model '" + model.model_string() + "' needs " +
                          std::to_string(model.parameter_count()));
  if (!truth.theta.allFinite()) throw InvalidArgument("simulate: truth parameters must be finite");
  Rng rng(noise.seed);
  Dataset out = design;
  out.has_displacement = true;
  out.has_id = true;
  if (outlier_rows) outlier_rows->clear();
  const auto ctx = model.contexts(design);
  for (size_t r = 0; r < out.rows.size(); ++r) {
    auto& m = out.rows[r];
    const Eigen::Matrix<double, 6, 1> pred = model.predict(truth.theta, design.rows[r], ctx[r]);
    const Eigen::Vector3d p = robot.tool_pose(design.rows[r].q).block<3, 1>(0, 3);
    const double sigma = noise.tracker_sigma_at(p);
    for (int k = 0; k < 3; ++k) m.displacement(k) = pred(k) + sigma * rng.normal();
    if (noise.outlier_rate > 0 && rng.uniform() < noise.outlier_rate) {
      Eigen::Vector3d u(rng.normal(), rng.normal(), rng.normal());
      m.displacement += noise.outlier_size_m * u.normalized();
      if (outlier_rows) outlier_rows->push_back(static_cast<int>(r));
    }
    m.sigma_d = sigma;
    out.has_sigma = out.has_sigma || sigma > 0;
    // What the force sensor and the encoders report, not what acted.
    for (int k = 0; k < 3; ++k) {
      // Two draws per component whatever the sum, so that a seed gives the same stream.
      const double a = noise.force_relative * std::abs(m.force(k));
      const double n1 = rng.normal(), n2 = rng.normal();
      m.force(k) += noise.force_error_linear ? (a + noise.force_absolute_N) * n1
                                             : a * n1 + noise.force_absolute_N * n2;
    }
    for (int j = 0; j < m.q.size(); ++j) m.q(j) += noise.joint_sigma_rad * rng.normal();
    if (m.id.empty()) m.id = std::to_string(r + 1);
    // Absurd inputs (a link of 1e300 m, a tracker at 1e300 m) overflow: never write inf/NaN.
    if (!m.displacement.allFinite() || !std::isfinite(m.sigma_d) || !m.force.allFinite() ||
        !m.q.allFinite())
      throw NumericalError("simulate: measurement " + std::to_string(r + 1) +
                           " is not finite (the robot, truth or noise values overflow; check "
                           "their units)");
  }
  out.set_meta("robot", robot.name);
  out.set_meta("source", "stiff virtual robot");
  // Which effects the truth holds stays out of the file: a blind test must stay blind
  // (`stiff simulate --record-truth` adds it).
  out.set_meta("tracker_sigma_m", fmt(noise.tracker_sigma_m));
  out.set_meta("tracker_ppm", fmt(noise.tracker_ppm));
  out.set_meta("force_relative", fmt(noise.force_relative));
  out.set_meta("force_absolute_N", fmt(noise.force_absolute_N));
  out.set_meta("force_error_sum", noise.force_error_linear ? "linear" : "quadrature");
  out.set_meta("joint_sigma_rad", fmt(noise.joint_sigma_rad));
  out.set_meta("outlier_rate", fmt(noise.outlier_rate));
  out.set_meta("seed", std::to_string(noise.seed));
  return out;
}

}  // namespace stiff
