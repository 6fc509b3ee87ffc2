// Compensation benchmark (docs/benchmarks.md, "Compensation"): points per second of the
// analytic IK (one nearest solution, all branches), the numerical IK (UR5) and the full path
// compensation (IK with branch kept + 6-D quasi-Newton compensation) on the rokae arm with the
// paper's joint stiffness, a contour path and a constant milling wrench.
#include <benchmark/benchmark.h>

#include <cmath>
#include <string>

#include "stiff/compensate/compensate.hpp"
#include "stiff/io/robot_io.hpp"
#include "stiff/sim/simulate.hpp"

namespace {

using namespace stiff;

const RobotModel& rokae() {
  static const RobotModel r =
      load_robot(std::string(STIFF_SOURCE_DIR) + "/examples/robots/rokae.yaml");
  return r;
}

// Circle of radius 80 mm, 150 mm below the shoulder, tool down, `n` points.
std::vector<Eigen::Matrix4d> circle(int n) {
  std::vector<Eigen::Matrix4d> poses;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * M_PI * i / n;
    Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
    t.block<3, 3>(0, 0) = Eigen::Vector3d(1, -1, -1).asDiagonal();
    t.block<3, 1>(0, 3) = Eigen::Vector3d(0.45 + 0.08 * std::cos(a), 0.08 * std::sin(a), -0.15);
    poses.push_back(t);
  }
  return poses;
}

Eigen::VectorXd paper_compliance() {
  Eigen::VectorXd k(6);
  k << 5.0914e4, 1.6382e4, 3.1311e4, 7.7911e3, 5.6136e3, 4.0e3;
  return k.cwiseInverse();
}

void BM_IkNearestAnalytic(benchmark::State& state) {
  const InverseKinematics ik(rokae());
  const auto poses = circle(1000);
  Eigen::VectorXd seed = Eigen::VectorXd::Zero(6);
  size_t i = 0;
  for (auto _ : state) {
    IkSolution s;
    ik.solve_nearest(poses[i++ % poses.size()], seed, &s);
    benchmark::DoNotOptimize(s.q.data());
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_IkNearestAnalytic);

void BM_IkNumericalUr5(benchmark::State& state) {
  const RobotModel ur5 = load_robot(std::string(STIFF_SOURCE_DIR) + "/examples/robots/ur5.urdf");
  const InverseKinematics ik(ur5);
  Eigen::VectorXd q(6);
  q << 0.3, -1.0, 1.2, -0.5, 1.1, 0.2;
  std::vector<Eigen::Matrix4d> poses;
  for (int k = 0; k < 100; ++k) {
    Eigen::VectorXd qk = q;
    qk(0) += 0.001 * k;
    poses.push_back(ur5.tool_pose(qk));
  }
  size_t i = 0;
  for (auto _ : state) {
    IkSolution s;
    ik.solve_nearest(poses[i % poses.size()], q, &s);  // seed 0-0.1 rad away: a path step
    ++i;
    benchmark::DoNotOptimize(s.q.data());
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_IkNumericalUr5);

void BM_CompensatePath(benchmark::State& state) {
  const DeflectionModel model(rokae(), {"joint"});
  const Eigen::VectorXd theta = paper_compliance();
  const auto poses = circle(static_cast<int>(state.range(0)));
  Eigen::MatrixXd w(1, 6);
  w << -60, 40, -120, 0, 0, 0;
  for (auto _ : state) {
    const PathCompensation pc = compensate_path(model, theta, poses, w, Eigen::VectorXd());
    benchmark::DoNotOptimize(pc.q_cmd.data());
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_CompensatePath)->Arg(1000)->Unit(benchmark::kMillisecond);

void BM_CompensatePathBacklash(benchmark::State& state) {
  const Truth truth =
      read_truth(std::string(STIFF_SOURCE_DIR) + "/examples/truths/rokae_backlash.yaml", rokae());
  const DeflectionModel model(rokae(), truth.effects);
  const auto poses = circle(1000);
  Eigen::MatrixXd w(1, 6);
  w << -60, 40, -120, 0, 0, 0;
  for (auto _ : state) {
    const PathCompensation pc = compensate_path(model, truth.theta, poses, w, Eigen::VectorXd());
    benchmark::DoNotOptimize(pc.q_cmd.data());
  }
  state.SetItemsProcessed(state.iterations() * 1000);
}
BENCHMARK(BM_CompensatePathBacklash)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
