// First alignment of absolute measurements with the nominal robot (start values of the
// registration, tool and tool_orientation effects).
#include <Eigen/QR>
#include <map>

#include "stiff/kinematics/rigid_fit.hpp"
#include "stiff/model/effects/common.hpp"

namespace stiff::effects {
namespace {

Alignment compute(const RobotModel& robot, const Dataset& data) {
  Alignment a;
  std::map<std::string, int> index;
  std::vector<int> row_session;
  // Session order as DeflectionModel numbers them: first appearance over all rows.
  for (const auto& m : data.rows)
    if (!index.count(m.session)) {
      index[m.session] = static_cast<int>(a.sessions.size());
      a.sessions.push_back(m.session);
    }
  const int ns = static_cast<int>(a.sessions.size());
  std::vector<Eigen::Matrix3d> rf;
  std::vector<Eigen::Vector3d> pf, y;
  for (const auto& m : data.rows) {
    if (!m.absolute) continue;
    const Eigen::Matrix4d f = robot.chain(m.q).flange;
    rf.push_back(f.topLeftCorner<3, 3>());
    pf.push_back(f.topRightCorner<3, 1>());
    y.push_back(m.position);
    row_session.push_back(index[m.session]);
  }
  a.rotation.assign(ns, Eigen::Matrix3d::Identity());
  a.translation.assign(ns, Eigen::Vector3d::Zero());
  const int n = static_cast<int>(y.size());
  if (n == 0) return a;
  const Eigen::Vector3d r0 = robot.measured_point;
  Eigen::Vector3d delta = Eigen::Vector3d::Zero();
  for (int iter = 0; iter < 50; ++iter) {
    // Rotations and translations per session for the current point (Arun et al.).
    for (int k = 0; k < ns; ++k) {
      std::vector<int> rows;
      for (int i = 0; i < n; ++i)
        if (row_session[i] == k) rows.push_back(i);
      if (rows.empty()) continue;
      Eigen::Matrix3Xd from(3, rows.size()), to(3, rows.size());
      for (size_t c = 0; c < rows.size(); ++c) {
        from.col(c) = rf[rows[c]] * (r0 + delta) + pf[rows[c]];
        to.col(c) = y[rows[c]];
      }
      if (!fit_rigid_motion(from, to, &a.rotation[k], &a.translation[k]))
        throw InvalidArgument("session '" + a.sessions[k] +
                              "': its target positions are (nearly) collinear; registering the "
                              "instrument needs points spread in a plane at least");
    }
    // Point offset and translations jointly for these rotations (linear least squares).
    // Normal equations: the unknowns are few (3 + 3 sessions) and the columns well scaled.
    const int p = 3 + 3 * ns;
    Eigen::MatrixXd ata = Eigen::MatrixXd::Zero(p, p);
    Eigen::VectorXd atb = Eigen::VectorXd::Zero(p);
    double bb = 0.0;
    for (int i = 0; i < n; ++i) {
      const int k = row_session[i];
      const Eigen::Matrix3d b = a.rotation[k] * rf[i];
      const Eigen::Vector3d r = y[i] - a.rotation[k] * (rf[i] * r0 + pf[i]);
      ata.topLeftCorner<3, 3>() += b.transpose() * b;
      ata.block<3, 3>(0, 3 + 3 * k) += b.transpose();
      ata.block<3, 3>(3 + 3 * k, 0) += b;
      ata.block<3, 3>(3 + 3 * k, 3 + 3 * k) += Eigen::Matrix3d::Identity();
      atb.head<3>() += b.transpose() * r;
      atb.segment<3>(3 + 3 * k) += r;
      bb += r.squaredNorm();
    }
    const Eigen::VectorXd x = ata.completeOrthogonalDecomposition().solve(atb);
    const Eigen::Vector3d step = x.head<3>() - delta;
    delta = x.head<3>();
    for (int k = 0; k < ns; ++k) a.translation[k] = x.segment<3>(3 + 3 * k);
    a.rms = std::sqrt(std::max(0.0, bb - x.dot(atb)) / n);
    if (step.norm() < 1e-9) break;
  }
  a.point_offset = delta;
  // The probe's rotation on the flange: the chordal mean of (R_s R_06)^T R_measured over the
  // rows with orientation, projected onto SO(3) (SVD).
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  int oriented = 0;
  for (const auto& m : data.rows) {
    if (!m.absolute || !m.has_orientation) continue;
    const Eigen::Matrix3d f = robot.chain(m.q).flange.topLeftCorner<3, 3>();
    sum += (a.rotation[index[m.session]] * f).transpose() * m.orientation;
    ++oriented;
  }
  if (oriented > 0) {
    const Eigen::Matrix3d r = nearest_rotation(sum);
    ceres::RotationMatrixToAngleAxis(r.data(), a.probe.data());
  }
  return a;
}

}  // namespace

Alignment alignment(const RobotModel& robot, const Dataset& data) { return compute(robot, data); }

}  // namespace stiff::effects
