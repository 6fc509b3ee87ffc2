// C ABI of the program filter's per-target call (stiff_filter_target, stiff_compensate.h): the
// frames of a robot program are mapped onto the core's measured-point pose and load-point
// wrench, and the core compensation (compensate_pose) does the work.
#include <Eigen/Geometry>

#include "boundary.hpp"
#include "handles.hpp"
#include "stiff/compensate/compensate.hpp"
#include "stiff/compensate/ik.hpp"
#include "stiff/stiff_compensate.h"

using namespace stiff;
using stiff::capi::guarded;
using stiff::capi::require;
using stiff::capi::require_finite;

namespace {

Eigen::Matrix4d frame_at(const double* p, const char* what) {
  return p ? capi::rigid_pose_at(p, what) : Eigen::Matrix4d::Identity();
}

Eigen::Matrix4d inverse(const Eigen::Matrix4d& t) {
  Eigen::Matrix4d i = Eigen::Matrix4d::Identity();
  i.block<3, 3>(0, 0) = t.block<3, 3>(0, 0).transpose();
  i.block<3, 1>(0, 3) = -i.block<3, 3>(0, 0) * t.block<3, 1>(0, 3);
  return i;
}

Eigen::Matrix4d translation(const Eigen::Vector3d& p) {
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  t.block<3, 1>(0, 3) = p;
  return t;
}

}  // namespace

stiff_status stiff_filter_target(double pose_out[16],
                                 double* q_out,
                                 size_t capacity,
                                 size_t* needed,
                                 int* status,
                                 double deflection[6],
                                 const stiff_model* model,
                                 const double pose[16],
                                 const double* q_seed,
                                 const double wrench[6],
                                 const double base[16],
                                 const double tool[16]) {
  return guarded(__func__, [&] {
    require(pose_out, "pose_out");
    require(status, "status");
    require(model, "model");
    require(pose, "pose");
    const RobotModel& r = model->robot;
    const int n = r.dof();
    stiff::capi::require_capacity(static_cast<size_t>(n), q_out, capacity, needed);
    const Eigen::Matrix4d target = frame_at(pose, "pose");
    const Eigen::Matrix4d b = frame_at(base, "base");
    const Eigen::Matrix4d t = frame_at(tool, "tool");
    Vector6d w = Vector6d::Zero();
    if (wrench) {
      require_finite(wrench, 6, "wrench");
      w = Eigen::Map<const Vector6d>(wrench);
    }
    Eigen::VectorXd seed = Eigen::VectorXd::Zero(n);
    if (q_seed) {
      require_finite(q_seed, static_cast<size_t>(n), "q_seed");
      for (int j = 0; j < n; ++j) seed(j) = q_seed[j];
    }
    // Core pose: the measured point with the flange orientation. The flange follows from the
    // program's TCP (tool frame given in the flange frame).
    const Eigen::Matrix4d tcp_base = b * target;
    const Eigen::Matrix4d mp_from_tcp = inverse(t) * translation(r.measured_point);
    const Eigen::Matrix4d mp_nominal = tcp_base * mp_from_tcp;
    // The wrench acts at the TCP, given in the program's reference frame: the core wants it at
    // the load point in the robot base frame (same force, moment transported).
    const Eigen::Matrix3d rb = b.block<3, 3>(0, 0);
    const Eigen::Matrix4d flange_nominal = tcp_base * inverse(t);
    const Eigen::Vector3d force = rb * w.head<3>();
    const Eigen::Vector3d p_load = (flange_nominal * r.load_point.homogeneous()).head<3>();
    const Eigen::Vector3d lever = tcp_base.block<3, 1>(0, 3) - p_load;
    Vector6d w_core;
    w_core << force, rb * w.tail<3>() + lever.cross(force);

    for (int k = 0; k < 16; ++k) pose_out[k] = pose[k];
    for (int j = 0; j < n; ++j) q_out[j] = seed(j);
    if (deflection)
      for (int k = 0; k < 6; ++k) deflection[k] = 0.0;
    *status = STIFF_POINT_OK;

    const InverseKinematics ik(r);
    IkSolution nominal;
    if (!ik.solve_nearest(mp_nominal, seed, &nominal)) {
      *status = STIFF_POINT_UNREACHABLE;
      return STIFF_OK;
    }
    if (nominal.singular) *status |= STIFF_POINT_SINGULAR;
    if (deflection) {
      // Deflection of the TCP at the nominal joints: the rigid flange body displaced by the
      // model's deflection (d, rot) of the measured point; reference-frame components.
      const Vector6d d = predict_deflection(*model->model, model->theta, nominal.q, w_core);
      const Eigen::Matrix4d tcp_loaded = loaded_pose(mp_nominal, d) * inverse(mp_from_tcp);
      const Eigen::Vector3d dp = tcp_loaded.block<3, 1>(0, 3) - tcp_base.block<3, 1>(0, 3);
      const Eigen::AngleAxisd da(tcp_loaded.block<3, 3>(0, 0) *
                                 tcp_base.block<3, 3>(0, 0).transpose());
      const Eigen::Vector3d dr = da.angle() * da.axis();
      for (int k = 0; k < 3; ++k) {
        deflection[k] = (rb.transpose() * dp)(k);
        deflection[3 + k] = (rb.transpose() * dr)(k);
      }
    }
    const PoseCompensation c =
        compensate_pose(*model->model, model->theta, mp_nominal, nominal.q, w_core);
    if (!c.converged) {
      *status |= STIFF_POINT_NOT_CONVERGED;
      for (int j = 0; j < n; ++j) q_out[j] = nominal.q(j);
      return STIFF_OK;
    }
    if (ik.sigma_min(c.q_cmd) < ik.options().singular_sigma) *status |= STIFF_POINT_SINGULAR;
    const Eigen::Matrix4d out = inverse(b) * r.tool_pose(c.q_cmd) * inverse(mp_from_tcp);
    for (int a = 0; a < 4; ++a)
      for (int k = 0; k < 4; ++k) pose_out[4 * a + k] = out(a, k);
    for (int j = 0; j < n; ++j) q_out[j] = c.q_cmd(j);
    return STIFF_OK;
  });
}

stiff_status stiff_robot_tool_points(double measured_point[3],
                                     double load_point[3],
                                     const stiff_robot* robot) {
  return guarded(__func__, [&] {
    require(robot, "robot");
    for (int k = 0; k < 3; ++k) {
      if (measured_point) measured_point[k] = robot->model.measured_point(k);
      if (load_point) load_point[k] = robot->model.load_point(k);
    }
    return STIFF_OK;
  });
}
