/// \file plan.hpp
/// Measurement planning: choose the poses AND the loads of a stiffness experiment so
/// that measurement errors leak as little as possible into the identified joint compliances.
///
/// The method follows Jiang & Fang (2023), section 2.2: a pool Omega = Omega_J x Omega_F of
/// candidate poses and loads, a criterion on the stacked observation matrix A of a chosen set
/// (the paper's kappa_F^-1(A), Jiang & Fang 2023), and simulated annealing over N-element subsets.
/// Beside it: further criteria (D, A, E optimality, the observability index O1, a task-oriented
/// prediction error), a Fedorov-style exchange algorithm and a continuous NLopt refinement.
/// The maths is in docs/planning.md.
///
/// Notation used below (all SI, base frame unless stated):
///  - n: joint count; m: number of identified compliances (the joints whose column of A is not
///    identically zero, e.g. m = 5 for the paper's setup where joint 6 drops).
///  - element i of the pool: one pose q_i and one force F_i at the load point. Its observation
///    block A_i (3 x m) is observation_block() (model.hpp) restricted to the identified columns:
///    A_i[r, k] = Jp(q_i)[r, j_k] * (Jl(q_i)[:, j_k] . F_i).
///  - row weight: each element is weighted by 1/sigma_i, sigma_i the tracker's per-axis sigma
///    at the tool point (NoiseModel::tracker_sigma_at); a constant sigma leaves every
///    scale-free criterion (kappa_a, kappa_j) unchanged.
///  - information matrix M = sum_i A_i^T A_i / sigma_i^2 (m x m), the inverse covariance of the
///    least-squares compliances.
///
/// Threading: every function is reentrant; a CandidatePool is immutable once finalized and may
/// be shared between threads. Randomness uses stiff::Rng seeded from the options: the same
/// seed gives the same plan on every platform.
/// @since 0.1
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include "stiff/io/dataset.hpp"
#include "stiff/kinematics/robot_model.hpp"
#include "stiff/sim/simulate.hpp"

namespace stiff {

// ------------------------------------------------------------------------------------------
// Candidate pool
// ------------------------------------------------------------------------------------------

/// How the pool of candidate poses and loads is built (build_pool()).
struct PoolOptions {
  // --- poses ---
  /// Number of random candidate poses kept (after rejection). Ignored with a candidate file.
  int pose_count = 500;
  /// Poses are uniform in this fraction of each joint's range, centred (paper: 0.95).
  double range_fraction = 0.95;
  /// Per joint: a value [rad] to hold the joint at, or NaN for free; empty = all free
  /// (the paper holds q6 = 0).
  std::vector<double> q_fixed;
  /// Reject near-singular poses: smallest singular value of the 3 x n translational Jacobian at
  /// the measured point below this [m]. Reported back in CandidatePool::min_sigma_m.
  double min_sigma_m = 0.05;
  /// Optional workspace box for the tool (measured point) position, base frame [m].
  bool use_workspace_box = false;
  Eigen::Vector3d box_min_m = Eigen::Vector3d::Constant(-1e9);
  Eigen::Vector3d box_max_m = Eigen::Vector3d::Constant(1e9);
  /// Optional measurement or plan CSV (read_measurements_csv) whose poses are the candidates
  /// (duplicates removed). Singular and out-of-box poses are still rejected.
  std::string candidate_file;
  /// With a candidate file: true = the file's rows (pose, force) are the pool elements as they
  /// are; false = its poses are crossed with the load candidates below.
  bool candidate_loads_from_file = false;

  // --- loads (force at the load point, base frame) ---
  /// Per-axis magnitude range [N]; each component gets a random sign. load_min_N may be 0.
  double load_min_N = 15.0;
  double load_max_N = 35.0;
  /// Grid step of the per-axis magnitudes [N] (paper: 5 N); 0 = continuous.
  double load_step_N = 5.0;
  /// Maximum force magnitude |F| [N]; loads above are rejected.
  double load_max_magnitude_N = std::numeric_limits<double>::infinity();
  /// Number of load candidates drawn (distinct where possible); 0 = the whole grid (needs a
  /// step, at most 1e5 loads).
  int load_count = 100;
  /// Fixed set of fixture directions (base frame, normalised internally); when non-empty the
  /// loads are every direction times every value of fixture_forces_N, and the per-axis range
  /// is not used.
  std::vector<Eigen::Vector3d> fixture_directions;
  std::vector<double> fixture_forces_N;

  // --- weighting, size, seed ---
  /// Tracker noise: row weights 1/sigma(p) with sigma from tracker_sigma_at(tool position).
  NoiseModel noise;
  /// Largest allowed pool (poses x loads).
  long max_elements = 1000000;
  uint64_t seed = 1;
};

namespace plan_detail {
struct KernelData;  // the planner's private packed data (plan_internal.hpp)
}  // namespace plan_detail

/// Candidate pool Omega: poses with their Jacobians, loads, and the list of elements
/// (pose index, load index). Fields are public for the planning kernels; call finalize() after
/// filling them by hand. Memory: O(poses * n + elements).
struct CandidatePool {
  int dof = 0;
  /// Identified joints (0-based), m = identified_joints.size(). Filled by finalize() when empty:
  /// the joints whose observation column is not identically zero over the pool.
  std::vector<int> identified_joints;
  /// Candidate poses q [rad] (size P).
  std::vector<Eigen::VectorXd> poses;
  /// Translational Jacobians (3 x n) at the measured point and at the load point, per pose.
  std::vector<Eigen::Matrix3Xd> jacobian_meas;
  std::vector<Eigen::Matrix3Xd> jacobian_load;
  /// Flange orientation R_flange (base <- flange) per pose.
  std::vector<Eigen::Matrix3d> flange_rotation;
  /// Tool (measured point) position per pose [m].
  std::vector<Eigen::Vector3d> tool_position_m;
  /// Tracker sigma per pose [m] (row weight 1/sigma) and smallest singular value of the
  /// translational Jacobian per pose [m].
  std::vector<double> sigma_m;
  std::vector<double> sigma_min_m;
  /// Candidate loads: force at the load point, base frame [N] (size L).
  std::vector<Eigen::Vector3d> forces;
  /// Elements: element e is (poses[element_pose[e]], forces[element_load[e]]).
  std::vector<int> element_pose;
  std::vector<int> element_load;

  /// Construction record: singularity threshold used [m], poses drawn and rejected.
  double min_sigma_m = 0.0;
  long poses_drawn = 0;
  long rejected_singular = 0;
  long rejected_workspace = 0;
  /// The options it was built with (refinement uses the joint, box and load limits).
  PoolOptions options;

  /// Packed data of the planning kernels, written by finalize(): private to the planner,
  /// immutable once written and shared by copies of the pool. Null before finalize().
  std::shared_ptr<const plan_detail::KernelData> kernel;

  int size() const { return static_cast<int>(element_pose.size()); }
  int identified_count() const { return static_cast<int>(identified_joints.size()); }
  /// Observation block A_e (3 x m, unweighted), from observation_block() semantics.
  Eigen::Matrix<double, 3, Eigen::Dynamic> block(int element) const;
  /// Weighted contribution A_e^T A_e / sigma_e^2 (m x m).
  Eigen::MatrixXd information(int element) const;
  /// Check sizes, determine identified joints (if empty) and write the kernel data.
  /// Throws InvalidArgument on inconsistent sizes or when no joint is identifiable.
  void finalize();
};

/// Build a pool from options: random poses (or a candidate file) x loads.
/// Throws InvalidArgument: bad ranges, empty load range, every pose singular or outside the
/// box, pool larger than max_elements; ParseError/IoError from the candidate file.
CandidatePool build_pool(const RobotModel& robot, const PoolOptions& options);

/// Pool whose elements are the rows of a dataset (pose, force), e.g. a printed design.
/// Moments must be zero. Poses are not rejected (min_sigma_m only recorded).
CandidatePool pool_from_dataset(const RobotModel& robot,
                                const Dataset& data,
                                const NoiseModel& noise = NoiseModel());

// ------------------------------------------------------------------------------------------
// Criteria
// ------------------------------------------------------------------------------------------

/// What a criterion sees of a chosen set of N elements.
struct CriterionInput {
  /// M = sum_i A_i^T A_i / sigma_i^2 (m x m).
  Eigen::MatrixXd information;
  /// J^T J of the stacked translational Jacobians at the measured point, identified columns,
  /// unweighted [m^2] (m x m): pose only, for kappa_j.
  Eigen::MatrixXd jacobian_information;
  /// S = mean_t B_t^T B_t of the task blocks (m x m); empty when there is no task.
  Eigen::MatrixXd task_information;
  /// Number of elements N (3N rows).
  int count = 0;
};

/// One criterion. `value` is the criterion in its natural form and sign (e.g. a_opt is
/// tr(M^-1), to be minimised); `larger_is_better` says which way is good. The optimizers
/// maximise score = larger_is_better ? value : -value. A singular M gives the worst value
/// (0 for kappa_a, kappa_j, e_opt, o1; -inf for d_opt; +inf for a_opt and task).
struct Criterion {
  std::string name;
  std::string description;
  bool larger_is_better = true;
  std::function<double(const CriterionInput&)> value;
};

/// Registry of the criteria, in this order:
///  kappa_a  m / sqrt(tr(M) tr(M^-1))                           (paper eq. 9; maximise)
///  kappa_j  m / sqrt(tr(J^T J) tr((J^T J)^-1))                 (paper eq. 6; maximise)
///  d_opt    log det M                                          (maximise)
///  a_opt    tr(M^-1) [(rad/(N*m))^2]                           (minimise)
///  e_opt    smallest eigenvalue of M                           (maximise)
///  o1       (prod sigma_k(A_w))^(1/m) / sqrt(N) = det(M)^(1/2m) / sqrt(N)  (maximise)
///  task     sqrt(tr(M^-1 S) / 3) [m]: expected RMS error of the predicted deflection over the
///           task poses and loads (minimise; needs a task)
const std::vector<Criterion>& criterion_registry();
/// Criterion by name; throws InvalidArgument listing the known names.
const Criterion& find_criterion(const std::string& name);
std::vector<std::string> criterion_names();
/// score = larger_is_better ? value : -value (NaN -> -inf).
double criterion_score(const Criterion& c, double value);

/// Options of evaluate_criteria().
struct CriteriaOptions {
  NoiseModel noise;  ///< row weights, as in PoolOptions::noise
  Dataset task;      ///< task poses and loads for `task`; no rows = no task (value NaN)
  /// Identified joints (0-based); empty = joints whose column of A is not identically zero.
  std::vector<int> identified_joints;
};

/// Every criterion's value for a given set (any dataset with poses and forces, moments are
/// used as in observation_block()). Keys are the registry names, plus "count" (N) and "m".
/// Throws InvalidArgument for invalid rows or when nothing is identifiable.
std::map<std::string, double> evaluate_criteria(const RobotModel& robot,
                                                const Dataset& data,
                                                const CriteriaOptions& options = CriteriaOptions());

// ------------------------------------------------------------------------------------------
// Incremental information matrix (the kernel of the set optimizers)
// ------------------------------------------------------------------------------------------

/// M of a set of pool elements, kept up to date under element replacement by rank-3 updates
/// (add A_in^T A_in, subtract A_out^T A_out) without rebuilding A. refresh() recomputes it from
/// scratch to bound round-off; the optimizers refresh every AnnealingOptions::refresh_interval.
class IncrementalInformation {
 public:
  IncrementalInformation(const CandidatePool& pool, std::vector<int> elements);
  /// Replace the element at `position` of the set by pool element `element`.
  void replace(int position, int element);
  const std::vector<int>& elements() const { return elements_; }
  /// Current (incrementally updated) M, m x m symmetric.
  Eigen::MatrixXd information() const;
  /// M summed from scratch for the current elements.
  Eigen::MatrixXd recomputed_information() const;
  void refresh();

 private:
  const CandidatePool* pool_;
  std::vector<int> elements_;
  std::vector<double> m_;  // lower triangle of M, row-major m x m
};

// ------------------------------------------------------------------------------------------
// Optimizers
// ------------------------------------------------------------------------------------------

/// Passed to the progress callback about every PlanOptions::progress_interval iterations.
struct PlanProgress {
  std::string optimizer;  ///< "annealing", "exchange" or "nlopt"
  long iteration = 0;
  long total = 0;              ///< planned iterations (0 if unknown)
  double best_score = 0.0;     ///< best score so far (larger is better)
  double current_score = 0.0;  ///< score of the current set
  double temperature = 0.0;    ///< annealing only
};

/// Simulated annealing exactly as the paper (section 2.2).
struct AnnealingOptions {
  bool enabled = true;
  long iterations = 100000;
  /// T0 in cost units; 0 = automatic: automatic_temperature_fraction times the mean cost
  /// increase of 200 random k0-swaps from the (random) start set.
  double initial_temperature = 0.0;
  /// The automatic T0 as a fraction of that mean. The cost increases that matter near good sets
  /// are about a hundredth of those around a random set; 0.01 gave the best designs over
  /// kappa_a, d_opt and a_opt, pools of 1e3 to 1e5 and 1e4 to 1e6 iterations (1.0, the classical
  /// rule, ran hot for most of the schedule: docs/planning.md, "Initial temperature").
  double automatic_temperature_fraction = 0.01;
  /// k0: elements swapped per step at the start; k falls linearly to 1 over the iterations:
  /// k(t) = max(1, ceil(k0 * (1 - t / iterations))). 0 = automatic: max(1, N / 3).
  int initial_swap_count = 0;
  /// Recompute M from scratch every this many accepted steps.
  int refresh_interval = 1000;
};

/// Modified Fedorov exchange (Cook & Nachtsheim): for each position of the set, the pool
/// element that improves the criterion most replaces it; passes until no exchange improves.
struct ExchangeOptions {
  bool enabled = true;
  int max_passes = 50;
  /// Candidates tried per position: all pool elements when N * pool <= this, else a fresh
  /// random sample of this / N elements per position.
  long max_evaluations_per_pass = 2000000;
};

/// Continuous refinement with NLopt of the chosen poses (free joints) and loads, starting from
/// the discrete result, within the pool's joint range, singularity threshold, box and load
/// limits (per-axis magnitude range keeping each component's sign, maximum magnitude). The
/// grid step of the loads is not kept. Never returns a worse set than its start.
struct RefineOptions {
  bool enabled = false;
  std::string algorithm = "LN_BOBYQA";  ///< any derivative-free NLopt name, e.g. LN_COBYLA
  int max_evaluations = 3000;
  bool refine_loads = true;  ///< false (or fixture directions): loads stay as chosen
};

/// Options of plan_measurements().
struct PlanOptions {
  int count = 10;  ///< N, number of measurements (3N >= m)
  /// Registry name. The default d_opt predicts deflections best in our Monte-Carlo study of
  /// the paper's setup (docs/paper-study.md); kappa_a (the paper's) stays available.
  std::string criterion = "d_opt";
  uint64_t seed = 1;
  AnnealingOptions annealing;
  ExchangeOptions exchange;
  RefineOptions refine;
  Dataset task;  ///< task poses and loads for the `task` criterion
  /// Return false to stop: the optimizer then throws stiff::Cancelled.
  std::function<bool(const PlanProgress&)> progress;
  long progress_interval = 1000;
};

/// What one optimizer did.
struct OptimizerTrace {
  std::string optimizer;  ///< "annealing", "exchange", "nlopt"
  double start_score = 0.0;
  double best_score = 0.0;  ///< score of its best set (larger is better)
  double best_value = 0.0;  ///< the criterion's value of that set
  long iterations = 0;      ///< annealing steps, exchange passes, NLopt evaluations
  long evaluations = 0;     ///< evaluated swaps (criterion evaluations)
  long accepted = 0;        ///< accepted steps / exchanges
  double seconds = 0.0;
  double initial_temperature = 0.0;  ///< annealing
  int initial_swap_count = 0;        ///< annealing
  std::string message;               ///< e.g. NLopt's termination reason
};

/// A discrete optimizer's result: indices into the pool.
struct SetSearchResult {
  std::vector<int> elements;
  double score = 0.0;
  OptimizerTrace trace;
};

/// The paper's simulated annealing on the pool (`robot` only serves the task criterion).
/// Throws InvalidArgument (bad count, unknown criterion, task criterion without task) or
/// Cancelled.
SetSearchResult anneal(const RobotModel& robot,
                       const CandidatePool& pool,
                       const PlanOptions& options);
/// Modified Fedorov exchange from a random (seeded) start set, or from `start` when given.
SetSearchResult exchange(const RobotModel& robot,
                         const CandidatePool& pool,
                         const PlanOptions& options,
                         const std::vector<int>* start = nullptr);
/// Score of a set of pool elements under options.criterion (same kernel as the optimizers;
/// options.count is ignored).
double set_score(const RobotModel& robot,
                 const CandidatePool& pool,
                 const std::vector<int>& elements,
                 const PlanOptions& options);

/// One planned measurement.
struct PlannedMeasurement {
  std::string id;                   ///< "p01", ...
  int pool_element = -1;            ///< index in the pool; -1 after continuous refinement
  Eigen::VectorXd q_rad;            ///< joint positions [rad]
  Eigen::Vector3d force_base_N;     ///< force at the load point, base frame [N]
  Eigen::Vector3d force_flange_N;   ///< R_flange^T F: what the operator sets on the fixture [N]
  Eigen::Vector3d tool_position_m;  ///< measured point, base frame [m]
  /// Leverage tr(A_i M^-1 A_i^T / sigma_i^2): share of the information; the leverages of a set
  /// sum to m. Written as the `contribution` column.
  double contribution = 0.0;
  /// score(set) - score(set without this element); +inf when the set needs it to be regular.
  double criterion_drop = 0.0;
};

/// Result of plan_measurements().
struct PlanResult {
  std::string robot;
  std::string criterion;
  bool larger_is_better = true;
  double value = 0.0;  ///< the criterion's value for the final set
  double score = 0.0;
  std::string found_by;  ///< optimizer whose set was kept ("annealing", "exchange", "nlopt")
  std::vector<PlannedMeasurement> measurements;
  /// Every registry criterion's value for the final set (plus "count", "m").
  std::map<std::string, double> criteria;
  std::vector<OptimizerTrace> trace;  ///< one per optimizer run, in run order
  std::vector<int> identified_joints;
  int pool_size = 0;
  int pool_poses = 0;
  int pool_loads = 0;
  double min_sigma_m = 0.0;  ///< singularity threshold of the pool [m]
  uint64_t seed = 0;
};

/// Checks every option that does not need the pool (counts, ranges, the annealing's T0 and
/// k0, the criterion's name); throws InvalidArgument naming the option and the value given.
/// plan_measurements() calls it before building the pool.
void check_plan_options(const PoolOptions& pool, const PlanOptions& plan);

/// Plan N measurements: annealing and/or exchange on the pool (the better set is kept), then
/// the optional NLopt refinement. Throws InvalidArgument (count > pool, 3N < m, unknown
/// criterion, nothing enabled) or Cancelled.
PlanResult plan_measurements(const RobotModel& robot,
                             const CandidatePool& pool,
                             const PlanOptions& options);
/// Same, building the pool first.
PlanResult plan_measurements(const RobotModel& robot,
                             const PoolOptions& pool_options,
                             const PlanOptions& options);

/// Continuous refinement of a planned set (what plan_measurements runs when enabled).
/// Returns the refined measurements and appends its trace to `trace` (may be null).
std::vector<PlannedMeasurement> refine_plan(const RobotModel& robot,
                                            const CandidatePool& pool,
                                            const std::vector<PlannedMeasurement>& start,
                                            const PlanOptions& options,
                                            OptimizerTrace* trace = nullptr);

/// The plan as a plan file (a measurement file without displacements): id, q1..qn [rad],
/// fx_N, fy_N, fz_N (base frame), extra columns fx_flange_N, fy_flange_N, fz_flange_N,
/// contribution; metadata: robot, criterion, every criterion's value, optimizer, seed.
Dataset plan_to_dataset(const PlanResult& result);
/// JSON summary: criterion, value, found_by, every criterion's value, traces, pool, the
/// measurements (q in rad, forces in N). Non-finite numbers are written as null.
std::string plan_summary_json(const PlanResult& result);

}  // namespace stiff
