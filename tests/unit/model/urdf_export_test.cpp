// URDF export (robot_to_urdf): the written chain, read back by the URDF reader, has the same
// forward kinematics, Jacobian, limits and gravity torques as the robot it was written from,
// for URDF, modified and standard DH robots and 7-joint arms with general (calibrated) joint
// transforms; the registration becomes a world link; names survive XML; bad robots are refused.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <string>

#include "stiff/error.hpp"
#include "stiff/io/robot_io.hpp"
#include "test_support.hpp"

namespace stiff {
namespace {

/// A small rigid motion: rotation vector and translation with the given scales [rad, m].
Eigen::Matrix4d small_motion(std::mt19937_64& rng, double angle, double length) {
  std::normal_distribution<double> z(0.0, 1.0);
  const Eigen::Vector3d w(angle * z(rng), angle * z(rng), angle * z(rng));
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  t.topLeftCorner<3, 3>() = Eigen::AngleAxisd(w.norm(), w.normalized()).matrix();
  t.topRightCorner<3, 1>() = Eigen::Vector3d(length * z(rng), length * z(rng), length * z(rng));
  return t;
}

/// The robot as a calibration leaves it: every joint's fixed transforms moved by a few mrad
/// and tenths of a millimetre, an offset turned into the joint's origin, a tool point.
RobotModel calibrated_like(RobotModel r, std::mt19937_64& rng) {
  std::normal_distribution<double> z(0.0, 1.0);
  for (Joint& j : r.joints) {
    Eigen::Matrix4d offset = Eigen::Matrix4d::Identity();
    offset.topLeftCorner<3, 3>() = Eigen::AngleAxisd(2e-3 * z(rng), j.axis).matrix();
    j.pre = j.pre * small_motion(rng, 2e-3, 3e-4) * offset;
    j.post = j.post * small_motion(rng, 1e-3, 2e-4);
  }
  r.measured_point += Eigen::Vector3d(0.01 * z(rng), 0.01 * z(rng), 0.08 + 0.01 * z(rng));
  r.tool_mass = 1.5;
  r.tool_com = Eigen::Vector3d(0.01, -0.02, 0.05);
  r.convention = Convention::urdf;
  return r;
}

double rotation_angle(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a * b.transpose()).angle();
}

/// The written robot read back (tip: the measured point) against the original, at random
/// poses within the limits: every link frame and the tool to 1e-9 m / 1e-9 rad (rounding of
/// 17-digit numbers and of the reader's quaternions is ~1e-15), the Jacobian, the gravity
/// torques (masses and centres of mass carried over) and the limits.
void expect_same_robot(const RobotModel& a, const RobotModel& b, const std::string& what) {
  ASSERT_EQ(a.dof(), b.dof()) << what;
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int j = 0; j < a.dof(); ++j) {
    EXPECT_EQ(a.joints[j].lower, b.joints[j].lower) << what << " joint " << j;
    EXPECT_EQ(a.joints[j].upper, b.joints[j].upper) << what << " joint " << j;
  }
  for (int trial = 0; trial < 40; ++trial) {
    Eigen::VectorXd q(a.dof());
    for (int j = 0; j < a.dof(); ++j)
      q(j) = a.joints[j].lower + u(rng) * (a.joints[j].upper - a.joints[j].lower);
    const Eigen::Matrix4d ta = a.tool_pose(q), tb = b.tool_pose(q);
    EXPECT_LT((ta.topRightCorner<3, 1>() - tb.topRightCorner<3, 1>()).norm(), 1e-9) << what;
    EXPECT_LT(rotation_angle(ta.topLeftCorner<3, 3>(), tb.topLeftCorner<3, 3>()), 1e-9) << what;
    const ChainState sa = a.chain(q), sb = b.chain(q);
    for (int j = 0; j < a.dof(); ++j) {
      EXPECT_LT((sa.axis.col(j) - sb.axis.col(j)).norm(), 1e-9) << what << " axis " << j;
      // The origins may differ along the axis; their offset must be parallel to it.
      EXPECT_LT((sa.origin.col(j) - sb.origin.col(j)).cross(sa.axis.col(j)).norm(), 1e-9)
          << what << " origin " << j;
    }
    EXPECT_LT((a.jacobian(q) - b.jacobian(q)).cwiseAbs().maxCoeff(), 1e-9) << what;
    const Eigen::VectorXd ga = gravity_torques(a, sa), gb = gravity_torques(b, sb);
    EXPECT_LT((ga - gb).cwiseAbs().maxCoeff(), 1e-9 * (1.0 + ga.cwiseAbs().maxCoeff())) << what;
  }
}

RobotModel reread(const std::string& urdf, const std::string& base = "") {
  return parse_robot_urdf(urdf, "exported.urdf", "tcp", base);
}

TEST(UrdfExport, CalibratedChainsKeepTheirKinematics) {
  std::mt19937_64 rng(5);
  for (const char* file :
       {"examples/robots/ur5.urdf", "examples/robots/puma560.yaml", "examples/robots/rokae.yaml",
        "examples/robots/ur10.yaml", "tests/data/urdf/iiwa14.urdf", "tests/data/urdf/panda.urdf"}) {
    const RobotModel nominal = load_robot(test::source_path(file));
    for (const RobotModel& r : {nominal, calibrated_like(nominal, rng)}) {
      const std::string text = robot_to_urdf(r);
      const RobotModel back = reread(text);
      expect_same_robot(r, back, file);
      EXPECT_EQ(back.name, r.name);
      for (int j = 0; j < r.dof(); ++j) EXPECT_EQ(back.joints[j].name, r.joints[j].name);
    }
  }
}

TEST(UrdfExport, LimitsAndVelocityLimitsOfAUrdfAreCarried) {
  const RobotModel r = load_robot(test::source_path("tests/data/urdf/iiwa14.urdf"));
  const RobotModel back = reread(robot_to_urdf(r));
  for (int j = 0; j < r.dof(); ++j) {
    EXPECT_GT(r.joints[j].velocity, 0.0) << j;
    EXPECT_EQ(back.joints[j].effort, r.joints[j].effort) << j;
    EXPECT_EQ(back.joints[j].velocity, r.joints[j].velocity) << j;
  }
}

TEST(UrdfExport, WorldLinkPlacesTheBase) {
  std::mt19937_64 rng(7);
  const RobotModel r =
      calibrated_like(load_robot(test::source_path("examples/robots/ur5.urdf")), rng);
  Eigen::Matrix4d world = Eigen::Matrix4d::Identity();
  world.topLeftCorner<3, 3>() =
      Eigen::AngleAxisd(2.1, Eigen::Vector3d(0.1, -0.2, 1.0).normalized()).matrix();
  world.topRightCorner<3, 1>() = Eigen::Vector3d(2.4, -1.1, 0.3);
  UrdfWriteOptions o;
  o.world_from_base = world;
  const std::string text = robot_to_urdf(r, o);
  // Read from base_link: the robot itself; from world: the robot in the instrument frame.
  expect_same_robot(r, reread(text, "base_link"), "base_link");
  const RobotModel placed = reread(text, "world");
  const Eigen::VectorXd q = Eigen::VectorXd::LinSpaced(6, -1.0, 1.5);
  const Eigen::Matrix4d expected = world * r.tool_pose(q), got = placed.tool_pose(q);
  const Eigen::Vector3d moved = (expected - got).topRightCorner<3, 1>();
  EXPECT_LT(moved.norm(), 1e-9);
  EXPECT_LT(rotation_angle(expected.topLeftCorner<3, 3>(), got.topLeftCorner<3, 3>()), 1e-9);
}

TEST(UrdfExport, OriginAnglesAtAndNearGimbalLock) {
  // pitch = +-90 deg: roll and yaw count only together; the written angles must still give
  // the rotation to rounding, also 1e-9 rad and 1e-5 rad away from the lock.
  for (const double pitch : {M_PI / 2, -M_PI / 2, M_PI / 2 - 1e-9, -M_PI / 2 + 1e-5, 0.3}) {
    RobotModel r = load_robot(test::source_path("examples/robots/rokae.yaml"));
    r.convention = Convention::urdf;
    Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
    t.topLeftCorner<3, 3>() = (Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(-0.4, Eigen::Vector3d::UnitX()))
                                  .matrix();
    r.joints[2].pre = r.joints[2].pre * t;
    expect_same_robot(r, reread(robot_to_urdf(r)), "pitch " + std::to_string(pitch));
  }
}

TEST(UrdfExport, HostileNamesSurviveXml) {
  RobotModel r = load_robot(test::source_path("examples/robots/ur5.urdf"));
  r.name = "arm \"<one>\" & 'two' </robot><robot name=\"x\">";
  r.joints[0].name = "a<b>&c\"d'e";
  r.joints[1].name = "-->";                      // ends a comment if written into one
  r.joints[2].name = "flange_joint";             // a name the writer also wants for a fixed joint
  r.joints[3].name = r.joints[4].name = "twin";  // URDF joint names must be unique
  r.joints[5].name = "";
  const std::string text = robot_to_urdf(r);
  const RobotModel back = reread(text);
  expect_same_robot(r, back, "hostile names");
  EXPECT_EQ(back.name, r.name);
  EXPECT_EQ(back.joints[0].name, r.joints[0].name);
  EXPECT_EQ(back.joints[1].name, r.joints[1].name);
  EXPECT_EQ(back.joints[2].name, "flange_joint");
  EXPECT_EQ(back.joints[3].name, "twin");
  EXPECT_EQ(back.joints[4].name, "twin_2");
  EXPECT_EQ(back.joints[5].name, "joint6");
  // A control character XML 1.0 cannot hold is replaced, the document stays readable.
  r.name = std::string("bell\x07") + "end";
  EXPECT_EQ(reread(robot_to_urdf(r)).name, "bell_end");
  // Comments hold any text.
  UrdfWriteOptions o;
  o.comments = {"a -- b -", "--> <!-- x"};
  EXPECT_NO_THROW(reread(robot_to_urdf(r, o)));
}

TEST(UrdfExport, NonFiniteOrNonRigidInputIsRefused) {
  RobotModel r = load_robot(test::source_path("examples/robots/ur5.urdf"));
  RobotModel bad = r;
  bad.joints[3].pre(0, 3) = NAN;
  EXPECT_THROW(robot_to_urdf(bad), InvalidArgument);
  bad = r;
  bad.joints[1].post(0, 0) = 2.0;  // not a rotation
  try {
    robot_to_urdf(bad);
    FAIL() << "no error";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("joint 2"), std::string::npos) << e.what();
  }
  bad = r;
  bad.measured_point(2) = INFINITY;
  EXPECT_THROW(robot_to_urdf(bad), InvalidArgument);
  UrdfWriteOptions o;
  o.world_from_base = Eigen::Matrix4d::Identity() * 2.0;
  EXPECT_THROW(robot_to_urdf(r, o), InvalidArgument);
}

}  // namespace
}  // namespace stiff
