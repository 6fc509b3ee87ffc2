// Results through the C ABI equal the C++ core to the last bit for the same inputs.
#include <gtest/gtest.h>

#include <cstddef>
#include <cstring>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "stiff/identify/identify.hpp"
#include "stiff/io/robot_io.hpp"
#include "stiff/plan/plan.hpp"
#include "stiff/sim/simulate.hpp"
#include "stiff/stiff.h"

namespace {

std::string src(const char* rel) { return std::string(STIFF_SOURCE_DIR) + "/" + rel; }

TEST(CApi, IdentificationAndPredictionEqualTheCoreBitForBit) {
  const std::string robot_path = src("examples/robots/rokae.yaml");
  const std::string design_path = src("examples/paper/design_kappa_a.csv");
  const double k[6] = {5.0914e4, 1.6382e4, 3.1311e4, 7.7911e3, 5.6136e3, 4.0e3};

  // C++ core.
  const stiff::RobotModel robot = stiff::load_robot(robot_path);
  stiff::NoiseModel noise;
  noise.tracker_sigma_m = 10e-6;
  noise.seed = 9;
  const stiff::Dataset data =
      stiff::simulate(robot, stiff::joint_truth(Eigen::Map<const Eigen::VectorXd>(k, 6)),
                      stiff::read_measurements_csv(design_path, 6), noise);
  const stiff::FitResult fit = stiff::identify_joint_linear(robot, data);
  const stiff::FitResult robust = stiff::identify(robot, data, {"joint"}, [] {
    stiff::IdentifyOptions o;
    o.loss = "huber";
    return o;
  }());

  // C ABI on the same inputs.
  stiff_robot* r = nullptr;
  stiff_dataset* design = nullptr;
  stiff_dataset* d = nullptr;
  stiff_result* f = nullptr;
  stiff_result* fr = nullptr;
  stiff_model* m = nullptr;
  ASSERT_EQ(stiff_robot_load(&r, robot_path.c_str()), STIFF_OK);
  ASSERT_EQ(stiff_dataset_read_csv(&design, r, design_path.c_str()), STIFF_OK);
  stiff_noise_options no;
  std::memset(&no, 0, sizeof no);
  no.struct_size = sizeof no;
  no.tracker_sigma_m = 10e-6;
  no.seed = 9;
  ASSERT_EQ(stiff_simulate(&d, r, design, nullptr, k, 6, &no), STIFF_OK);
  ASSERT_EQ(stiff_identify(&f, r, d, nullptr), STIFF_OK);
  stiff_identify_options io = STIFF_IDENTIFY_OPTIONS_INIT;
  io.loss = "huber";
  ASSERT_EQ(stiff_identify(&fr, r, d, &io), STIFF_OK);

  double c[6], se[6];
  ASSERT_EQ(stiff_result_parameters(c, se, 6, nullptr, f), STIFF_OK);
  for (int j = 0; j < 6; ++j) EXPECT_EQ(c[j], fit.parameters[j].value) << "joint " << j + 1;
  for (int j = 0; j < 5; ++j) EXPECT_EQ(se[j], fit.parameters[j].standard_error);
  ASSERT_EQ(stiff_result_parameters(c, se, 6, nullptr, fr), STIFF_OK);
  for (int j = 0; j < 6; ++j) EXPECT_EQ(c[j], robust.parameters[j].value) << "joint " << j + 1;

  ASSERT_EQ(stiff_model_create(&m, r, f), STIFF_OK);
  stiff::DeflectionModel model(robot, fit.model);
  for (const auto& row : data.rows) {
    double w[6] = {row.force(0), row.force(1), row.force(2), 0, 0, 0};
    double out[6];
    ASSERT_EQ(stiff_predict(out, m, row.q.data(), 6, w), STIFF_OK);
    const auto expect = model.predict(fit.theta(), row, model.context(row, 0));
    for (int k6 = 0; k6 < 6; ++k6) EXPECT_EQ(out[k6], expect(k6));
  }
  stiff_model_destroy(m);
  stiff_result_destroy(fr);
  stiff_result_destroy(f);
  stiff_dataset_destroy(d);
  stiff_dataset_destroy(design);
  stiff_robot_destroy(r);
}

// A small, quick plan request: annealing only, on a 50 x 10 pool.
stiff_plan_options small_plan_options() {
  stiff_plan_options o;
  std::memset(&o, 0, sizeof o);
  o.struct_size = sizeof o;
  o.count = 10;
  o.pool_poses = 50;
  o.pool_loads = 10;
  o.optimizers = STIFF_PLAN_ANNEALING;
  o.annealing_iterations = 500;
  return o;
}

std::string plan_json(const stiff_plan* p) {
  size_t needed = 0;
  EXPECT_EQ(stiff_plan_json(nullptr, 0, &needed, p), STIFF_E_BUFFER_TOO_SMALL);
  std::vector<char> text(needed);
  EXPECT_EQ(stiff_plan_json(text.data(), text.size(), &needed, p), STIFF_OK);
  return std::string(text.data());
}

// The annealing entry of the plan JSON's optimizer trace.
nlohmann::json annealing_trace(const std::string& text) {
  const auto j = nlohmann::json::parse(text);
  for (const auto& t : j.at("trace"))
    if (t.at("optimizer") == "annealing") return t;
  ADD_FAILURE() << "no annealing trace in " << text;
  return nlohmann::json::object();
}

TEST(CApi, PlanAnnealingInitialTemperatureAndSwapCountReachTheOptimizer) {
  stiff_robot* r = nullptr;
  ASSERT_EQ(stiff_robot_load(&r, src("examples/robots/rokae.yaml").c_str()), STIFF_OK);

  stiff_plan_options o = small_plan_options();
  o.annealing_initial_temperature = 0.125;
  o.annealing_initial_swap_count = 2;
  stiff_plan* p = nullptr;
  ASSERT_EQ(stiff_plan_create(&p, r, &o), STIFF_OK) << stiff_last_error();
  const auto trace = annealing_trace(plan_json(p));
  EXPECT_EQ(trace.value("initial_temperature", -1.0), 0.125);
  EXPECT_EQ(trace.value("initial_swap_count", -1), 2);
  stiff_plan_destroy(p);

  // A caller compiled against the header before these fields (smaller struct_size; whatever
  // lies where the new fields would be is not read) gets the automatic T0 and
  // k0 = max(1, N / 3).
  stiff_plan_options old = small_plan_options();
  old.annealing_initial_temperature = -7.0;  // beyond the old struct_size: never read
  old.annealing_initial_swap_count = 9;
  old.struct_size =
      static_cast<uint32_t>(offsetof(stiff_plan_options, annealing_initial_temperature));
  p = nullptr;
  ASSERT_EQ(stiff_plan_create(&p, r, &old), STIFF_OK) << stiff_last_error();
  const auto automatic = annealing_trace(plan_json(p));
  EXPECT_GT(automatic.value("initial_temperature", -1.0), 0.0);
  EXPECT_EQ(automatic.value("initial_swap_count", -1), 3);
  stiff_plan_destroy(p);
  stiff_robot_destroy(r);
}

TEST(CApi, PlanRejectsANegativeOrNonFiniteInitialTemperature) {
  stiff_robot* r = nullptr;
  ASSERT_EQ(stiff_robot_load(&r, src("examples/robots/rokae.yaml").c_str()), STIFF_OK);
  for (const double t0 :
       {-1.0, std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    stiff_plan_options o = small_plan_options();
    o.annealing_initial_temperature = t0;
    stiff_plan* p = nullptr;
    EXPECT_EQ(stiff_plan_create(&p, r, &o), STIFF_E_INVALID_ARGUMENT) << t0;
    EXPECT_EQ(p, nullptr);
    const std::string msg = stiff_last_error();
    EXPECT_EQ(msg.rfind("stiff_plan_create", 0), 0u) << msg;
    EXPECT_NE(msg.find("initial temperature T0"), std::string::npos) << msg;
  }
  stiff_robot_destroy(r);
}

// stiff_plan_options_init writes the core's own defaults (one source for every surface), and
// for a caller compiled against an older, smaller struct touches nothing beyond its size.
TEST(CApi, PlanOptionsInitGivesTheCoreDefaults) {
  stiff_plan_options o;
  std::memset(&o, 0xAB, sizeof o);
  ASSERT_EQ(stiff_plan_options_init(&o, sizeof o), STIFF_OK) << stiff_last_error();
  const stiff::PlanOptions plan;
  const stiff::PoolOptions pool;
  EXPECT_EQ(o.struct_size, sizeof o);
  EXPECT_EQ(o.count, static_cast<uint32_t>(plan.count));
  EXPECT_EQ(std::string(o.criterion), plan.criterion);
  EXPECT_EQ(o.seed, plan.seed);
  EXPECT_EQ(o.pool_poses, static_cast<uint32_t>(pool.pose_count));
  EXPECT_EQ(o.pool_loads, static_cast<uint32_t>(pool.load_count));
  EXPECT_EQ(o.range_fraction, pool.range_fraction);
  EXPECT_EQ(o.load_min_N, pool.load_min_N);
  EXPECT_EQ(o.load_max_N, pool.load_max_N);
  EXPECT_EQ(o.load_step_N, pool.load_step_N);
  EXPECT_EQ(o.min_sigma_m, pool.min_sigma_m);
  EXPECT_EQ(o.annealing_iterations, static_cast<uint32_t>(plan.annealing.iterations));
  EXPECT_EQ(o.optimizers, STIFF_PLAN_ANNEALING | STIFF_PLAN_EXCHANGE);
  EXPECT_EQ(o.tracker_sigma_m, pool.noise.tracker_sigma_m);
  EXPECT_EQ(o.q_fixed, nullptr);
  EXPECT_EQ(o.task, nullptr);
  EXPECT_EQ(o.progress, nullptr);

  stiff_plan_options old;
  std::memset(&old, 0xAB, sizeof old);
  const size_t old_size = offsetof(stiff_plan_options, annealing_initial_temperature);
  ASSERT_EQ(stiff_plan_options_init(&old, old_size), STIFF_OK);
  EXPECT_EQ(old.struct_size, old_size);
  EXPECT_EQ(old.count, static_cast<uint32_t>(plan.count));
  unsigned char tail[sizeof old - old_size];
  std::memset(tail, 0xAB, sizeof tail);
  EXPECT_EQ(std::memcmp(reinterpret_cast<const unsigned char*>(&old) + old_size, tail, sizeof tail),
            0);
  EXPECT_EQ(stiff_plan_options_init(&old, 3), STIFF_E_INVALID_ARGUMENT);
  EXPECT_EQ(stiff_plan_options_init(nullptr, sizeof old), STIFF_E_INVALID_ARGUMENT);
}

}  // namespace
