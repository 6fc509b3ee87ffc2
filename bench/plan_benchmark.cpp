// Measurement planning benchmark: evaluated swaps per second of the paper's simulated annealing
// (N = 10, m = 5, ROKAE arm) and the time to the final set, for pools of 1e3, 1e4, 1e5 elements.
//
//   plan_benchmark [google benchmark flags]
//   plan_benchmark --dump-pool <file> <poses> <loads>   write the pool for bench/plan_compare.py
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <string>

#include "stiff/io/robot_io.hpp"
#include "stiff/plan/plan.hpp"

namespace {

using namespace stiff;

const RobotModel& robot() {
  static const RobotModel r =
      load_robot(std::string(STIFF_SOURCE_DIR) + "/examples/robots/rokae.yaml");
  return r;
}

// Pool of poses x loads, paper setup (q6 = 0, loads multiples of 5 N in 15..35 N per axis).
const CandidatePool& pool(int poses, int loads) {
  static std::map<std::pair<int, int>, CandidatePool> cache;
  auto it = cache.find({poses, loads});
  if (it != cache.end()) return it->second;
  PoolOptions o;
  o.pose_count = poses;
  o.load_count = loads;
  o.q_fixed = {NAN, NAN, NAN, NAN, NAN, 0.0};
  o.seed = 42;
  return cache.emplace(std::make_pair(poses, loads), build_pool(robot(), o)).first->second;
}

int poses_for(long size) { return size <= 1000 ? 100 : (size <= 10000 ? 200 : 1000); }

// Evaluated swaps per second: one annealing run of `iterations` steps per benchmark iteration.
void anneal_swaps(benchmark::State& state, double temperature_fraction) {
  const long size = state.range(0);
  const int p = poses_for(size);
  const CandidatePool& pl = pool(p, static_cast<int>(size / p));
  PlanOptions o;
  o.count = 10;
  o.criterion = "kappa_a";  // the paper's criterion (the library default is d_opt)
  o.annealing.iterations = 100000;
  o.annealing.automatic_temperature_fraction = temperature_fraction;
  double t0used = 0;
  long swaps = 0, accepted = 0;
  double score = 0;
  for (auto _ : state) {
    const SetSearchResult r = anneal(robot(), pl, o);
    swaps += r.trace.evaluations;
    accepted += r.trace.accepted;
    score = r.score;
    t0used = r.trace.initial_temperature;
    benchmark::DoNotOptimize(r.elements.data());
  }
  state.counters["swaps_per_s"] =
      benchmark::Counter(static_cast<double>(swaps), benchmark::Counter::kIsRate);
  state.counters["kappa_a"] = score;
  state.counters["accepted"] = swaps > 0 ? static_cast<double>(accepted) / swaps : 0.0;
  state.counters["pool"] = static_cast<double>(pl.size());
  state.counters["T0"] = t0used;
  state.SetLabel("N=10 m=5 iterations=1e5");
}
// The default automatic T0 (about 0.1 % of the moves accepted).
void BM_AnnealSwaps(benchmark::State& state) { anneal_swaps(state, 0.01); }
// The classical T0 = mean uphill cost change (about half the moves accepted): a hot chain
// whose decisions the processor cannot predict, for comparison.
void BM_AnnealSwapsClassicalT0(benchmark::State& state) { anneal_swaps(state, 1.0); }
BENCHMARK(BM_AnnealSwaps)->Arg(1000)->Arg(10000)->Arg(100000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_AnnealSwapsClassicalT0)
    ->Arg(1000)
    ->Arg(10000)
    ->Arg(100000)
    ->Unit(benchmark::kMillisecond);

// Time to the final set, the whole plan_measurements (annealing only; pool prebuilt).
void BM_PlanToFinalSet(benchmark::State& state) {
  const long size = state.range(0);
  const int p = poses_for(size);
  const CandidatePool& pl = pool(p, static_cast<int>(size / p));
  PlanOptions o;
  o.count = 10;
  o.criterion = "kappa_a";
  o.annealing.iterations = 100000;
  o.exchange.enabled = false;
  for (auto _ : state) {
    const PlanResult r = plan_measurements(robot(), pl, o);
    benchmark::DoNotOptimize(r.value);
  }
}
BENCHMARK(BM_PlanToFinalSet)->Arg(1000)->Arg(10000)->Arg(100000)->Unit(benchmark::kMillisecond);

// Exchange algorithm on the 1e4 pool, for comparison.
void BM_Exchange(benchmark::State& state) {
  const CandidatePool& pl = pool(200, 50);
  PlanOptions o;
  o.count = 10;
  o.criterion = "kappa_a";
  long evals = 0;
  for (auto _ : state) {
    const SetSearchResult r = exchange(robot(), pl, o);
    evals += r.trace.evaluations;
    state.counters["kappa_a"] = r.score;
  }
  state.counters["evals_per_s"] =
      benchmark::Counter(static_cast<double>(evals), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_Exchange)->Unit(benchmark::kMillisecond);

// Building the pool (kinematics of every pose).
void BM_BuildPool(benchmark::State& state) {
  PoolOptions o;
  o.pose_count = static_cast<int>(state.range(0));
  o.load_count = 100;
  o.q_fixed = {NAN, NAN, NAN, NAN, NAN, 0.0};
  for (auto _ : state) benchmark::DoNotOptimize(build_pool(robot(), o).size());
}
BENCHMARK(BM_BuildPool)->Arg(1000)->Unit(benchmark::kMillisecond);

// Binary dump: header "STIFFPOOL" int32 P, L, E, m, then per pose Jm (3 x m, column-major),
// Jl (3 x m), weight 1/sigma^2; per load F (3); per element pose, load (int32).
int dump_pool(const char* path, int poses, int loads) {
  const CandidatePool& p = pool(poses, loads);
  std::ofstream f(path, std::ios::binary);
  if (!f) return 1;
  const int m = p.identified_count();
  const int32_t head[4] = {static_cast<int32_t>(p.poses.size()),
                           static_cast<int32_t>(p.forces.size()), p.size(), m};
  f.write("STIFFPOOL", 9);
  f.write(reinterpret_cast<const char*>(head), sizeof head);
  for (size_t i = 0; i < p.poses.size(); ++i) {
    for (const auto* jac : {&p.jacobian_meas[i], &p.jacobian_load[i]})
      for (int k = 0; k < m; ++k)
        for (int r = 0; r < 3; ++r) {
          const double v = (*jac)(r, p.identified_joints[k]);
          f.write(reinterpret_cast<const char*>(&v), sizeof v);
        }
    const double weight2 = 1.0 / (p.sigma_m[i] * p.sigma_m[i]);
    f.write(reinterpret_cast<const char*>(&weight2), sizeof weight2);
  }
  for (const auto& F : p.forces)
    f.write(reinterpret_cast<const char*>(F.data()), 3 * sizeof(double));
  for (int e = 0; e < p.size(); ++e) {
    const int32_t pe[2] = {p.element_pose[e], p.element_load[e]};
    f.write(reinterpret_cast<const char*>(pe), sizeof pe);
  }
  return f ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 5 && std::strcmp(argv[1], "--dump-pool") == 0)
    return dump_pool(argv[2], std::atoi(argv[3]), std::atoi(argv[4]));
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
