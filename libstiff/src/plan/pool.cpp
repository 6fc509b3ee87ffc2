// Candidate pool Omega = Omega_J x Omega_F (Jiang & Fang 2023, section 2.2 steps 1-2).
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

#include "io/number_text.hpp"
#include "plan_internal.hpp"
#include "stiff/error.hpp"
#include "stiff/kinematics/joint_torque.hpp"
#include "stiff/kinematics/sampling.hpp"
#include "stiff/random.hpp"

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace stiff {
namespace {

std::string num(double v) { return detail::num(v, 6); }

struct PoseData {
  Eigen::Matrix3Xd jm, jl;
  Eigen::Matrix3d rot;
  Eigen::Vector3d tool;
  double sigma_min;
};

PoseData pose_data(const RobotModel& robot, const Eigen::VectorXd& q) {
  const ChainState s = robot.chain(q);
  PoseData d;
  d.tool = robot.point_position(s, robot.measured_point);
  d.jm = robot.jacobian_at(s, d.tool).topRows<3>();
  d.jl = robot.jacobian_at(s, robot.point_position(s, robot.load_point)).topRows<3>();
  d.rot = s.flange.block<3, 3>(0, 0);
  // sigma_min(Jp) from the 3 x 3 Gram matrix: cheaper than an SVD of 3 x n.
  const Eigen::Matrix3d g = d.jm * d.jm.transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(g, Eigen::EigenvaluesOnly);
  d.sigma_min = std::sqrt(std::max(0.0, es.eigenvalues()(0)));
  return d;
}

void add_pose(CandidatePool& p, const Eigen::VectorXd& q, const PoseData& d, double sigma) {
  p.poses.push_back(q);
  p.jacobian_meas.push_back(d.jm);
  p.jacobian_load.push_back(d.jl);
  p.flange_rotation.push_back(d.rot);
  p.tool_position_m.push_back(d.tool);
  p.sigma_m.push_back(sigma);
  p.sigma_min_m.push_back(d.sigma_min);
}

bool in_box(const PoolOptions& o, const Eigen::Vector3d& x) {
  if (!o.use_workspace_box) return true;
  return (x.array() >= o.box_min_m.array()).all() && (x.array() <= o.box_max_m.array()).all();
}

std::vector<Eigen::Vector3d> make_loads(const PoolOptions& o, Rng& rng) {
  std::vector<Eigen::Vector3d> loads;
  const double max_mag = o.load_max_magnitude_N;
  if (!(max_mag > 0)) throw InvalidArgument("plan pool: load_max_magnitude_N must be > 0");
  if (!o.fixture_directions.empty()) {
    if (o.fixture_forces_N.empty())
      throw InvalidArgument("plan pool: fixture directions need fixture_forces_N");
    for (const auto& d : o.fixture_directions) {
      if (!d.allFinite() || d.norm() == 0)
        throw InvalidArgument("plan pool: a fixture direction is zero or not finite");
      for (double f : o.fixture_forces_N) {
        if (!(f > 0) || !std::isfinite(f))
          throw InvalidArgument("plan pool: fixture forces must be finite and > 0 N");
        if (f <= max_mag) loads.push_back(f * d.normalized());
      }
    }
    if (loads.empty())
      throw InvalidArgument("plan pool: empty load range (every fixture force > max magnitude)");
    return loads;
  }
  if (!(o.load_min_N >= 0 && o.load_max_N >= o.load_min_N && o.load_max_N > 0) ||
      !std::isfinite(o.load_max_N))
    throw InvalidArgument("plan pool: empty load range [" + num(o.load_min_N) + ", " +
                          num(o.load_max_N) + "] N (need 0 <= min <= max, max > 0)");
  if (!(o.load_step_N >= 0)) throw InvalidArgument("plan pool: load_step_N must be >= 0");
  if (o.load_count < 0) throw InvalidArgument("plan pool: load_count must be >= 0");
  std::vector<double> axis;  // signed per-axis values of the grid
  if (o.load_step_N > 0) {
    axis = signed_load_grid(o.load_min_N, o.load_max_N, o.load_step_N);
    if (axis.empty())
      throw InvalidArgument("plan pool: empty load range: no multiple of " + num(o.load_step_N) +
                            " N in [" + num(o.load_min_N) + ", " + num(o.load_max_N) + "] N");
  }
  auto ok = [&](const Eigen::Vector3d& f) {
    return f.norm() > 0 && f.norm() <= max_mag * (1 + 1e-12);
  };
  if (o.load_count == 0) {
    if (axis.empty())
      throw InvalidArgument("plan pool: load_count 0 (whole grid) needs load_step_N > 0");
    const double total = std::pow(static_cast<double>(axis.size()), 3);
    if (total > 1e5)
      throw InvalidArgument("plan pool: load grid has " + num(total) + " loads (> 1e5)");
    for (double x : axis)
      for (double y : axis)
        for (double z : axis)
          if (ok(Eigen::Vector3d(x, y, z))) loads.emplace_back(x, y, z);
  } else {
    std::set<std::tuple<double, double, double>> seen;
    const long max_tries = 200L * o.load_count + 1000;
    for (long t = 0; t < max_tries && static_cast<int>(loads.size()) < o.load_count; ++t) {
      Eigen::Vector3d f;
      for (int k = 0; k < 3; ++k)
        f(k) = random_load_component(o.load_min_N, o.load_max_N, axis, rng);
      if (!ok(f)) continue;
      if (!axis.empty() && !seen.insert({f(0), f(1), f(2)}).second) continue;
      loads.push_back(f);
    }
  }
  if (loads.empty())
    throw InvalidArgument("plan pool: empty load range: no load with per-axis magnitude in [" +
                          num(o.load_min_N) + ", " + num(o.load_max_N) +
                          "] N and |F| <= " + num(max_mag) + " N");
  return loads;
}

}  // namespace

CandidatePool build_pool(const RobotModel& robot, const PoolOptions& o) {
  const int n = robot.dof();
  if (n == 0) throw InvalidArgument("plan pool: robot has no joints");
  if (!(o.range_fraction > 0 && o.range_fraction <= 1))
    throw InvalidArgument("plan pool: range_fraction must be in (0, 1]");
  if (!o.q_fixed.empty() && static_cast<int>(o.q_fixed.size()) != n)
    throw InvalidArgument("plan pool: q_fixed needs one value per joint (" + std::to_string(n) +
                          ")");
  for (size_t j = 0; j < o.q_fixed.size(); ++j) {
    const double v = o.q_fixed[j];
    const auto& joint = robot.joints[j];
    if (std::isnan(v)) continue;  // free
    if (!(std::isfinite(v) && joint.lower <= v && v <= joint.upper)) {
      std::ostringstream m;
      m.precision(6);
      m << "plan: joint " << j + 1 << " fixed at " << v * 180.0 / M_PI
        << " deg is outside its limits [" << joint.lower * 180.0 / M_PI << ", "
        << joint.upper * 180.0 / M_PI << "] deg";
      throw InvalidArgument(m.str());
    }
  }
  if (!(o.min_sigma_m >= 0)) throw InvalidArgument("plan pool: min_sigma_m must be >= 0");
  if (o.use_workspace_box && !(o.box_min_m.array() < o.box_max_m.array()).all())
    throw InvalidArgument("plan pool: workspace box needs min < max on every axis");
  Rng rng(o.seed);
  CandidatePool p;
  p.dof = n;
  p.options = o;
  p.min_sigma_m = o.min_sigma_m;

  auto sigma_at = [&](const Eigen::Vector3d& x) {
    const double s = o.noise.tracker_sigma_at(x);
    if (!(s > 0) || !std::isfinite(s))
      throw InvalidArgument("plan pool: tracker sigma must be > 0 (row weights 1/sigma)");
    return s;
  };
  auto accept = [&](const PoseData& d) {
    if (d.sigma_min < o.min_sigma_m) {
      ++p.rejected_singular;
      return false;
    }
    if (!in_box(o, d.tool)) {
      ++p.rejected_workspace;
      return false;
    }
    return true;
  };

  std::vector<std::pair<int, Eigen::Vector3d>> file_elements;  // (pose, force) from the file
  if (!o.candidate_file.empty()) {
    const Dataset cand = read_measurements_csv(o.candidate_file, n);
    validate_dataset(cand, n, false);
    std::vector<Eigen::VectorXd> seen;  // distinct file poses
    std::vector<int> seen_pool;         // their pool pose index, -1 when rejected
    for (const auto& row : cand.rows) {
      if (o.candidate_loads_from_file && row.moment.norm() != 0)
        throw InvalidArgument("plan pool: candidate row '" + row.id +
                              "' has a moment; plan loads are forces only");
      int idx = -1;
      size_t k = 0;
      while (k < seen.size() && seen[k] != row.q) ++k;
      if (k < seen.size()) {
        idx = seen_pool[k];
      } else {
        ++p.poses_drawn;
        seen.push_back(row.q);
        const PoseData d = pose_data(robot, row.q);
        if (accept(d)) {
          add_pose(p, row.q, d, sigma_at(d.tool));
          idx = static_cast<int>(p.poses.size()) - 1;
        }
        seen_pool.push_back(idx);
      }
      if (o.candidate_loads_from_file && idx >= 0) file_elements.push_back({idx, row.force});
    }
  } else {
    if (o.pose_count <= 0) throw InvalidArgument("plan pool: pose_count must be > 0");
    const long max_tries = 1000L * o.pose_count;
    while (static_cast<int>(p.poses.size()) < o.pose_count && p.poses_drawn < max_tries) {
      const Eigen::VectorXd q = random_joint_pose(robot, o.range_fraction, o.q_fixed, rng);
      ++p.poses_drawn;
      const PoseData d = pose_data(robot, q);
      if (accept(d)) add_pose(p, q, d, sigma_at(d.tool));
    }
  }
  if (p.poses.empty())
    throw InvalidArgument("plan pool: all " + std::to_string(p.poses_drawn) +
                          " candidate poses are near-singular (sigma_min of the translational "
                          "Jacobian < " +
                          num(o.min_sigma_m) + " m: " + std::to_string(p.rejected_singular) +
                          ") or outside the workspace box (" +
                          std::to_string(p.rejected_workspace) + ")");

  if (o.candidate_loads_from_file && !o.candidate_file.empty()) {
    // Elements are the file's rows; loads deduplicated.
    for (const auto& [pose, f] : file_elements) {
      int l = -1;
      for (size_t k = 0; k < p.forces.size(); ++k)
        if (p.forces[k] == f) l = static_cast<int>(k);
      if (l < 0) {
        p.forces.push_back(f);
        l = static_cast<int>(p.forces.size()) - 1;
      }
      p.element_pose.push_back(pose);
      p.element_load.push_back(l);
    }
  } else {
    p.forces = make_loads(o, rng);
    const double total = static_cast<double>(p.poses.size()) * static_cast<double>(p.forces.size());
    if (total > static_cast<double>(o.max_elements))
      throw InvalidArgument("plan pool: " + std::to_string(p.poses.size()) + " poses x " +
                            std::to_string(p.forces.size()) + " loads exceeds max_elements " +
                            std::to_string(o.max_elements));
    p.element_pose.reserve(static_cast<size_t>(total));
    p.element_load.reserve(static_cast<size_t>(total));
    for (int i = 0; i < static_cast<int>(p.poses.size()); ++i)
      for (int l = 0; l < static_cast<int>(p.forces.size()); ++l) {
        p.element_pose.push_back(i);
        p.element_load.push_back(l);
      }
  }
  p.finalize();
  return p;
}

CandidatePool pool_from_dataset(const RobotModel& robot,
                                const Dataset& data,
                                const NoiseModel& noise) {
  validate_dataset(data, robot.dof(), false);
  if (data.rows.empty()) throw InvalidArgument("plan pool: the dataset has no rows");
  CandidatePool p;
  p.dof = robot.dof();
  p.options.noise = noise;
  p.options.min_sigma_m = 0.0;
  for (const auto& row : data.rows) {
    if (row.moment.norm() != 0)
      throw InvalidArgument("plan pool: row '" + row.id +
                            "' has a moment; plan loads are forces only");
    const PoseData d = pose_data(robot, row.q);
    const double s = noise.tracker_sigma_at(d.tool);
    if (!(s > 0)) throw InvalidArgument("plan pool: tracker sigma must be > 0");
    add_pose(p, row.q, d, s);
    p.forces.push_back(row.force);
    p.element_pose.push_back(static_cast<int>(p.poses.size()) - 1);
    p.element_load.push_back(static_cast<int>(p.forces.size()) - 1);
  }
  p.poses_drawn = static_cast<long>(data.rows.size());
  p.finalize();
  return p;
}

void CandidatePool::finalize() {
  const size_t np = poses.size();
  if (dof <= 0) throw InvalidArgument("plan pool: dof must be > 0");
  if (jacobian_meas.size() != np || jacobian_load.size() != np || sigma_m.size() != np)
    throw InvalidArgument("plan pool: per-pose arrays differ in size");
  if (element_pose.size() != element_load.size())
    throw InvalidArgument("plan pool: element arrays differ in size");
  for (size_t e = 0; e < element_pose.size(); ++e)
    if (element_pose[e] < 0 || element_pose[e] >= static_cast<int>(np) || element_load[e] < 0 ||
        element_load[e] >= static_cast<int>(forces.size()))
      throw InvalidArgument("plan pool: element " + std::to_string(e) + " out of range");
  if (identified_joints.empty()) {
    // A joint's column of A is J_p[:, j] (J_l[:, j] . F): identically zero when either
    // Jacobian column vanishes at every pose (e.g. joint 6 with the point on its axis).
    std::vector<double> s(dof, 0.0);
    for (size_t i = 0; i < np; ++i)
      for (int j = 0; j < dof; ++j)
        s[j] = std::max(s[j], jacobian_meas[i].col(j).norm() * jacobian_load[i].col(j).norm());
    const double top = *std::max_element(s.begin(), s.end());
    for (int j = 0; j < dof; ++j)
      if (s[j] > 1e-9 * top && s[j] > 0) identified_joints.push_back(j);
  }
  const int m = identified_count();
  if (m == 0) throw InvalidArgument("plan pool: no joint compliance is identifiable");
  if (m > plan_detail::kMaxM)
    throw InvalidArgument("plan pool: at most " + std::to_string(plan_detail::kMaxM) +
                          " identified joints supported");
  auto k = std::make_shared<plan_detail::KernelData>();
  k->packed_gram.assign(np * m * m, 0.0);
  k->packed_load_jacobian.assign(np * 3 * m, 0.0);
  k->weight2.assign(np, 0.0);
  for (size_t i = 0; i < np; ++i) {
    for (int a = 0; a < m; ++a) {
      const int ja = identified_joints[a];
      for (int b = 0; b < m; ++b)
        k->packed_gram[i * m * m + a * m + b] =
            jacobian_meas[i].col(ja).dot(jacobian_meas[i].col(identified_joints[b]));
      for (int r = 0; r < 3; ++r)
        k->packed_load_jacobian[i * 3 * m + 3 * a + r] = jacobian_load[i](r, ja);
    }
    k->weight2[i] = 1.0 / (sigma_m[i] * sigma_m[i]);
  }
  k->packed_force.resize(3 * forces.size());
  for (size_t l = 0; l < forces.size(); ++l)
    for (int r = 0; r < 3; ++r) k->packed_force[3 * l + r] = forces[l](r);
  // Rows of the element table start on cache lines and are padded to whole lines.
  constexpr int kLine = plan_detail::kCacheLineDoubles;
  k->element_table_stride = (plan_detail::packed_size(m) + kLine - 1) / kLine * kLine;
  kernel = k;
  // Per-element A_e^T A_e / sigma_e^2 for the optimizers' inner loop, below a memory budget
  // (computed by the kernels from the per-pose data just stored).
  const size_t ne = element_pose.size(), stride = static_cast<size_t>(k->element_table_stride);
  if (static_cast<double>(ne) * stride * sizeof(double) <= plan_detail::kElementTableBudgetBytes) {
    k->element_table_storage.assign(ne * stride, 0.0);
    double* table = k->element_table_storage.data();
    for (size_t e = 0; e < ne; ++e)
      plan_detail::element_information<0>(*this, static_cast<int>(e), table + e * stride);
  }
}

namespace plan_detail {

namespace {
constexpr std::size_t kHugePageBytes = std::size_t{2} << 20;
std::align_val_t table_alignment(std::size_t bytes) {
  return std::align_val_t{bytes >= kHugePageBytes ? kHugePageBytes : std::size_t{kCacheLineBytes}};
}
}  // namespace

void* allocate_table(std::size_t bytes) {
  void* p = ::operator new(bytes, table_alignment(bytes));
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  // Before the first write, so that the pages are faulted in huge. Only a hint: ignore errors.
  if (bytes >= kHugePageBytes) madvise(p, bytes, MADV_HUGEPAGE);
#endif
  return p;
}

void free_table(void* p, std::size_t bytes) noexcept {
  ::operator delete(p, table_alignment(bytes));
}

const KernelData& kernel_of(const CandidatePool& p) {
  if (!p.kernel) throw InvalidArgument("plan: the pool is not finalized");
  return *p.kernel;
}

}  // namespace plan_detail

Eigen::Matrix<double, 3, Eigen::Dynamic> CandidatePool::block(int e) const {
  if (e < 0 || e >= size()) throw InvalidArgument("plan pool: element index out of range");
  const int p = element_pose[e];
  const int m = identified_count();
  Eigen::Matrix<double, 3, Eigen::Dynamic> a(3, m);
  for (int k = 0; k < m; ++k) {
    const int j = identified_joints[k];
    a.col(k) =
        jacobian_meas[p].col(j) * force_torque(jacobian_load[p].col(j), forces[element_load[e]]);
  }
  return a;
}

Eigen::MatrixXd CandidatePool::information(int e) const {
  const auto a = block(e);
  return plan_detail::kernel_of(*this).weight2[element_pose[e]] * (a.transpose() * a);
}

}  // namespace stiff
