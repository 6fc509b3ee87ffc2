// Diagnosis cost (docs/diagnosis.md): 60 measurements of the virtual robot with a hidden
// effect, scored against the whole effect library (one fit of the given model, one re-fit with
// the top effect, every candidate's Jacobian), and the --auto loop.
#include <benchmark/benchmark.h>

#include "stiff/diagnose/diagnose.hpp"
#include "stiff/io/robot_io.hpp"
#include "stiff/model/model.hpp"
#include "stiff/sim/simulate.hpp"

namespace {

struct Fixture {
  stiff::RobotModel robot =
      stiff::load_robot(std::string(STIFF_SOURCE_DIR) + "/examples/robots/rokae.yaml");
  stiff::Dataset calib, valid;
  Fixture() {
    stiff::DeflectionModel m(robot, {"joint", "force_frame"});
    stiff::Truth t;
    t.effects = {"joint", "force_frame"};
    t.theta = m.null_parameters();
    const double k[6] = {5.0914e4, 1.6382e4, 3.1311e4, 7.7911e3, 5.6136e3, 4.0e3};
    for (int j = 0; j < 6; ++j) t.theta(j) = 1.0 / k[j];
    t.theta(m.offset(1) + 2) = 0.087;
    stiff::NoiseModel n;
    n.tracker_sigma_m = 10e-6;
    n.tracker_ppm = 5;
    n.force_relative = 0.01;
    n.force_absolute_N = 0.3;
    stiff::RandomDesignOptions o;
    o.count = 60;
    calib = stiff::simulate(robot, t, stiff::random_design(robot, o), n);
    o.count = 40;
    o.seed = 2;
    n.seed = 2;
    valid = stiff::simulate(robot, t, stiff::random_design(robot, o), n);
  }
};

const Fixture& fixture() {
  static const Fixture f;
  return f;
}

/// The calibration data as new to the library: one reading moved by k picometres, so that no
/// result of an earlier iteration (backlash's preload search is kept for a model built again on
/// the same data) is reused. Built outside the timed region.
stiff::Dataset fresh(const stiff::Dataset& calib, int k) {
  stiff::Dataset c = calib;
  c.rows[0].displacement.x() += 1e-12 * k;
  return c;
}

void BM_Diagnose60WholeLibrary(benchmark::State& state) {
  const Fixture& f = fixture();
  int k = 0;
  for (auto _ : state) {
    state.PauseTiming();
    const stiff::Dataset calib = fresh(f.calib, ++k);
    state.ResumeTiming();
    const stiff::Diagnosis d = stiff::diagnose(f.robot, calib, &f.valid, {"joint"});
    benchmark::DoNotOptimize(d.verdict.data());
  }
}
BENCHMARK(BM_Diagnose60WholeLibrary)->Unit(benchmark::kMillisecond);

void BM_Diagnose60Auto(benchmark::State& state) {
  const Fixture& f = fixture();
  stiff::DiagnosisOptions o;
  o.auto_loop = true;
  int k = 0;
  for (auto _ : state) {
    state.PauseTiming();
    const stiff::Dataset calib = fresh(f.calib, ++k);
    state.ResumeTiming();
    const stiff::Diagnosis d = stiff::diagnose(f.robot, calib, &f.valid, {"joint"}, o);
    benchmark::DoNotOptimize(d.verdict.data());
  }
}
BENCHMARK(BM_Diagnose60Auto)->Unit(benchmark::kMillisecond);

void BM_DiagnosisJson(benchmark::State& state) {
  const Fixture& f = fixture();
  const stiff::Diagnosis d = stiff::diagnose(f.robot, f.calib, &f.valid, {"joint"});
  for (auto _ : state) benchmark::DoNotOptimize(stiff::diagnosis_to_json(d).size());
}
BENCHMARK(BM_DiagnosisJson)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
