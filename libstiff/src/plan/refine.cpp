// Continuous NLopt refinement of a discrete plan, and the final report of a plan.
#include <Eigen/Eigenvalues>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <nlopt.hpp>

#include "plan_internal.hpp"
#include "stiff/error.hpp"
#include "stiff/model/model.hpp"

namespace stiff {

using namespace plan_detail;

namespace plan_detail {

std::vector<PlannedMeasurement> to_measurements(const CandidatePool& pool,
                                                const std::vector<int>& set) {
  std::vector<PlannedMeasurement> ms;
  const int width = set.size() >= 100 ? 3 : 2;
  for (size_t i = 0; i < set.size(); ++i) {
    const int e = set[i], p = pool.element_pose[e];
    PlannedMeasurement m;
    char id[32];
    std::snprintf(id, sizeof id, "p%0*d", width, static_cast<int>(i) + 1);
    m.id = id;
    m.pool_element = e;
    m.q_rad = pool.poses[p];
    m.force_base_N = pool.forces[pool.element_load[e]];
    m.force_flange_N = pool.flange_rotation[p].transpose() * m.force_base_N;
    m.tool_position_m = pool.tool_position_m[p];
    ms.push_back(m);
  }
  return ms;
}

void finish_result(const RobotModel& robot,
                   const CandidatePool& pool,
                   const PlanOptions& o,
                   std::vector<PlannedMeasurement> ms,
                   PlanResult& r) {
  const Criterion& crit = find_criterion(o.criterion);
  const auto& ident = pool.identified_joints;
  const int m = static_cast<int>(ident.size());
  const NoiseModel& noise = pool.options.noise;
  const auto task = task_information(robot, o.task, ident);
  std::vector<Row> rows;
  for (auto& x : ms) {
    const ChainState cs = robot.chain(x.q_rad);
    x.force_flange_N = cs.flange.block<3, 3>(0, 0).transpose() * x.force_base_N;
    x.tool_position_m = robot.point_position(cs, robot.measured_point);
    rows.push_back({x.q_rad, x.force_base_N, Eigen::Vector3d::Zero()});
  }
  const CriterionInput in = criterion_input(robot, rows, ident, noise, task);
  for (const auto& c : criterion_registry()) r.criteria[c.name] = c.value(in);
  r.criteria["count"] = static_cast<double>(ms.size());
  r.criteria["m"] = static_cast<double>(m);
  r.criterion = crit.name;
  r.larger_is_better = crit.larger_is_better;
  r.value = r.criteria[crit.name];
  r.score = criterion_score(crit, r.value);

  // Leverage tr(A_i M^-1 A_i^T)/sigma_i^2 and the drop of the criterion without element i.
  Eigen::LDLT<Eigen::MatrixXd> ldlt(in.information);
  const bool regular = ldlt.info() == Eigen::Success && ldlt.isPositive();
  for (size_t i = 0; i < ms.size(); ++i) {
    const CriterionInput one = criterion_input(robot, {rows[i]}, ident, noise, {});
    CriterionInput minus = in;
    minus.information -= one.information;
    minus.jacobian_information -= one.jacobian_information;
    minus.count -= 1;
    ms[i].contribution =
        regular ? (ldlt.solve(one.information)).trace() : std::numeric_limits<double>::quiet_NaN();
    const double s_minus = minus.count > 0 ? criterion_score(crit, crit.value(minus)) : -kInf;
    ms[i].criterion_drop = r.score - s_minus;
  }
  r.measurements = std::move(ms);
  r.robot = robot.name;
  r.identified_joints = ident;
  r.pool_size = pool.size();
  r.pool_poses = static_cast<int>(pool.poses.size());
  r.pool_loads = static_cast<int>(pool.forces.size());
  r.min_sigma_m = pool.min_sigma_m;
  r.seed = o.seed;
}

}  // namespace plan_detail

namespace {

struct RefineProblem {
  const RobotModel* robot;
  const CandidatePool* pool;
  const PlanOptions* o;
  const Criterion* crit;
  std::vector<double> task;
  std::vector<int> free_joints;
  bool loads_free;
  std::vector<PlannedMeasurement> base;
  long evals = 0;
  double best = -kInf;
  std::vector<double> best_x;
  bool cancelled = false;

  std::vector<Row> rows(const double* x) const {
    std::vector<Row> out;
    int k = 0;
    for (const auto& b : base) {
      Row r;
      r.q = b.q_rad;
      for (int j : free_joints) r.q(j) = x[k++];
      r.force = b.force_base_N;
      if (loads_free)
        for (int c = 0; c < 3; ++c) r.force(c) = x[k++];
      out.push_back(r);
    }
    return out;
  }

  // Score, or a large negative penalty outside the singularity threshold, box or load limit.
  double evaluate(const double* x) {
    const auto rs = rows(x);
    const PoolOptions& po = pool->options;
    for (const auto& r : rs) {
      if (r.force.norm() > po.load_max_magnitude_N * (1 + 1e-12)) return -1e300;
      const ChainState cs = robot->chain(r.q);
      const Eigen::Vector3d p = robot->point_position(cs, robot->measured_point);
      if (po.use_workspace_box &&
          !((p.array() >= po.box_min_m.array()).all() && (p.array() <= po.box_max_m.array()).all()))
        return -1e300;
      const Eigen::Matrix3Xd jp = robot->jacobian_at(cs, p).topRows<3>();
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(jp * jp.transpose(),
                                                        Eigen::EigenvaluesOnly);
      if (std::sqrt(std::max(0.0, es.eigenvalues()(0))) < pool->min_sigma_m) return -1e300;
    }
    const CriterionInput in =
        criterion_input(*robot, rs, pool->identified_joints, pool->options.noise, task);
    const double s = criterion_score(*crit, crit->value(in));
    return std::isfinite(s) ? s : -1e300;
  }
};

double objective(unsigned n, const double* x, double* grad, void* data) {
  (void)grad;
  auto* p = static_cast<RefineProblem*>(data);
  const double s = p->evaluate(x);
  ++p->evals;
  if (s > p->best) {
    p->best = s;
    p->best_x.assign(x, x + n);
  }
  if (p->o->progress && p->evals % p->o->progress_interval == 0) {
    PlanProgress pr;
    pr.optimizer = "nlopt";
    pr.iteration = p->evals;
    pr.total = p->o->refine.max_evaluations;
    pr.best_score = p->best;
    pr.current_score = s;
    if (!p->o->progress(pr)) {
      p->cancelled = true;
      throw nlopt::forced_stop();
    }
  }
  return s;
}

}  // namespace

std::vector<PlannedMeasurement> refine_plan(const RobotModel& robot,
                                            const CandidatePool& pool,
                                            const std::vector<PlannedMeasurement>& start,
                                            const PlanOptions& o,
                                            OptimizerTrace* trace) {
  const auto t0 = std::chrono::steady_clock::now();
  const PoolOptions& po = pool.options;
  const int n = robot.dof();
  if (pool.dof != n) throw InvalidArgument("plan refine: pool and robot differ in joint count");
  if (start.empty()) throw InvalidArgument("plan refine: nothing to refine");
  if (o.refine.max_evaluations < 1)
    throw InvalidArgument("plan refine: max_evaluations must be >= 1");
  const nlopt_algorithm alg = nlopt_algorithm_from_string(o.refine.algorithm.c_str());
  if (static_cast<int>(alg) < 0 || o.refine.algorithm.rfind("LN_", 0) != 0)
    throw InvalidArgument("plan refine: '" + o.refine.algorithm +
                          "' is not a derivative-free local NLopt algorithm (e.g. LN_BOBYQA, "
                          "LN_COBYLA, LN_SBPLX)");
  RefineProblem prob;
  prob.robot = &robot;
  prob.pool = &pool;
  prob.o = &o;
  prob.crit = &find_criterion(o.criterion);
  prob.task = task_information(robot, o.task, pool.identified_joints);
  if (prob.crit->name == "task" && prob.task.empty())
    throw InvalidArgument("plan: criterion 'task' needs task poses and loads (PlanOptions::task)");
  for (int j = 0; j < n; ++j)
    if (po.q_fixed.empty() || std::isnan(po.q_fixed[j])) prob.free_joints.push_back(j);
  prob.loads_free = o.refine.refine_loads && po.fixture_directions.empty();
  prob.base = start;

  std::vector<double> x, lb, ub, step;
  for (const auto& m : start) {
    if (m.q_rad.size() != n) throw InvalidArgument("plan refine: pose with wrong joint count");
    for (int j : prob.free_joints) {
      const auto& jt = robot.joints[j];
      const double mid = 0.5 * (jt.lower + jt.upper);
      const double half = 0.5 * (jt.upper - jt.lower) * po.range_fraction;
      x.push_back(m.q_rad(j));
      lb.push_back(std::min(mid - half, m.q_rad(j)));
      ub.push_back(std::max(mid + half, m.q_rad(j)));
      step.push_back(std::min(0.05, 0.25 * (ub.back() - lb.back())));
    }
    if (prob.loads_free) {
      for (int c = 0; c < 3; ++c) {
        const double v = m.force_base_N(c), lo = po.load_min_N, hi = po.load_max_N;
        double a = -hi, b = hi;
        if (lo > 0 && v > 0) a = lo;
        if (lo > 0 && v < 0) b = -lo;
        x.push_back(v);
        lb.push_back(std::min(a, v));
        ub.push_back(std::max(b, v));
        step.push_back(std::max(1e-3, std::min(2.0, 0.25 * (ub.back() - lb.back()))));
      }
    }
  }
  const unsigned dim = static_cast<unsigned>(x.size());
  const double start_score = prob.evaluate(x.data());
  prob.best = start_score;
  prob.best_x = x;
  std::string message = "no free variable";
  if (dim > 0) {
    nlopt::opt opt(static_cast<nlopt::algorithm>(alg), dim);
    opt.set_lower_bounds(lb);
    opt.set_upper_bounds(ub);
    opt.set_initial_step(step);
    opt.set_max_objective(objective, &prob);
    opt.set_maxeval(o.refine.max_evaluations);
    opt.set_xtol_rel(1e-10);
    std::vector<double> xo = x;
    double f = 0;
    try {
      const nlopt::result res = opt.optimize(xo, f);
      message = nlopt_result_to_string(static_cast<nlopt_result>(res));
    } catch (const nlopt::forced_stop&) {
      message = "forced stop";
    } catch (const nlopt::roundoff_limited&) {
      message = "roundoff limited";
    } catch (const std::exception& e) {
      message = std::string("nlopt: ") + e.what();
    }
    if (prob.cancelled) throw Cancelled("plan: cancelled by the progress callback during nlopt");
  }
  std::vector<PlannedMeasurement> out = start;
  const bool better = prob.best > start_score;
  if (better) {
    const auto rs = prob.rows(prob.best_x.data());
    for (size_t i = 0; i < out.size(); ++i) {
      out[i].q_rad = rs[i].q;
      out[i].force_base_N = rs[i].force;
      out[i].pool_element = -1;
      const ChainState cs = robot.chain(rs[i].q);
      out[i].force_flange_N = cs.flange.block<3, 3>(0, 0).transpose() * rs[i].force;
      out[i].tool_position_m = robot.point_position(cs, robot.measured_point);
    }
  }
  if (trace) {
    trace->optimizer = "nlopt";
    trace->start_score = start_score;
    trace->best_score = better ? prob.best : start_score;
    trace->best_value = prob.crit->larger_is_better ? trace->best_score : -trace->best_score;
    trace->iterations = prob.evals;
    trace->evaluations = prob.evals;
    trace->accepted = better ? 1 : 0;
    trace->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    trace->message = o.refine.algorithm + ": " + message;
  }
  return out;
}

}  // namespace stiff
