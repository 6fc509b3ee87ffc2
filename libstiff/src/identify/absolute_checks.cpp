// Checks of absolute measurements against the nominal robot (identify.hpp).
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include "identify/robust.hpp"
#include "stiff/error.hpp"
#include "stiff/identify/identify.hpp"

namespace stiff {
namespace {

using robust::median;

std::string fmt(const char* f, double v) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

double angle(const Eigen::Matrix3d& r) {
  return std::acos(std::max(-1.0, std::min(1.0, 0.5 * (r.trace() - 1.0))));
}

}  // namespace

void check_absolute_data(const RobotModel& robot, const Dataset& data, bool registered) {
  constexpr double kPi = 3.141592653589793;
  // Limits far outside what geometric errors of a robot do (sub-degree, millimetres) and far
  // inside what a wrong frame or convention does.
  constexpr double kFrameOff = 0.5;                // [m]
  constexpr double kAngleOff = 5.0 * kPi / 180.0;  // [rad]
  std::vector<double> distance;
  std::map<std::string, std::vector<int>> oriented;  // session -> rows with orientation
  std::map<std::string, std::vector<Eigen::Matrix3d>> flange;
  for (size_t r = 0; r < data.rows.size(); ++r) {
    const Measurement& m = data.rows[r];
    if (!m.absolute) continue;
    if (m.q.size() != robot.dof()) continue;  // validation names it
    const Eigen::Matrix4d f = robot.chain(m.q).flange;
    distance.push_back(
        (f.topLeftCorner<3, 3>() * robot.measured_point + f.topRightCorner<3, 1>() - m.position)
            .norm());
    if (m.has_orientation) {
      oriented[m.session].push_back(static_cast<int>(r));
      flange[m.session].push_back(f.topLeftCorner<3, 3>());
    }
  }
  if (distance.empty()) return;
  const double off = median(distance);
  if (!registered && off > kFrameOff)
    throw InvalidArgument(
        "absolute positions lie a median " + fmt("%.3g", off) +
        " m from where the nominal robot puts the target: the instrument frame is metres "
        "away from the robot base; add 'registration' to the model (one rigid motion per "
        "session), or give the positions in the base frame");
  for (const auto& kv : oriented) {
    const auto& rows = kv.second;
    const auto& fl = flange[kv.first];
    std::vector<double> diff;
    for (size_t i = 1; i < rows.size(); ++i) {
      // The probe turns between two poses by the angle the flange turns (a conjugation by
      // the fixed registration and tool rotations keeps the angle).
      const double measured =
          angle(data.rows[rows[i - 1]].orientation.transpose() * data.rows[rows[i]].orientation);
      const double nominal = angle(fl[i - 1].transpose() * fl[i]);
      diff.push_back(std::abs(measured - nominal));
    }
    if (diff.size() >= 2 && median(diff) > kAngleOff)
      throw InvalidArgument(
          "session '" + kv.first + "': the measured orientations turn between poses by angles " +
          "that differ from the robot's by a median " + fmt("%.3g", median(diff) * 180.0 / kPi) +
          " deg (geometric errors give well under a degree): check the Euler convention ('# "
          "euler: xyz' or 'zyx') and the unit of a, b, c (_deg or _rad)");
  }
}

}  // namespace stiff
