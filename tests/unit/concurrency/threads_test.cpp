// Distinct handles are independent (stiff.h, "Threading"): 8 threads each load the robot, read
// the design, simulate, identify (linear and Ceres), write/read the fit and predict on their own
// handles, and get the same numbers as one thread, bit for bit. Run under ThreadSanitizer by
// scripts/ci-sanitize.sh (test names contain "Threads").
#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "stiff/stiff.h"

namespace {

struct Outcome {
  int failed_status = 0;
  std::string error;
  std::vector<double> displacement, stiffness, parameters_ceres, deflection, jacobian;
  std::string json;
};

/// Everything a client does with its own handles; `seed` varies the simulated noise.
Outcome workflow(uint64_t seed) {
  Outcome o;
  const std::string src = STIFF_SOURCE_DIR;
  stiff_robot* robot = nullptr;
  stiff_dataset* design = nullptr;
  stiff_dataset* data = nullptr;
  stiff_result* fit = nullptr;
  stiff_result* fit_ceres = nullptr;
  stiff_model* model = nullptr;
  auto check = [&](stiff_status s) {
    if (s != STIFF_OK && o.failed_status == 0) {
      o.failed_status = s;
      o.error = stiff_last_error();
    }
    return s == STIFF_OK;
  };
  const double k[6] = {5.0914e4, 1.6382e4, 3.1311e4, 7.7911e3, 5.6136e3, 4.0e3};
  stiff_noise_options noise;
  std::memset(&noise, 0, sizeof noise);
  noise.struct_size = sizeof noise;
  noise.tracker_sigma_m = 10e-6;
  noise.force_relative = 0.01;
  noise.seed = seed;
  size_t needed = 0, rows = 0;
  if (check(stiff_robot_load(&robot, (src + "/examples/robots/rokae.yaml").c_str())) &&
      check(stiff_dataset_read_csv(&design, robot,
                                   (src + "/examples/paper/design_kappa_j.csv").c_str())) &&
      check(stiff_simulate(&data, robot, design, nullptr, k, 6, &noise)) &&
      check(stiff_dataset_size(&rows, nullptr, data))) {
    o.displacement.resize(rows * 3);
    check(stiff_dataset_get(o.displacement.data(), o.displacement.size(), &needed, data,
                            STIFF_COLUMN_DISPLACEMENT));
    stiff_identify_options opt = STIFF_IDENTIFY_OPTIONS_INIT;
    if (check(stiff_identify(&fit, robot, data, &opt))) {
      o.stiffness.resize(6);
      check(stiff_result_joint_stiffness(o.stiffness.data(), 6, &needed, fit));
      stiff_result_json(nullptr, 0, &needed, fit);
      o.json.resize(needed);
      check(stiff_result_json(o.json.data(), o.json.size(), &needed, fit));
      if (check(stiff_model_create(&model, robot, fit))) {
        const double q[12] = {0.1, 1.2, 0.5, -1.0, 1.3, 0.0, -0.4, 0.8, 0.9, 0.3, -1.1, 0.2};
        const double w[12] = {20, -30, 25, 1, 0, -2, -10, 5, 40, 0, 0.5, 0};
        o.deflection.resize(12);
        check(stiff_predict_batch(o.deflection.data(), 12, &needed, model, q, w, 2, 6));
        o.jacobian.resize(36);
        check(stiff_robot_jacobian(o.jacobian.data(), 36, &needed, robot, q, 6));
      }
    }
    stiff_identify_options ceres = STIFF_IDENTIFY_OPTIONS_INIT;
    ceres.model = "joint";
    ceres.loss = "huber";
    ceres.max_iterations = 20;
    if (check(stiff_identify(&fit_ceres, robot, data, &ceres))) {
      stiff_result_parameters(nullptr, nullptr, 0, &needed, fit_ceres);
      o.parameters_ceres.resize(needed);
      check(
          stiff_result_parameters(o.parameters_ceres.data(), nullptr, needed, &needed, fit_ceres));
    }
  }
  stiff_model_destroy(model);
  stiff_result_destroy(fit_ceres);
  stiff_result_destroy(fit);
  stiff_dataset_destroy(data);
  stiff_dataset_destroy(design);
  stiff_robot_destroy(robot);
  return o;
}

/// Bitwise equality (NaN == NaN when the bits agree: unidentified joints are NaN).
bool same_bits(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
}

void expect_same(const Outcome& got, const Outcome& want, int thread) {
  SCOPED_TRACE("thread " + std::to_string(thread));
  EXPECT_EQ(got.failed_status, 0) << got.error;
  EXPECT_TRUE(same_bits(got.displacement, want.displacement));
  EXPECT_TRUE(same_bits(got.stiffness, want.stiffness));
  EXPECT_TRUE(same_bits(got.parameters_ceres, want.parameters_ceres));
  EXPECT_TRUE(same_bits(got.deflection, want.deflection));
  EXPECT_TRUE(same_bits(got.jacobian, want.jacobian));
  EXPECT_EQ(got.json, want.json);
}

TEST(Threads, SeparateHandlesGiveTheSameResultsAsOneThreadBitForBit) {
  constexpr int kThreads = 8;
  std::vector<Outcome> serial;
  for (int t = 0; t < kThreads; ++t) serial.push_back(workflow(1 + t % 2));
  ASSERT_EQ(serial[0].failed_status, 0) << serial[0].error;
  ASSERT_FALSE(serial[0].stiffness.empty());

  std::vector<Outcome> parallel(kThreads);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t)
    threads.emplace_back([t, &parallel] { parallel[t] = workflow(1 + t % 2); });
  for (auto& th : threads) th.join();
  for (int t = 0; t < kThreads; ++t) expect_same(parallel[t], serial[t], t);
  // Same seed, same data: the two seeds' runs agree among themselves.
  expect_same(serial[2], serial[0], 2);
}

// Errors are per thread: a failure on one thread does not change another's last error.
TEST(Threads, LastErrorIsPerThread) {
  stiff_robot* r = nullptr;
  ASSERT_EQ(stiff_robot_load(&r, "/nonexistent/a.yaml"), STIFF_E_IO);
  const std::string mine = stiff_last_error();
  std::string other;
  std::thread th([&] {
    stiff_robot* r2 = nullptr;
    EXPECT_EQ(stiff_robot_load(&r2, "/nonexistent/b.yaml"), STIFF_E_IO);
    other = stiff_last_error();
  });
  th.join();
  EXPECT_NE(mine.find("a.yaml"), std::string::npos);
  EXPECT_NE(other.find("b.yaml"), std::string::npos);
  EXPECT_EQ(std::string(stiff_last_error()), mine);
}

}  // namespace
