// Measurement planning through the C ABI.
#include "stiff/plan/plan.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "boundary.hpp"
#include "handles.hpp"

struct stiff_plan {
  stiff::PlanResult result;
};

using namespace stiff;
using namespace stiff::capi;

namespace {
/// Every criterion's value of `set` as JSON; errors name the calling function `fn`.
stiff_status criteria_json(const char* fn,
                           char* json,
                           size_t capacity,
                           size_t* needed,
                           const stiff_robot* robot,
                           const stiff_dataset* set,
                           const stiff_dataset* task,
                           double tracker_sigma_m) {
  return guarded(fn, [&] {
    require(robot, "robot");
    require(set, "set");
    if (!(std::isfinite(tracker_sigma_m) && tracker_sigma_m >= 0))
      throw InvalidArgument("tracker_sigma_m must be finite and >= 0");
    CriteriaOptions co;
    if (tracker_sigma_m > 0) co.noise.tracker_sigma_m = tracker_sigma_m;
    if (task) co.task = task->data;
    nlohmann::json j = nlohmann::json::object();
    for (const auto& [name, value] : evaluate_criteria(robot->model, set->data, co))
      j[name] = std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
    return copy_string(j.dump(), json, capacity, needed);
  });
}
}  // namespace

extern "C" {

stiff_status stiff_plan_options_init(stiff_plan_options* options, size_t struct_size) {
  return guarded(__func__, [&] {
    // The defaults are the core's own option structs: nothing is restated here.
    const PoolOptions pool;
    const PlanOptions plan;
    stiff_plan_options o{};
    o.count = static_cast<uint32_t>(plan.count);
    o.criterion = static_string([] { return PlanOptions{}.criterion; });
    o.seed = plan.seed;
    o.pool_poses = static_cast<uint32_t>(pool.pose_count);
    o.pool_loads = static_cast<uint32_t>(pool.load_count);
    o.range_fraction = pool.range_fraction;
    o.load_min_N = pool.load_min_N;
    o.load_max_N = pool.load_max_N;
    o.load_step_N = pool.load_step_N > 0 ? pool.load_step_N : -1.0;
    // The C field's 0 is the core's "unlimited" (infinity).
    o.load_max_magnitude_N =
        std::isfinite(pool.load_max_magnitude_N) ? pool.load_max_magnitude_N : 0.0;
    o.min_sigma_m = pool.min_sigma_m;
    o.optimizers = (plan.annealing.enabled ? STIFF_PLAN_ANNEALING : 0u) |
                   (plan.exchange.enabled ? STIFF_PLAN_EXCHANGE : 0u) |
                   (plan.refine.enabled ? STIFF_PLAN_REFINE : 0u);
    o.annealing_iterations = static_cast<uint32_t>(plan.annealing.iterations);
    o.tracker_sigma_m = pool.noise.tracker_sigma_m;
    o.tracker_ppm = pool.noise.tracker_ppm;
    o.annealing_initial_temperature = plan.annealing.initial_temperature;
    o.annealing_initial_swap_count = static_cast<uint32_t>(plan.annealing.initial_swap_count);
    return init_options(options, struct_size,
                        offsetof(stiff_plan_options, annealing_initial_temperature),
                        "stiff_plan_options", o);
  });
}

stiff_status stiff_plan_create(stiff_plan** out,
                               const stiff_robot* robot,
                               const stiff_plan_options* options) {
  if (out) *out = nullptr;
  return guarded(__func__, [&] {
    require(out, "out");
    require(robot, "robot");
    const stiff_plan_options o = read_options(options);
    const double nums[] = {o.range_fraction,       o.load_min_N,  o.load_max_N,      o.load_step_N,
                           o.load_max_magnitude_N, o.min_sigma_m, o.tracker_sigma_m, o.tracker_ppm};
    require_finite(nums, sizeof nums / sizeof nums[0], "options");
    PoolOptions pool;
    PlanOptions plan;
    if (o.count) plan.count = static_cast<int>(o.count);
    if (o.criterion) plan.criterion = o.criterion;
    if (o.seed) plan.seed = pool.seed = o.seed;
    if (o.pool_poses) pool.pose_count = static_cast<int>(o.pool_poses);
    if (o.pool_loads) pool.load_count = static_cast<int>(o.pool_loads);
    if (o.range_fraction != 0) pool.range_fraction = o.range_fraction;
    if (o.load_min_N != 0) pool.load_min_N = o.load_min_N;
    if (o.load_max_N != 0) pool.load_max_N = o.load_max_N;
    if (o.load_step_N > 0) pool.load_step_N = o.load_step_N;
    if (o.load_step_N < 0) pool.load_step_N = 0.0;
    if (o.load_max_magnitude_N != 0) pool.load_max_magnitude_N = o.load_max_magnitude_N;
    if (o.min_sigma_m != 0) pool.min_sigma_m = o.min_sigma_m;
    if (o.q_fixed) {
      if (o.q_fixed_count != static_cast<size_t>(robot->model.dof()))
        throw InvalidArgument("q_fixed has " + std::to_string(o.q_fixed_count) +
                              " values, the robot has " + std::to_string(robot->model.dof()) +
                              " joints");
      pool.q_fixed.assign(o.q_fixed, o.q_fixed + o.q_fixed_count);
    }
    if (o.candidate_file) pool.candidate_file = o.candidate_file;
    if (o.tracker_sigma_m != 0) pool.noise.tracker_sigma_m = o.tracker_sigma_m;
    pool.noise.tracker_ppm = o.tracker_ppm;
    if (o.optimizers) {
      plan.annealing.enabled = o.optimizers & STIFF_PLAN_ANNEALING;
      plan.exchange.enabled = o.optimizers & STIFF_PLAN_EXCHANGE;
      plan.refine.enabled = o.optimizers & STIFF_PLAN_REFINE;
    }
    if (o.annealing_iterations) plan.annealing.iterations = o.annealing_iterations;
    // Validated once, in the core (check_plan_options), before the pool is built.
    plan.annealing.initial_temperature = o.annealing_initial_temperature;
    // The core caps k0 at N and at pool - N; the cap here only keeps the value an int.
    plan.annealing.initial_swap_count = static_cast<int>(
        std::min<uint32_t>(o.annealing_initial_swap_count, std::numeric_limits<int>::max()));
    if (o.use_workspace_box) {
      require_finite(o.box_min_m, 3, "box_min_m");
      require_finite(o.box_max_m, 3, "box_max_m");
      pool.use_workspace_box = true;
      pool.box_min_m = Eigen::Vector3d(o.box_min_m);
      pool.box_max_m = Eigen::Vector3d(o.box_max_m);
      for (int k = 0; k < 3; ++k)
        if (!(pool.box_min_m(k) < pool.box_max_m(k)))
          throw InvalidArgument("workspace box: min must be below max on every axis");
    }
    if (o.fixture_direction_count) {
      require(o.fixture_directions, "fixture_directions");
      require(o.fixture_forces_N, "fixture_forces_N");
      if (!o.fixture_force_count) throw InvalidArgument("fixture_forces_N: no force given");
      require_finite(o.fixture_directions, 3 * o.fixture_direction_count, "fixture_directions");
      require_finite(o.fixture_forces_N, o.fixture_force_count, "fixture_forces_N");
      for (size_t k = 0; k < o.fixture_direction_count; ++k)
        pool.fixture_directions.emplace_back(o.fixture_directions[3 * k],
                                             o.fixture_directions[3 * k + 1],
                                             o.fixture_directions[3 * k + 2]);
      pool.fixture_forces_N.assign(o.fixture_forces_N, o.fixture_forces_N + o.fixture_force_count);
    }
    if (o.task) plan.task = o.task->data;
    if (o.progress) {
      const auto fn = o.progress;
      void* ud = o.progress_user_data;
      plan.progress = [fn, ud](const PlanProgress& p) {
        int stop = 1;
        try {
          stop = fn(p.optimizer.c_str(), static_cast<uint64_t>(p.iteration),
                    static_cast<uint64_t>(p.total), p.best_score, ud);
        } catch (...) {
          stop = 1;  // an exception in user code stops the call cleanly
        }
        return stop == 0;
      };
    }
    auto r = std::make_unique<stiff_plan>();
    r->result = plan_measurements(robot->model, pool, plan);
    *out = r.release();
    return STIFF_OK;
  });
}

void stiff_plan_destroy(stiff_plan* plan) { delete plan; }

stiff_status stiff_plan_dataset(stiff_dataset** out, const stiff_plan* plan) {
  if (out) *out = nullptr;
  return guarded(__func__, [&] {
    require(out, "out");
    require(plan, "plan");
    auto d = std::make_unique<stiff_dataset>();
    d->data = plan_to_dataset(plan->result);
    *out = d.release();
    return STIFF_OK;
  });
}

stiff_status stiff_plan_json(char* json, size_t capacity, size_t* needed, const stiff_plan* plan) {
  return guarded(__func__, [&] {
    require(plan, "plan");
    return copy_string(plan_summary_json(plan->result), json, capacity, needed);
  });
}

stiff_status stiff_criteria_task_json(char* json,
                                      size_t capacity,
                                      size_t* needed,
                                      const stiff_robot* robot,
                                      const stiff_dataset* set,
                                      const stiff_dataset* task,
                                      double tracker_sigma_m) {
  return criteria_json(__func__, json, capacity, needed, robot, set, task, tracker_sigma_m);
}

stiff_status stiff_criteria_json(char* json,
                                 size_t capacity,
                                 size_t* needed,
                                 const stiff_robot* robot,
                                 const stiff_dataset* set,
                                 double tracker_sigma_m) {
  return criteria_json(__func__, json, capacity, needed, robot, set, nullptr, tracker_sigma_m);
}

size_t stiff_criterion_count(void) { return criterion_registry().size(); }

stiff_status stiff_criterion_name(char* name, size_t capacity, size_t* needed, size_t index) {
  return guarded(__func__, [&] {
    const auto& reg = criterion_registry();
    if (index >= reg.size())
      throw InvalidArgument("criterion index " + std::to_string(index) + " out of range");
    return copy_string(reg[index].name, name, capacity, needed);
  });
}

}  // extern "C"
