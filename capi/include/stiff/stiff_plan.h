/* stiff_plan.h - measurement planning through the C ABI (part of stiff.h; include that).
 * Chooses N poses AND loads that identify the joint compliances best (docs/planning.md). */
#ifndef STIFF_PLAN_H
#define STIFF_PLAN_H

#include "stiff/stiff.h"

#ifdef __cplusplus
extern "C" {
#endif

/** A planned set of measurements (opaque). @since 0.1 */
typedef struct stiff_plan stiff_plan;

/** Progress of planning: optimizer name ("annealing", "exchange", "nlopt"), iteration of
 *  total (0: unknown) and the best score so far. Return 0 to continue, non-zero to stop (the
 *  call then returns STIFF_E_CANCELLED). Called on the calling thread. Its counters are
 *  uint64_t and identification's (stiff_progress_fn) uint32_t: both stay as released
 *  (changing either would break the ABI). @since 0.1 */
typedef int (*stiff_plan_progress_fn)(
    const char* optimizer, uint64_t iteration, uint64_t total, double best_score, void* user_data);

/** Optimizers, a bit mask. @since 0.1 */
#define STIFF_PLAN_ANNEALING 1u /**< the paper's simulated annealing */
#define STIFF_PLAN_EXCHANGE 2u  /**< Fedorov exchange */
#define STIFF_PLAN_REFINE 4u    /**< NLopt continuous refinement of the discrete result */

/** Planning options; zero fields take the defaults in brackets. The pointers (criterion,
 *  q_fixed, candidate_file, task, fixture_directions, fixture_forces_N, progress_user_data)
 *  are borrowed for the duration of stiff_plan_create: read during it, never kept; a plan
 *  never refers to them. @since 0.1 */
typedef struct stiff_plan_options {
  uint32_t struct_size;
  uint32_t count;                /**< measurements N [10] */
  const char* criterion;         /**< d_opt, kappa_a, kappa_j, a_opt, e_opt, o1, task [d_opt] */
  uint64_t seed;                 /**< random seed; same seed, same plan [1] */
  uint32_t pool_poses;           /**< random candidate poses [500] */
  uint32_t pool_loads;           /**< candidate loads [100] */
  double range_fraction;         /**< poses within this fraction of each joint range [0.95] */
  double load_min_N;             /**< per-axis load magnitude, lower bound [15] */
  double load_max_N;             /**< per-axis load magnitude, upper bound [35] */
  double load_step_N;            /**< grid step of the magnitudes [5]; negative: continuous */
  double load_max_magnitude_N;   /**< largest |F| [unlimited] */
  double min_sigma_m;            /**< reject poses whose translational Jacobian has a smallest
                                      singular value below this [0.05 m] */
  const double* q_fixed;         /**< per joint a value [rad] to hold it at, NaN = free; may be
                                      NULL (all free) */
  size_t q_fixed_count;          /**< number of values in q_fixed (the robot's dof) */
  uint32_t optimizers;           /**< STIFF_PLAN_* mask [ANNEALING | EXCHANGE] */
  uint32_t annealing_iterations; /**< [100000] */
  const char* candidate_file;    /**< CSV whose poses are the candidates; NULL: random */
  const stiff_dataset* task;     /**< task poses and loads for the `task` criterion */
  double tracker_sigma_m;        /**< row weighting noise [10e-6] */
  double tracker_ppm;            /**< distance-proportional tracker noise [0] */
  stiff_plan_progress_fn progress;
  void* progress_user_data;
  uint32_t use_workspace_box; /**< non-zero: keep only poses whose measured point lies in the
                                   box below */
  double box_min_m[3];        /**< workspace box, base frame [m] */
  double box_max_m[3];
  const double* fixture_directions; /**< k x 3 load directions of a loading fixture (base frame,
                                         normalised inside); NULL: per-axis loads as above */
  size_t fixture_direction_count;   /**< k */
  const double* fixture_forces_N;   /**< force magnitudes applied along each direction [N] */
  size_t fixture_force_count;
  /* Appended fields: a caller whose struct_size ends before them gets the defaults. */
  double annealing_initial_temperature;  /**< T0 in cost units; 0 = automatic [0]; negative or
                                              non-finite: INVALID_ARGUMENT. @since 0.1 */
  uint32_t annealing_initial_swap_count; /**< k0; 0 = automatic, max(1, N/3) [0]; capped at N
                                              and at pool - N. @since 0.1 */
} stiff_plan_options;

/** Fill *options with the library's defaults (the values in brackets above; the automatic
 *  choices stay 0) and struct_size = sizeof(stiff_plan_options), the one place where the
 *  defaults are written (libgit2's options_init convention). Callers then change only the
 *  fields they mean to set. struct_size: sizeof(stiff_plan_options) as the caller knows it;
 *  fields beyond it are not touched. Errors: INVALID_ARGUMENT (NULL, struct_size smaller than
 *  the first released struct or not the end of one of its versions).
 *  @since 0.1 */
STIFF_API stiff_status stiff_plan_options_init(stiff_plan_options* options, size_t struct_size);

/** Plan measurements for robot. Errors: INVALID_ARGUMENT (count larger than the pool, too few
 *  to identify the compliances, empty load range, every pose singular, unknown criterion,
 *  negative or non-finite annealing_initial_temperature),
 *  PARSE/IO (candidate file), CANCELLED. Release with stiff_plan_destroy. @since 0.1 */
STIFF_API stiff_status stiff_plan_create(stiff_plan** out,
                                         const stiff_robot* robot,
                                         const stiff_plan_options* options);
/** Release a plan; NULL is a no-op. @since 0.1 */
STIFF_API void stiff_plan_destroy(stiff_plan* plan);
/** The plan as a plan file (a measurement dataset without displacements, with extra columns
 *  fx_flange_N, fy_flange_N, fz_flange_N, contribution). Release with stiff_dataset_destroy.
 *  @since 0.1 */
STIFF_API stiff_status stiff_plan_dataset(stiff_dataset** out, const stiff_plan* plan);
/** JSON summary: criterion, value, which optimizer found the set, every criterion's value,
 *  optimizer traces, pool size, the measurements. UTF-8 with NUL, buffer in bytes.
 *  @since 0.1 */
STIFF_API stiff_status stiff_plan_json(char* json,
                                       size_t capacity,
                                       size_t* needed,
                                       const stiff_plan* plan);
/** Every criterion's value (JSON object name -> value; also "count", "m") for any given set of
 *  poses and loads, e.g. a printed design. tracker_sigma_m weights the rows (0: the planning
 *  default, stiff_plan_options_init's tracker_sigma_m). @since 0.1 */
STIFF_API stiff_status stiff_criteria_json(char* json,
                                           size_t capacity,
                                           size_t* needed,
                                           const stiff_robot* robot,
                                           const stiff_dataset* set,
                                           double tracker_sigma_m);
/** As stiff_criteria_json, with the task poses and loads that the `task` criterion needs
 *  (task may be NULL: its value is then null). @since 0.1 */
STIFF_API stiff_status stiff_criteria_task_json(char* json,
                                                size_t capacity,
                                                size_t* needed,
                                                const stiff_robot* robot,
                                                const stiff_dataset* set,
                                                const stiff_dataset* task,
                                                double tracker_sigma_m);
/** Number of criteria. @since 0.1 */
STIFF_API size_t stiff_criterion_count(void);
/** Name of criterion `index` (0 .. count-1), UTF-8 with NUL; buffer in bytes. @since 0.1 */
STIFF_API stiff_status stiff_criterion_name(char* name,
                                            size_t capacity,
                                            size_t* needed,
                                            size_t index);

#ifdef __cplusplus
}
#endif
#endif /* STIFF_PLAN_H */
