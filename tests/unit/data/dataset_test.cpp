#include "stiff/io/dataset.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "stiff/error.hpp"

namespace stiff {
namespace {

const char* kGood =
    "# robot: rokae-xb4\n"
    "# source: laser tracker\n"
    "id,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,fx_N,fy_N,fz_N,dx_mm,dy_mm,dz_mm,note\n"
    "c01,-30,90,47,-100,100,0,-35,-15,30,0.1012,-0.0413,0.2210,first\n"
    "c02,0,-50,47,140,-60,0,-15,35,-20,0.05,0.01,-0.02,\"with, comma\"\n";

TEST(MeasurementCsv, ReadsConvertsToSiAndKeepsMetadataAndExtraColumns) {
  const Dataset d = parse_measurements_csv(kGood, "good.csv", 6);
  ASSERT_EQ(d.size(), 2u);
  EXPECT_EQ(d.dof, 6);
  EXPECT_NEAR(d.rows[0].q(0), -30 * M_PI / 180, 1e-15);
  EXPECT_NEAR(d.rows[0].displacement(2), 0.2210e-3, 1e-18);
  EXPECT_EQ(d.meta("robot"), "rokae-xb4");
  ASSERT_EQ(d.extra_columns.size(), 1u);
  EXPECT_EQ(d.rows[1].extra[0], "with, comma");
  EXPECT_TRUE(d.has_displacement);
  EXPECT_FALSE(d.has_moment);
  // Written back in SI and read again: the same numbers to the last bit, metadata kept.
  const Dataset back = parse_measurements_csv(format_measurements_csv(d), "back.csv", 6);
  EXPECT_EQ(back.meta("source"), "laser tracker");
  EXPECT_EQ(back.rows[1].id, "c02");
  EXPECT_EQ(back.rows[1].extra[0], "with, comma");
  for (size_t r = 0; r < 2; ++r) {
    EXPECT_EQ(back.rows[r].q, d.rows[r].q);
    EXPECT_EQ(back.rows[r].displacement, d.rows[r].displacement);
  }
}

TEST(MeasurementCsv, PlanFilesWithoutDisplacementsAreRead) {
  const Dataset d = parse_measurements_csv(
      "q1_rad,q2_rad,fx_N,fy_N,fz_N,fx_flange_N\n0.1,0.2,1,2,3,4\n", "plan.csv", 0);
  EXPECT_EQ(d.dof, 2);
  EXPECT_FALSE(d.has_displacement);
  EXPECT_EQ(d.extra_columns[0], "fx_flange_N");
}

struct BadCase {
  const char* name;
  std::string text;
  int dof;
  const char* message;
  int line;
  int column;
};

TEST(MeasurementCsv, EveryBadInputHasItsOwnErrorWithFileLineColumn) {
  const std::string head = "id,q1_deg,q2_deg,fx_N,fy_N,fz_N,dx_m,dy_m,dz_m\n";
  const BadCase cases[] = {
      {"missing column", "id,q1_deg,q2_deg,fx_N,fy_N,dx_m,dy_m,dz_m\n", 2,
       "missing required column: fx, fy, fz", 1, 1},
      {"missing joint", "id,q1_deg,fx_N,fy_N,fz_N\n", 2, "missing required column q2", 1, 1},
      {"unknown unit", "id,q1_deg,q2_furlong,fx_N,fy_N,fz_N\n", 2, "unknown unit 'furlong'", 1, 11},
      {"no unit", "id,q1_deg,q2_deg,fx,fy_N,fz_N\n", 2, "has no unit suffix", 1, 18},
      {"NaN", head + "a,1,2,3,4,5,nan,0,0\n", 2, "not a finite number", 2, 13},
      {"text", head + "a,1,2,3,x4,5,0,0,0\n", 2, "'x4' is not a number", 2, 9},
      {"field count", head + "a,1,2,3,4,5,0,0\n", 2, "wrong field count", 2, 0},
      {"duplicate id", head + "a,1,2,3,4,5,0,0,0\na,1,2,3,4,5,0,0,0\n", 2, "duplicate id 'a'", 3,
       1},
      {"joint count mismatch", "id,q1_deg,q2_deg,q3_deg,fx_N,fy_N,fz_N\n", 2,
       "joint count mismatch", 1, 18},
      {"empty value", head + "a,1,,3,4,5,0,0,0\n", 2, "empty value", 2, 5},
      {"duplicate column", "id,q1_deg,q1_deg,fx_N,fy_N,fz_N\n", 0, "duplicate column", 1, 11},
      {"no header", "# only a comment\n", 0, "no header row", 1, 1},
  };
  for (const auto& c : cases) {
    try {
      parse_measurements_csv(c.text, "bad.csv", c.dof);
      ADD_FAILURE() << c.name << ": accepted";
    } catch (const ParseError& e) {
      EXPECT_NE(std::string(e.what()).find(c.message), std::string::npos)
          << c.name << ": " << e.what();
      EXPECT_EQ(e.path(), "bad.csv") << c.name;
      EXPECT_EQ(e.line(), c.line) << c.name << ": " << e.what();
      if (c.column > 0) EXPECT_EQ(e.column(), c.column) << c.name << ": " << e.what();
    }
  }
}

TEST(MeasurementCsv, UnitsConvertToSi) {
  const Dataset d = parse_measurements_csv(
      "q1_rad,mx_Nmm,my_Nm,mz_Nm,fx_N,fy_N,fz_N,dx_um,dy_m,dz_mm,sigma_d_um,t_min\n"
      "0,1000,0,0,0,0,0,5,0,0,10,2\n",
      "u.csv", 1);
  EXPECT_NEAR(d.rows[0].moment(0), 1.0, 1e-15);
  EXPECT_NEAR(d.rows[0].displacement(0), 5e-6, 1e-20);
  EXPECT_NEAR(d.rows[0].sigma_d, 1e-5, 1e-20);
  EXPECT_NEAR(d.rows[0].time, 120.0, 1e-12);
}

}  // namespace
}  // namespace stiff
