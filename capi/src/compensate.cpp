// C ABI of inverse kinematics, path files and compensation (stiff_compensate.h).
#include "stiff/compensate/compensate.hpp"

#include <algorithm>

#include "boundary.hpp"
#include "handles.hpp"
#include "stiff/compensate/ik.hpp"
#include "stiff/io/path_io.hpp"
#include "stiff/sim/simulate.hpp"
#include "stiff/stiff_compensate.h"

using namespace stiff;
using stiff::capi::fail;
using stiff::capi::guarded;
using stiff::capi::require;
using stiff::capi::require_finite;

static_assert(STIFF_POINT_SINGULAR == kPointSingular);
static_assert(STIFF_POINT_UNREACHABLE == kPointUnreachable);
static_assert(STIFF_POINT_BRANCH_CHANGE == kPointBranchChange);
static_assert(STIFF_POINT_JUMP == kPointJump);
static_assert(STIFF_POINT_NOT_CONVERGED == kPointNotConverged);

namespace {

std::vector<Eigen::Matrix4d> poses_of(const double* poses, size_t rows) {
  require(poses, "poses");
  std::vector<Eigen::Matrix4d> out;
  out.reserve(rows);
  for (size_t i = 0; i < rows; ++i)
    out.push_back(capi::rigid_pose_at(poses + 16 * i, ("poses row " + std::to_string(i)).c_str()));
  return out;
}

Eigen::VectorXd joints_of(const RobotModel& r, const double* q, const char* what) {
  Eigen::VectorXd v(r.dof());
  require_finite(q, static_cast<size_t>(r.dof()), what);
  for (int j = 0; j < r.dof(); ++j) v(j) = q[j];
  return v;
}

Eigen::MatrixXd rows_of(const double* v, size_t rows, Eigen::Index cols, const char* what) {
  require(v, what);
  require_finite(v, stiff::capi::values_of(rows, static_cast<size_t>(cols), what), what);
  Eigen::MatrixXd m(static_cast<Eigen::Index>(rows), cols);
  for (Eigen::Index i = 0; i < m.rows(); ++i)
    for (Eigen::Index c = 0; c < cols; ++c) m(i, c) = v[i * cols + c];
  return m;
}

void write_rows(const Eigen::MatrixXd& m, double* dst) {
  for (Eigen::Index i = 0; i < m.rows(); ++i)
    for (Eigen::Index c = 0; c < m.cols(); ++c) dst[i * m.cols() + c] = m(i, c);
}

}  // namespace

stiff_status stiff_ik_analytic(int* analytic, const stiff_robot* robot) {
  return guarded(__func__, [&] {
    require(analytic, "analytic");
    require(robot, "robot");
    *analytic = analyse_wrist(robot->model).analytic ? 1 : 0;
    return STIFF_OK;
  });
}

namespace {
void tool_poses_into(double* poses,
                     size_t capacity,
                     size_t* needed,
                     const stiff_robot* robot,
                     const double* q,
                     size_t rows) {
  const RobotModel& r = robot->model;
  stiff::capi::require_capacity(stiff::capi::values_of(rows, 16, "poses"), poses, capacity, needed);
  const Eigen::MatrixXd qm = rows_of(q, rows, r.dof(), "q");
  for (Eigen::Index i = 0; i < qm.rows(); ++i) {
    const Eigen::Matrix4d t = r.tool_pose(qm.row(i).transpose());
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) poses[16 * i + 4 * a + b] = t(a, b);
  }
}
}  // namespace

stiff_status stiff_tool_pose_batch(double* poses,
                                   size_t capacity,
                                   size_t* needed,
                                   const stiff_robot* robot,
                                   const double* q,
                                   size_t rows) {
  return guarded(__func__, [&] {
    require(robot, "robot");
    tool_poses_into(poses, capacity, needed, robot, q, rows);
    return STIFF_OK;
  });
}

stiff_status stiff_tool_poses(double* poses,
                              size_t capacity,
                              size_t* needed,
                              const stiff_robot* robot,
                              const double* q,
                              size_t rows,
                              size_t n) {
  return guarded(__func__, [&] {
    require(robot, "robot");
    stiff::capi::require_joint_width(n, robot);
    tool_poses_into(poses, capacity, needed, robot, q, rows);
    return STIFF_OK;
  });
}

stiff_status stiff_ik(double* q_out,
                      size_t capacity,
                      size_t* needed,
                      const stiff_robot* robot,
                      const double pose[16],
                      const double* q_seed) {
  return guarded(__func__, [&] {
    require(robot, "robot");
    require(pose, "pose");
    const RobotModel& r = robot->model;
    const Eigen::Matrix4d t = capi::rigid_pose_at(pose, "pose");
    const Eigen::VectorXd seed =
        q_seed ? joints_of(r, q_seed, "q_seed") : Eigen::VectorXd::Zero(r.dof());
    const InverseKinematics ik(r);
    std::vector<IkSolution> all = ik.solve_all(t, &seed);
    if (all.empty()) throw NumericalError("the pose is unreachable within the joint limits");
    std::stable_sort(all.begin(), all.end(), [&](const IkSolution& a, const IkSolution& b) {
      return (a.q - seed).norm() < (b.q - seed).norm();
    });
    const size_t n = all.size() * static_cast<size_t>(r.dof());
    stiff::capi::require_capacity(n, q_out, capacity, needed);
    for (size_t s = 0; s < all.size(); ++s)
      for (int j = 0; j < r.dof(); ++j) q_out[s * static_cast<size_t>(r.dof()) + j] = all[s].q(j);
    return STIFF_OK;
  });
}

stiff_status stiff_ik_path(double* q_out,
                           size_t capacity,
                           size_t* needed,
                           int* status_per_point,
                           const stiff_robot* robot,
                           const double* poses,
                           size_t rows,
                           const double* q_start) {
  return guarded(__func__, [&] {
    require(robot, "robot");
    const RobotModel& r = robot->model;
    stiff::capi::require_capacity(
        stiff::capi::values_of(rows, static_cast<size_t>(r.dof()), "q_out"), q_out, capacity,
        needed);
    const auto p = poses_of(poses, rows);
    const Eigen::VectorXd start = q_start ? joints_of(r, q_start, "q_start") : Eigen::VectorXd();
    const IkPath path = solve_path(InverseKinematics(r), p, start);
    write_rows(path.q, q_out);
    if (status_per_point)
      for (size_t i = 0; i < rows; ++i) status_per_point[i] = path.status[i];
    return STIFF_OK;
  });
}

stiff_status stiff_compensate_pose(
    double* q_cmd, const stiff_model* model, const double* q, size_t n, const double wrench[6]) {
  return guarded(__func__, [&] {
    require(q_cmd, "q_cmd");
    require(model, "model");
    require(q, "q");
    require(wrench, "wrench");
    const RobotModel& r = model->robot;
    if (n != static_cast<size_t>(r.dof()))
      throw InvalidArgument("q has " + std::to_string(n) + " values, the robot has " +
                            std::to_string(r.dof()) + " joints");
    const Eigen::VectorXd qv = joints_of(r, q, "q");
    require_finite(wrench, 6, "wrench");
    const Vector6d w = Eigen::Map<const Vector6d>(wrench);
    const PoseCompensation c = compensate_pose(*model->model, model->theta, r.tool_pose(qv), qv, w);
    if (!c.converged)
      throw NumericalError("the compensation did not converge (residual " +
                           std::to_string(c.residual) + " after " + std::to_string(c.iterations) +
                           " iterations)");
    for (int j = 0; j < r.dof(); ++j) q_cmd[j] = c.q_cmd(j);
    return STIFF_OK;
  });
}

stiff_status stiff_compensate_path(double* q_cmd,
                                   size_t capacity,
                                   size_t* needed,
                                   int* status_per_point,
                                   const stiff_model* model,
                                   const double* poses,
                                   const double* wrench,
                                   size_t rows,
                                   const double* q_start) {
  return guarded(__func__, [&] {
    require(model, "model");
    const RobotModel& r = model->robot;
    stiff::capi::require_capacity(
        stiff::capi::values_of(rows, static_cast<size_t>(r.dof()), "q_cmd"), q_cmd, capacity,
        needed);
    const auto p = poses_of(poses, rows);
    const Eigen::MatrixXd w = rows_of(wrench, rows, 6, "wrench");
    const Eigen::VectorXd start = q_start ? joints_of(r, q_start, "q_start") : Eigen::VectorXd();
    const PathCompensation pc = compensate_path(*model->model, model->theta, p,
                                                rows == 0 ? Eigen::MatrixXd::Zero(1, 6) : w, start);
    write_rows(pc.q_cmd, q_cmd);
    if (status_per_point)
      for (size_t i = 0; i < rows; ++i) status_per_point[i] = pc.status[i];
    return STIFF_OK;
  });
}

stiff_status stiff_truth_deviation(double* deviation,
                                   size_t capacity,
                                   size_t* needed,
                                   const stiff_robot* robot,
                                   const char* truth_path,
                                   const double* q,
                                   const double* poses,
                                   const double* wrench,
                                   size_t rows) {
  return guarded(__func__, [&] {
    require(robot, "robot");
    capi::require_string(truth_path, "truth_path");
    const RobotModel& r = robot->model;
    stiff::capi::require_capacity(stiff::capi::values_of(rows, 6, "deviation"), deviation, capacity,
                                  needed);
    const Truth truth = read_truth(truth_path, r);
    const DeflectionModel model(r, truth.effects);
    const auto p = poses_of(poses, rows);
    const Eigen::MatrixXd qm = rows_of(q, rows, r.dof(), "q");
    const Eigen::MatrixXd w = rows_of(wrench, rows, 6, "wrench");
    if (rows == 0) return STIFF_OK;
    write_rows(loaded_deviation(model, truth.theta, p, qm, w), deviation);
    return STIFF_OK;
  });
}

stiff_status stiff_path_options_init(stiff_path_options* options, size_t struct_size) {
  return guarded(__func__, [&] {
    // The core's PathOptions{}: the frame and the default tool orientation as x y z r p y.
    const PathOptions po;
    stiff_path_options o{};
    const Eigen::Matrix<double, 6, 1> frame = xyz_rpy_from_pose(po.frame);
    for (int k = 0; k < 6; ++k) o.frame[k] = frame(k);
    Eigen::Matrix4d tool = Eigen::Matrix4d::Identity();
    tool.block<3, 3>(0, 0) = po.tool_orientation;
    const Eigen::Matrix<double, 6, 1> rpy = xyz_rpy_from_pose(tool);
    // Written but not used until flags has STIFF_PATH_TOOL_RPY: setting that bit alone keeps
    // the default orientation.
    for (int k = 0; k < 3; ++k) o.tool_rpy[k] = rpy(3 + k);
    o.flags = 0u;
    o.segment_m = po.segment_m;
    return capi::init_options(options, struct_size, sizeof(stiff_path_options),
                              "stiff_path_options", o);
  });
}

namespace {
ToolPath read_path_with(const char* path, const stiff_path_options* options) {
  capi::require_string(path, "path");
  const stiff_path_options o = capi::read_options(options);
  PathOptions po;
  Eigen::Matrix<double, 6, 1> f;
  require_finite(o.frame, 6, "options.frame");
  require_finite(o.tool_rpy, 3, "options.tool_rpy");
  for (int k = 0; k < 6; ++k) f(k) = o.frame[k];
  po.frame = pose_from_xyz_rpy(f);
  if (o.flags & STIFF_PATH_TOOL_RPY) {
    f << 0, 0, 0, o.tool_rpy[0], o.tool_rpy[1], o.tool_rpy[2];
    po.tool_orientation = pose_from_xyz_rpy(f).block<3, 3>(0, 0);
  }
  po.segment_m = o.segment_m;
  return read_path(path, po);
}

void require_points(size_t capacity, size_t n) {
  if (capacity < n)
    throw Error(Status::buffer_too_small, "buffer holds " + std::to_string(capacity) + " points, " +
                                              std::to_string(n) + " needed");
}
}  // namespace

stiff_status stiff_path_read(double* poses,
                             double* wrench,
                             uint32_t* lines,
                             size_t capacity,
                             size_t* rows,
                             int* has_wrench,
                             const char* path,
                             const stiff_path_options* options) {
  return guarded(__func__, [&] {
    const ToolPath tp = read_path_with(path, options);
    if (rows) *rows = tp.size();
    if (has_wrench) *has_wrench = tp.has_wrench ? 1 : 0;
    require_points(capacity, tp.size());
    for (size_t i = 0; i < tp.size(); ++i) {
      const PathPoint& pt = tp.points[i];
      if (poses)
        for (int r = 0; r < 4; ++r)
          for (int c = 0; c < 4; ++c) poses[16 * i + 4 * r + c] = pt.pose(r, c);
      if (wrench)
        for (int k = 0; k < 6; ++k) wrench[6 * i + k] = pt.wrench(k);
      if (lines) lines[i] = static_cast<uint32_t>(pt.line);
    }
    return STIFF_OK;
  });
}

stiff_status stiff_path_read_flags(uint32_t* flags,
                                   size_t capacity,
                                   size_t* rows,
                                   const char* path,
                                   const stiff_path_options* options) {
  return guarded(__func__, [&] {
    const ToolPath tp = read_path_with(path, options);
    if (rows) *rows = tp.size();
    require_points(capacity, tp.size());
    if (flags)
      for (size_t i = 0; i < tp.size(); ++i)
        flags[i] = tp.points[i].rapid ? STIFF_PATH_POINT_RAPID : 0u;
    return STIFF_OK;
  });
}
