// Path files: CSV of tool poses and the G-code subset; bad input names path:line:column.
#include "stiff/io/path_io.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "stiff/compensate/ik.hpp"
#include "stiff/error.hpp"
#include "test_support.hpp"

namespace stiff {
namespace {

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const ParseError& e) {
    return e.what();
  }
  return "no ParseError";
}

std::string csv_error(const std::string& text) {
  return error_of([&] { parse_path_csv(text, "p.csv"); });
}
std::string gcode_error(const std::string& text) {
  return error_of([&] { parse_gcode(text, "p.nc"); });
}

TEST(PathCsv, ReadsUnitsOrientationsWrenchAndFrame) {
  PathOptions o;
  Eigen::Matrix<double, 6, 1> f;
  f << 0.4, 0.1, -0.2, 0, 0, M_PI / 2;  // workpiece frame: shifted, turned 90 deg about z
  o.frame = pose_from_xyz_rpy(f);
  const ToolPath p = parse_path_csv(
      "# comment\n"
      "id,x_mm,y_mm,z_mm,rx_deg,ry_deg,rz_deg,fx_N,fy_N,fz_N,note\n"
      "a,10,0,0,180,0,0,1,2,3,hello\n"
      "\n"
      "b,0,20,0,90,10,20,0,0,0,x\n",
      "p.csv", o);
  ASSERT_EQ(p.size(), 2u);
  EXPECT_TRUE(p.has_wrench);
  EXPECT_EQ(p.points[0].line, 3);
  EXPECT_EQ(p.points[1].line, 5);
  EXPECT_NEAR(p.points[0].pose(0, 3), 0.4, 1e-12);  // 10 mm along workpiece x = base y
  EXPECT_NEAR(p.points[0].pose(1, 3), 0.11, 1e-12);
  EXPECT_NEAR(p.points[0].wrench(0), -2.0, 1e-12);  // force rotated into the base frame
  EXPECT_NEAR(p.points[0].wrench(1), 1.0, 1e-12);
  // Roll-pitch-yaw round trip.
  Eigen::Matrix<double, 6, 1> v;
  v << 0, 0.02, 0, M_PI / 2, 10 * M_PI / 180, 20 * M_PI / 180;
  const Eigen::Matrix4d local = o.frame.inverse() * p.points[1].pose;
  EXPECT_LT((xyz_rpy_from_pose(local) - v).norm(), 1e-12);
  // Quaternions, metres, no wrench.
  const ToolPath q = parse_path_csv("x_m,y_m,z_m,qw,qx,qy,qz\n0.5,0,0.1,0,1,0,0\n", "q.csv");
  EXPECT_FALSE(q.has_wrench);
  EXPECT_NEAR(q.points[0].pose(2, 2), -1.0, 1e-12);
  // No orientation: the default tool orientation (pointing down).
  const ToolPath d = parse_path_csv("x_mm,y_mm,z_mm\n1,2,3\n", "d.csv");
  EXPECT_NEAR(d.points[0].pose(2, 2), -1.0, 1e-12);
}

TEST(PathCsv, BadInputNamesLineAndColumn) {
  EXPECT_EQ(csv_error(""), "p.csv: empty path file (no header line)");
  EXPECT_NE(csv_error("x_mm,y_mm\n1,2\n").find("p.csv:1:1: the header needs all of x, y, z"),
            std::string::npos);
  EXPECT_EQ(csv_error("x_mm,y_km,z_mm\n"),
            "p.csv:1:6: column 'y_km': unknown unit 'km' (accepted: _m, _mm, _um)");
  EXPECT_EQ(csv_error("x,y_mm,z_mm\n"), "p.csv:1:1: column 'x' has no unit suffix (e.g. x_mm)");
  EXPECT_EQ(csv_error("x_mm,y_mm,z_mm\n1,2,3\n1,abc,3\n"),
            "p.csv:3:3: 'abc' is not a finite number (column 'y_mm')");
  EXPECT_EQ(csv_error("x_mm,y_mm,z_mm\n1,2,3\n1,2\n"),
            "p.csv:3:1: row has 2 fields, the header has 3");
  EXPECT_NE(csv_error("x_mm,y_mm,z_mm,qw,qx,qy,qz\n1,2,3,1,1,0,0\n").find("p.csv:2:1: quaternion"),
            std::string::npos);
  EXPECT_EQ(csv_error("x_mm,y_mm,z_mm,x_mm\n"), "p.csv:1:16: duplicate column 'x_mm'");
  EXPECT_EQ(csv_error("x_mm,y_mm,z_mm\n"), "p.csv:1: the path has no points");
  EXPECT_NE(csv_error("x_mm,y_mm,z_mm,fx_N\n").find("fx, fy, fz"), std::string::npos);
}

TEST(Gcode, ReadsTheSubset) {
  PathOptions o;
  o.frame(2, 3) = -0.15;
  const ToolPath p = parse_gcode(
      "%\n"
      "(header comment)\n"
      "N10 G21 G90 G17\n"
      "G0 X10 Y10 Z5 ; rapid\n"
      "G1 Z-2 F600\n"
      "X20\n"
      "G91 G1 Y5\n"
      "G20 G90 X1\n"  // inch, absolute: x = 25.4 mm
      "M30\n",
      "p.nc", o);
  ASSERT_EQ(p.size(), 5u);
  EXPECT_TRUE(p.points[0].rapid);
  EXPECT_EQ(p.points[0].line, 4);
  EXPECT_NEAR(p.points[1].pose(2, 3), -0.152, 1e-12);
  EXPECT_NEAR(p.points[1].feed_m_s, 0.01, 1e-12);  // 600 mm/min
  EXPECT_NEAR(p.points[2].pose(0, 3), 0.020, 1e-12);
  EXPECT_NEAR(p.points[3].pose(1, 3), 0.015, 1e-12);
  EXPECT_NEAR(p.points[4].pose(0, 3), 0.0254, 1e-12);
  EXPECT_NEAR(p.points[4].pose(2, 2), -1.0, 1e-12);  // fixed tool axis pointing down
  // Segmentation of G1 moves.
  o.segment_m = 0.001;
  const ToolPath s = parse_gcode("G0 X0 Y0 Z0\nG1 X10 F100\n", "s.nc", o);
  EXPECT_EQ(s.size(), 11u);
  EXPECT_EQ(s.points.back().line, 2);
}

TEST(Gcode, BadInputNamesLineAndColumn) {
  EXPECT_EQ(gcode_error("G0 X0 Y0\nG2 X10 Y0 I5 J0 F100\n"),
            "p.nc:2:1: arc before the position is known (X, Y and Z not all given)");
  const std::string off_circle = gcode_error("G0 X0 Y0 Z0\nG2 X10 Y1 I5 J0 F100\n");
  EXPECT_EQ(off_circle.rfind("p.nc:2:1: arc end point is not on the circle", 0), 0u);
  EXPECT_NE(gcode_error("G1 X1 A30 F100\n").find("p.nc:1:7: rotary axis word 'A30'"),
            std::string::npos);
  EXPECT_EQ(gcode_error("G0 X0 (open\n"), "p.nc:1:7: unterminated comment '('");
  EXPECT_EQ(gcode_error("G0 X0\nG1 X5\n"), "p.nc:2:1: G1 move without a feed (F word)");
  EXPECT_EQ(gcode_error("G1 Xabc F10\n"), "p.nc:1:4: expected a number after 'X'");
  EXPECT_EQ(gcode_error("X10 Y5\n"), "p.nc:1:1: coordinates before any G0/G1 motion command");
  EXPECT_NE(gcode_error("G33 X1\n").find("p.nc:1:1: unsupported G-code G33"), std::string::npos);
  EXPECT_EQ(gcode_error("(only a comment)\n"),
            "p.nc:1: the G-code has no move that reaches a known position (X, Y and Z all "
            "given)");
}

TEST(ExamplePaths, AreReachableByTheRokaeArm) {
  const RobotModel r = test::rokae();
  const InverseKinematics ik(r);
  const ToolPath csv = read_path(test::source_path("examples/paths/rokae_contour.csv"));
  PathOptions o;
  Eigen::Matrix<double, 6, 1> f;
  f << 0.37, -0.04, -0.15, 0, 0, 0;
  o.frame = pose_from_xyz_rpy(f);
  o.segment_m = 0.002;  // joint jumps are judged on a densely sampled path
  const ToolPath nc = read_path(test::source_path("examples/paths/pocket.nc"), o);
  EXPECT_GT(csv.size(), 300u);
  EXPECT_TRUE(csv.has_wrench);
  for (const ToolPath* p : {&csv, &nc}) {
    const IkPath q = solve_path(ik, p->poses(), Eigen::VectorXd());
    for (size_t i = 0; i < p->size(); ++i) EXPECT_EQ(q.status[i], kPointOk) << i;
  }
}

}  // namespace
}  // namespace stiff
