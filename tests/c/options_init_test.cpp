// Every stiff_*_options_init writes the C++ core's own defaults (compared with the core's
// option structs, not with numbers typed here), refuses NULL and struct sizes that are no
// version of the struct, and a struct it filled gives the same result as NULL options.
#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <iterator>
#include <string>
#include <vector>

#include "stiff/diagnose/diagnose.hpp"
#include "stiff/export/fmu_export.hpp"
#include "stiff/identify/identify.hpp"
#include "stiff/io/path_io.hpp"
#include "stiff/io/robot_io.hpp"
#include "stiff/model/model.hpp"
#include "stiff/plan/plan.hpp"
#include "stiff/sim/simulate.hpp"
#include "stiff/stiff.h"

namespace {

std::string src(const char* rel) { return std::string(STIFF_SOURCE_DIR) + "/" + rel; }

/// A string out of a (text, capacity, needed, handle) call.
template <typename Handle>
std::string text_of(stiff_status (*fn)(char*, size_t, size_t*, const Handle*), const Handle* h) {
  size_t needed = 0;
  fn(nullptr, 0, &needed, h);
  std::vector<char> buf(needed + 1);
  EXPECT_EQ(fn(buf.data(), buf.size(), &needed, h), STIFF_OK) << stiff_last_error();
  return std::string(buf.data());
}

/// The checks every init shares: NULL and struct sizes that are no version of the struct are
/// INVALID_ARGUMENT with a message naming the function and the cause; nothing is written then.
template <typename T>
void expect_refuses_bad_arguments(stiff_status (*init)(T*, size_t),
                                  const char* name,
                                  size_t first_size) {
  SCOPED_TRACE(name);
  EXPECT_EQ(init(nullptr, sizeof(T)), STIFF_E_INVALID_ARGUMENT);
  std::string msg = stiff_last_error();
  EXPECT_EQ(msg.rfind(name, 0), 0u) << msg;
  EXPECT_NE(msg.find("options is NULL"), std::string::npos) << msg;

  T o;
  std::memset(&o, 0xAB, sizeof o);
  const T untouched = o;
  for (const size_t size : {size_t{0}, size_t{3}, first_size - 1}) {
    EXPECT_EQ(init(&o, size), STIFF_E_INVALID_ARGUMENT) << "struct_size " << size;
    msg = stiff_last_error();
    EXPECT_EQ(msg.rfind(name, 0), 0u) << msg;
    EXPECT_NE(msg.find("struct_size " + std::to_string(size)), std::string::npos) << msg;
    EXPECT_EQ(std::memcmp(&o, &untouched, sizeof o), 0) << "written on failure";
  }
  // A size that ends inside a field (here: the first field appended after the first release)
  // is no version of the struct.
  if (first_size < sizeof(T)) {
    EXPECT_EQ(init(&o, first_size + 1), STIFF_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(stiff_last_error()).find("no version of"), std::string::npos)
        << stiff_last_error();
  }

  // A caller compiled against a newer, larger struct: the library writes its own part only
  // and says so in struct_size.
  unsigned char big[sizeof(T) + 16];
  std::memset(big, 0xCD, sizeof big);
  EXPECT_EQ(init(reinterpret_cast<T*>(big), sizeof big), STIFF_OK) << stiff_last_error();
  uint32_t written = 0;
  std::memcpy(&written, big, sizeof written);
  EXPECT_EQ(written, sizeof(T));
  for (size_t i = sizeof(T); i < sizeof big; ++i) EXPECT_EQ(big[i], 0xCD) << "byte " << i;
}

/// init with sizeof: struct_size is sizeof(T).
template <typename T>
T filled(stiff_status (*init)(T*, size_t)) {
  T o;
  std::memset(&o, 0xAB, sizeof o);  // every field must be written
  EXPECT_EQ(init(&o, sizeof o), STIFF_OK) << stiff_last_error();
  EXPECT_EQ(o.struct_size, sizeof o);
  return o;
}

std::string str(const char* s) { return s ? std::string(s) : std::string(); }

class OptionsInit : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_EQ(stiff_robot_load(&robot_, src("examples/robots/rokae.yaml").c_str()), STIFF_OK);
    ASSERT_EQ(stiff_design_random(&design_, robot_, 40, 3), STIFF_OK) << stiff_last_error();
  }
  void TearDown() override {
    stiff_dataset_destroy(design_);
    stiff_robot_destroy(robot_);
  }
  /// Measurements of the random design on the paper's stiffness, with the given noise.
  stiff_dataset* measured(const stiff_noise_options* noise) {
    const double k[6] = {5.0914e4, 1.6382e4, 3.1311e4, 7.7911e3, 5.6136e3, 4.0e3};
    stiff_dataset* d = nullptr;
    EXPECT_EQ(stiff_simulate(&d, robot_, design_, nullptr, k, 6, noise), STIFF_OK)
        << stiff_last_error();
    return d;
  }
  std::vector<double> displacements(const stiff_dataset* d) {
    size_t rows = 0;
    EXPECT_EQ(stiff_dataset_size(&rows, nullptr, d), STIFF_OK);
    std::vector<double> v(3 * rows);
    EXPECT_EQ(stiff_dataset_get(v.data(), v.size(), nullptr, d, STIFF_COLUMN_DISPLACEMENT),
              STIFF_OK);
    return v;
  }
  stiff_robot* robot_ = nullptr;
  stiff_dataset* design_ = nullptr;
};

TEST_F(OptionsInit, RobotOptions) {
  const stiff_robot_options o = filled(stiff_robot_options_init);
  const stiff::RobotLoadOptions core;
  EXPECT_EQ(str(o.base_link), core.base_link);
  EXPECT_EQ(str(o.tip_link), core.tip_link);
  EXPECT_EQ(o.set, 0u);  // the core replaces none of the file's values by default
  EXPECT_FALSE(core.measured_point || core.load_point || core.tool_mass || core.tool_com);
  expect_refuses_bad_arguments(stiff_robot_options_init, "stiff_robot_options_init",
                               sizeof(stiff_robot_options));

  // Same robot as NULL options, for a YAML robot and a URDF chain.
  for (const char* file : {"examples/robots/rokae.yaml", "examples/robots/ur5.urdf"}) {
    SCOPED_TRACE(file);
    stiff_robot *a = nullptr, *b = nullptr;
    const stiff_status sa = stiff_robot_load_with(&a, src(file).c_str(), nullptr);
    const stiff_status sb = stiff_robot_load_with(&b, src(file).c_str(), &o);
    ASSERT_EQ(sa, sb) << stiff_last_error();
    if (sa == STIFF_OK) {
      EXPECT_EQ(text_of(stiff_robot_to_yaml, a), text_of(stiff_robot_to_yaml, b));
      EXPECT_EQ(text_of(stiff_robot_notes, a), text_of(stiff_robot_notes, b));
    }
    stiff_robot_destroy(a);
    stiff_robot_destroy(b);
  }
}

TEST_F(OptionsInit, NoiseOptions) {
  const stiff_noise_options o = filled(stiff_noise_options_init);
  const stiff::NoiseModel core;
  EXPECT_EQ(o.tracker_sigma_m, core.tracker_sigma_m);
  EXPECT_EQ(o.tracker_ppm, core.tracker_ppm);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(o.tracker_position_m[k], core.tracker_position_m(k));
  EXPECT_EQ(o.force_relative, core.force_relative);
  EXPECT_EQ(o.force_absolute_N, core.force_absolute_N);
  EXPECT_EQ(o.joint_sigma_rad, core.joint_sigma_rad);
  EXPECT_EQ(o.outlier_rate, core.outlier_rate);
  EXPECT_EQ(o.outlier_size_m, core.outlier_size_m);
  EXPECT_EQ(o.seed, core.seed);
  expect_refuses_bad_arguments(stiff_noise_options_init, "stiff_noise_options_init",
                               sizeof(stiff_noise_options));

  // The init struct is the noise of NULL options, bit for bit (and it is noise: the default
  // tracker is not perfect).
  stiff_dataset* a = measured(nullptr);
  stiff_dataset* b = measured(&o);
  ASSERT_TRUE(a && b);
  EXPECT_EQ(displacements(a), displacements(b));
  stiff_noise_options zero;
  std::memset(&zero, 0, sizeof zero);
  zero.struct_size = sizeof zero;
  stiff_dataset* exact = measured(&zero);
  ASSERT_TRUE(exact);
  EXPECT_NE(displacements(a), displacements(exact));
  stiff_dataset_destroy(exact);
  stiff_dataset_destroy(b);
  stiff_dataset_destroy(a);

  // The noise is checked once, in the core: its message names the field.
  stiff_noise_options bad = o;
  bad.outlier_rate = -0.1;
  stiff_dataset* d = nullptr;
  const double k[6] = {1e4, 1e4, 1e4, 1e4, 1e4, 1e4};
  EXPECT_EQ(stiff_simulate(&d, robot_, design_, nullptr, k, 6, &bad), STIFF_E_INVALID_ARGUMENT);
  EXPECT_NE(std::string(stiff_last_error()).find("outlier_rate must be finite and >= 0"),
            std::string::npos)
      << stiff_last_error();
}

TEST_F(OptionsInit, DesignRandomOptions) {
  const stiff_design_random_options o = filled(stiff_design_random_options_init);
  const stiff::RandomDesignOptions core;
  EXPECT_EQ(o.count, static_cast<uint32_t>(core.count));
  EXPECT_EQ(o.seed, core.seed);
  EXPECT_EQ(o.range_fraction, core.range_fraction);
  EXPECT_EQ(o.load_min_N, core.load_min_N);
  EXPECT_EQ(o.load_max_N, core.load_max_N);
  EXPECT_EQ(o.load_step_N, core.load_step_N);
  EXPECT_EQ(o.min_sigma_m, core.min_sigma);
  EXPECT_EQ(o.q_fixed, nullptr);
  EXPECT_EQ(o.use_workspace_box, 0u);
  expect_refuses_bad_arguments(stiff_design_random_options_init, "stiff_design_random_options_init",
                               sizeof(stiff_design_random_options));
  stiff_dataset *a = nullptr, *b = nullptr;
  ASSERT_EQ(stiff_design_random_with_options(&a, robot_, nullptr), STIFF_OK) << stiff_last_error();
  ASSERT_EQ(stiff_design_random_with_options(&b, robot_, &o), STIFF_OK) << stiff_last_error();
  for (const stiff_column c : {STIFF_COLUMN_Q, STIFF_COLUMN_FORCE}) {
    size_t na = 0, nb = 0;
    stiff_dataset_get(nullptr, 0, &na, a, c);
    stiff_dataset_get(nullptr, 0, &nb, b, c);
    std::vector<double> va(na), vb(nb);
    ASSERT_EQ(stiff_dataset_get(va.data(), na, nullptr, a, c), STIFF_OK);
    ASSERT_EQ(stiff_dataset_get(vb.data(), nb, nullptr, b, c), STIFF_OK);
    EXPECT_EQ(va, vb);
  }
  stiff_dataset_destroy(a);
  stiff_dataset_destroy(b);
}

TEST_F(OptionsInit, IdentifyOptions) {
  const stiff_identify_options o = filled(stiff_identify_options_init);
  const stiff::IdentifyOptions core;
  EXPECT_EQ(str(o.model), stiff::kDefaultModel);
  EXPECT_EQ(str(o.loss), core.loss);
  EXPECT_EQ(o.loss_scale_m, core.loss_scale_m);
  EXPECT_EQ(o.max_iterations, static_cast<uint32_t>(core.max_iterations));
  EXPECT_EQ(o.method, static_cast<uint32_t>(STIFF_METHOD_AUTO));
  EXPECT_EQ(o.progress, nullptr);
  EXPECT_EQ(o.progress_user_data, nullptr);
  EXPECT_EQ(o.max_relative_se, core.max_relative_se);
  EXPECT_EQ(o.max_relative_se, stiff::LinearOptions{}.max_relative_se);
  EXPECT_EQ(o.start, nullptr);
  EXPECT_EQ(o.refit, nullptr);
  EXPECT_EQ(o.select_terms, core.select_terms ? 1 : -1);
  expect_refuses_bad_arguments(stiff_identify_options_init, "stiff_identify_options_init",
                               offsetof(stiff_identify_options, max_relative_se));

  // The first released struct (before max_relative_se) is a version: its fields are written.
  stiff_identify_options old;
  std::memset(&old, 0xAB, sizeof old);
  const size_t old_size = offsetof(stiff_identify_options, max_relative_se);
  ASSERT_EQ(stiff_identify_options_init(&old, old_size), STIFF_OK) << stiff_last_error();
  EXPECT_EQ(old.struct_size, old_size);
  EXPECT_EQ(str(old.loss), core.loss);
  unsigned char ab[sizeof old];
  std::memset(ab, 0xAB, sizeof ab);
  EXPECT_EQ(
      std::memcmp(reinterpret_cast<unsigned char*>(&old) + old_size, ab, sizeof old - old_size), 0);

  // Same fit as NULL options: the linear default and the nonlinear path with the init values.
  stiff_dataset* data = measured(nullptr);
  ASSERT_TRUE(data);
  stiff_result *a = nullptr, *b = nullptr;
  ASSERT_EQ(stiff_identify(&a, robot_, data, nullptr), STIFF_OK) << stiff_last_error();
  ASSERT_EQ(stiff_identify(&b, robot_, data, &o), STIFF_OK) << stiff_last_error();
  EXPECT_EQ(text_of(stiff_result_json, a), text_of(stiff_result_json, b));
  stiff_result_destroy(a);
  stiff_result_destroy(b);
  stiff_identify_options ceres_zero = STIFF_IDENTIFY_OPTIONS_INIT;
  ceres_zero.method = STIFF_METHOD_CERES;
  stiff_identify_options ceres_init = o;
  ceres_init.method = STIFF_METHOD_CERES;
  ASSERT_EQ(stiff_identify(&a, robot_, data, &ceres_zero), STIFF_OK) << stiff_last_error();
  ASSERT_EQ(stiff_identify(&b, robot_, data, &ceres_init), STIFF_OK) << stiff_last_error();
  EXPECT_EQ(text_of(stiff_result_json, a), text_of(stiff_result_json, b));
  stiff_result_destroy(a);
  stiff_result_destroy(b);

  // select_terms: the data have no nonlinear reducer, so nonlinear_joint's optional terms
  // (all null in truth) are each kept only when they lower the BIC, i.e. with the chance of a
  // chi2(1) above ln(3N) (a few %): the default fit leaves terms out; < 0 fits every term and
  // leaves none out; > 0 is the default.
  {
    auto fit_text = [&](int32_t select) {
      stiff_identify_options t = o;
      t.model = "joint+nonlinear_joint";
      t.select_terms = select;
      stiff_result* r = nullptr;
      EXPECT_EQ(stiff_identify(&r, robot_, data, &t), STIFF_OK) << stiff_last_error();
      const std::string text = r ? text_of(stiff_result_json, r) : "";
      stiff_result_destroy(r);
      return text;
    };
    const std::string by_default = fit_text(0), all = fit_text(-1);
    EXPECT_NE(by_default.find("is left out"), std::string::npos);
    EXPECT_EQ(all.find("is left out"), std::string::npos);
    EXPECT_EQ(fit_text(1), by_default);
  }

  // Checked once, in the core, whichever method solves: the same message for both.
  for (const uint32_t method : {uint32_t{STIFF_METHOD_LINEAR}, uint32_t{STIFF_METHOD_CERES}}) {
    stiff_identify_options bad = o;
    bad.method = method;
    bad.loss_scale_m = std::nan("");
    EXPECT_EQ(stiff_identify(&a, robot_, data, &bad), STIFF_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(stiff_last_error()).find("loss_scale_m must be finite and >= 0"),
              std::string::npos)
        << stiff_last_error();
  }
  stiff_dataset_destroy(data);
}

TEST_F(OptionsInit, PathOptions) {
  const stiff_path_options o = filled(stiff_path_options_init);
  const stiff::PathOptions core;
  const Eigen::Matrix<double, 6, 1> frame = stiff::xyz_rpy_from_pose(core.frame);
  for (int k = 0; k < 6; ++k) EXPECT_EQ(o.frame[k], frame(k));
  // tool_rpy is the core's default tool orientation.
  Eigen::Matrix<double, 6, 1> tool;
  tool << 0, 0, 0, o.tool_rpy[0], o.tool_rpy[1], o.tool_rpy[2];
  EXPECT_LT((stiff::pose_from_xyz_rpy(tool).block<3, 3>(0, 0) - core.tool_orientation).norm(),
            1e-15);
  EXPECT_EQ(o.flags, 0u);
  EXPECT_EQ(o.segment_m, core.segment_m);
  expect_refuses_bad_arguments(stiff_path_options_init, "stiff_path_options_init",
                               sizeof(stiff_path_options));

  // Same path as NULL options; setting STIFF_PATH_TOOL_RPY alone keeps the orientation.
  stiff_path_options with_bit = o;
  with_bit.flags = STIFF_PATH_TOOL_RPY;
  for (const char* file : {"examples/paths/pocket.nc", "examples/paths/rokae_contour.csv"}) {
    SCOPED_TRACE(file);
    const std::string path = src(file);
    size_t rows = 0;
    stiff_path_read(nullptr, nullptr, nullptr, 0, &rows, nullptr, path.c_str(), nullptr);
    ASSERT_GT(rows, 0u) << stiff_last_error();
    std::vector<double> a(16 * rows), b(16 * rows), c(16 * rows);
    ASSERT_EQ(
        stiff_path_read(a.data(), nullptr, nullptr, rows, &rows, nullptr, path.c_str(), nullptr),
        STIFF_OK);
    ASSERT_EQ(stiff_path_read(b.data(), nullptr, nullptr, rows, &rows, nullptr, path.c_str(), &o),
              STIFF_OK);
    ASSERT_EQ(
        stiff_path_read(c.data(), nullptr, nullptr, rows, &rows, nullptr, path.c_str(), &with_bit),
        STIFF_OK);
    EXPECT_EQ(a, b);
    for (size_t i = 0; i < a.size(); ++i) EXPECT_NEAR(a[i], c[i], 1e-12) << "value " << i;
  }
}

TEST_F(OptionsInit, DiagnoseOptions) {
  const stiff_diagnose_options o = filled(stiff_diagnose_options_init);
  const stiff::DiagnosisOptions core;
  EXPECT_EQ(str(o.model), stiff::kDefaultModel);
  EXPECT_EQ(o.candidates, nullptr);
  EXPECT_TRUE(core.candidates.empty());
  EXPECT_EQ(o.alpha, core.alpha);
  EXPECT_EQ(o.auto_steps, 0u);  // with auto_loop: the core's own number of steps
  EXPECT_EQ(o.auto_loop, core.auto_loop ? 1u : 0u);
  EXPECT_EQ(str(o.command_prefix), core.command_prefix);
  expect_refuses_bad_arguments(stiff_diagnose_options_init, "stiff_diagnose_options_init",
                               offsetof(stiff_diagnose_options, auto_loop));

  stiff_dataset* data = measured(nullptr);
  ASSERT_TRUE(data);
  stiff_diagnosis *a = nullptr, *b = nullptr;
  ASSERT_EQ(stiff_diagnose(&a, robot_, data, nullptr, nullptr), STIFF_OK) << stiff_last_error();
  ASSERT_EQ(stiff_diagnose(&b, robot_, data, nullptr, &o), STIFF_OK) << stiff_last_error();
  EXPECT_EQ(text_of(stiff_diagnosis_json, a), text_of(stiff_diagnosis_json, b));
  stiff_diagnosis_destroy(a);
  stiff_diagnosis_destroy(b);

  // auto_loop alone walks the loop with the core's number of steps.
  stiff_diagnose_options loop = o, steps = o;
  loop.auto_loop = 1;
  steps.auto_steps = static_cast<uint32_t>(core.max_steps);
  ASSERT_EQ(stiff_diagnose(&a, robot_, data, nullptr, &loop), STIFF_OK) << stiff_last_error();
  ASSERT_EQ(stiff_diagnose(&b, robot_, data, nullptr, &steps), STIFF_OK) << stiff_last_error();
  EXPECT_EQ(text_of(stiff_diagnosis_json, a), text_of(stiff_diagnosis_json, b));
  stiff_diagnosis_destroy(a);
  stiff_diagnosis_destroy(b);

  // alpha is checked once, in the core.
  stiff_diagnose_options bad = o;
  bad.alpha = 1.5;
  EXPECT_EQ(stiff_diagnose(&a, robot_, data, nullptr, &bad), STIFF_E_INVALID_ARGUMENT);
  EXPECT_NE(std::string(stiff_last_error()).find("diagnose: alpha must be in (0, 1)"),
            std::string::npos)
      << stiff_last_error();
  stiff_dataset_destroy(data);
}

std::string file_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

TEST_F(OptionsInit, FmuOptions) {
  const stiff_fmu_options o = filled(stiff_fmu_options_init);
  const stiff::FmuExportOptions core;
  EXPECT_EQ(o.fmi_version, static_cast<uint32_t>(core.fmi_version));
  EXPECT_EQ(str(o.model_identifier), core.model_identifier);
  EXPECT_EQ(str(o.binaries_dir), core.binaries_dir);
  EXPECT_EQ(o.array_inputs, core.array_inputs ? 1u : 0u);
  expect_refuses_bad_arguments(stiff_fmu_options_init, "stiff_fmu_options_init",
                               offsetof(stiff_fmu_options, array_inputs));

  // The same FMU (or the same failure, where the FMU binaries are not built) as NULL options.
  stiff_dataset* data = measured(nullptr);
  ASSERT_TRUE(data);
  stiff_result* fit = nullptr;
  ASSERT_EQ(stiff_identify(&fit, robot_, data, nullptr), STIFF_OK) << stiff_last_error();
  const std::string a = ::testing::TempDir() + "options_init_null.fmu";
  const std::string b = ::testing::TempDir() + "options_init_init.fmu";
  const stiff_status sa = stiff_fmu_export(a.c_str(), robot_, fit, nullptr);
  const std::string ma = sa == STIFF_OK ? "" : stiff_last_error();
  const stiff_status sb = stiff_fmu_export(b.c_str(), robot_, fit, &o);
  const std::string mb = sb == STIFF_OK ? "" : stiff_last_error();
  EXPECT_EQ(sa, sb);
  if (sa == STIFF_OK) {
    const std::string fa = file_bytes(a);
    EXPECT_FALSE(fa.empty());
    EXPECT_EQ(fa, file_bytes(b));
  } else {
    EXPECT_EQ(ma, mb);
  }
  std::remove(a.c_str());
  std::remove(b.c_str());
  stiff_result_destroy(fit);
  stiff_dataset_destroy(data);
}

TEST_F(OptionsInit, PlanOptionsRefuseSizesThatAreNoVersion) {
  expect_refuses_bad_arguments(stiff_plan_options_init, "stiff_plan_options_init",
                               offsetof(stiff_plan_options, annealing_initial_temperature));
  // load_max_magnitude_N: the C field's 0 is the core's "unlimited".
  const stiff_plan_options o = filled(stiff_plan_options_init);
  const stiff::PoolOptions pool;
  EXPECT_EQ(o.load_max_magnitude_N,
            std::isfinite(pool.load_max_magnitude_N) ? pool.load_max_magnitude_N : 0.0);
}

// A joint held outside its limits is refused by the core (build_pool), so the C ABI shows the
// message Python and the command line show.
TEST_F(OptionsInit, PlanQFixedOutsideTheLimitsIsRefusedByTheCore) {
  stiff_plan_options o = filled(stiff_plan_options_init);
  double lower[6], upper[6];
  ASSERT_EQ(stiff_robot_limits(lower, upper, 6, nullptr, robot_), STIFF_OK);
  const double nan = std::nan("");
  const double q_fixed[6] = {upper[0] + 0.1, nan, nan, nan, nan, nan};
  o.q_fixed = q_fixed;
  o.q_fixed_count = 6;
  stiff_plan* p = nullptr;
  EXPECT_EQ(stiff_plan_create(&p, robot_, &o), STIFF_E_INVALID_ARGUMENT);
  EXPECT_EQ(p, nullptr);
  EXPECT_NE(std::string(stiff_last_error()).find("plan: joint 1 fixed at"), std::string::npos)
      << stiff_last_error();
  EXPECT_NE(std::string(stiff_last_error()).find("is outside its limits"), std::string::npos);
}

}  // namespace
