// Criteria registry and evaluation of a given set (Jiang & Fang 2023, docs/planning.md).
#include <cmath>

#include "plan_internal.hpp"
#include "stiff/error.hpp"
#include "stiff/model/model.hpp"

namespace stiff {
namespace plan_detail {

void to_array(const Eigen::MatrixXd& a, double* out) {
  const int m = static_cast<int>(a.rows());
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < m; ++j) out[i * m + j] = a(i, j);
}

Eigen::MatrixXd from_lower(const double* lower, int m) {
  Eigen::MatrixXd a(m, m);
  for (int i = 0; i < m; ++i)
    for (int j = 0; j <= i; ++j) a(i, j) = a(j, i) = lower[i * m + j];
  return a;
}

namespace {

struct Entry {
  const char* name;
  Crit id;
  bool larger_is_better;
  const char* description;
};

const Entry kEntries[] = {
    {"kappa_a", Crit::kappa_a, true,
     "inverse condition number of the stacked observation matrix, m/sqrt(tr(M) tr(M^-1)) "
     "(Jiang & Fang 2023, eq. 9)"},
    {"kappa_j", Crit::kappa_j, true,
     "inverse condition number of the stacked translational Jacobians (identified columns, "
     "unweighted), pose only (Jiang & Fang 2023, eq. 6)"},
    {"d_opt", Crit::d_opt, true, "log det M (D-optimality)"},
    {"a_opt", Crit::a_opt, false, "tr(M^-1), sum of the compliance variances (A-optimality)"},
    {"e_opt", Crit::e_opt, true, "smallest eigenvalue of M (E-optimality)"},
    {"o1", Crit::o1, true,
     "observability index O1 = (prod sigma_k)^(1/m)/sqrt(N) (Sun & Hollerbach 2008)"},
    {"task", Crit::task, false,
     "expected RMS error of the predicted deflection over the task poses and loads [m]"},
};

double registry_value(Crit id, bool larger, const CriterionInput& in) {
  const int m = static_cast<int>(in.information.rows());
  if (m == 0 || m > kMaxM || in.information.cols() != m)
    throw InvalidArgument("criterion: information matrix must be m x m with 1 <= m <= 16");
  if (id == Crit::kappa_j &&
      (in.jacobian_information.rows() != m || in.jacobian_information.cols() != m))
    throw InvalidArgument("criterion kappa_j: jacobian_information must be m x m");
  if (id == Crit::task && in.task_information.size() == 0)
    return std::numeric_limits<double>::quiet_NaN();
  if (id == Crit::task && (in.task_information.rows() != m || in.task_information.cols() != m))
    throw InvalidArgument("criterion task: task_information must be m x m");
  double a[kMaxM * kMaxM], j[kMaxM * kMaxM], t[kMaxM * kMaxM];
  to_array(in.information, a);
  if (id == Crit::kappa_j) to_array(in.jacobian_information, j);
  Context c;
  c.id = id;
  c.m = m;
  c.count = std::max(in.count, 1);
  if (id == Crit::task) {
    to_array(in.task_information, t);
    c.task = t;
  }
  const double s = score<0>(c, a, j);
  return larger ? s : -s;
}

std::vector<Criterion> make_registry() {
  std::vector<Criterion> r;
  for (const auto& e : kEntries) {
    Criterion c;
    c.name = e.name;
    c.description = e.description;
    c.larger_is_better = e.larger_is_better;
    const Crit id = e.id;
    const bool larger = e.larger_is_better;
    c.value = [id, larger](const CriterionInput& in) { return registry_value(id, larger, in); };
    r.push_back(std::move(c));
  }
  return r;
}

std::string known_names() {
  std::string s;
  for (const auto& e : kEntries) s += (s.empty() ? "" : ", ") + std::string(e.name);
  return s;
}

}  // namespace

Crit criterion_id(const std::string& name) {
  for (const auto& e : kEntries)
    if (name == e.name) return e.id;
  throw InvalidArgument("unknown plan criterion '" + name + "' (known: " + known_names() + ")");
}

std::vector<double> task_information(const RobotModel& robot,
                                     const Dataset& task,
                                     const std::vector<int>& identified) {
  const int m = static_cast<int>(identified.size());
  if (task.rows.empty()) return {};
  validate_dataset(task, robot.dof(), false);
  Eigen::MatrixXd s = Eigen::MatrixXd::Zero(m, m);
  for (const auto& row : task.rows) {
    const ChainState cs = robot.chain(row.q);
    const Matrix6X<double> jm =
        robot.jacobian_at(cs, robot.point_position(cs, robot.measured_point));
    const Matrix6X<double> jl = robot.jacobian_at(cs, robot.point_position(cs, robot.load_point));
    Eigen::Matrix<double, 6, 1> w;
    w << row.force, row.moment;
    const Eigen::Matrix<double, 3, Eigen::Dynamic> b = observation_block(jm, jl, w);
    Eigen::Matrix<double, 3, Eigen::Dynamic> bi(3, m);
    for (int k = 0; k < m; ++k) bi.col(k) = b.col(identified[k]);
    s += bi.transpose() * bi;
  }
  s /= static_cast<double>(task.rows.size());
  std::vector<double> out(m * m);
  to_array(s, out.data());
  return out;
}

CriterionInput criterion_input(const RobotModel& robot,
                               const std::vector<Row>& rows,
                               const std::vector<int>& identified,
                               const NoiseModel& noise,
                               const std::vector<double>& task) {
  const int m = static_cast<int>(identified.size());
  CriterionInput in;
  in.information = Eigen::MatrixXd::Zero(m, m);
  in.jacobian_information = Eigen::MatrixXd::Zero(m, m);
  in.count = static_cast<int>(rows.size());
  for (const auto& row : rows) {
    const ChainState cs = robot.chain(row.q);
    const Eigen::Vector3d p = robot.point_position(cs, robot.measured_point);
    const Matrix6X<double> jm = robot.jacobian_at(cs, p);
    const Matrix6X<double> jl = robot.jacobian_at(cs, robot.point_position(cs, robot.load_point));
    Eigen::Matrix<double, 6, 1> w;
    w << row.force, row.moment;
    const Eigen::Matrix<double, 3, Eigen::Dynamic> a = observation_block(jm, jl, w);
    Eigen::Matrix<double, 3, Eigen::Dynamic> ai(3, m), ji(3, m);
    for (int k = 0; k < m; ++k) {
      ai.col(k) = a.col(identified[k]);
      ji.col(k) = jm.block<3, 1>(0, identified[k]);
    }
    const double sigma = noise.tracker_sigma_at(p);
    if (!(sigma > 0)) throw InvalidArgument("criteria: tracker sigma must be > 0");
    in.information += ai.transpose() * ai / (sigma * sigma);
    in.jacobian_information += ji.transpose() * ji;
  }
  if (!task.empty()) in.task_information = Eigen::Map<const Eigen::MatrixXd>(task.data(), m, m);
  return in;
}

}  // namespace plan_detail

const std::vector<Criterion>& criterion_registry() {
  static const std::vector<Criterion> r = plan_detail::make_registry();
  return r;
}

const Criterion& find_criterion(const std::string& name) {
  const auto& r = criterion_registry();
  for (const auto& c : r)
    if (c.name == name) return c;
  plan_detail::criterion_id(name);  // throws with the list of names
  throw InvalidArgument("unknown plan criterion '" + name + "'");
}

std::vector<std::string> criterion_names() {
  std::vector<std::string> n;
  for (const auto& c : criterion_registry()) n.push_back(c.name);
  return n;
}

double criterion_score(const Criterion& c, double value) {
  if (std::isnan(value)) return -plan_detail::kInf;
  return c.larger_is_better ? value : -value;
}

std::map<std::string, double> evaluate_criteria(const RobotModel& robot,
                                                const Dataset& data,
                                                const CriteriaOptions& options) {
  validate_dataset(data, robot.dof(), false);
  if (data.rows.empty()) throw InvalidArgument("evaluate_criteria: the dataset has no rows");
  const int n = robot.dof();
  std::vector<int> identified = options.identified_joints;
  if (identified.empty()) {
    const Eigen::MatrixXd a = observation_matrix(robot, data);
    const Eigen::VectorXd norms = a.colwise().norm();
    const double top = norms.maxCoeff();
    for (int j = 0; j < n; ++j)
      if (norms(j) > 1e-9 * top && norms(j) > 0) identified.push_back(j);
  }
  for (int j : identified)
    if (j < 0 || j >= n) throw InvalidArgument("evaluate_criteria: identified joint out of range");
  if (identified.empty())
    throw InvalidArgument("evaluate_criteria: no joint compliance is identifiable");
  std::vector<plan_detail::Row> rows;
  for (const auto& r : data.rows) rows.push_back({r.q, r.force, r.moment});
  const auto task = plan_detail::task_information(robot, options.task, identified);
  const CriterionInput in =
      plan_detail::criterion_input(robot, rows, identified, options.noise, task);
  std::map<std::string, double> out;
  for (const auto& c : criterion_registry()) out[c.name] = c.value(in);
  out["count"] = static_cast<double>(data.rows.size());
  out["m"] = static_cast<double>(identified.size());
  return out;
}

}  // namespace stiff
