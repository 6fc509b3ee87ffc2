// Absolute measurement rows in the measurement file: reading, writing, mixed files and the
// bad inputs (docs/formats.md, absolute measurements).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "stiff/io/dataset.hpp"
#include "stiff/error.hpp"

namespace stiff {
namespace {

const char* kHeader = "id,session,q1_deg,q2_deg,q3_deg,px_mm,py_mm,pz_mm\n";

std::string rows(const std::string& session, int count, int first = 0) {
  std::string s;
  for (int i = 0; i < count; ++i)
    s += "r" + std::to_string(first + i) + "," + session + ",10,20," + std::to_string(i) + "," +
         std::to_string(100 + i) + "," + std::to_string(i * i) + ",5\n";
  return s;
}

std::string error_of(const std::string& text) {
  try {
    parse_measurements_csv(text, "t.csv");
  } catch (const ParseError& e) {
    return e.what();
  }
  return "";
}

TEST(AbsoluteDataset, ReadsPositionsInSiAndKeepsSessions) {
  const Dataset d = parse_measurements_csv(kHeader + rows("A", 3) + rows("B", 3, 3), "t.csv");
  ASSERT_EQ(d.size(), 6u);
  EXPECT_TRUE(d.has_position);
  EXPECT_FALSE(d.has_force);
  EXPECT_EQ(d.absolute_rows(), 6);
  EXPECT_TRUE(d.rows[0].absolute);
  EXPECT_NEAR(d.rows[1].position(0), 0.101, 1e-15);
  EXPECT_NEAR(d.rows[0].q(0), 10 * M_PI / 180, 1e-15);
  EXPECT_EQ(d.rows[4].session, "B");
  EXPECT_EQ(d.rows[1].observed(), d.rows[1].position);
}

TEST(AbsoluteDataset, WriteReadRoundTripWithOrientation) {
  const std::string text =
      "# euler: zyx\n"
      "id,session,q1_rad,q2_rad,px_m,py_m,pz_m,a_deg,b_deg,c_deg,temp_C,sigma_p_um,sigma_o_urad\n"
      "1,s,0.1,0.2,1,2,3,10,-20,30,21.5,15,20\n"
      "2,s,0.3,0.2,1,2.5,3,170,80,-60,21.6,15,20\n"
      "3,s,0.1,0.7,1.5,2,3,-90,5,0,21.7,15,20\n";
  const Dataset d = parse_measurements_csv(text, "t.csv");
  ASSERT_TRUE(d.has_orientation);
  EXPECT_EQ(d.euler, EulerConvention::zyx);
  const double r = M_PI / 180;
  const Eigen::Matrix3d expect = (Eigen::AngleAxisd(10 * r, Eigen::Vector3d::UnitZ()) *
                                  Eigen::AngleAxisd(-20 * r, Eigen::Vector3d::UnitY()) *
                                  Eigen::AngleAxisd(30 * r, Eigen::Vector3d::UnitX()))
                                     .toRotationMatrix();
  EXPECT_LT((d.rows[0].orientation - expect).norm(), 1e-14);
  EXPECT_NEAR(d.rows[1].temperature, 21.6, 1e-12);
  EXPECT_NEAR(d.rows[0].sigma_p, 15e-6, 1e-18);
  EXPECT_NEAR(d.rows[0].sigma_o, 20e-6, 1e-18);
  const Dataset back = parse_measurements_csv(format_measurements_csv(d), "back.csv");
  ASSERT_EQ(back.size(), d.size());
  for (size_t i = 0; i < d.size(); ++i) {
    EXPECT_LT((back.rows[i].position - d.rows[i].position).norm(), 1e-15);
    EXPECT_LT((back.rows[i].orientation - d.rows[i].orientation).norm(), 1e-12);
    EXPECT_EQ(back.rows[i].session, d.rows[i].session);
    EXPECT_DOUBLE_EQ(back.rows[i].temperature, d.rows[i].temperature);
  }
}

TEST(AbsoluteDataset, EulerXyzIsRxRyRz) {
  const Eigen::Matrix3d r = euler_to_matrix(EulerConvention::xyz, 0.1, -0.4, 2.0);
  const Eigen::Matrix3d e = (Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitX()) *
                             Eigen::AngleAxisd(-0.4, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(2.0, Eigen::Vector3d::UnitZ()))
                                .toRotationMatrix();
  EXPECT_LT((r - e).norm(), 1e-15);
  const Eigen::Vector3d back = matrix_to_euler(EulerConvention::xyz, r);
  EXPECT_LT((back - Eigen::Vector3d(0.1, -0.4, 2.0)).norm(), 1e-12);
}

TEST(AbsoluteDataset, MixedFileHoldsBothKinds) {
  const std::string text =
      "id,session,q1_rad,fx_N,fy_N,fz_N,dx_um,dy_um,dz_um,px_m,py_m,pz_m\n"
      "d1,,0.1,10,0,0,5,6,7,,,\n"
      "a1,S,0.2,,,,,,,1,2,3\n"
      "a2,S,0.3,,,,,,,1,2.1,3\n"
      "a3,S,0.4,,,,,,,1.2,2,3\n";
  const Dataset d = parse_measurements_csv(text, "t.csv");
  EXPECT_FALSE(d.rows[0].absolute);
  EXPECT_NEAR(d.rows[0].displacement(1), 6e-6, 1e-18);
  EXPECT_TRUE(d.rows[1].absolute);
  EXPECT_EQ(d.rows[1].force, Eigen::Vector3d::Zero());  // no load given: only gravity
  EXPECT_EQ(d.absolute_rows(), 3);
  const Dataset back = parse_measurements_csv(format_measurements_csv(d), "back.csv");
  EXPECT_EQ(back.absolute_rows(), 3);
  EXPECT_EQ(back.rows[0].displacement, d.rows[0].displacement);
}

TEST(AbsoluteDataset, BadInputsNameWhatAndWhere) {
  // Absolute row without a session.
  EXPECT_NE(error_of("id,q1_deg,px_m,py_m,pz_m\n1,0,1,2,3\n").find("without a session"),
            std::string::npos);
  EXPECT_NE(error_of(std::string(kHeader) + "r1,,1,2,3,4,5,6\n").find("without a session"),
            std::string::npos);
  // A session with too few rows to register.
  const std::string few = error_of(kHeader + rows("A", 3) + rows("B", 2, 3));
  EXPECT_NE(few.find("session 'B' has 2 absolute rows"), std::string::npos) << few;
  EXPECT_NE(few.find("t.csv:5:"), std::string::npos) << few;
  // Duplicate ids across sessions.
  const std::string dup = error_of(kHeader + rows("A", 3) + rows("B", 3));
  EXPECT_NE(dup.find("duplicate id 'r0' (already in session 'A'"), std::string::npos) << dup;
  // Euler angles without their convention, or with an unknown one.
  const std::string abc = "id,session,q1_rad,px_m,py_m,pz_m,a_rad,b_rad,c_rad\n";
  const std::string body = "1,s,0,1,2,3,0.1,0.2,0.3\n2,s,0,1,2,4,0.1,0.2,0.3\n3,s,0,1,3,3,0,0,0\n";
  EXPECT_NE(error_of(abc + body).find("# euler: xyz"), std::string::npos);
  EXPECT_NE(error_of("# euler: yxz\n" + abc + body).find("unknown Euler convention"),
            std::string::npos);
  // Degrees in a radian column.
  const std::string deg = error_of("# euler: xyz\n" + abc +
                                   "1,s,0,1,2,3,10,20,90\n2,s,0,1,2,4,0,0,0\n3,s,0,1,3,3,0,0,0\n");
  EXPECT_NE(deg.find("are these degrees"), std::string::npos) << deg;
  EXPECT_NE(deg.find("t.csv:3:"), std::string::npos) << deg;
  // A row with both kinds, and a row with neither.
  const std::string mixed = "id,session,q1_rad,fx_N,fy_N,fz_N,dx_m,dy_m,dz_m,px_m,py_m,pz_m\n";
  EXPECT_NE(error_of(mixed + "1,s,0,0,0,0,1,1,1,1,1,1\n").find("both"), std::string::npos);
  EXPECT_NE(error_of(mixed + "1,s,0,0,0,0,,,,,,\n").find("neither"), std::string::npos);
  // Half an orientation.
  EXPECT_NE(error_of("# euler: xyz\n" + abc + "1,s,0,1,2,3,0.1,,0.3\n").find("'b_rad': empty"),
            std::string::npos);
}

}  // namespace
}  // namespace stiff
