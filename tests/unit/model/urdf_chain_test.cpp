// URDF chains as ROS robot descriptions have them (docs/formats.md, URDF): base and tip link,
// frames fixed beside the arm, locked and continuous joints, tool options. Kinematic values are
// checked against transforms composed here from the joint origins written in the test.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "stiff/error.hpp"
#include "stiff/io/robot_io.hpp"
#include "test_support.hpp"

namespace stiff {
namespace {

// A 3-joint arm with a `base` frame beside it (turned by pi about z), a locked joint (lower =
// upper = 0.3), a continuous joint, flange/tool0 after the last joint and a prismatic finger.
const char* kArm = R"(<?xml version="1.0"?>
<robot name="arm">
  <link name="base_link"/><link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/>
  <link name="l4"/><link name="flange"/><link name="tool0"/><link name="finger"/>
  <joint name="base_link-base" type="fixed"><parent link="base_link"/><child link="base"/>
    <origin xyz="0 0 0" rpy="0 0 3.141592653589793"/></joint>
  <joint name="j1" type="revolute"><parent link="base_link"/><child link="l1"/>
    <origin xyz="0 0 0.4" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.1 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="0.3" upper="0.3" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.5 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j4" type="continuous"><parent link="l3"/><child link="l4"/>
    <origin xyz="0.4 0 0" rpy="0 0 0"/><axis xyz="1 0 0"/></joint>
  <joint name="l4-flange" type="fixed"><parent link="l4"/><child link="flange"/>
    <origin xyz="0.08 0 0" rpy="0 0 0"/></joint>
  <joint name="flange-tool0" type="fixed"><parent link="flange"/><child link="tool0"/>
    <origin xyz="0 0 0" rpy="0 1.5707963267948966 0"/></joint>
  <joint name="finger" type="prismatic"><parent link="tool0"/><child link="finger"/>
    <axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>
</robot>)";

Eigen::Matrix4d tr(double x, double y, double z) {
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  t.block<3, 1>(0, 3) = Eigen::Vector3d(x, y, z);
  return t;
}
Eigen::Matrix4d rot(const Eigen::Vector3d& axis, double a) {
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  t.block<3, 3>(0, 0) = Eigen::AngleAxisd(a, axis.normalized()).toRotationMatrix();
  return t;
}

// base_link -> tool0 at (q1, q3, q4), the locked j2 at 0.3, composed from kArm's origins.
Eigen::Matrix4d expected_tool0(double q1, double q3, double q4) {
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX(), y = Eigen::Vector3d::UnitY(),
                        z = Eigen::Vector3d::UnitZ();
  return tr(0, 0, 0.4) * rot(z, q1) * tr(0.1, 0, 0) * rot(y, 0.3) * tr(0.5, 0, 0) * rot(y, q3) *
         tr(0.4, 0, 0) * rot(x, q4) * tr(0.08, 0, 0) * rot(y, M_PI / 2);
}

TEST(UrdfChain, DefaultsToTool0AndLocksLowerEqualsUpper) {
  RobotFileReport report;
  const RobotModel r = parse_robot_urdf(kArm, "arm.urdf", "", "", &report);
  ASSERT_EQ(r.dof(), 3);  // j2 locked, the prismatic finger beside the chain
  EXPECT_EQ(report.base_link, "base_link");
  EXPECT_EQ(report.tip_link, "tool0");
  EXPECT_EQ(r.joints[1].name, "j3");
  EXPECT_NEAR(r.joints[2].lower, -2 * M_PI, 1e-15);  // continuous: one turn either way
  EXPECT_NEAR(r.joints[2].upper, 2 * M_PI, 1e-15);
  const Eigen::Vector3d q(0.4, -0.7, 2.5);
  EXPECT_LT((r.tool_pose(q) - expected_tool0(q(0), q(1), q(2))).cwiseAbs().maxCoeff(), 1e-14);
  bool locked_noted = false;
  for (const auto& n : report.notes) locked_noted |= n.find("'j2'") != std::string::npos;
  EXPECT_TRUE(locked_noted);
}

TEST(UrdfChain, BaseFrameBesideTheArm) {
  const RobotModel r = parse_robot_urdf(kArm, "arm.urdf", "flange", "base");
  const Eigen::Vector3d q(0.4, -0.7, 2.5);
  const Eigen::Matrix4d base = rot(Eigen::Vector3d::UnitZ(), M_PI);
  const Eigen::Matrix4d flange =
      expected_tool0(q(0), q(1), q(2)) * rot(Eigen::Vector3d::UnitY(), -M_PI / 2);
  EXPECT_LT((r.tool_pose(q) - base.inverse() * flange).cwiseAbs().maxCoeff(), 1e-14);
}

TEST(UrdfChain, ErrorsNameTheProblem) {
  auto message = [](const std::string& text, const std::string& tip, const std::string& base) {
    try {
      parse_robot_urdf(text, "arm.urdf", tip, base);
    } catch (const ParseError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message(kArm, "finger", "").find("joint 'finger' on the way is not revolute"),
            std::string::npos);
  EXPECT_NE(message(kArm, "nolink", "").find("no link named 'nolink'"), std::string::npos);
  // Without tool0 and flange, two chain ends of equal length: both are listed.
  std::string two = kArm;
  for (const char* name : {"\"tool0\"", "\"flange\""}) {
    for (size_t p = two.find(name); p != std::string::npos; p = two.find(name))
      two.replace(p, std::string(name).size(),
                  std::string(name) == "\"tool0\"" ? "\"t\"" : "\"f\"");
  }
  two.replace(two.find("</robot>"), 8,
              "<link name=\"side\"/><joint name=\"js\" type=\"revolute\"><parent link=\"l3\"/>"
              "<child link=\"side\"/><axis xyz=\"0 0 1\"/><limit lower=\"-1\" upper=\"1\" "
              "effort=\"1\" velocity=\"1\"/></joint></robot>");
  const std::string m = message(two, "", "");
  EXPECT_NE(m.find("several possible tip links"), std::string::npos) << m;
  EXPECT_NE(m.find("t (3 joints)"), std::string::npos) << m;
  EXPECT_NE(m.find("side (3 joints)"), std::string::npos) << m;
}

TEST(UrdfChain, RealRobotFilesLoadWithTheirToolFrame) {
  struct Case {
    const char* file;
    const char* tip;
    int dof;
  };
  for (const Case& c :
       {Case{"ur3.urdf", "tool0", 6}, Case{"ur5.urdf", "tool0", 6}, Case{"ur10.urdf", "tool0", 6},
        Case{"kuka_kr6r900sixx.urdf", "tool0", 6}, Case{"kuka_kr16_2.urdf", "tool0", 6},
        Case{"kuka_kr210l150.urdf", "tool0", 6}, Case{"abb_irb2400.urdf", "tool0", 6},
        Case{"abb_irb6640_185_280.urdf", "tool0", 6}, Case{"panda.urdf", "panda_hand_tcp", 7},
        Case{"iiwa14.urdf", "iiwa_link_ee", 7}}) {
    RobotFileReport report;
    const RobotModel r =
        load_robot(test::source_path(std::string("tests/data/urdf/") + c.file), {}, &report);
    EXPECT_EQ(report.tip_link, c.tip) << c.file;
    EXPECT_EQ(r.dof(), c.dof) << c.file;
  }
}

TEST(UrdfChain, ToolOptionsApplyToUrdfAndYaml) {
  RobotLoadOptions o;
  o.measured_point = Eigen::Vector3d(0, 0, 0.15);
  o.tool_mass = 2.0;
  const RobotModel r = load_robot(test::source_path("tests/data/urdf/ur5.urdf"), o);
  EXPECT_EQ(r.measured_point, Eigen::Vector3d(0, 0, 0.15));
  EXPECT_EQ(r.load_point, Eigen::Vector3d(0, 0, 0.15));  // follows the measured point
  EXPECT_EQ(r.tool_mass, 2.0);
  RobotLoadOptions tip;
  tip.tip_link = "tool0";
  EXPECT_THROW(load_robot(test::source_path("examples/robots/rokae.yaml"), tip), InvalidArgument);
}

}  // namespace
}  // namespace stiff
