// Every C ABI function on bad input: NULL handles and pointers, NaN and infinite values, wrong
// sizes, unknown names, buffers too small. Each returns its status and a message that starts
// with the function's name; nothing crashes (ASan/valgrind runs of this test check leaks).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include "stiff/stiff.h"

namespace {

const double kNaN = std::numeric_limits<double>::quiet_NaN();
const double kInf = std::numeric_limits<double>::infinity();

std::string src(const char* rel) { return std::string(STIFF_SOURCE_DIR) + "/" + rel; }

// A versioned options struct as a C caller starts it: every field 0 (the library's defaults),
// struct_size set.
template <class Options>
Options zeroed() {
  Options o;
  std::memset(&o, 0, sizeof o);
  o.struct_size = sizeof o;
  return o;
}

struct Fixture {
  stiff_robot* robot = nullptr;
  stiff_dataset* design = nullptr;
  stiff_dataset* data = nullptr;
  stiff_result* fit = nullptr;
  stiff_model* model = nullptr;
  Fixture() {
    const double k[6] = {5.0914e4, 1.6382e4, 3.1311e4, 7.7911e3, 5.6136e3, 4.0e3};
    EXPECT_EQ(stiff_robot_load(&robot, src("examples/robots/rokae.yaml").c_str()), STIFF_OK);
    EXPECT_EQ(
        stiff_dataset_read_csv(&design, robot, src("examples/paper/design_kappa_a.csv").c_str()),
        STIFF_OK);
    EXPECT_EQ(stiff_simulate(&data, robot, design, nullptr, k, 6, nullptr), STIFF_OK);
    EXPECT_EQ(stiff_identify(&fit, robot, data, nullptr), STIFF_OK);
    EXPECT_EQ(stiff_model_create(&model, robot, fit), STIFF_OK);
  }
  ~Fixture() {
    stiff_model_destroy(model);
    stiff_result_destroy(fit);
    stiff_dataset_destroy(data);
    stiff_dataset_destroy(design);
    stiff_robot_destroy(robot);
  }
};

struct Case {
  const char* function;
  stiff_status expected;
  std::function<stiff_status()> call;
};

TEST(CApiMisuse, EveryFunctionReturnsItsStatusAndNamesItself) {
  Fixture f;
  const double q[6] = {0.1, 1.2, 0.5, -1.0, 1.3, 0.0};
  const double q_nan[6] = {0.1, kNaN, 0.5, -1.0, 1.3, 0.0};
  const double w[6] = {20, -30, 25, 0, 0, 0};
  const double w_inf[6] = {20, kInf, 25, 0, 0, 0};
  double out[64];
  double pose[16];
  char text[4];
  size_t needed = 0, n = 0;
  int flag = 0;
  stiff_robot* r = nullptr;
  stiff_dataset* d = nullptr;
  stiff_result* res = nullptr;
  stiff_model* m = nullptr;
  stiff_plan* p = nullptr;
  stiff_diagnosis* dg = nullptr;
  stiff_robot_tool_pose(pose, f.robot, q, 6);
  const std::vector<Case> cases = {
      {"stiff_robot_load", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_robot_load(nullptr, "x.yaml"); }},
      {"stiff_robot_load", STIFF_E_INVALID_ARGUMENT, [&] { return stiff_robot_load(&r, nullptr); }},
      {"stiff_robot_load", STIFF_E_IO, [&] { return stiff_robot_load(&r, "/nonexistent.yaml"); }},
      {"stiff_robot_load", STIFF_E_PARSE,
       [&] { return stiff_robot_load(&r, src("examples/paper/design_kappa_a.csv").c_str()); }},
      {"stiff_robot_dof", STIFF_E_INVALID_ARGUMENT, [&] { return stiff_robot_dof(&n, nullptr); }},
      {"stiff_robot_dof", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_robot_dof(nullptr, f.robot); }},
      {"stiff_robot_name", STIFF_E_BUFFER_TOO_SMALL,
       [&] { return stiff_robot_name(text, sizeof text, &needed, f.robot); }},
      {"stiff_robot_limits", STIFF_E_BUFFER_TOO_SMALL,
       [&] { return stiff_robot_limits(out, out, 3, &needed, f.robot); }},
      {"stiff_robot_tool_pose", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_robot_tool_pose(pose, f.robot, q_nan, 6); }},
      {"stiff_robot_tool_pose", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_robot_tool_pose(pose, f.robot, q, 5); }},
      {"stiff_robot_jacobian", STIFF_E_BUFFER_TOO_SMALL,
       [&] { return stiff_robot_jacobian(out, 35, &needed, f.robot, q, 6); }},
      {"stiff_robot_to_urdf", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_robot_to_urdf(text, sizeof text, &needed, nullptr, nullptr); }},
      {"stiff_robot_to_urdf", STIFF_E_BUFFER_TOO_SMALL,
       [&] { return stiff_robot_to_urdf(text, sizeof text, &needed, f.robot, nullptr); }},
      {"stiff_robot_to_urdf", STIFF_E_INVALID_ARGUMENT,
       [&] {
         double world[16] = {2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1};  // not rigid
         return stiff_robot_to_urdf(nullptr, 0, &needed, f.robot, world);
       }},
      {"stiff_result_registration", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_result_registration(pose, nullptr, nullptr); }},
      {"stiff_result_registration", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_result_registration(nullptr, f.fit, nullptr); }},
      {"stiff_result_registration", STIFF_E_INVALID_ARGUMENT,  // a deflection fit: none
       [&] { return stiff_result_registration(pose, f.fit, nullptr); }},
      {"stiff_dataset_read_csv", STIFF_E_IO,
       [&] { return stiff_dataset_read_csv(&d, f.robot, "/nonexistent.csv"); }},
      {"stiff_dataset_read_csv", STIFF_E_PARSE,
       [&] {
         return stiff_dataset_read_csv(&d, f.robot, src("examples/robots/rokae.yaml").c_str());
       }},
      {"stiff_dataset_write_csv", STIFF_E_IO,
       [&] { return stiff_dataset_write_csv(f.data, "/nonexistent-dir/x.csv"); }},
      {"stiff_dataset_write_csv", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_dataset_write_csv(nullptr, "x.csv"); }},
      {"stiff_dataset_create", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_dataset_create(&d, 1, 6, q_nan, w, nullptr, nullptr, nullptr); }},
      {"stiff_dataset_create", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_dataset_create(&d, 0, 6, q, w, nullptr, nullptr, nullptr); }},
      {"stiff_dataset_create", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_dataset_create(&d, 1, 6, q, nullptr, nullptr, nullptr, nullptr); }},
      {"stiff_dataset_size", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_dataset_size(&n, &n, nullptr); }},
      {"stiff_dataset_has", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_dataset_has(&flag, f.data, static_cast<stiff_column>(99)); }},
      {"stiff_dataset_get", STIFF_E_BUFFER_TOO_SMALL,
       [&] { return stiff_dataset_get(out, 2, &needed, f.data, STIFF_COLUMN_FORCE); }},
      {"stiff_dataset_get", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_dataset_get(out, 64, &needed, f.design, STIFF_COLUMN_DISPLACEMENT); }},
      {"stiff_dataset_set_displacement", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_dataset_set_displacement(f.design, out, 3); }},
      {"stiff_dataset_id", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_dataset_id(text, sizeof text, &needed, f.data, 99); }},
      {"stiff_noise_read", STIFF_E_IO,
       [&] {
         auto o = zeroed<stiff_noise_options>();
         return stiff_noise_read(&o, "/nonexistent.yaml");
       }},
      {"stiff_design_random", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_design_random(&d, f.robot, 0, 1); }},
      {"stiff_design_random_options_init", STIFF_E_INVALID_ARGUMENT,
       [&] {
         return stiff_design_random_options_init(nullptr, sizeof(stiff_design_random_options));
       }},
      {"stiff_design_random_options_init", STIFF_E_INVALID_ARGUMENT,
       [&] {
         auto o = zeroed<stiff_design_random_options>();
         return stiff_design_random_options_init(&o, 6);  // ends inside `count`
       }},
      {"stiff_design_random_with_options", STIFF_E_INVALID_ARGUMENT,
       [&] {
         auto o = zeroed<stiff_design_random_options>();
         o.use_workspace_box = 1;  // min = max = 0: an empty box
         return stiff_design_random_with_options(&d, f.robot, &o);
       }},
      {"stiff_design_random_with_options", STIFF_E_INVALID_ARGUMENT,
       [&] {
         auto o = zeroed<stiff_design_random_options>();
         const double q[2] = {0, 0};
         o.q_fixed = q;
         o.q_fixed_count = 2;
         return stiff_design_random_with_options(&d, f.robot, &o);
       }},
      {"stiff_simulate", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_simulate(&d, f.robot, f.design, nullptr, w_inf, 6, nullptr); }},
      {"stiff_simulate", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_simulate(&d, f.robot, f.design, nullptr, w, 5, nullptr); }},
      {"stiff_simulate", STIFF_E_INVALID_ARGUMENT,
       [&] {
         auto o = zeroed<stiff_noise_options>();
         o.tracker_sigma_m = -1;
         const double k[6] = {1, 1, 1, 1, 1, 1};
         return stiff_simulate(&d, f.robot, f.design, nullptr, k, 6, &o);
       }},
      {"stiff_identify", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_identify(&res, f.robot, f.design, nullptr); }},
      {"stiff_identify", STIFF_E_INVALID_ARGUMENT,
       [&] {
         stiff_identify_options o = STIFF_IDENTIFY_OPTIONS_INIT;
         o.loss = "squared_sinus";
         return stiff_identify(&res, f.robot, f.data, &o);
       }},
      {"stiff_identify", STIFF_E_INVALID_ARGUMENT,
       [&] {
         // A newer caller's larger struct with non-zero unknown fields.
         struct Bigger {
           stiff_identify_options o;
           double future;
         } b;
         std::memset(&b, 0, sizeof b);
         b.o.struct_size = sizeof b;
         b.future = 1.0;
         return stiff_identify(&res, f.robot, f.data, &b.o);
       }},
      {"stiff_result_read_json", STIFF_E_PARSE,
       [&] { return stiff_result_read_json(&res, src("examples/robots/rokae.yaml").c_str()); }},
      {"stiff_result_write_json", STIFF_E_IO,
       [&] { return stiff_result_write_json(f.fit, "/nonexistent-dir/fit.json"); }},
      {"stiff_result_json", STIFF_E_BUFFER_TOO_SMALL,
       [&] { return stiff_result_json(text, sizeof text, &needed, f.fit); }},
      {"stiff_result_joint_stiffness", STIFF_E_BUFFER_TOO_SMALL,
       [&] { return stiff_result_joint_stiffness(out, 5, &needed, f.fit); }},
      {"stiff_result_joint_stiffness_se", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_result_joint_stiffness_se(out, 6, &needed, nullptr); }},
      {"stiff_result_parameters", STIFF_E_BUFFER_TOO_SMALL,
       [&] { return stiff_result_parameters(out, nullptr, 1, &needed, f.fit); }},
      {"stiff_result_covariance", STIFF_E_BUFFER_TOO_SMALL,
       [&] { return stiff_result_covariance(out, 35, &needed, f.fit); }},
      {"stiff_result_residuals", STIFF_E_BUFFER_TOO_SMALL,
       [&] { return stiff_result_residuals(out, 29, &needed, f.fit); }},
      {"stiff_result_statistics", STIFF_E_INVALID_ARGUMENT,
       [&] {
         stiff_fit_statistics s;
         std::memset(&s, 0, sizeof s);  // struct_size 0
         return stiff_result_statistics(&s, f.fit);
       }},
      {"stiff_result_warning", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_result_warning(text, sizeof text, &needed, f.fit, 1000); }},
      {"stiff_model_create", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_model_create(&m, f.robot, nullptr); }},
      {"stiff_predict", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_predict(out, f.model, q_nan, 6, w); }},
      {"stiff_predict", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_predict(out, f.model, q, 6, w_inf); }},
      {"stiff_predict", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_predict(out, f.model, q, 7, w); }},
      {"stiff_predict_batch", STIFF_E_BUFFER_TOO_SMALL,
       [&] { return stiff_predict_batch(out, 5, &needed, f.model, q, w, 1, 6); }},
      {"stiff_effect_name", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_effect_name(text, sizeof text, &needed, 1000); }},
      {"stiff_effect_describe", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_effect_describe(text, sizeof text, &needed, nullptr, "warp_drive"); }},
      {"stiff_plan_create", STIFF_E_INVALID_ARGUMENT,
       [&] {
         auto o = zeroed<stiff_plan_options>();
         o.criterion = "prettiest";
         return stiff_plan_create(&p, f.robot, &o);
       }},
      {"stiff_plan_create", STIFF_E_INVALID_ARGUMENT,
       [&] {
         auto o = zeroed<stiff_plan_options>();
         o.load_min_N = kNaN;
         return stiff_plan_create(&p, f.robot, &o);
       }},
      {"stiff_plan_create", STIFF_E_INVALID_ARGUMENT,
       [&] {
         auto o = zeroed<stiff_plan_options>();
         o.annealing_initial_temperature = -1.0;
         return stiff_plan_create(&p, f.robot, &o);
       }},
      {"stiff_plan_dataset", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_plan_dataset(&d, nullptr); }},
      {"stiff_plan_json", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_plan_json(text, sizeof text, &needed, nullptr); }},
      {"stiff_criteria_json", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_criteria_json(text, sizeof text, &needed, f.robot, f.design, kNaN); }},
      {"stiff_criterion_name", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_criterion_name(text, sizeof text, &needed, 1000); }},
      {"stiff_diagnose", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_diagnose(&dg, f.robot, f.design, nullptr, nullptr); }},
      {"stiff_diagnosis_json", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_diagnosis_json(text, sizeof text, &needed, nullptr); }},
      {"stiff_diagnosis_verdict", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_diagnosis_verdict(text, sizeof text, &needed, nullptr); }},
      {"stiff_fmu_export", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_fmu_export("x.fmu", f.robot, nullptr, nullptr); }},
      {"stiff_ik_analytic", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_ik_analytic(&flag, nullptr); }},
      {"stiff_tool_pose_batch", STIFF_E_BUFFER_TOO_SMALL,
       [&] { return stiff_tool_pose_batch(out, 15, &needed, f.robot, q, 1); }},
      {"stiff_tool_poses", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_tool_poses(out, 64, &needed, f.robot, q, 1, 5); }},
      {"stiff_robot_jacobians", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_robot_jacobians(out, 64, &needed, f.robot, q, 1, 5); }},
      {"stiff_robot_jacobians", STIFF_E_BUFFER_TOO_SMALL,
       [&] { return stiff_robot_jacobians(out, 35, &needed, f.robot, q, 1, 6); }},
      {"stiff_predict_dataset_cross_fitted", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_predict_dataset_cross_fitted(out, 64, &needed, nullptr, f.data); }},
      // A plan has no readings to estimate the session's own parameters from.
      {"stiff_predict_dataset_cross_fitted", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_predict_dataset_cross_fitted(out, 64, &needed, f.model, f.design); }},
      {"stiff_predict_dataset_cross_fitted", STIFF_E_BUFFER_TOO_SMALL,
       [&] { return stiff_predict_dataset_cross_fitted(out, 2, &needed, f.model, f.data); }},
      {"stiff_file_write", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_file_write(nullptr, "x", 1); }},
      {"stiff_file_write", STIFF_E_IO,
       [&] { return stiff_file_write("/nonexistent-dir/x.txt", "x", 1); }},
      {"stiff_ik", STIFF_E_INVALID_ARGUMENT,
       [&] {
         double bad[16];
         std::memcpy(bad, pose, sizeof bad);
         bad[3] = kNaN;
         return stiff_ik(out, 64, &needed, f.robot, bad, nullptr);
       }},
      {"stiff_ik_path", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_ik_path(out, 64, &needed, nullptr, nullptr, pose, 1, nullptr); }},
      {"stiff_compensate_pose", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_compensate_pose(out, f.model, q, 6, w_inf); }},
      {"stiff_compensate_path", STIFF_E_BUFFER_TOO_SMALL,
       [&] {
         return stiff_compensate_path(out, 5, &needed, nullptr, f.model, pose, w, 1, nullptr);
       }},
      {"stiff_filter_target", STIFF_E_INVALID_ARGUMENT,
       [&] {
         double bad[16];
         std::memcpy(bad, pose, sizeof bad);
         bad[0] = 2.0;  // not a rotation
         return stiff_filter_target(out, out + 16, 6, &needed, &flag, nullptr, f.model, pose,
                                    nullptr, w, bad, nullptr);
       }},
      {"stiff_filter_target", STIFF_E_BUFFER_TOO_SMALL,
       [&] {
         return stiff_filter_target(out, out + 16, 5, &needed, &flag, nullptr, f.model, pose,
                                    nullptr, w, nullptr, nullptr);
       }},
      {"stiff_robot_tool_points", STIFF_E_INVALID_ARGUMENT,
       [&] { return stiff_robot_tool_points(out, out + 3, nullptr); }},
      {"stiff_truth_deviation", STIFF_E_IO,
       [&] {
         return stiff_truth_deviation(out, 64, &needed, f.robot, "/nonexistent.yaml", q, pose, w,
                                      1);
       }},
      {"stiff_path_read", STIFF_E_IO,
       [&] {
         return stiff_path_read(out, out, nullptr, 1, &needed, &flag, "/nonexistent.csv", nullptr);
       }},
  };
  for (const auto& c : cases) {
    const stiff_status s = c.call();
    EXPECT_EQ(s, c.expected) << c.function << ": " << stiff_status_name(s) << " - "
                             << stiff_last_error();
    const std::string msg = stiff_last_error();
    EXPECT_EQ(msg.rfind(c.function, 0), 0u)
        << "message does not name " << c.function << ": " << msg;
    EXPECT_GT(msg.size(), std::strlen(c.function) + 4) << c.function;
  }
  // Failed creators leave their out-parameters NULL.
  EXPECT_EQ(r, nullptr);
  EXPECT_EQ(d, nullptr);
  EXPECT_EQ(res, nullptr);
  EXPECT_EQ(m, nullptr);
  EXPECT_EQ(p, nullptr);
  EXPECT_EQ(dg, nullptr);
  // Buffer protocol: `needed` tells the size, and a second call with it succeeds.
  ASSERT_EQ(stiff_robot_jacobian(out, 0, &needed, f.robot, q, 6), STIFF_E_BUFFER_TOO_SMALL);
  EXPECT_EQ(needed, 36u);
  EXPECT_EQ(stiff_robot_jacobian(out, needed, &needed, f.robot, q, 6), STIFF_OK);
  // Destroy(NULL) is a no-op for every handle type.
  stiff_robot_destroy(nullptr);
  stiff_dataset_destroy(nullptr);
  stiff_result_destroy(nullptr);
  stiff_model_destroy(nullptr);
  stiff_plan_destroy(nullptr);
  stiff_diagnosis_destroy(nullptr);
}

// One buffer convention (boundary.hpp require_capacity): a NULL buffer is capacity 0, so
// (NULL, 0, &needed) is the size query, and NULL is accepted when nothing is to be written.
TEST(CApiMisuse, BufferConventionIsTheSameEverywhere) {
  Fixture f;
  const double q[6] = {0.1, 1.2, 0.5, -1.0, 1.3, 0.0};
  const double w[6] = {20, -30, 25, 0, 0, 0};
  double lo[6], hi[6], out[64];
  size_t needed = 0;

  EXPECT_EQ(stiff_robot_limits(nullptr, nullptr, 0, &needed, f.robot), STIFF_E_BUFFER_TOO_SMALL);
  EXPECT_EQ(needed, 6u);
  EXPECT_EQ(stiff_robot_limits(lo, nullptr, 6, &needed, f.robot), STIFF_E_BUFFER_TOO_SMALL);
  EXPECT_EQ(stiff_robot_limits(nullptr, hi, 6, &needed, f.robot), STIFF_E_BUFFER_TOO_SMALL);
  EXPECT_EQ(stiff_robot_limits(lo, hi, needed, &needed, f.robot), STIFF_OK);

  needed = 0;
  EXPECT_EQ(stiff_result_parameters(nullptr, nullptr, 0, &needed, f.fit), STIFF_E_BUFFER_TOO_SMALL);
  EXPECT_EQ(needed, 6u);
  EXPECT_EQ(stiff_result_parameters(nullptr, nullptr, 64, &needed, f.fit),
            STIFF_E_BUFFER_TOO_SMALL);
  EXPECT_EQ(stiff_result_parameters(out, nullptr, needed, &needed, f.fit), STIFF_OK);

  needed = 99;
  EXPECT_EQ(stiff_predict_batch(nullptr, 0, &needed, f.model, q, w, 1, 6),
            STIFF_E_BUFFER_TOO_SMALL);
  EXPECT_EQ(needed, 6u);
  // Nothing to write: a NULL buffer is fine, as for copy_out-based functions.
  EXPECT_EQ(stiff_predict_batch(nullptr, 0, &needed, f.model, q, w, 0, 6), STIFF_OK);
  EXPECT_EQ(needed, 0u);
  EXPECT_EQ(stiff_tool_pose_batch(nullptr, 0, &needed, f.robot, q, 0), STIFF_OK);
  EXPECT_EQ(needed, 0u);
}

TEST(CApiMisuse, LastErrorIsPerThread) {
  stiff_robot* r = nullptr;
  ASSERT_EQ(stiff_robot_load(&r, "/nonexistent-main.yaml"), STIFF_E_IO);
  std::string other;
  std::thread t([&] {
    stiff_robot* r2 = nullptr;
    stiff_robot_load(&r2, "/nonexistent-thread.yaml");
    other = stiff_last_error();
  });
  t.join();
  EXPECT_NE(std::string(stiff_last_error()).find("nonexistent-main"), std::string::npos);
  EXPECT_NE(other.find("nonexistent-thread"), std::string::npos);
}

}  // namespace

// A struct_size must be where a version of the struct ends. One that ends inside a field was
// read as half a pointer (a crash in strlen) or written back as a torn double.
TEST(CApiMisuse, StructSizeEndingInsideAFieldIsRefused) {
  Fixture f;
  stiff_result* res = nullptr;
  for (uint32_t size : {5u, 10u, 15u, 20u, 30u}) {
    auto o = zeroed<stiff_identify_options>();
    o.model = "joint";
    o.struct_size = size;
    EXPECT_EQ(stiff_identify(&res, f.robot, f.data, &o), STIFF_E_INVALID_ARGUMENT) << size;
    EXPECT_NE(std::string(stiff_last_error()).find("no version of the struct"), std::string::npos)
        << stiff_last_error();
    EXPECT_EQ(res, nullptr);
  }
  // Sizes that end on a field: the fields after it keep their defaults.
  for (uint32_t size : {4u, 8u, 16u, 24u, static_cast<uint32_t>(sizeof(stiff_identify_options))}) {
    auto o = zeroed<stiff_identify_options>();
    o.struct_size = size;
    EXPECT_EQ(stiff_identify(&res, f.robot, f.data, &o), STIFF_OK) << size << stiff_last_error();
    stiff_result_destroy(res);
    res = nullptr;
  }
  // Output structs: the caller's bytes are left as they were when the size is refused.
  stiff_noise_options noise;
  std::memset(&noise, 0xab, sizeof noise);
  noise.struct_size = 12;
  const std::string path = src("examples/truths/noise_realistic.yaml");
  EXPECT_EQ(stiff_noise_read(&noise, path.c_str()), STIFF_E_INVALID_ARGUMENT);
  unsigned char expected[sizeof noise];
  std::memset(expected, 0xab, sizeof expected);
  EXPECT_EQ(
      std::memcmp(reinterpret_cast<unsigned char*>(&noise) + 4, expected + 4, sizeof noise - 4), 0);
  stiff_fit_statistics st;
  std::memset(&st, 0, sizeof st);
  st.struct_size = 6;
  EXPECT_EQ(stiff_result_statistics(&st, f.fit), STIFF_E_INVALID_ARGUMENT);
  // A newer caller's larger output struct: its unknown tail is its own business.
  struct Bigger {
    stiff_fit_statistics s;
    double future;
  } b;
  std::memset(&b, 0, sizeof b);
  b.s.struct_size = sizeof b;
  b.future = 7.0;
  EXPECT_EQ(stiff_result_statistics(&b.s, f.fit), STIFF_OK) << stiff_last_error();
  EXPECT_EQ(b.future, 7.0);
  EXPECT_GT(b.s.measurements, 0u);
}

// rows x width products that wrap around size_t must not pass the capacity check.
TEST(CApiMisuse, RowCountsThatOverflowAreRefused) {
  Fixture f;
  const double q[6] = {0.1, 1.2, 0.5, -1.0, 1.3, 0.0};
  const double w[6] = {20, -30, 25, 0, 0, 0};
  double out[16];
  size_t needed = 0;
  const size_t huge = std::numeric_limits<size_t>::max() / 6 + 2;  // 6 * huge wraps to 6
  EXPECT_EQ(stiff_predict_batch(out, 16, &needed, f.model, q, w, huge, 6),
            STIFF_E_INVALID_ARGUMENT);
  EXPECT_NE(std::string(stiff_last_error()).find("more than memory"), std::string::npos)
      << stiff_last_error();
  const size_t huge16 = std::numeric_limits<size_t>::max() / 16 + 2;
  EXPECT_EQ(stiff_tool_pose_batch(out, 16, &needed, f.robot, q, huge16), STIFF_E_INVALID_ARGUMENT);
}
